//! The frame's transfer work as plain data, built by pure functions (no GPU): which pieces
//! each atlas draws ([`build_schedule`]) and, for the compute path, which pieces touch each
//! tile of the final lightmap ([`build_tiles`]).
//!
//! # Data flow
//! `TransferPiece`s (from the binning stage) → [`build_schedule`] validates them against the
//! atlas and lightmap sizes and groups them per atlas into [`PieceInstance`]s (one instanced
//! quad each in the blend path) → [`build_tiles`] buckets each atlas's instances by the
//! `TILE_SIZE×TILE_SIZE` lightmap tiles their destination rectangles overlap (compute path:
//! one workgroup per non-empty tile, no atomics).
//!
//! # Conventions
//! Rectangles are in texels, `x` right, `y` down (row 0 = `v = 1`). A piece of level `ℓ`
//! reads its first-order light at block `⌊t / 2^ℓ⌋ + Δ` of pyramid level `ℓ`
//! ([`crate::pyramid`]; level 0 = the first-order map, `t + Δt`), `t` the *destination* texel.
//!
//! # Cropping (no bounds test in the shaders)
//! Pieces with `w == 0` or `h == 0` are dropped (they do nothing), and pieces are cropped to
//! the texels whose read `⌊t / 2^ℓ⌋ + Δ` lies inside level `ℓ`'s `⌈W/2^ℓ⌉ × ⌈H/2^ℓ⌉` blocks
//! (the rest add exactly 0, since `P_ℓ = 0` outside). The kept texels still form a rectangle:
//! along an axis `0 ≤ ⌊t/2^ℓ⌋ + Δ < n` ⟺ `−Δ·2^ℓ ≤ t < (n − Δ)·2^ℓ`. So the shaders read
//! without a bounds test, which matters for levels > 0: they live side by side in one packed
//! texture, and an out-of-level read would see another level. A piece must lie inside its
//! atlas and its destination inside the lightmap, and its level must be at most
//! [`MAX_PIECE_LEVEL`]; anything else is an error (the binning stage produces such pieces
//! only when its inputs disagree with the render's).
//!
//! # Receiver blocks and the accumulation target ([`target_size`], [`block_origin`])
//! A piece of receiver level `r > 0` ([`TransferPiece::receiver_level`]) writes one value per
//! `2^r × 2^r` receiver block into `G_r`, the level-`r` block grid (`⌈W/2^r⌉ × ⌈H/2^r⌉`), which
//! every covered texel of the block then adds (the resolve step of either path). The work is
//! drawn into one *accumulation target*: the lightmap at `(0, 0)` and, below it, the grids
//! `G_1..G_R` packed as the first-order pyramid packs its levels ([`crate::pyramid`]):
//! `block_origin(r) = level_origin(r) + (0, H)`. Instances carry target coordinates: a
//! receiver-block instance's `dst` is `block_origin(r) + c`, and its read is
//! `origin_ℓ + ⌊(t − block_origin(r)) / 2^(ℓ−r)⌋ + Δ`, which for `r = 0` (`block_origin = 0`) is
//! the read above. Cropping works in level-`r` blocks: `0 ≤ ⌊c/2^(ℓ−r)⌋ + Δ < n_ℓ`. Without
//! receiver blocks the target is the lightmap itself.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::pyramid::{level_origin, level_size, packed_size};
use crate::types::{MAX_PIECE_LEVEL, TransferPiece};

/// Side of a compute-path tile in texels (= workgroup size in each dimension).
/// Must match `TILE_SIZE` in `shaders/transfer_gather.wgsl`.
pub const TILE_SIZE: u32 = 8;

/// One piece as the GPU sees it. 56 bytes (a multiple of its 8-byte alignment, as WGSL lays
/// out the storage array). Must match `PieceInstance` in `shaders/transfer_gather.wgsl` and
/// the instance vertex attributes (locations 0–6) of `shaders/transfer.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PieceInstance {
    /// Top-left texel of the rectangle in the atlas.
    pub src: [u32; 2],
    /// Top-left texel receiving it in the accumulation target (module docs): a lightmap texel
    /// for receiver level 0, `block_origin(r) + c` for a receiver block `c` of level `r`.
    pub dst: [u32; 2],
    /// Width and height in texels.
    pub size: [u32; 2],
    /// `Δ` in level-`level` blocks (texels at level 0; `+y` down).
    pub offset: [i32; 2],
    /// Pyramid level `ℓ` read (0 = the first-order map).
    pub level: u32,
    /// Receiver level `r ≤ ℓ` (0: one value per texel).
    pub receiver_level: u32,
    /// Origin of level `ℓ` in the packed pyramid texture ([`crate::pyramid::level_origin`];
    /// `(0, 0)` at level 0).
    pub origin: [u32; 2],
    /// [`block_origin`]`(r)` (`(0, 0)` for `r = 0`): the read is
    /// `origin + ⌊(t − block_origin) / 2^(ℓ−r)⌋ + Δ` for `ℓ ≥ 1`, `t` the target texel.
    pub block_origin: [u32; 2],
}

