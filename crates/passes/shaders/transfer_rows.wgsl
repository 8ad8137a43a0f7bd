// Transfer pass, rows path: every texel sums its own row of (weight, source) entries — the
// same maps as transfer.wgsl, turned around once per scene (src/rows.rs). No blending, no
// atomics, one invocation per texel.
// Mirror: src/cpu/transfer_rows.rs. Host side: src/transfer_rows.rs.
//
// cs_pack: source[i] = first_order texel i (i < W·H, row-major), else the packed pyramid's
//          texel i − W·H (rows of params.packed_width texels); once per frame.
// cs_rows: final[t] = base[t] + Σ_{k in row(t)} w_k · source[s_k].rgb, skipping entries with
//          the COVERED_ONLY bit (receiver blocks) where base[t].a == 0; alpha = base's.
//          One dispatch per band of lightmap rows (a band's entries fit one storage binding).
//
// Bindings (one bind group per band; order = @binding order; must match `RowsPass` in
// transfer_rows.rs): 0 = RowParams (uniform), 1 = first-order map (the pieces' input),
// 2 = base map (the first-order term the final starts from), 3 = packed pyramid (1×1 dummy
// without levels), 4 = source (storage, read_write), 5 = final map (storage texture, write),
// 6 = the band's row offsets (storage, read), 7 = the band's entries (storage, read).

// Must match `RowParams` in transfer_rows.rs (32 bytes).
struct RowParams {
    lightmap_size: vec2<u32>,
    // First lightmap row of the band and its row count.
    y0: u32,
    rows: u32,
    // Texels of the source array and the width of its packed pyramid.
    source_len: u32,
    packed_width: u32,
    _pad0: u32,
    _pad1: u32,
}

// Must match `PACK_GROUP` and `MAX_GROUPS_X` in transfer_rows.rs.
const PACK_GROUP: u32 = 64u;
const MAX_GROUPS_X: u32 = 65535u;
// Must match `rows::COVERED_ONLY`.
const COVERED_ONLY: u32 = 0x80000000u;

@group(0) @binding(0) var<uniform> params: RowParams;
@group(0) @binding(1) var first_order: texture_2d<f32>;
@group(0) @binding(2) var base_map: texture_2d<f32>;
@group(0) @binding(3) var pyramid: texture_2d<f32>;
@group(0) @binding(4) var<storage, read_write> source: array<vec4<f32>>;
@group(0) @binding(5) var final_map: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> offsets: array<u32>;
// Must match `RowEntry` in rows.rs: the weight's f32 bits in .xyz, the source index in .w.
@group(0) @binding(7) var<storage, read> entries: array<vec4<u32>>;

@compute @workgroup_size(PACK_GROUP)
fn cs_pack(@builtin(global_invocation_id) gid: vec3<u32>) {
    let i = gid.y * (MAX_GROUPS_X * PACK_GROUP) + gid.x;
    if (i >= params.source_len) {
        return;
    }
    let w = params.lightmap_size.x;
    let n = w * params.lightmap_size.y;
    var v: vec4<f32>;
    if (i < n) {
        v = textureLoad(first_order, vec2<i32>(i32(i % w), i32(i / w)), 0);
    } else {
        let j = i - n;
        let pw = params.packed_width;
        v = textureLoad(pyramid, vec2<i32>(i32(j % pw), i32(j / pw)), 0);
    }
    source[i] = v;
}

@compute @workgroup_size(8, 8)
fn cs_rows(@builtin(global_invocation_id) gid: vec3<u32>) {
    if (gid.x >= params.lightmap_size.x || gid.y >= params.rows) {
        return;
    }
    let t = vec2<i32>(i32(gid.x), i32(params.y0 + gid.y));
    let b = textureLoad(base_map, t, 0);
    let covered = b.a > 0.0;
    let i = gid.y * params.lightmap_size.x + gid.x;
    var sum = vec3<f32>(0.0);
    let end = offsets[i + 1u];
    for (var k = offsets[i]; k < end; k++) {
        let e = entries[k];
        if ((e.w & COVERED_ONLY) != 0u && !covered) {
            continue;
        }
        sum += bitcast<vec3<f32>>(e.xyz) * source[e.w & ~COVERED_ONLY].rgb;
    }
    textureStore(final_map, t, vec4<f32>(b.rgb + sum, b.a));
}
