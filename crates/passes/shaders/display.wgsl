// Display pass: the mesh textured with a lightmap, seen by a perspective camera.
// (lights.wgsl and shadow.wgsl, the latter for bind group 2, are prepended.) Mirror:
// src/cpu/display.rs. Host side: src/display.rs.
//
// Two ways to light a pixel:
// - lightmap (fs_filtered*, fs_manual*; the paper's display): L = B/π, B the lightmap's
//   radiosity (W/m²) looked up between texel centres, plus an optional unshadowed
//   Blinn-Phong specular term;
// - per-pixel direct (fs_direct_filtered, fs_direct_manual, vertex shader vs_direct):
//   L = w·ρ·E/π + (1 − w)·B_o/π + T/π (+ shadowed specular), with E the shadowed irradiance
//   of every light at the pixel's own surface point and normal (shadow.wgsl: the first-order
//   pass's shadow maps, 2×2 PCF, normal offset), ρ and the diffusion length ℓ from the
//   `surface` map, B_o the first-order lightmap, T the transferred light final − first
//   order, and w = clamp(1 − ℓ/footprint, 0, 1) the share of per-pixel direct light (1 on
//   diffuse surfaces, ℓ = 0; 0 on subsurface ones whose diffusion length exceeds the
//   pixel's footprint on the surface, which keep the lightmap's diffused light; the
//   direct-only view shows the unscattered first order, so w = 1 there). The bound
//   lightmap is T (SUBSURFACE off: L = ρ·E/π + T/π), or with SUBSURFACE the final light
//   B = B_o + T (L = w·ρ·E/π + (B − w·B_o)/π, so that w = 0 is B/π, what fs_filtered and
//   fs_manual draw for the triangles whose every pixel takes w = 0, src/display_split.rs).
//   Without lightmap (instance index 1: the side-by-side left half and the first-order
//   view) L = ρ·E/π.
// Then exposure, Reinhard L/(1+L) per channel, sRGB encoding, written to an Rgba8Unorm target.
//
// Lookups between texel centres: *_filtered entry points use the sampler's bilinear filter
// (needs FLOAT32_FILTERABLE for RGBA32F maps), *_manual ones textureLoads; the override
// BICUBIC turns the lightmap lookups (not ρ) into a uniform cubic B-spline (4 bilinear taps,
// or 16 loads). Without specular the lightmap pipelines use vs_uv (only the UV is
// interpolated, no light loop); the override SPECULAR switches the direct pipelines' term,
// SUBSURFACE their diffusion-length split (off: w = 1, no derivatives, no first-order lookup),
// LIGHTS their light loop (off where no light reaches a triangle).
//
// Bindings (bind-group order = @binding order; must match `DisplayPass` in display.rs):
//   group 0: 0 = View (uniform), 1 = spec_lights (storage, read; lightmap specular only)
//   group 1: 0 = lightmap (float texture), 1 = bilinear clamp-to-edge sampler (*_filtered
//            only)
//   group 2 (per-pixel direct only): shadow.wgsl's 0 = params, 1 = lights, 2 = layer
//            matrices, 4 = shadow maps, 5 = comparison sampler; 6 = surface (RGBA32F: ρ, ℓ in
//            metres; dilated), 7 = first-order lightmap (dilated)

override BICUBIC: bool = false;
override SPECULAR: bool = false;
override SUBSURFACE: bool = false;
// Off for the triangles no light reaches (src/display_split.rs): no light loop, E = 0.
override LIGHTS: bool = true;

const PI: f32 = 3.14159265358979;

// Must match `DisplayView` in display.rs (112 bytes).
struct View {
    view_proj: mat4x4<f32>,
    // xyz: camera position (m); w: exposure (multiplies radiance, W/(m²·sr) → display units).
    eye_exposure: vec4<f32>,
    lightmap_size: vec2<u32>,
    light_count: u32,
    // 1 = specular on (informative: the pipeline's entry points decide).
    specular_on: u32,
    // x: specular reflectance k_s; y: Blinn-Phong exponent; zw unused.
    specular: vec4<f32>,
}

@group(0) @binding(0) var<uniform> view: View;
@group(0) @binding(1) var<storage, read> spec_lights: array<GpuLight>;
@group(1) @binding(0) var lightmap: texture_2d<f32>;
@group(1) @binding(1) var lightmap_sampler: sampler;
@group(2) @binding(6) var surface: texture_2d<f32>;
@group(2) @binding(7) var first_order_map: texture_2d<f32>;

