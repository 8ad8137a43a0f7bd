// Gutter dilation driven by a per-scene source plan (nearest covered texel, built on the CPU:
// `dilation_sources` in src/dilate.rs). Per texel t with source s:
//   s = t (covered in the plan)          → the input texel, unchanged;
//   alpha > 0 in the input               → the input texel, unchanged (never overwritten);
//   s = NO_SOURCE                        → 0;
//   s covered in the input               → its RGB, alpha FILLED_ALPHA;
//   s empty in the input                 → 0 (a map whose coverage differs from the plan's).
// Mirror: src/cpu/dilate.rs. Host side: src/dilate.rs.
//
// fs_dilate runs over one full-screen triangle (vs_fullscreen; inputs that cannot be copied
// into the RGBA32F target) or, after the input was copied into the target, only over
// rectangles holding every texel the plan does not mark covered (vs_rect, one instance per
// rectangle): fs_dilate returns the input at plan-covered texels, so both give the same map.
//
// Bindings (bind-group order = @binding order; must match `DilatePass` in dilate.rs):
//   group 0: 0 = input map (float texture, textureLoad), 1 = sources (R32Uint, x | y << 16)
// Output: the RGBA32F render target (pixel (x, y) = texel (x, y)).

// Must match `FILLED_ALPHA` in dilate.rs.
const FILLED_ALPHA: f32 = 0.5;
// Must match `NO_SOURCE` in dilate.rs.
const NO_SOURCE: u32 = 0xffffffffu;

@group(0) @binding(0) var src: texture_2d<f32>;
@group(0) @binding(1) var sources: texture_2d<u32>;

// Texel t, not covered in the plan, with packed source s.
fn fill(t: vec2<i32>, s: u32) -> vec4<f32> {
    let c = textureLoad(src, t, 0);
    if (c.a > 0.0) {
        return c;
    }
    if (s == NO_SOURCE) {
        return vec4<f32>(0.0);
    }
    let v = textureLoad(src, vec2<i32>(i32(s & 0xffffu), i32(s >> 16u)), 0);
    if (v.a > 0.0) {
        return vec4<f32>(v.rgb, FILLED_ALPHA);
    }
    return vec4<f32>(0.0);
}

@fragment
fn fs_dilate(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let t = vec2<i32>(floor(pos.xy));
    let s = textureLoad(sources, t, 0).r;
    if (s == (u32(t.x) | (u32(t.y) << 16u))) {
        return textureLoad(src, t, 0);
    }
    return fill(t, s);
}

// One rectangle per instance (two triangles, 6 vertices), corners in clip space.
@vertex
fn vs_rect(
    @builtin(vertex_index) vi: u32,
    @location(0) clip_min: vec2<f32>,
    @location(1) clip_max: vec2<f32>,
) -> @builtin(position) vec4<f32> {
    // Corners 0 1 2 / 2 1 3 of (min.x, min.y), (max.x, min.y), (min.x, max.y), (max.x, max.y).
    let corner = array<u32, 6>(0u, 1u, 2u, 2u, 1u, 3u)[vi];
    let x = select(clip_min.x, clip_max.x, (corner & 1u) != 0u);
    let y = select(clip_min.y, clip_max.y, (corner & 2u) != 0u);
    return vec4<f32>(x, y, 0.0, 1.0);
}
