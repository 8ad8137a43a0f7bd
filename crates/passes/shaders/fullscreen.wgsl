// One triangle covering the whole target (vertices 0..3 at clip (−1, −1), (3, −1), (−1, 3)):
// the vertex stage of every full-screen pass (`util::fullscreen_pipeline`). Prepended to the
// shaders that use it (`util::FULLSCREEN_WGSL`).
@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(vi & 1u) * 4 - 1);
    let y = f32(i32(vi >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

