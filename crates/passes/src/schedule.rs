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
//! Rectangles are in texels, `x` right, `y` down (row 0 = `v = 1`). Offsets `Δt` are added
//! to the *destination* texel to find the first-order texel read.
//!
//! # Limits
//! Pieces with `w == 0` or `h == 0` are dropped (they do nothing), and pieces are cropped to
//! the texels whose first-order read `t + Δt` lies in the map (the rest add 0). A piece must lie inside
//! its atlas and its destination inside the lightmap; anything else is an error (the binning
//! stage produces such pieces only when its inputs disagree with the render's).

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::types::TransferPiece;

/// Side of a compute-path tile in texels (= workgroup size in each dimension).
/// Must match `TILE_SIZE` in `shaders/transfer_gather.wgsl`.
pub const TILE_SIZE: u32 = 8;

/// One piece as the GPU sees it. 32 bytes.
/// Must match `PieceInstance` in `shaders/transfer_gather.wgsl` and the instance vertex
/// attributes (locations 0–3) of `shaders/transfer.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PieceInstance {
    /// Top-left texel of the rectangle in the atlas.
    pub src: [u32; 2],
    /// Top-left lightmap texel receiving it.
    pub dst: [u32; 2],
    /// Width and height in texels.
    pub size: [u32; 2],
    /// `Δt` in texels (`+y` down).
    pub offset: [i32; 2],
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
}

impl FrameSchedule {
    /// Total texels written by all pieces (= texel blends per frame in the blend path).
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
    for (i, p) in pieces.iter().enumerate() {
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
        if p.dst_x as u64 + p.w as u64 > lw as u64 || p.dst_y as u64 + p.h as u64 > lh as u64 {
            return Err(PassError::InvalidInput {
                what: format!("pieces[{i}] destination rectangle"),
                problem: format!(
                    "({}, {}) + {}×{} leaves the {lw}×{lh} lightmap; render with the lightmap \
                     size the maps were baked for",
                    p.dst_x, p.dst_y, p.w, p.h
                ),
            });
        }
        // Crop to the texels whose source t + Δt lies in the map: first order is 0
        // outside it (Eq. 4), so the cropped texels add exactly nothing, and the shaders
        // need no bounds test on the first-order read.
        let (Some((x0, w)), Some((y0, h))) = (
            read_inside(p.dst_x, p.w, p.offset[0], lw),
            read_inside(p.dst_y, p.h, p.offset[1], lh),
        ) else {
            continue;
        };
        per_atlas[p.atlas as usize].push(PieceInstance {
            src: [p.src_x + x0, p.src_y + y0],
            dst: [p.dst_x + x0, p.dst_y + y0],
            size: [w, h],
            offset: p.offset,
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
    })
}

/// Along one axis: the first local index and the count of `dst + i` (`0 ≤ i < len`) whose
/// read `dst + i + offset` lies in `[0, map)`; `None` if there is none.
fn read_inside(dst: u32, len: u32, offset: i32, map: u32) -> Option<(u32, u32)> {
    let (dst, len, offset, map) = (dst as i64, len as i64, offset as i64, map as i64);
    let lo = (-offset - dst).max(0);
    let hi = (map - offset - dst).min(len);
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

/// Buckets each batch's instances by the tiles their destination rectangles overlap.
/// Within a tile, instances keep their input order.
pub fn build_tiles(schedule: &FrameSchedule) -> Vec<AtlasTiles> {
    let [lw, lh] = schedule.lightmap_size;
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
        }
    }

    #[test]
    fn shared_struct_sizes() {
        assert_eq!(std::mem::size_of::<PieceInstance>(), 32);
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
