// Transfer pass, blend path with paired pieces (src/pairing.rs): one quad per pair of pieces
// over the bounding box of both destination rectangles; per fragment one pair-page fetch,
// two first-order fetches and one additive blend of both contributions.
// Mirror: src/cpu/transfer.rs (`transfer_paired`). Host side: src/transfer.rs.
//
// Bindings (bind-group order = @binding order; must match `TransferPass` layouts in transfer.rs):
//   group 0: binding 0 = Params (uniform), binding 1 = first-order lightmap (RGBA32F),
//            binding 2 = packed pyramid levels ≥ 1 (RGBA32F; a 1×1 dummy when no piece has level > 0)
//   group 1: binding 0 = the pair page being drawn (RGBA32Uint)
// The host prepends the declarations of `first_order`, `pyramid` and `page` and their texel
// readers `load_first_order(t)`, `load_pyramid(t)`, `load_page(t)` (`util::TexelReads::wgsl`).
// Pair texel: x = a.r | a.g << 16, y = a.b | b.r << 16, z = b.g | b.b << 16 (binary16, scaled
// by 2^k per piece; values are 0 outside a piece's own rectangle).
// Coordinates: texel (x, y), y down, row 0 = v = 1; framebuffer pixel (x, y) is lightmap texel (x, y).

// Params (binding 0 of group 0): transfer_params.wgsl; `texel_to_clip` and `quad_clip`:
// transfer_quad.wgsl; both prepended by the host. Pairs hold receiver level 0 only (pairing.rs).

// Both pieces of a pair have the same pyramid level ℓ (pairing.rs): piece X reads
// P_ℓ(⌊t/2^ℓ⌋ + Δ_X), level 0 = the first-order map.
// Per-instance attributes: must match `PairInstance` in pairing.rs (64 bytes, locations 0–7).
struct PairIn {
    @location(0) src: vec2<u32>,
    @location(1) dst: vec2<u32>,
    @location(2) size: vec2<u32>,
    @location(3) offset_a: vec2<i32>,
    @location(4) offset_b: vec2<i32>,
    @location(5) scale: vec2<f32>,
    // x = pyramid level ℓ, y = padding.
    @location(6) level: vec2<u32>,
    // Origin of level ℓ in the packed pyramid.
    @location(7) origin: vec2<u32>,
}

struct PairOut {
    @builtin(position) clip: vec4<f32>,
    // Page texel minus destination texel.
    @location(0) @interpolate(flat) src_minus_dst: vec2<i32>,
    @location(1) @interpolate(flat) offset_a: vec2<i32>,
    @location(2) @interpolate(flat) offset_b: vec2<i32>,
    @location(3) @interpolate(flat) scale: vec2<f32>,
    @location(4) @interpolate(flat) level: u32,
    @location(5) @interpolate(flat) origin: vec2<i32>,
}

@vertex
fn vs_pair(@builtin(vertex_index) vi: u32, pair: PairIn) -> PairOut {
    var out: PairOut;
    out.clip = quad_clip(vi, pair.dst, pair.size);
    out.src_minus_dst = vec2<i32>(pair.src) - vec2<i32>(pair.dst);
    out.offset_a = pair.offset_a;
    out.offset_b = pair.offset_b;
    out.scale = pair.scale;
    out.level = pair.level.x;
    out.origin = vec2<i32>(pair.origin);
    return out;
}

// Additive blend (One, One): alpha output 0 leaves coverage untouched.
@fragment
fn fs_pair(in: PairOut) -> @location(0) vec4<f32> {
    let t = vec2<i32>(floor(in.clip.xy));
    let p = load_page(t + in.src_minus_dst);
    let x = unpack2x16float(p.x);
    let y = unpack2x16float(p.y);
    let z = unpack2x16float(p.z);
    let a = vec3<f32>(x.x, x.y, y.x) * in.scale.x;
    let b = vec3<f32>(y.y, z.x, z.y) * in.scale.y;
    // Inside the bounding box but outside a piece's own rectangle the read t + Δt may leave
    // the map; its value is 0 there, so a clamped (in-map, finite) read adds exactly 0.
    // Level ℓ > 0: the same within level ℓ (⌈size/2^ℓ⌉ blocks at `origin` of the pyramid).
    var fa: vec3<f32>;
    var fb: vec3<f32>;
    if (in.level == 0u) {
        let hi = vec2<i32>(params.lightmap_size) - 1;
        fa = load_first_order(clamp(t + in.offset_a, vec2<i32>(0), hi)).rgb;
        fb = load_first_order(clamp(t + in.offset_b, vec2<i32>(0), hi)).rgb;
    } else {
        let l = vec2<u32>(in.level);
        let hi = vec2<i32>((params.lightmap_size + (vec2<u32>(1u) << l) - 1u) >> l) - 1;
        let tl = t >> l;
        fa = load_pyramid(in.origin + clamp(tl + in.offset_a, vec2<i32>(0), hi)).rgb;
        fb = load_pyramid(in.origin + clamp(tl + in.offset_b, vec2<i32>(0), hi)).rgb;
    }
    return vec4<f32>(a * fa + b * fb, 0.0);
}