/// Top-left texel of the receiver-block grid `G_r` (`r ≥ 1`) in the accumulation target
/// (module docs); `(0, 0)` for `r = 0` (the lightmap).
pub fn block_origin(lightmap_size: [u32; 2], r: u32) -> [u32; 2] {
    if r == 0 {
        return [0, 0];
    }
    let o = level_origin(lightmap_size, r);
    [o[0], lightmap_size[1] + o[1]]
}

/// Size of the accumulation target holding the lightmap and the grids `G_1..=G_R`
/// (`receiver_levels = R`; the lightmap size when `R = 0`).
pub fn target_size(lightmap_size: [u32; 2], receiver_levels: u32) -> [u32; 2] {
    if receiver_levels == 0 {
        return lightmap_size;
    }
    let p = packed_size(lightmap_size, receiver_levels);
    [lightmap_size[0].max(p[0]), lightmap_size[1] + p[1]]
}

/// All pieces of one atlas, drawn together.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AtlasBatch {
    /// Index of the atlas.
    pub atlas: u32,
    /// Its pieces, in input order.
    pub instances: Vec<PieceInstance>,
}

/// The whole frame's transfer work.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FrameSchedule {
    /// Lightmap `[width, height]`.
    pub lightmap_size: [u32; 2],
    /// One batch per atlas that has pieces, in increasing atlas order.
    pub batches: Vec<AtlasBatch>,
    /// `R`: the highest receiver level of any piece (0: no receiver blocks, the target is the
    /// lightmap).
    pub receiver_levels: u32,
}

impl FrameSchedule {
    /// Size of the accumulation target ([`target_size`]).
    pub fn target_size(&self) -> [u32; 2] {
        target_size(self.lightmap_size, self.receiver_levels)
    }

    /// The highest piece level (0 when every piece reads the first-order map, or none).
    pub fn max_level(&self) -> u32 {
        self.batches
            .iter()
            .flat_map(|b| &b.instances)
            .map(|i| i.level)
            .max()
            .unwrap_or(0)
    }

    /// Total texels (or receiver blocks) written by all pieces (= blends per frame in the
    /// blend path).
    pub fn texel_blends(&self) -> u64 {
        self.batches
            .iter()
            .flat_map(|b| &b.instances)
            .map(|i| i.size[0] as u64 * i.size[1] as u64)
            .sum()
    }
}

