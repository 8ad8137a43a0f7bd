// Gutter dilation in one pass, driven by a per-scene source map (nearest covered texel,
// built on the CPU: `dilation_sources` in src/dilate.rs). Per texel:
//   alpha > 0 in the input (covered)     → the input texel, unchanged;
//   source = NO_SOURCE                   → 0;
//   source texel covered in the input    → its RGB, alpha FILLED_ALPHA;
//   source texel empty in the input      → 0 (a map whose coverage differs from the plan's).
// So covered texels are never overwritten. Mirror: src/cpu/dilate.rs. Host side: src/dilate.rs.
//
// Bindings (bind-group order = @binding order; must match `DilatePass` in dilate.rs):
//   group 0: 0 = input map (float texture, textureLoad), 1 = sources (R32Uint, x | y << 16)
// Output: the RGBA32F render target of one full-screen triangle (pixel (x, y) = texel (x, y)).
// A fragment pass rather than a compute dispatch: lavapipe runs full-screen fragment work in
// 4×4 blocks of 64×64 tiles, which measured faster than 8×8 compute workgroups here.

// Must match `FILLED_ALPHA` in dilate.rs.
const FILLED_ALPHA: f32 = 0.5;
// Must match `NO_SOURCE` in dilate.rs.
const NO_SOURCE: u32 = 0xffffffffu;

@group(0) @binding(0) var src: texture_2d<f32>;
@group(0) @binding(1) var sources: texture_2d<u32>;

@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(vi & 1u) * 4 - 1);
    let y = f32(i32(vi >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

@fragment
fn fs_dilate(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let t = vec2<i32>(floor(pos.xy));
    let c = textureLoad(src, t, 0);
    if (c.a > 0.0) {
        return c;
    }
    let s = textureLoad(sources, t, 0).r;
    if (s == NO_SOURCE) {
        return vec4<f32>(0.0);
    }
    let v = textureLoad(src, vec2<i32>(i32(s & 0xffffu), i32(s >> 16u)), 0);
    if (v.a > 0.0) {
        return vec4<f32>(v.rgb, FILLED_ALPHA);
    }
    return vec4<f32>(0.0);
}
