//! The frame's transfer as sparse receiver rows (plain data, no GPU): for the rows path
//! ([`crate::transfer::TransferPath::Rows`], [`crate::transfer_rows`]).
//!
//! The maps of Eq. 9 say, per piece and texel, "add `atlas[src + (i,j)]` times the first-order
//! light read at one place". The blend and gather paths walk the maps; this path turns them
//! around once per scene: every lightmap texel `t` gets the list of what it adds, one
//! [`RowEntry`] `(w, s)` per distinct place `s` it reads, and a frame is
//!
//! ```text
//! final[t] = base[t] + Σ_{(w, s) ∈ row(t)} w · source[s]
//! ```
//!
//! — one pass, one invocation per texel, no blending, no tiles. The same maps, the same
//! products: a piece's value at `t` multiplies the first order read at `⌊t/2^ℓ⌋ + Δ` of level
//! `ℓ`, so its entry is that value with that read's address. Entries of one texel that read
//! the same place are summed (in `f64`, stored `f32`), and zero map values are dropped.
//!
//! # The source
//! `source` is one array of RGBA texels: the first-order map (the transfer's input, `W×H`,
//! row-major) followed by the packed first-order pyramid ([`crate::pyramid`],
//! `packed_size(W×H, L)` row-major, `L` the highest piece level), so a read of level `ℓ` at
//! block `q` is `W·H + (origin_ℓ.y + q.y)·PW + origin_ℓ.x + q.x` ([`source_index`]). The
//! rows pass copies both into it each frame (`cs_pack`), a few percent of the lightmap's
//! texels more than the lightmap.
//!
//! # Receiver blocks
//! A piece of receiver level `r > 0` adds its block value into every *covered* texel of the
//! block (the other paths' resolve step). Its entries are repeated in the rows of the block's
//! texels with [`COVERED_ONLY`] set in `s`: the pass skips them where the base's alpha
//! (coverage) is 0, which only the frame knows. So the rows hold what the blocks share once
//! per texel: their memory, not their arithmetic, is what the blocks saved.
//!
//! # Pruning
//! [`build_rows_pruned`] drops, per row, the entries of smallest weight whose weights sum to
//! at most `τ` times the row's (weights measured by their largest channel's magnitude, `Σ_k
//! |w_k|` the row's). A texel's transfer then changes by at most `τ · Σ_k |w_k| · max_s
//! source[s]` per channel, under any first order. On the head's default bake at 256² (`ortm
//! bake head --size 256 --levels 3e-3`, 7.81 M entries) an eighth of the entries (12.4 %)
//! together carry at most a ten-thousandth of their rows' weight: mostly far blocks read with
//! weights below 10⁻⁶ of their row's (docs/render.md, "Rows pruning"). [`crate::transfer::TransferOptions::best_for`] prunes at
//! [`ROWS_PRUNE`]; `build_rows` (and `TransferOptions::default()`) keeps every entry.
//!
//! # Order and precision
//! Rows are in texel order (`y·W + x`), entries within a row by source index (reads that lie
//! close in memory come together). Summation order differs from the other paths: the GPU sums
//! in `f32` in row order, as [`crate::cpu::transfer_rows`] does.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::pyramid::{level_size, packed_size};
use crate::schedule::FrameSchedule;
use crate::types::AtlasData;

/// Bit of [`RowEntry::source`] marking an entry of a receiver block: added only where the
/// base's alpha (coverage) is above 0.
pub const COVERED_ONLY: u32 = 1 << 31;

/// One entry of a receiver's row: its weight per channel and where it reads. 16 bytes.
/// Must match the `vec4<f32>` entries of `shaders/transfer_rows.wgsl` (`w` in `.rgb`, the
/// source index's bits in `.a`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct RowEntry {
    /// Dimensionless transfer weight, RGB.
    pub w: [f32; 3],
    /// Index into the source array (module docs), [`COVERED_ONLY`] or'ed in for receiver
    /// blocks.
    pub source: u32,
}

