// Gutter dilation: one iteration fills every empty texel (alpha = 0) that has a non-empty
// 8-neighbour with the mean of those neighbours, alpha = 0.5 ("filled"); texels with
// alpha > 0 (covered = 1, filled = 0.5) are copied unchanged, so covered texels are never
// overwritten. Mirror: src/cpu/dilate.rs. Host side: src/dilate.rs.
//
// Bindings (bind-group order = @binding order; must match `DilatePass` in dilate.rs):
//   group 0: 0 = Params (uniform), 1 = source (texture, textureLoad)
// Output: the RGBA32F render target of one full-screen triangle (pixel (x, y) = texel (x, y)).
// A fragment pass rather than a compute dispatch: lavapipe runs full-screen fragment work in
// 4×4 blocks of 64×64 tiles, which measured faster than 8×8 compute workgroups here.

// Must match `DilateParams` in dilate.rs (16 bytes).
struct Params {
    size: vec2<u32>,
    _pad: vec2<u32>,
}

// Must match `FILLED_ALPHA` in dilate.rs.
const FILLED_ALPHA: f32 = 0.5;

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var src: texture_2d<f32>;

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
    var sum = vec3<f32>(0.0);
    var n = 0.0;
    for (var dy = -1; dy <= 1; dy++) {
        for (var dx = -1; dx <= 1; dx++) {
            let q = t + vec2<i32>(dx, dy);
            if ((dx == 0 && dy == 0) || any(q < vec2<i32>(0)) || any(q >= vec2<i32>(params.size))) {
                continue;
            }
            let v = textureLoad(src, q, 0);
            if (v.a > 0.0) {
                sum += v.rgb;
                n += 1.0;
            }
        }
    }
    if (n > 0.0) {
        return vec4<f32>(sum / n, FILLED_ALPHA);
    }
    return vec4<f32>(0.0);
}