/// Validates `pieces` and groups them per atlas.
///
/// `atlas_sizes[i]` is `[width, height]` of atlas `i`.
pub fn build_schedule(
    lightmap_size: [u32; 2],
    atlas_sizes: &[[u32; 2]],
    pieces: &[TransferPiece],
) -> Result<FrameSchedule, PassError> {
    let [lw, lh] = lightmap_size;
    let mut per_atlas: Vec<Vec<PieceInstance>> = vec![Vec::new(); atlas_sizes.len()];
    let mut receiver_levels = 0;
    for (i, p) in pieces.iter().enumerate() {
        if p.level > MAX_PIECE_LEVEL {
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}].level"),
                problem: format!(
                    "is {} but pyramid levels go up to {MAX_PIECE_LEVEL}; the index is corrupt \
                     or from a newer baker",
                    p.level
                ),
            });
        }
        if p.receiver_level > p.level {
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}].receiver_level"),
                problem: format!(
                    "is {} but the piece reads pyramid level {}; a receiver block is at most \
                     as large as the sender block it reads (the index is corrupt)",
                    p.receiver_level, p.level
                ),
            });
        }
        if p.w == 0 || p.h == 0 {
            continue;
        }
        let Some(&[aw, ah]) = atlas_sizes.get(p.atlas as usize) else {
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}].atlas"),
                problem: format!(
                    "is {} but only {} atlases were given; pass every atlas the index names",
                    p.atlas,
                    atlas_sizes.len()
                ),
            });
        };
        if p.src_x as u64 + p.w as u64 > aw as u64 || p.src_y as u64 + p.h as u64 > ah as u64 {
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}] source rectangle"),
                problem: format!(
                    "({}, {}) + {}×{} leaves atlas {} ({aw}×{ah}); the atlas or index is stale",
                    p.src_x, p.src_y, p.w, p.h, p.atlas
                ),
            });
        }
        let r = p.receiver_level;
        let [rw, rh] = level_size(lightmap_size, r);
        if p.dst_x as u64 + p.w as u64 > rw as u64 || p.dst_y as u64 + p.h as u64 > rh as u64 {
            let grid = if r == 0 {
                format!("the {lw}×{lh} lightmap")
            } else {
                format!("the {rw}×{rh} receiver blocks of level {r} (lightmap {lw}×{lh})")
            };
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}] destination rectangle"),
                problem: format!(
                    "({}, {}) + {}×{} leaves {grid}; render with the lightmap size the maps \
                     were baked for",
                    p.dst_x, p.dst_y, p.w, p.h
                ),
            });
        }
        // Crop to the receivers c (texels or level-r blocks) whose read ⌊c/2^(ℓ−r)⌋ + Δ lies
        // in level ℓ: first order (and so every level) is 0 outside it (Eq. 4), so the
        // cropped receivers add exactly nothing, and the shaders need no bounds test.
        let [nw, nh] = level_size(lightmap_size, p.level);
        let (Some((x0, w)), Some((y0, h))) = (
            read_inside(p.dst_x, p.w, p.offset[0], nw, p.level - r),
            read_inside(p.dst_y, p.h, p.offset[1], nh, p.level - r),
        ) else {
            continue;
        };
        let bo = block_origin(lightmap_size, r);
        receiver_levels = receiver_levels.max(r);
        per_atlas[p.atlas as usize].push(PieceInstance {
            src: [p.src_x + x0, p.src_y + y0],
            dst: [bo[0] + p.dst_x + x0, bo[1] + p.dst_y + y0],
            size: [w, h],
            offset: p.offset,
            level: p.level,
            receiver_level: r,
            origin: level_origin(lightmap_size, p.level),
            block_origin: bo,
        });
    }
    let batches = per_atlas
        .into_iter()
        .enumerate()
        .filter(|(_, v)| !v.is_empty())
        .map(|(a, instances)| AtlasBatch {
            atlas: a as u32,
            instances,
        })
        .collect();
    Ok(FrameSchedule {
        lightmap_size,
        batches,
        receiver_levels,
    })
}

/// Along one axis: the first local index and the count of `t = dst + i` (`0 ≤ i < len`) whose
/// read `⌊t / 2^level⌋ + offset` lies in `[0, blocks)` (`level` = the sender level less the
/// receiver level); `None` if there is none. (`⌊t/2^ℓ⌋ ≥ k`
/// ⟺ `t ≥ k·2^ℓ` and `⌊t/2^ℓ⌋ < k` ⟺ `t < k·2^ℓ` for integer `k`.)
fn read_inside(dst: u32, len: u32, offset: i32, blocks: u32, level: u32) -> Option<(u32, u32)> {
    let (dst, len, offset, blocks) = (dst as i64, len as i64, offset as i64, blocks as i64);
    let scale = 1i64 << level;
    let lo = (-offset * scale - dst).max(0);
    let hi = ((blocks - offset) * scale - dst).min(len);
    (hi > lo).then_some((lo as u32, (hi - lo) as u32))
}

/// Compute-path work of one atlas: for every non-empty tile, the instances overlapping it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct AtlasTiles {
    /// Index of the atlas.
    pub atlas: u32,
    /// The atlas's instances (same as its [`AtlasBatch`]).
    pub instances: Vec<PieceInstance>,
    /// One entry per non-empty tile (= per workgroup).
    pub tiles: Vec<TileWork>,
    /// Concatenated per-tile lists of indices into `instances`.
    pub entries: Vec<u32>,
}