/// Every texel's row: the rows path's per-scene data.
#[derive(Clone, Debug, PartialEq)]
pub struct RowSchedule {
    /// Lightmap `[width, height]`.
    pub lightmap_size: [u32; 2],
    /// The highest level read (0: no pyramid in the source).
    pub max_level: u32,
    /// Texels in the source array (the lightmap's plus the packed pyramid's).
    pub source_len: u32,
    /// `W·H + 1` offsets into `entries`: texel `y·W + x` owns `offsets[i]..offsets[i + 1]`.
    pub offsets: Vec<u32>,
    /// All rows' entries, concatenated.
    pub entries: Vec<RowEntry>,
}

impl RowSchedule {
    /// Width of the packed pyramid in the source (0 without levels).
    pub fn packed_width(&self) -> u32 {
        packed_width(self.lightmap_size, self.max_level)
    }

    /// The entries of texel `(x, y)`.
    pub fn row(&self, x: u32, y: u32) -> &[RowEntry] {
        let i = (y * self.lightmap_size[0] + x) as usize;
        &self.entries[self.offsets[i] as usize..self.offsets[i + 1] as usize]
    }
}

fn packed_width(size: [u32; 2], max_level: u32) -> u32 {
    if max_level == 0 {
        0
    } else {
        packed_size(size, max_level)[0]
    }
}

/// Where a read of level `level` at block `q` lies in the source array of a `size` lightmap
/// whose pieces read levels up to `max_level`; `None` outside the level (the read is 0).
pub fn source_index(size: [u32; 2], max_level: u32, level: u32, q: [i64; 2]) -> Option<u32> {
    let [n0, n1] = level_size(size, level);
    if q[0] < 0 || q[1] < 0 || q[0] >= n0 as i64 || q[1] >= n1 as i64 {
        return None;
    }
    let (x, y) = (q[0] as u64, q[1] as u64);
    let texels = size[0] as u64 * size[1] as u64;
    let i = if level == 0 {
        y * size[0] as u64 + x
    } else {
        let o = crate::pyramid::level_origin(size, level);
        texels + (o[1] as u64 + y) * packed_width(size, max_level) as u64 + o[0] as u64 + x
    };
    Some(i as u32)
}

/// The pruning `τ` that [`crate::transfer::TransferOptions::best_for`] takes for the rows path
/// (module docs, "Pruning").
pub const ROWS_PRUNE: f32 = 1e-4;

/// The rows of `schedule`'s pieces over `atlases` (module docs), every entry kept.
///
/// Errors: [`PassError::TooLarge`] when the source or the entries do not fit 32-bit indices
/// (with the high bit kept for [`COVERED_ONLY`]).
pub fn build_rows(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
) -> Result<RowSchedule, PassError> {
    build_rows_pruned(schedule, atlases, 0.0)
}

