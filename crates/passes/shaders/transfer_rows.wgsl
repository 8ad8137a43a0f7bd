// Transfer pass, rows path: every texel sums its own row of (weight, source) entries — the
// same maps as transfer.wgsl, turned around once per scene (src/rows.rs). No blending, no
// atomics, one invocation per texel.
// Mirror: src/cpu/transfer_rows.rs. Host side: src/transfer_rows.rs.
//
// cs_pack: source[i] = first_order texel i (i < W·H, row-major), else the packed pyramid's
//          texel i − W·H (rows of params.packed_width texels); once per frame.
// cs_rows: final[t] = base[t] + Σ_{k in row(t)} w_k · source[s_k].rgb, skipping entries with
//          the COVERED_ONLY bit (receiver blocks) where base[t].a == 0; alpha = base's.
//          One dispatch per band of lightmap rows (a band's entries fit one texture).
// Element i of the source and entries textures lies at (i mod TEXTURE_WIDTH, i / TEXTURE_WIDTH).
// Both are textures because on lavapipe a texel fetch is one gather while a storage-buffer
// load at a per-invocation address is done invocation by invocation (transfer_rows.rs).
//
// Bindings (order = @binding order; must match `RowsPass` in transfer_rows.rs):
//   cs_pack (one bind group per frame): 0 = RowParams (uniform), 1 = first-order map (the
//     pieces' input), 3 = packed pyramid (1×1 dummy without levels), 4 = source (storage
//     texture, write);
//   cs_rows (one bind group per band): 0 = RowParams, 2 = base map (the first-order term the
//     final starts from), 5 = final map (storage texture, write), 6 = the band's row offsets
//     (storage, read), 7 = the band's entries (RGBA32Uint texture), 8 = source (texture).

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
@group(0) @binding(4) var source: texture_storage_2d<rgba32float, write>;
@group(0) @binding(5) var final_map: texture_storage_2d<rgba32float, write>;
@group(0) @binding(6) var<storage, read> offsets: array<u32>;
// Must match `RowEntry` in rows.rs: the weight's f32 bits in .xyz, the source index in .w.
@group(0) @binding(7) var entries: texture_2d<u32>;
// The source as cs_rows reads it (the texture cs_pack wrote through binding 4).
@group(0) @binding(8) var source_in: texture_2d<f32>;
// Must match `TEXTURE_WIDTH` in transfer_rows.rs.
const TEXTURE_WIDTH: u32 = 4096u;

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
    textureStore(source, vec2<u32>(i % TEXTURE_WIDTH, i / TEXTURE_WIDTH), v);
}

fn entry(k: u32) -> vec4<u32> {
    return textureLoad(entries, vec2<u32>(k % TEXTURE_WIDTH, k / TEXTURE_WIDTH), 0);
}

// Entry k's weight times its source.
fn term(k: u32) -> vec3<f32> {
    let e = entry(k);
    let s = e.w & ~COVERED_ONLY;
    return bitcast<vec3<f32>>(e.xyz) * textureLoad(source_in, vec2<u32>(s % TEXTURE_WIDTH, s / TEXTURE_WIDTH), 0).rgb;
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
    var k = offsets[i];
    if (covered) {
        // Every entry counts: two per iteration (on lavapipe the loop's own cost was an
        // eighth of the pass; four per iteration gained nothing more).
        for (; k + 1u < end; k += 2u) {
            sum += term(k) + term(k + 1u);
        }
        if (k < end) {
            sum += term(k);
        }
    } else {
        for (; k < end; k++) {
            if ((entry(k).w & COVERED_ONLY) == 0u) {
                sum += term(k);
            }
        }
    }
    textureStore(final_map, t, vec4<f32>(b.rgb + sum, b.a));
}
