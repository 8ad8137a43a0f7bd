// Roofline microbenchmark: full-screen triangles writing a constant with additive blending,
// i.e. pure blended framebuffer writes with no texture reads — the upper bound on texel
// blends per second the transfer pass's blend path can reach on this adapter.
// Host side: src/bench.rs (no bindings).

@vertex
fn vs_fullscreen(@builtin(vertex_index) vi: u32) -> @builtin(position) vec4<f32> {
    let x = f32(i32(vi & 1u) * 4 - 1);
    let y = f32(i32(vi >> 1u) * 4 - 1);
    return vec4<f32>(x, y, 0.0, 1.0);
}

@fragment
fn fs_const() -> @location(0) vec4<f32> {
    return vec4<f32>(1e-3, 2e-3, 3e-3, 0.0);
}
