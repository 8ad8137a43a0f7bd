// Shared by every transfer shader (transfer.wgsl, transfer_pair.wgsl, transfer_gather.wgsl,
// transfer_resolve.wgsl; the host prepends it, WGSL has no includes): the uniform they read
// and the layout of the accumulation target (src/schedule.rs, "Receiver blocks").
// Coordinates: texel (x, y), y down, row 0 = v = 1.

// Must match `TransferParams` in transfer.rs (32 bytes).
struct Params {
    // The accumulation target: the lightmap at (0, 0), the receiver-block grids G_1..G_R below.
    target_size: vec2<u32>,
    lightmap_size: vec2<u32>,
    // R: the highest receiver level (0: the target is the lightmap).
    receiver_levels: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;

// ⌈n / 2^l⌉ (src/pyramid.rs `level_size`).
fn level_len(n: u32, l: u32) -> u32 {
    return (n + (1u << l) - 1u) >> l;
}

// Top-left texel of G_r (r ≥ 1) in the target: the pyramid's packed layout (level 1 at (0, 0),
// levels ≥ 2 in the column right of it) moved down by the lightmap height. Must match
// `block_origin` in schedule.rs.
fn block_origin(r: u32) -> vec2<u32> {
    let size = params.lightmap_size;
    if (r <= 1u) {
        return vec2<u32>(0u, select(0u, size.y, r == 1u));
    }
    var y = size.y;
    for (var k = 2u; k < r; k++) {
        y += level_len(size.y, k);
    }
    return vec2<u32>(level_len(size.x, 1u), y);
}
