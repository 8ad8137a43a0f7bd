// Roofline microbenchmark: full-screen triangles (`vs_fullscreen`, passes' fullscreen.wgsl,
// prepended) writing a constant with additive blending, i.e. pure blended framebuffer
// writes with no texture reads — the upper bound on texel blends per second the transfer
// pass's blend path can reach on this adapter. Host side: roofline.rs (no bindings).

@fragment
fn fs_const() -> @location(0) vec4<f32> {
    return vec4<f32>(1e-3, 2e-3, 3e-3, 0.0);
}