// Vertex layout: must match `Vertex` in first_order.rs (32 bytes).
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
}

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
}

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    out.clip = view.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.uv = v.uv;
    return out;
}

// Without specular the fragment shader reads only the UV.
struct UvOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) uv: vec2<f32>,
}

@vertex
fn vs_uv(v: VertexIn) -> UvOut {
    return UvOut(view.view_proj * vec4<f32>(v.position, 1.0), v.uv);
}

// Texel-space coordinates of a UV: texel (x, y) has centre u = (x+0.5)/W, v = 1 − (y+0.5)/H,
// so texel centres land on integers.
fn texel_coords(uv: vec2<f32>) -> vec2<f32> {
    let size = vec2<f32>(view.lightmap_size);
    return vec2<f32>(uv.x * size.x, (1.0 - uv.y) * size.y) - 0.5;
}

// textureLoad with the coordinates clamped into the map.
fn load_clamped(t: texture_2d<f32>, i: vec2<i32>) -> vec4<f32> {
    let hi = vec2<i32>(view.lightmap_size) - 1;
    return textureLoad(t, clamp(i, vec2<i32>(0), hi), 0);
}

// Bilinear lookup between texel centres; coordinates clamp at the map border.
fn bilinear_of(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    let st = texel_coords(uv);
    let i0 = floor(st);
    let f = st - i0;
    let a = vec2<i32>(i0);
    let c00 = load_clamped(t, a);
    let c10 = load_clamped(t, a + vec2<i32>(1, 0));
    let c01 = load_clamped(t, a + vec2<i32>(0, 1));
    let c11 = load_clamped(t, a + vec2<i32>(1, 1));
    return mix(mix(c00, c10, f.x), mix(c01, c11, f.x), f.y);
}

// Uniform cubic B-spline weights of the texels at offsets −1, 0, 1, 2 from floor(st), for
// the fraction f (per axis). They sum to 1 and are ≥ 0: a smoothing (not interpolating)
// filter that never over- or undershoots, so it cannot ring at chart borders.
struct BsplineWeights {
    w0: vec2<f32>,
    w1: vec2<f32>,
    w2: vec2<f32>,
    w3: vec2<f32>,
}

fn bspline_weights(f: vec2<f32>) -> BsplineWeights {
    let f2 = f * f;
    let f3 = f2 * f;
    let g = 1.0 - f;
    var w: BsplineWeights;
    w.w0 = g * g * g / 6.0;
    w.w1 = (4.0 - 6.0 * f2 + 3.0 * f3) / 6.0;
    w.w2 = (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) / 6.0;
    w.w3 = f3 / 6.0;
    return w;
}

// Cubic B-spline lookup by 16 clamped loads.
fn bicubic_of(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    let st = texel_coords(uv);
    let i0 = floor(st);
    let w = bspline_weights(st - i0);
    let wx = array<f32, 4>(w.w0.x, w.w1.x, w.w2.x, w.w3.x);
    let wy = array<f32, 4>(w.w0.y, w.w1.y, w.w2.y, w.w3.y);
    let a = vec2<i32>(i0) - 1;
    var out = vec4<f32>(0.0);
    for (var j = 0; j < 4; j++) {
        var row = vec4<f32>(0.0);
        for (var i = 0; i < 4; i++) {
            row += wx[i] * load_clamped(t, a + vec2<i32>(i, j));
        }
        out += wy[j] * row;
    }
    return out;
}

// Bilinear lookup by the sampler: texture coordinates (u, 1 − v) put texel (x, y)'s centre
// where `bilinear_of` has it; clamp-to-edge clamps like its index clamping.
fn filtered_of(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    return textureSampleLevel(t, lightmap_sampler, vec2<f32>(uv.x, 1.0 - uv.y), 0.0);
}

