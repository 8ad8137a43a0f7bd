// First-order pass: B_o = ρ·E per lightmap texel, with shadow maps.
// (lights.wgsl is prepended.) Mirror: src/cpu/first_order.rs. Host side: src/first_order.rs.
//
// vs_shadow:   mesh positions into one layer of the shadow-map array (layer = instance index).
// vs_gbuffer:  (once per scene) mesh rasterised by its lightmap UVs, clip = (2u − 1, 2v − 1):
//              v = 1 → row 0, so framebuffer pixel (x, y) is lightmap texel (x, y); the
//              rasteriser's centre rule gives exactly the covered texels.
// fs_gbuffer:  world position (w = 1: covered; cleared to 0) and normal interpolated at the
//              texel centre.
// fs_lightmap: (per frame, full-screen triangle) G-buffer position/normal of the texel; E
//              summed over lights with shadows; out = (ρ·E, 1): alpha = 1 marks coverage,
//              uncovered texels 0.
//
// Bindings (bind-group order = @binding order; must match `FirstOrderPass` in first_order.rs):
//   group 0: 0 = Params (uniform), 1 = lights (uniform array), 2 = layer matrices (uniform
//            array), 3 = albedo (RGBA32F), 4 = shadow maps (depth 2D array),
//            5 = comparison sampler, 6 = G-buffer position (RGBA32F, w = coverage),
//            7 = G-buffer normal (RGBA32F)
//   vs_gbuffer/fs_gbuffer use no bindings.

// Must match `FirstOrderParams` in first_order.rs (32 bytes).
struct Params {
    lightmap_size: vec2<u32>,
    light_count: u32,
    shadow_size: u32,
    // Normal offset of shadow lookups in shadow texels.
    normal_offset_texels: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

@group(0) @binding(0) var<uniform> params: Params;
// MAX_LAYERS is replaced by FirstOrderOptions::max_shadow_layers when the module is built
// (uniform, not storage, arrays: llvmpipe reads storage buffers lane by lane).
@group(0) @binding(1) var<uniform> lights: array<GpuLight, MAX_LAYERS>;
@group(0) @binding(2) var<uniform> layer_view_proj: array<mat4x4<f32>, MAX_LAYERS>;
@group(0) @binding(4) var shadow_maps: texture_depth_2d_array;
@group(0) @binding(5) var shadow_sampler: sampler_comparison;
// Bindings 3 (albedo), 6 (gbuffer_position), 7 (gbuffer_normal) and their readers
// load_albedo(t), load_gbuffer_position(t), load_gbuffer_normal(t) are prepended by the host
// (`util::TexelReads::wgsl`: sampled or read-only storage textures).

// Vertex layout: must match `Vertex` in first_order.rs (32 bytes).
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
}

// Shadow pass vertex: positions only (`position_layout` in first_order.rs, 12 bytes).
@vertex
fn vs_shadow(@location(0) position: vec3<f32>, @builtin(instance_index) layer: u32) -> @builtin(position) vec4<f32> {
    return layer_view_proj[layer] * vec4<f32>(position, 1.0);
}

struct GbufferOut {
    @location(0) position: vec4<f32>,
    @location(1) normal: vec4<f32>,
}

@fragment
fn fs_gbuffer(in: LightmapOut) -> GbufferOut {
    var out: GbufferOut;
    out.position = vec4<f32>(in.world, 1.0);
    out.normal = vec4<f32>(in.normal, 0.0);
    return out;
}

// Full-screen triangle over the lightmap (per-frame lighting pass): `vs_fullscreen`
// (fullscreen.wgsl, prepended).
struct LightmapOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
}

@vertex
fn vs_gbuffer(v: VertexIn) -> LightmapOut {
    var out: LightmapOut;
    out.clip = vec4<f32>(2.0 * v.uv.x - 1.0, 2.0 * v.uv.y - 1.0, 0.0, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    return out;
}

// Cube face of a direction, in the order +X, −X, +Y, −Y, +Z, −Z (must match
// `point_face_dirs` in first_order.rs).
fn cube_face(v: vec3<f32>) -> u32 {
    let a = abs(v);
    if (a.x >= a.y && a.x >= a.z) {
        return select(1u, 0u, v.x > 0.0);
    }
    if (a.y >= a.z) {
        return select(3u, 2u, v.y > 0.0);
    }
    return select(5u, 4u, v.z > 0.0);
}

// Fraction of the light reaching p (1 lit, 0 shadowed; 2×2 hardware PCF in between).
fn shadow_visibility(light: GpuLight, p: vec3<f32>, n: vec3<f32>) -> f32 {
    // Normal offset: move the lookup point off the surface by a few shadow texels.
    var texel_m = light.cone.w;
    if (light.kind != LIGHT_DIRECTIONAL) {
        texel_m = light.cone.z * distance(p, light.position.xyz);
    }
    let q = p + n * (params.normal_offset_texels * texel_m);
    var layer = light.first_layer;
    if (light.kind == LIGHT_POINT && light.layer_count == 6u) {
        layer += cube_face(q - light.position.xyz);
    }
    let clip = layer_view_proj[layer] * vec4<f32>(q, 1.0);
    if (clip.w <= 0.0) {
        return 1.0;
    }
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(0.5 * ndc.x + 0.5, 0.5 - 0.5 * ndc.y);
    if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0 || ndc.z < 0.0) {
        return 1.0; // outside the map: nothing there can occlude (maps bound the scene)
    }
    return textureSampleCompareLevel(shadow_maps, shadow_sampler, uv, i32(layer), ndc.z);
}

@fragment
fn fs_lightmap(@builtin(position) clip: vec4<f32>) -> @location(0) vec4<f32> {
    let t = vec2<i32>(floor(clip.xy));
    let g = load_gbuffer_position(t);
    if (g.w == 0.0) {
        return vec4<f32>(0.0);
    }
    let world = g.xyz;
    let rho = load_albedo(t).rgb;
    let n = normalize(load_gbuffer_normal(t).xyz);
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < params.light_count; i++) {
        let light = lights[i];
        let e_light = unshadowed_irradiance(light, world, n);
        if (any(e_light > vec3<f32>(0.0))) {
            e += e_light * shadow_visibility(light, world, n);
        }
    }
    return vec4<f32>(rho * e, 1.0);
}
