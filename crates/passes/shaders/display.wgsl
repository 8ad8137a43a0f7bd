// Display pass: the mesh textured with a lightmap, seen by a perspective camera.
// (lights.wgsl is prepended.) Mirror: src/cpu/display.rs. Host side: src/display.rs.
//
// Radiance L = B/π (B: lightmap radiosity, W/m², bilinear between texel centres) plus an
// optional unshadowed Blinn-Phong specular term; then exposure, Reinhard L/(1+L) per
// channel, sRGB encoding, written to an Rgba8Unorm target.
//
// Entry points: lookup fs_filtered* (the sampler's bilinear filter; needs FLOAT32_FILTERABLE
// for RGBA32F lightmaps) or fs_manual* (four textureLoads); without specular vs_uv +
// fs_filtered / fs_manual (only the UV is interpolated and there is no light loop), with it
// vs_main + fs_filtered_specular / fs_manual_specular.
//
// Bindings (bind-group order = @binding order; must match `DisplayPass` in display.rs):
//   group 0: 0 = View (uniform), 1 = lights (storage, read)
//   group 1: 0 = lightmap (float texture), 1 = bilinear clamp-to-edge sampler (fs_filtered
//            only)

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
@group(0) @binding(1) var<storage, read> lights: array<GpuLight>;
@group(1) @binding(0) var lightmap: texture_2d<f32>;
@group(1) @binding(1) var lightmap_sampler: sampler;

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

// Bilinear lookup between texel centres: texel (x, y) has centre u = (x+0.5)/W,
// v = 1 − (y+0.5)/H; coordinates clamp at the map border.
fn bilinear(uv: vec2<f32>) -> vec3<f32> {
    let size = vec2<f32>(view.lightmap_size);
    let st = vec2<f32>(uv.x * size.x, (1.0 - uv.y) * size.y) - 0.5;
    let i0 = floor(st);
    let f = st - i0;
    let hi = vec2<i32>(view.lightmap_size) - 1;
    let a = clamp(vec2<i32>(i0), vec2<i32>(0), hi);
    let b = clamp(vec2<i32>(i0) + 1, vec2<i32>(0), hi);
    let c00 = textureLoad(lightmap, vec2<i32>(a.x, a.y), 0).rgb;
    let c10 = textureLoad(lightmap, vec2<i32>(b.x, a.y), 0).rgb;
    let c01 = textureLoad(lightmap, vec2<i32>(a.x, b.y), 0).rgb;
    let c11 = textureLoad(lightmap, vec2<i32>(b.x, b.y), 0).rgb;
    return mix(mix(c00, c10, f.x), mix(c01, c11, f.x), f.y);
}

// Bilinear lookup by the sampler: texture coordinates (u, 1 − v) put texel (x, y)'s centre
// where `bilinear` has it; clamp-to-edge clamps like `bilinear`'s index clamping.
fn filtered(uv: vec2<f32>) -> vec3<f32> {
    return textureSampleLevel(lightmap, lightmap_sampler, vec2<f32>(uv.x, 1.0 - uv.y), 0.0).rgb;
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
        let inc = light_incident(lights[i], world);
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
    return display(filtered(in.uv) / PI);
}

@fragment
fn fs_manual(in: UvOut) -> @location(0) vec4<f32> {
    return display(bilinear(in.uv) / PI);
}

@fragment
fn fs_filtered_specular(in: VertexOut) -> @location(0) vec4<f32> {
    return display(filtered(in.uv) / PI + specular(in.world, in.normal));
}

@fragment
fn fs_manual_specular(in: VertexOut) -> @location(0) vec4<f32> {
    return display(bilinear(in.uv) / PI + specular(in.world, in.normal));
}