// Cubic B-spline lookup by four bilinear taps: per axis the weight pairs (w0, w1) and
// (w2, w3) become one tap each, at the position between the two texels that the bilinear
// filter weighs in the ratio w1 : w0 (resp. w3 : w2). Clamp-to-edge clamps like the loads.
fn bicubic_filtered_of(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    let size = vec2<f32>(view.lightmap_size);
    let st = texel_coords(uv);
    let i0 = floor(st);
    let w = bspline_weights(st - i0);
    let g0 = w.w0 + w.w1;
    let g1 = w.w2 + w.w3;
    // Tap positions in texel space (centres at integers), then texture coordinates.
    let p0 = (i0 - 1.0 + w.w1 / g0 + 0.5) / size;
    let p1 = (i0 + 1.0 + w.w3 / g1 + 0.5) / size;
    let s00 = textureSampleLevel(t, lightmap_sampler, vec2<f32>(p0.x, p0.y), 0.0);
    let s10 = textureSampleLevel(t, lightmap_sampler, vec2<f32>(p1.x, p0.y), 0.0);
    let s01 = textureSampleLevel(t, lightmap_sampler, vec2<f32>(p0.x, p1.y), 0.0);
    let s11 = textureSampleLevel(t, lightmap_sampler, vec2<f32>(p1.x, p1.y), 0.0);
    return g0.y * (g0.x * s00 + g1.x * s10) + g1.y * (g0.x * s01 + g1.x * s11);
}

// A lightmap lookup with loads: bilinear, or the B-spline when BICUBIC.
fn manual_lookup(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    if (BICUBIC) {
        return bicubic_of(t, uv);
    }
    return bilinear_of(t, uv);
}

// A lightmap lookup with the sampler: bilinear, or the B-spline when BICUBIC.
fn filtered_lookup(t: texture_2d<f32>, uv: vec2<f32>) -> vec4<f32> {
    if (BICUBIC) {
        return bicubic_filtered_of(t, uv);
    }
    return filtered_of(t, uv);
}

// Linear → sRGB transfer function (IEC 61966-2-1) to within 0.012/255: above the linear
// segment, 1.055·c^(1/2.4) − 0.055 is a minimax fit in c^(1/2), c^(1/4), c^(1/8) and c
// (three square roots instead of pow's log2 + exp2). Mirror: cpu::display::srgb_encode,
// same coefficients.
fn srgb_encode(c: vec3<f32>) -> vec3<f32> {
    let lo = c * 12.92;
    let s1 = sqrt(c);
    let s2 = sqrt(s1);
    let s3 = sqrt(s2);
    let hi = 0.642383337 * s1 + 0.712090135 * s2 - 0.336861491 * s3 - 0.0175689720 * c;
    return select(hi, lo, c <= vec3<f32>(0.0031308));
}

// Unshadowed normalised Blinn-Phong radiance k_s·(s+8)/(8π)·(n·h)^s·E·cos summed over the
// lights, W/(m²·sr).
fn specular(world: vec3<f32>, normal: vec3<f32>) -> vec3<f32> {
    let n = normalize(normal);
    let to_eye = normalize(view.eye_exposure.xyz - world);
    let s = view.specular.y;
    var out = vec3<f32>(0.0);
    for (var i = 0u; i < view.light_count; i++) {
        let inc = light_incident(spec_lights[i], world);
        let cos_i = dot(n, inc.to_light);
        if (cos_i > 0.0) {
            let h = normalize(inc.to_light + to_eye);
            let lobe = view.specular.x * (s + 8.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), s);
            out += inc.e_normal * cos_i * lobe;
        }
    }
    return out;
}

// Display colour of a radiance (W/(m²·sr)): exposure, Reinhard, sRGB encoding.
fn display(radiance: vec3<f32>) -> vec4<f32> {
    let l = max(radiance * view.eye_exposure.w, vec3<f32>(0.0));
    return vec4<f32>(srgb_encode(l / (1.0 + l)), 1.0);
}

@fragment
fn fs_filtered(in: UvOut) -> @location(0) vec4<f32> {
    return display(filtered_lookup(lightmap, in.uv).rgb / PI);
}

@fragment
fn fs_manual(in: UvOut) -> @location(0) vec4<f32> {
    return display(manual_lookup(lightmap, in.uv).rgb / PI);
}

@fragment
fn fs_filtered_specular(in: VertexOut) -> @location(0) vec4<f32> {
    return display(filtered_lookup(lightmap, in.uv).rgb / PI + specular(in.world, in.normal));
}

@fragment
fn fs_manual_specular(in: VertexOut) -> @location(0) vec4<f32> {
    return display(manual_lookup(lightmap, in.uv).rgb / PI + specular(in.world, in.normal));
}

