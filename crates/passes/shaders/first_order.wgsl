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
// fs_lightmap_averaged: the same with SAMPLES×SAMPLES sub-texels per texel (odd SAMPLES; the
//              G-buffer is SAMPLES× the lightmap's size and its normal.w holds each sub-texel's
//              world area): location 1 (the transfer's input) = ρ × the area-weighted mean of
//              E over the covered sub-texels; location 0 (the lightmap's first-order term) =
//              ρ × mix(mean, E at the centre, albedo.a) — albedo.a = 1 on opaque texels (their
//              own first order is the centre's, as the reference defines it), 0 on translucent
//              ones (their light is the scattered mean). Coverage = the centre sub-texel's,
//              which is the texel's centre (odd SAMPLES).
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
    // The world area of this framebuffer pixel (a texel, or a sub-texel of the averaged
    // pass): |∂P/∂x × ∂P/∂y|, constant over a triangle (P is affine in the pixel's position).
    out.normal = vec4<f32>(in.normal, length(cross(dpdx(in.world), dpdy(in.world))));
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

// Sub-texels per texel side of `fs_lightmap_averaged` (substituted by the host; odd).
const SAMPLES: i32 = SAMPLES_PER_SIDE;

struct AveragedOut {
    @location(0) first_order: vec4<f32>,
    @location(1) transfer_input: vec4<f32>,
}

@fragment
fn fs_lightmap_averaged(@builtin(position) clip: vec4<f32>) -> AveragedOut {
    var out: AveragedOut;
    let t = vec2<i32>(floor(clip.xy));
    let base = t * SAMPLES;
    let c = base + vec2<i32>(SAMPLES / 2);
    let gc = load_gbuffer_position(c);
    if (gc.w == 0.0) {
        out.first_order = vec4<f32>(0.0);
        out.transfer_input = vec4<f32>(0.0);
        return out;
    }
    let centre = shadowed_irradiance(gc.xyz, normalize(load_gbuffer_normal(c).xyz));
    var sum = vec3<f32>(0.0);
    var area = 0.0;
    for (var sy = 0; sy < SAMPLES; sy++) {
        for (var sx = 0; sx < SAMPLES; sx++) {
            let s = base + vec2<i32>(sx, sy);
            let g = load_gbuffer_position(s);
            if (g.w == 0.0) {
                continue;
            }
            let nrm = load_gbuffer_normal(s);
            sum += nrm.w * shadowed_irradiance(g.xyz, normalize(nrm.xyz));
            area += nrm.w;
        }
    }
    var mean = centre;
    if (area > 0.0) {
        mean = sum / area;
    }
    let albedo = load_albedo(t);
    out.transfer_input = vec4<f32>(albedo.rgb * mean, 1.0);
    out.first_order = vec4<f32>(albedo.rgb * mix(mean, centre, albedo.a), 1.0);
    return out;
}
