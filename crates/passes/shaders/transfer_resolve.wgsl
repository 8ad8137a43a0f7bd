// Transfer pass, blend path with receiver blocks: the final lightmap from the accumulation
// target (src/schedule.rs, "Receiver blocks"):
//   final[t] = acc[t] + covered(t) · Σ_{r=1..R} acc[block_origin(r) + ⌊t / 2^r⌋]
// covered(t) = acc[t].a > 0 (the first-order coverage the copy put there; pieces add alpha 0).
// Mirror: src/cpu/transfer.rs (`resolve`). Host side: src/transfer.rs.
//
// Bindings: group 0: binding 0 = Params (uniform, transfer_params.wgsl, prepended),
//           binding 1 = the accumulation target (texture_2d<f32>, any float format).
// Drawn over `vs_fullscreen` (fullscreen.wgsl, prepended) into the W×H final lightmap.

@group(0) @binding(1) var acc_tex: texture_2d<f32>;

@fragment
fn fs_resolve(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    let t = vec2<u32>(floor(pos.xy));
    let own = textureLoad(acc_tex, vec2<i32>(t), 0);
    if (own.a <= 0.0) {
        return own;
    }
    var sum = own.rgb;
    for (var r = 1u; r <= params.receiver_levels; r++) {
        sum += textureLoad(acc_tex, vec2<i32>(block_origin(r) + (t >> vec2<u32>(r))), 0).rgb;
    }
    return vec4<f32>(sum, own.a);
}