// ---- Per-pixel direct light ----

struct DirectOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) world: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) uv: vec2<f32>,
    // 0: add the bound lightmap (transferred light); 1: direct light only.
    @location(3) @interpolate(flat) direct_only: u32,
}

@vertex
fn vs_direct(v: VertexIn, @builtin(instance_index) instance: u32) -> DirectOut {
    var out: DirectOut;
    out.clip = view.view_proj * vec4<f32>(v.position, 1.0);
    out.world = v.position;
    out.normal = v.normal;
    out.uv = v.uv;
    out.direct_only = instance;
    return out;
}

// Per-pixel direct radiance of the lights at p (normal n, interpolated): ρ·E/π with shadowed
// irradiance E (shadow.wgsl) times the share w, plus (SPECULAR) the normalised Blinn-Phong
// term k_s·(s+8)/(8π)·(n·h)^s·E, shadowed too. W/(m²·sr).
fn direct_radiance(p: vec3<f32>, normal: vec3<f32>, rho: vec3<f32>, w: f32) -> vec3<f32> {
    let n = normalize(normal);
    if (!SPECULAR) {
        return (w * rho / PI) * shadowed_irradiance(p, n);
    }
    let to_eye = normalize(view.eye_exposure.xyz - p);
    let s = view.specular.y;
    var e = vec3<f32>(0.0);
    var spec = vec3<f32>(0.0);
    for (var i = 0u; i < params.light_count; i++) {
        let light = lights[i];
        let inc = light_incident(light, p);
        let cos_i = dot(n, inc.to_light);
        if (cos_i > 0.0 && any(inc.e_normal > vec3<f32>(0.0))) {
            let e_light = inc.e_normal * cos_i * shadow_visibility(light, p, n);
            e += e_light;
            let h = normalize(inc.to_light + to_eye);
            spec += e_light * (view.specular.x * (s + 8.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), s));
        }
    }
    return (w * rho / PI) * e + spec;
}

// The larger side of the pixel's footprint on the surface, metres (screen-space derivatives
// of the interpolated world position).
fn pixel_footprint(world: vec3<f32>) -> f32 {
    return max(length(dpdx(world)), length(dpdy(world)));
}

// Share of per-pixel direct light for diffusion length ell (m) and footprint (m).
fn direct_share(ell: f32, footprint: f32) -> f32 {
    return clamp(1.0 - ell / max(footprint, 1e-12), 0.0, 1.0);
}

@fragment
fn fs_direct_filtered(in: DirectOut) -> @location(0) vec4<f32> {
    let s = filtered_of(surface, in.uv);
    var w = 1.0;
    if (SUBSURFACE) {
        // The direct-only view shows the unscattered first order: per pixel everywhere.
        w = select(direct_share(s.a, pixel_footprint(in.world)), 1.0, in.direct_only != 0u);
    }
    var l = vec3<f32>(0.0);
    if (LIGHTS) {
        l = direct_radiance(in.world, in.normal, s.rgb, w);
    }
    if (in.direct_only == 0u) {
        if (SUBSURFACE) {
            // The bound map is the final light B = B_o + T.
            let b_o = filtered_lookup(first_order_map, in.uv).rgb;
            l += (filtered_lookup(lightmap, in.uv).rgb - w * b_o) / PI;
        } else {
            l += filtered_lookup(lightmap, in.uv).rgb / PI;
        }
    }
    return display(l);
}

@fragment
fn fs_direct_manual(in: DirectOut) -> @location(0) vec4<f32> {
    let s = bilinear_of(surface, in.uv);
    var w = 1.0;
    if (SUBSURFACE) {
        // The direct-only view shows the unscattered first order: per pixel everywhere.
        w = select(direct_share(s.a, pixel_footprint(in.world)), 1.0, in.direct_only != 0u);
    }
    var l = vec3<f32>(0.0);
    if (LIGHTS) {
        l = direct_radiance(in.world, in.normal, s.rgb, w);
    }
    if (in.direct_only == 0u) {
        if (SUBSURFACE) {
            // The bound map is the final light B = B_o + T.
            let b_o = manual_lookup(first_order_map, in.uv).rgb;
            l += (manual_lookup(lightmap, in.uv).rgb - w * b_o) / PI;
        } else {
            l += manual_lookup(lightmap, in.uv).rgb / PI;
        }
    }
    return display(l);
}
