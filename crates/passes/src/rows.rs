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

/// The rows of `schedule`'s pieces over `atlases` (module docs).
///
/// Errors: [`PassError::TooLarge`] when the source or the entries do not fit 32-bit indices
/// (with the high bit kept for [`COVERED_ONLY`]).
pub fn build_rows(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
) -> Result<RowSchedule, PassError> {
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
}