/// One workgroup's work. 16 bytes.
/// Must match `TileWork` in `shaders/transfer_gather.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct TileWork {
    /// Tile coordinates (`tile_x`, `tile_y`); the tile covers texels
    /// `[tile_x·TILE_SIZE, (tile_x+1)·TILE_SIZE)` × same in `y`.
    pub tile: [u32; 2],
    /// First index into `entries`.
    pub first: u32,
    /// Number of entries.
    pub count: u32,
}

/// Buckets each batch's instances by the tiles of the accumulation target
/// ([`FrameSchedule::target_size`]) their destination rectangles overlap. Within a tile,
/// instances keep their input order.
pub fn build_tiles(schedule: &FrameSchedule) -> Vec<AtlasTiles> {
    let [lw, lh] = schedule.target_size();
    let tx = lw.div_ceil(TILE_SIZE) as usize;
    let ty = lh.div_ceil(TILE_SIZE) as usize;
    schedule
        .batches
        .iter()
        .map(|b| {
            let mut lists: Vec<Vec<u32>> = vec![Vec::new(); tx * ty];
            for (k, inst) in b.instances.iter().enumerate() {
                let x0 = inst.dst[0] / TILE_SIZE;
                let y0 = inst.dst[1] / TILE_SIZE;
                let x1 = (inst.dst[0] + inst.size[0] - 1) / TILE_SIZE;
                let y1 = (inst.dst[1] + inst.size[1] - 1) / TILE_SIZE;
                for y in y0..=y1 {
                    for x in x0..=x1 {
                        lists[y as usize * tx + x as usize].push(k as u32);
                    }
                }
            }
            let mut tiles = Vec::new();
            let mut entries = Vec::new();
            for (t, list) in lists.into_iter().enumerate() {
                if list.is_empty() {
                    continue;
                }
                tiles.push(TileWork {
                    tile: [(t % tx) as u32, (t / tx) as u32],
                    first: entries.len() as u32,
                    count: list.len() as u32,
                });
                entries.extend(list);
            }
            AtlasTiles {
                atlas: b.atlas,
                instances: b.instances.clone(),
                tiles,
                entries,
            }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn piece(
        atlas: u32,
        src: [u32; 2],
        size: [u32; 2],
        dst: [u32; 2],
        off: [i32; 2],
    ) -> TransferPiece {
        TransferPiece {
            atlas,
            src_x: src[0],
            src_y: src[1],
            w: size[0],
            h: size[1],
            dst_x: dst[0],
            dst_y: dst[1],
            offset: off,
            level: 0,
            receiver_level: 0,
        }
    }

    #[test]
    fn shared_struct_sizes() {
        assert_eq!(std::mem::size_of::<PieceInstance>(), 56);
        assert_eq!(std::mem::size_of::<TileWork>(), 16);
    }

    #[test]
    fn groups_by_atlas_in_order_and_drops_empty() {
        let pieces = [
            piece(1, [0, 0], [2, 2], [0, 0], [1, 0]),
            piece(0, [1, 1], [3, 1], [5, 5], [0, -1]),
            piece(1, [2, 0], [1, 4], [7, 0], [0, 0]),
            piece(0, [0, 0], [0, 4], [0, 0], [0, 0]),
        ];
        let s = build_schedule([8, 8], &[[4, 4], [4, 4]], &pieces).unwrap();
        assert_eq!(s.batches.len(), 2);
        assert_eq!(s.batches[0].atlas, 0);
        assert_eq!(s.batches[0].instances.len(), 1);
        assert_eq!(s.batches[0].instances[0].dst, [5, 5]);
        assert_eq!(s.batches[1].instances.len(), 2);
        assert_eq!(s.batches[1].instances[1].src, [2, 0]);
        assert_eq!(s.texel_blends(), 4 + 3 + 4);
    }

    #[test]
    fn crops_pieces_to_reads_inside_the_map() {
        // 8×8 map; piece at dst (1, 2), 4×3 texels, Δt = (−3, 6): reads x + 1 − 3 ≥ 0 needs
        // local x ≥ 2, reads y + 2 + 6 < 8 needs local y < 0 → dropped; with Δt = (−3, 4)
        // local y < 2 stays.
        let pieces = [
            piece(0, [10, 20], [4, 3], [1, 2], [-3, 6]),
            piece(0, [10, 20], [4, 3], [1, 2], [-3, 4]),
        ];
        let s = build_schedule([8, 8], &[[32, 32]], &pieces).unwrap();
        assert_eq!(s.batches.len(), 1);
        let inst = &s.batches[0].instances;
        assert_eq!(inst.len(), 1);
        assert_eq!(inst[0].src, [12, 20]);
        assert_eq!(inst[0].dst, [3, 2]);
        assert_eq!(inst[0].size, [2, 2]);
        // Brute force: exactly the texels of the uncropped piece whose read is inside.
        for j in 0..3i32 {
            for i in 0..4i32 {
                let (x, y) = (1 + i, 2 + j);
                let inside = (0..8).contains(&(x - 3)) && (0..8).contains(&(y + 4));
                let kept = (3..5).contains(&x) && (2..4).contains(&y);
                assert_eq!(inside, kept, "texel ({x}, {y})");
            }
        }
    }

    /// Level crops keep exactly the texels whose read `⌊t/2^ℓ⌋ + Δ` lies inside level ℓ
    /// (brute force over texels, levels and offsets on a non-power-of-two map).
    #[test]
    fn crops_level_pieces_to_reads_inside_their_level() {
        let map = [37u32, 29];
        for level in 0..4u32 {
            let [nw, nh] = level_size(map, level);
            for (dx, dy) in [(-3, 2), (0, 0), (5, -7), (-9, 9), (2, 3)] {
                let mut p = piece(0, [0, 0], [30, 20], [4, 6], [dx, dy]);
                p.level = level;
                let s = build_schedule(map, &[[64, 64]], &[p]).unwrap();
                let inst = s.batches.first().map(|b| b.instances[0]);
                for y in 6..26u32 {
                    for x in 4..34u32 {
                        let (bx, by) = ((x >> level) as i32 + dx, (y >> level) as i32 + dy);
                        let inside = bx >= 0 && by >= 0 && (bx as u32) < nw && (by as u32) < nh;
                        let kept = inst.is_some_and(|i| {
                            (i.dst[0]..i.dst[0] + i.size[0]).contains(&x)
                                && (i.dst[1]..i.dst[1] + i.size[1]).contains(&y)
                        });
                        assert_eq!(
                            inside, kept,
                            "level {level} Δ ({dx}, {dy}) texel ({x}, {y})"
                        );
                    }
                }
                if let Some(i) = inst {
                    assert_eq!(i.level, level);
                    assert_eq!(i.origin, level_origin(map, level));
                    assert_eq!([i.dst[0] - i.src[0], i.dst[1] - i.src[1]], [4, 6]);
                }
            }
        }
        let mut p = piece(0, [0, 0], [1, 1], [0, 0], [0, 0]);
        p.level = MAX_PIECE_LEVEL + 1;
        let e = build_schedule(map, &[[4, 4]], &[p])
            .unwrap_err()
            .to_string();
        assert!(e.contains("pieces[0].level"), "{e}");
    }

    /// Receiver-block pieces: placed at `block_origin(r) + c` in the target, cropped to the
    /// blocks `c` whose read `⌊c/2^(ℓ−r)⌋ + Δ` lies in level ℓ (brute force), validated
    /// against the level-r grid, `r ≤ ℓ` enforced; the target holds every `G_r` below the
    /// lightmap without overlap.
    #[test]
    fn receiver_block_pieces_live_below_the_lightmap() {
        let map = [37u32, 29];
        for level in 1..5u32 {
            for r in 1..=level {
                let [gw, gh] = level_size(map, r);
                let [nw, nh] = level_size(map, level);
                for (dx, dy) in [(-3, 2), (0, 0), (5, -7), (2, 3)] {
                    let mut p = piece(0, [0, 0], [gw, gh], [0, 0], [dx, dy]);
                    (p.level, p.receiver_level) = (level, r);
                    let s = build_schedule(map, &[[64, 64]], &[p]).unwrap();
                    let inst = s.batches.first().map(|b| b.instances[0]);
                    let bo = block_origin(map, r);
                    for cy in 0..gh {
                        for cx in 0..gw {
                            let s = level - r;
                            let (bx, by) = ((cx >> s) as i32 + dx, (cy >> s) as i32 + dy);
                            let inside = bx >= 0 && by >= 0 && (bx as u32) < nw && (by as u32) < nh;
                            let (x, y) = (bo[0] + cx, bo[1] + cy);
                            let kept = inst.is_some_and(|i| {
                                (i.dst[0]..i.dst[0] + i.size[0]).contains(&x)
                                    && (i.dst[1]..i.dst[1] + i.size[1]).contains(&y)
                            });
                            assert_eq!(
                                inside, kept,
                                "ℓ {level} r {r} Δ ({dx}, {dy}) c ({cx}, {cy})"
                            );
                        }
                    }
                    if let Some(i) = inst {
                        assert_eq!((i.receiver_level, i.block_origin), (r, bo));
                        assert_eq!(s.receiver_levels, r);
                        let [tw, th] = s.target_size();
                        assert!(i.dst[0] + i.size[0] <= tw && i.dst[1] + i.size[1] <= th);
                    }
                }
                // One block too far right is an error naming the level-r grid.
                let mut p = piece(0, [0, 0], [1, 1], [gw, 0], [0, 0]);
                (p.level, p.receiver_level) = (level, r);
                let e = build_schedule(map, &[[64, 64]], &[p])
                    .unwrap_err()
                    .to_string();
                assert!(e.contains(&format!("receiver blocks of level {r}")), "{e}");
            }
        }
        // The grids G_1..G_5 are disjoint, below the lightmap and inside the target.
        let [tw, th] = target_size(map, 5);
        let mut owner = vec![0u32; (tw * th) as usize];
        for r in 1..=5u32 {
            let o = block_origin(map, r);
            let [gw, gh] = level_size(map, r);
            assert!(o[1] >= map[1]);
            for y in o[1]..o[1] + gh {
                for x in o[0]..o[0] + gw {
                    assert_eq!(
                        owner[(y * tw + x) as usize],
                        0,
                        "G_{r} overlaps at ({x}, {y})"
                    );
                    owner[(y * tw + x) as usize] = r;
                }
            }
        }
        let mut p = piece(0, [0, 0], [1, 1], [0, 0], [0, 0]);
        (p.level, p.receiver_level) = (1, 2);
        let e = build_schedule(map, &[[4, 4]], &[p])
            .unwrap_err()
            .to_string();
        assert!(e.contains("pieces[0].receiver_level"), "{e}");
    }

    #[test]
    fn rejects_out_of_range_pieces() {
        let atl = [[4, 4]];
        assert!(build_schedule([8, 8], &atl, &[piece(1, [0, 0], [1, 1], [0, 0], [0, 0])]).is_err());
        assert!(build_schedule([8, 8], &atl, &[piece(0, [3, 0], [2, 1], [0, 0], [0, 0])]).is_err());
        assert!(build_schedule([8, 8], &atl, &[piece(0, [0, 0], [2, 2], [7, 0], [0, 0])]).is_err());
        assert!(build_schedule([8, 8], &atl, &[piece(0, [0, 0], [4, 4], [4, 4], [-9, 9])]).is_ok());
    }

    #[test]
    fn tiles_cover_exactly_the_overlapping_pieces() {
        // Brute force: a tile lists a piece iff some texel of the piece lies in the tile.
        let pieces = [
            piece(0, [0, 0], [9, 3], [3, 2], [0, 0]),
            piece(0, [0, 0], [1, 1], [16, 16], [0, 0]),
            piece(0, [0, 0], [17, 17], [0, 0], [0, 0]),
        ];
        let s = build_schedule([20, 19], &[[32, 32]], &pieces).unwrap();
        let t = &build_tiles(&s)[0];
        let (tx, ty) = (20u32.div_ceil(TILE_SIZE), 19u32.div_ceil(TILE_SIZE));
        for ty_ in 0..ty {
            for tx_ in 0..tx {
                let want: Vec<u32> = s.batches[0]
                    .instances
                    .iter()
                    .enumerate()
                    .filter(|(_, p)| {
                        (p.dst[1]..p.dst[1] + p.size[1]).any(|y| {
                            (p.dst[0]..p.dst[0] + p.size[0])
                                .any(|x| x / TILE_SIZE == tx_ && y / TILE_SIZE == ty_)
                        })
                    })
                    .map(|(k, _)| k as u32)
                    .collect();
                let got: Vec<u32> = t
                    .tiles
                    .iter()
                    .find(|w| w.tile == [tx_, ty_])
                    .map(|w| t.entries[w.first as usize..(w.first + w.count) as usize].to_vec())
                    .unwrap_or_default();
                assert_eq!(got, want, "tile ({tx_}, {ty_})");
            }
        }
    }
}
