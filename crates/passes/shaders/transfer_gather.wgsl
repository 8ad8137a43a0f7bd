// Transfer pass, compute (gather) path: same result as transfer.wgsl, no blending, no atomics.
// Mirror: src/cpu/transfer_gather.rs. Host side: src/transfer_gather.rs.
//
// acc spans the accumulation target (src/schedule.rs, "Receiver blocks"): the lightmap at
// (0, 0) and the receiver-block grids G_1..G_R below it (R = params.receiver_levels).
// cs_init:    acc[t] = first_order[t] inside the lightmap, 0 below  (one invocation per texel)
// cs_gather:  per atlas, one workgroup per non-empty 8×8 tile: each invocation owns one texel,
//             sums the tile's pieces containing it, adds to acc (no other workgroup writes it);
//             a piece of level ℓ reads P_ℓ(⌊t/2^ℓ⌋ + Δ) (level 0: the first-order map), a
//             receiver block c = t − block_origin(r) reads P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)
// cs_resolve: final[t] = acc[t] + (acc[t].a > 0) · Σ_{r=1..R} acc[block_origin(r) + ⌊t/2^r⌋]
//
// Params (group 0, binding 0) and `block_origin`: transfer_params.wgsl, prepended by the host.
// Bindings (bind-group order = @binding order; must match `GatherPass` layouts in transfer_gather.rs):
//   group 0: 0 = Params (uniform), 1 = first-order map (texture, textureLoad),
//            2 = acc (storage, read_write, target-size vec4), 3 = final map (storage texture, write),
//            4 = packed pyramid levels ≥ 1 (texture, textureLoad; 1×1 dummy when unused)
//   group 1: 0 = atlas (texture), 1 = instances (storage, read), 2 = tiles (storage, read),
//            3 = entries (storage, read)

// Must match `TILE_SIZE` in schedule.rs.
const TILE_SIZE: u32 = 8u;

// Must match `PieceInstance` in schedule.rs (56 bytes).
struct PieceInstance {
    src: vec2<u32>,
    dst: vec2<u32>,
    size: vec2<u32>,
    offset: vec2<i32>,
    level: u32,
    receiver_level: u32,
    origin: vec2<u32>,
    block_origin: vec2<u32>,
}

// Must match `TileWork` in schedule.rs (16 bytes).
struct TileWork {
    tile: vec2<u32>,
    first: u32,
    count: u32,
}

@group(0) @binding(1) var first_order: texture_2d<f32>;
@group(0) @binding(2) var<storage, read_write> acc: array<vec4<f32>>;
@group(0) @binding(3) var final_map: texture_storage_2d<rgba32float, write>;
@group(0) @binding(4) var pyramid: texture_2d<f32>;

@group(1) @binding(0) var atlas: texture_2d<f32>;
@group(1) @binding(1) var<storage, read> instances: array<PieceInstance>;
@group(1) @binding(2) var<storage, read> tiles: array<TileWork>;
@group(1) @binding(3) var<storage, read> entries: array<u32>;

fn first_order_at(t: vec2<i32>) -> vec3<f32> {
    let size = vec2<i32>(params.lightmap_size);
    if (any(t < vec2<i32>(0)) || any(t >= size)) {
        return vec3<f32>(0.0);
    }
    return textureLoad(first_order, t, 0).rgb;
}

@compute @workgroup_size(8, 8)
fn cs_init(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (any(gid.xy >= params.target_size)) {
        return;
    }
    var v = vec4<f32>(0.0);
    if (all(gid.xy < params.lightmap_size)) {
        v = textureLoad(first_order, vec2<i32>(gid.xy), 0);
    }
    acc[gid.y * params.target_size.x + gid.x] = v;
}

@compute @workgroup_size(TILE_SIZE, TILE_SIZE)
fn cs_gather(@builtin(workgroup_id) wid: vec3<u32>, @builtin(local_invocation_id) lid: vec3<u32>) {
    // 2D dispatch: workgroup (x, y) handles tile entry y·65535 + x (dimension limit 65535).
    let idx = wid.y * 65535u + wid.x;
    if (idx >= arrayLength(&tiles)) {
        return;
    }
    let work = tiles[idx];
    let t = work.tile * TILE_SIZE + lid.xy;
    if (any(t >= params.target_size)) {
        return;
    }
    var sum = vec3<f32>(0.0);
    for (var k = work.first; k < work.first + work.count; k++) {
        let inst = instances[entries[k]];
        let local = vec2<i32>(t) - vec2<i32>(inst.dst);
        if (any(local < vec2<i32>(0)) || any(local >= vec2<i32>(inst.size))) {
            continue;
        }
        let a = textureLoad(atlas, vec2<i32>(inst.src) + local, 0).rgb;
        if (inst.level == 0u) {
            sum += a * first_order_at(vec2<i32>(t) + inst.offset);
        } else {
            // Cropped so the read lies in level ℓ (schedule.rs): no bounds test needed.
            let c = t - inst.block_origin;
            let shift = vec2<u32>(inst.level - inst.receiver_level);
            let p = vec2<i32>(inst.origin) + vec2<i32>(c >> shift) + inst.offset;
            sum += a * textureLoad(pyramid, p, 0).rgb;
        }
    }
    let i = t.y * params.target_size.x + t.x;
    acc[i] = acc[i] + vec4<f32>(sum, 0.0);
}

@compute @workgroup_size(8, 8)
fn cs_resolve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = gid.xy;
    if (any(t >= params.lightmap_size)) {
        return;
    }
    let own = acc[t.y * params.target_size.x + t.x];
    var sum = own.rgb;
    if (own.a > 0.0) {
        for (var r = 1u; r <= params.receiver_levels; r++) {
            let b = block_origin(r) + (t >> vec2<u32>(r));
            sum += acc[b.y * params.target_size.x + b.x].rgb;
        }
    }
    textureStore(final_map, vec2<i32>(t), vec4<f32>(sum, own.a));
}