/// [`build_rows`] with each row pruned at `prune` (`τ`, module docs "Pruning"; 0 keeps every
/// entry).
///
/// # Panics
/// When `prune` is negative or not finite.
pub fn build_rows_pruned(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    prune: f32,
) -> Result<RowSchedule, PassError> {
    assert!(
        prune.is_finite() && prune >= 0.0,
        "build_rows_pruned: prune {prune} must be finite and ≥ 0"
    );
    let size = schedule.lightmap_size;
    let [w, h] = size;
    let max_level = schedule.max_level();
    let texels = w as u64 * h as u64;
    let source_len = texels
        + if max_level > 0 {
            let p = packed_size(size, max_level);
            p[0] as u64 * p[1] as u64
        } else {
            0
        };
    if source_len >= COVERED_ONLY as u64 {
        return Err(PassError::TooLarge {
            what: "rows path: first-order texels and pyramid blocks".into(),
            size: source_len,
            limit: COVERED_ONLY as u64 - 1,
        });
    }
    // Each non-zero map value: the receivers it adds into, its source and weight; called
    // twice (count, then fill) so that the entries are laid out without a sort of them all.
    let visit = |f: &mut dyn FnMut(u32, u32, [f32; 3])| {
        for batch in &schedule.batches {
            let atlas = &atlases[batch.atlas as usize];
            for inst in &batch.instances {
                let r = inst.receiver_level;
                let shift = inst.level - r;
                for j in 0..inst.size[1] {
                    for i in 0..inst.size[0] {
                        let a =
                            atlas.rgb[((inst.src[1] + j) * atlas.width + inst.src[0] + i) as usize];
                        if a == [0.0; 3] {
                            continue;
                        }
                        let c = [
                            inst.dst[0] + i - inst.block_origin[0],
                            inst.dst[1] + j - inst.block_origin[1],
                        ];
                        let q = [
                            (c[0] >> shift) as i64 + inst.offset[0] as i64,
                            (c[1] >> shift) as i64 + inst.offset[1] as i64,
                        ];
                        let Some(s) = source_index(size, max_level, inst.level, q) else {
                            continue;
                        };
                        if r == 0 {
                            f(c[1] * w + c[0], s, a);
                            continue;
                        }
                        let side = 1u32 << r;
                        for v in c[1] * side..((c[1] + 1) * side).min(h) {
                            for u in c[0] * side..((c[0] + 1) * side).min(w) {
                                f(v * w + u, s | COVERED_ONLY, a);
                            }
                        }
                    }
                }
            }
        }
    };
    let mut counts = vec![0u64; texels as usize + 1];
    visit(&mut |t, _, _| counts[t as usize + 1] += 1);
    for i in 1..counts.len() {
        counts[i] += counts[i - 1];
    }
    let total = counts[texels as usize];
    if total > u32::MAX as u64 {
        return Err(PassError::TooLarge {
            what: "rows path: row entries".into(),
            size: total,
            limit: u32::MAX as u64,
        });
    }
    let mut next: Vec<u64> = counts[..texels as usize].to_vec();
    let mut raw = vec![RowEntry::default(); total as usize];
    visit(&mut |t, s, a| {
        let k = &mut next[t as usize];
        raw[*k as usize] = RowEntry { w: a, source: s };
        *k += 1;
    });
    // Per row: by source (stable, so equal reads keep the pieces' order), equal reads summed,
    // the merged row written over the front of `raw` (it never outruns the rows it reads).
    let mut offsets = Vec::with_capacity(texels as usize + 1);
    offsets.push(0u32);
    let mut write = 0usize;
    for t in 0..texels as usize {
        let (start, end) = (counts[t] as usize, counts[t + 1] as usize);
        raw[start..end].sort_by_key(|e| e.source);
        let row_start = write;
        let mut k = start;
        while k < end {
            let s = raw[k].source;
            let mut sum = [0.0f64; 3];
            while k < end && raw[k].source == s {
                for (acc, v) in sum.iter_mut().zip(raw[k].w) {
                    *acc += v as f64;
                }
                k += 1;
            }
            raw[write] = RowEntry {
                w: sum.map(|v| v as f32),
                source: s,
            };
            write += 1;
        }
        write = row_start + prune_row(&mut raw[row_start..write], prune as f64);
        offsets.push(write as u32);
    }
    raw.truncate(write);
    raw.shrink_to_fit();
    let entries = raw;
    Ok(RowSchedule {
        lightmap_size: size,
        max_level,
        source_len: source_len as u32,
        offsets,
        entries,
    })
}

