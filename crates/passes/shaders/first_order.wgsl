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

// Params (binding 0), lights (1), layer matrices (2), shadow maps (4) and the comparison
// sampler (5), with `shadow_visibility`, come from shadow.wgsl (prepended by the host).
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
    let e = shadowed_irradiance(world, n);
    return vec4<f32>(rho * e, 1.0);
}
