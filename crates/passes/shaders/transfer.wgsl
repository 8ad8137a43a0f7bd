// Transfer pass, blend path (paper Eq. 9): final = first_order + Σ_pieces atlas · P_ℓ(⌊t/2^ℓ⌋ + Δ)
// (P_0 = first_order, P_ℓ≥1 = the packed first-order pyramid, src/pyramid.rs). Pieces of
// receiver level r > 0 draw into the receiver-block grid G_r below the lightmap in the same
// target and read P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ) for their block c; transfer_resolve.wgsl then adds G_r
// into the covered texels (src/schedule.rs, "Receiver blocks").
// Mirror: src/cpu/transfer.rs. Host side: src/transfer.rs.
//
// Bindings (bind-group order = @binding order; must match `TransferPass` layouts in transfer.rs):
//   group 0: binding 0 = Params (uniform), binding 1 = first-order lightmap (RGBA32F),
//            binding 2 = packed pyramid levels ≥ 1 (RGBA32F; a 1×1 dummy when no piece has level > 0)
//   group 1: binding 0 = the atlas being drawn (RGBA32F)
// The host prepends the declarations of `first_order`, `pyramid` and `atlas` and their texel
// readers `load_first_order(t)`, `load_pyramid(t)`, `load_atlas(t)` (`util::TexelReads::wgsl`: sampled or read-only
// storage texture, chosen by `TransferOptions::texel_reads`).
// Coordinates: texel (x, y), y down, row 0 = v = 1; framebuffer pixel (x, y) is lightmap texel (x, y).

// Params (binding 0 of group 0): transfer_params.wgsl; `texel_to_clip` and `quad_clip`:
// transfer_quad.wgsl; both prepended by the host.

// Per-instance attributes: must match `PieceInstance` in schedule.rs (56 bytes, locations 0–6).
struct PieceIn {
    @location(0) src: vec2<u32>,
    @location(1) dst: vec2<u32>,
    @location(2) size: vec2<u32>,
    @location(3) offset: vec2<i32>,
    // x = pyramid level ℓ, y = receiver level r ≤ ℓ.
    @location(4) level: vec2<u32>,
    // Origin of level ℓ in the packed pyramid.
    @location(5) origin: vec2<u32>,
    // Origin of G_r in the target ((0, 0) for r = 0).
    @location(6) block_origin: vec2<u32>,
}

struct PieceOut {
    @builtin(position) clip: vec4<f32>,
    // Atlas texel minus destination texel: atlas texel = lightmap texel + src_minus_dst.
    @location(0) @interpolate(flat) src_minus_dst: vec2<i32>,
    @location(1) @interpolate(flat) offset: vec2<i32>,
    // x = ℓ, y = ℓ − r (the shift from a receiver to its sender block).
    @location(2) @interpolate(flat) level: vec2<u32>,
    @location(3) @interpolate(flat) origin: vec2<i32>,
    @location(4) @interpolate(flat) block_origin: vec2<i32>,
}

// One quad (two triangles, 6 vertices) per piece covering texels [dst, dst + size).
@vertex
fn vs_piece(@builtin(vertex_index) vi: u32, piece: PieceIn) -> PieceOut {
    var out: PieceOut;
    out.clip = quad_clip(vi, piece.dst, piece.size);
    out.src_minus_dst = vec2<i32>(piece.src) - vec2<i32>(piece.dst);
    out.offset = piece.offset;
    out.level = vec2<u32>(piece.level.x, piece.level.x - piece.level.y);
    out.origin = vec2<i32>(piece.origin);
    out.block_origin = vec2<i32>(piece.block_origin);
    return out;
}

// Additive blend (One, One): alpha output 0 leaves coverage untouched.
@fragment
fn fs_piece(in: PieceOut) -> @location(0) vec4<f32> {
    let t = vec2<i32>(floor(in.clip.xy));
    let a = load_atlas(t + in.src_minus_dst).rgb;
    // Pieces are cropped so the read lies in level ℓ (schedule.rs): no bounds test here.
    // Level 0 reads the first-order map exactly as before levels existed; a receiver block c
    // = t − block_origin (texel t itself for r = 0) reads block ⌊c/2^(ℓ−r)⌋ + Δ.
    var f: vec3<f32>;
    if (in.level.x == 0u) {
        f = load_first_order(t + in.offset).rgb;
    } else {
        let c = t - in.block_origin;
        f = load_pyramid(in.origin + (c >> vec2<u32>(in.level.y)) + in.offset).rgb;
    }
    return vec4<f32>(a * f, 0.0);
}

// fs_copy (over `vs_fullscreen`, fullscreen.wgsl, prepended) copies the first-order map (RGB
// and coverage alpha) into the accumulation target before the pieces are blended on top
// (scissored to the lightmap when the target also holds receiver blocks).
@fragment
fn fs_copy(@builtin(position) pos: vec4<f32>) -> @location(0) vec4<f32> {
    return load_first_order(vec2<i32>(floor(pos.xy)));
}