/// Drops the entries of `row` of smallest magnitude (largest channel's `|w|`) as long as
/// their magnitudes sum to at most `prune` times the row's; keeps the others in their order
/// and returns how many are kept (at the front of `row`).
fn prune_row(row: &mut [RowEntry], prune: f64) -> usize {
    if prune <= 0.0 || row.len() < 2 {
        return row.len();
    }
    let mag = |e: &RowEntry| e.w.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64));
    let budget = prune * row.iter().map(mag).sum::<f64>();
    let mut order: Vec<usize> = (0..row.len()).collect();
    order.sort_by(|&a, &b| mag(&row[a]).total_cmp(&mag(&row[b])));
    let mut dropped = vec![false; row.len()];
    let mut spent = 0.0;
    for k in order {
        spent += mag(&row[k]);
        if spent > budget {
            break;
        }
        dropped[k] = true;
    }
    let mut kept = 0;
    for k in 0..row.len() {
        if !dropped[k] {
            row[kept] = row[k];
            kept += 1;
        }
    }
    kept
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::schedule::build_schedule;
    use crate::types::TransferPiece;

    fn atlas(width: u32, height: u32, f: impl Fn(u32, u32) -> [f32; 3]) -> AtlasData {
        AtlasData {
            width,
            height,
            rgb: (0..height)
                .flat_map(|y| (0..width).map(move |x| (x, y)))
                .map(|(x, y)| f(x, y))
                .collect(),
        }
    }

    fn piece(dst: [u32; 2], size: [u32; 2], offset: [i32; 2], level: u32, r: u32) -> TransferPiece {
        TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w: size[0],
            h: size[1],
            dst_x: dst[0],
            dst_y: dst[1],
            offset,
            level,
            receiver_level: r,
        }
    }

    fn entry(w: [f32; 3], source: u32) -> RowEntry {
        RowEntry { w, source }
    }

    #[test]
    fn a_level_zero_piece_becomes_one_entry_per_non_zero_value() {
        let a = atlas(2, 2, |x, y| {
            if (x, y) == (1, 1) {
                [0.0; 3]
            } else {
                [1.0, 2.0, 3.0]
            }
        });
        let s = build_schedule([4, 4], &[[2, 2]], &[piece([1, 1], [2, 2], [-1, 2], 0, 0)]).unwrap();
        let rows = build_rows(&s, &[a]).unwrap();
        assert_eq!(rows.source_len, 16);
        // Texel (1,1) reads (0,3); (2,1) reads (1,3); (1,2) and (2,2) read below the map
        // (cropped away), and (2,2)'s value is 0 anyway.
        assert_eq!(rows.row(1, 1), &[entry([1.0, 2.0, 3.0], 12)]);
        assert_eq!(rows.row(2, 1), &[entry([1.0, 2.0, 3.0], 13)]);
        assert!(rows.row(1, 2).is_empty() && rows.row(2, 2).is_empty());
        assert_eq!(rows.entries.len(), 2);
    }

    #[test]
    fn equal_reads_are_summed_and_levels_read_the_packed_pyramid() {
        // Two level-1 pieces whose texels (0,0) and (1,0) read the same block: one entry each.
        let a = atlas(2, 1, |x, _| [0.5 + x as f32, 1.0, 0.0]);
        let p = piece([0, 0], [2, 1], [1, 0], 1, 0);
        let s = build_schedule([4, 4], &[[2, 1]], &[p, p]).unwrap();
        let rows = build_rows(&s, &[a]).unwrap();
        assert_eq!(rows.max_level, 1);
        // Level 1 of 4×4 is 2×2, packed alone: block (1, 0) is source 16 + 1.
        assert_eq!(rows.source_len, 16 + 4);
        assert_eq!(rows.row(0, 0), &[entry([1.0, 2.0, 0.0], 17)]);
        assert_eq!(rows.row(1, 0), &[entry([3.0, 2.0, 0.0], 17)]);
    }

    #[test]
    fn receiver_blocks_repeat_in_their_texels_marked_covered_only() {
        // A level-1 receiver block (0, 0) of a 3×3 lightmap: texels (0..2, 0..2).
        let a = atlas(1, 1, |_, _| [0.25; 3]);
        let s = build_schedule([3, 3], &[[1, 1]], &[piece([0, 0], [1, 1], [1, 1], 1, 1)]).unwrap();
        let rows = build_rows(&s, &[a]).unwrap();
        let e = RowEntry {
            w: [0.25; 3],
            source: (9 + 3) | COVERED_ONLY,
        };
        for (x, y) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            assert_eq!(rows.row(x, y), &[e], "texel ({x}, {y})");
        }
        assert_eq!(rows.entries.len(), 4);
    }

    /// Entries' weights spanning nine decades on a 16×16 map read by level-0 pieces of many
    /// offsets: pruning keeps the kept entries in order, drops no more than `τ` of each row's
    /// weight, changes each texel's transfer by at most `τ · Σ|w| · max source` under random
    /// sources, drops more as `τ` grows, and keeps everything at `τ = 0`.
    #[test]
    fn pruning_drops_at_most_tau_of_each_row() {
        let size = [16u32, 16];
        let mut pieces = Vec::new();
        let mut sizes = Vec::new();
        let mut atlases = Vec::new();
        for (k, (dx, dy)) in [(-3, 0), (-1, 2), (0, 0), (1, 1), (2, -3), (4, 4), (-5, 1)]
            .into_iter()
            .enumerate()
        {
            // Weight of texel (x, y) of piece k: 10^-(x + y + k) mod 9, times channel factors.
            atlases.push(atlas(16, 16, move |x, y| {
                let e = ((x + 3 * y + k as u32) % 10) as i32;
                let w = 10f32.powi(-e);
                [w, 0.5 * w, if e % 3 == 0 { -w } else { 0.25 * w }]
            }));
            sizes.push([16, 16]);
            pieces.push(TransferPiece {
                atlas: k as u32,
                ..piece([0, 0], [16, 16], [dx, dy], 0, 0)
            });
        }
        let s = build_schedule(size, &sizes, &pieces).unwrap();
        let full = build_rows(&s, &atlases).unwrap();
        assert_eq!(build_rows_pruned(&s, &atlases, 0.0).unwrap(), full);
        let mag = |e: &RowEntry| e.w.iter().fold(0.0f64, |m, v| m.max(v.abs() as f64));
        let mut seed = 7u64;
        let source: Vec<[f64; 3]> = (0..full.source_len)
            .map(|_| {
                [0; 3].map(|_| {
                    seed = seed
                        .wrapping_mul(6364136223846793005)
                        .wrapping_add(1442695040888963407);
                    (seed >> 40) as f64 / (1u64 << 24) as f64
                })
            })
            .collect();
        let apply = |row: &[RowEntry]| {
            row.iter().fold([0.0f64; 3], |acc, e| {
                let v = source[e.source as usize];
                [0, 1, 2].map(|c| acc[c] + e.w[c] as f64 * v[c])
            })
        };
        let mut kept_before = full.entries.len();
        for tau in [1e-6f32, 1e-4, 1e-2] {
            let pruned = build_rows_pruned(&s, &atlases, tau).unwrap();
            assert!(
                pruned.entries.len() <= kept_before,
                "τ {tau}: more entries than a smaller τ"
            );
            kept_before = pruned.entries.len();
            for y in 0..size[1] {
                for x in 0..size[0] {
                    let (a, b) = (full.row(x, y), pruned.row(x, y));
                    // The kept entries: a subsequence of the full row, in order.
                    let mut it = a.iter();
                    assert!(
                        b.iter().all(|e| it.any(|f| f == e)),
                        "τ {tau}: ({x}, {y}) reordered"
                    );
                    let total: f64 = a.iter().map(mag).sum();
                    let dropped = total - b.iter().map(mag).sum::<f64>();
                    assert!(
                        dropped <= tau as f64 * total * (1.0 + 1e-9),
                        "τ {tau}: ({x}, {y}) dropped {dropped} of {total}"
                    );
                    let (fa, fb) = (apply(a), apply(b));
                    for c in 0..3 {
                        assert!(
                            (fa[c] - fb[c]).abs() <= tau as f64 * total + 1e-12,
                            "τ {tau}: ({x}, {y}) channel {c}"
                        );
                    }
                }
            }
        }
        assert!(
            kept_before < full.entries.len() * 3 / 4,
            "τ = 1e-2 dropped little: {kept_before} of {}",
            full.entries.len()
        );
    }
}
