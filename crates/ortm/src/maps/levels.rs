//! Multi-resolution offset maps: Eq. 9 with senders read from a pyramid of the first-order
//! lightmap.
//!
//! # The form
//! Level `ℓ` of the [`Pyramid`] holds the first-order radiosity averaged over `2^ℓ × 2^ℓ`
//! blocks of texels, weighted by each texel's area (uncovered texels weigh 0, so gutters never
//! darken a block): `P_ℓ(b) = Σ_{j ∈ b} A_j B_o(j) / Σ_{j ∈ b} A_j`. A [`TransferMap`] of level `ℓ`
//! ([`TransferMap::level`]) and offset `Δ` (in level-`ℓ` blocks) holds full-resolution receiver values: its value at
//! texel `t` multiplies `P_ℓ(⌊t / 2^ℓ⌋ + Δ)`,
//!
//! ```text
//! B(t) = B_o(t) + Σ_maps map(t) · P_ℓ(⌊t / 2^ℓ⌋ + Δ) .
//! ```
//!
//! Level 0 is today's form (`P_0 = B_o`). On the GPU a level-`ℓ` map is one more shifted read:
//! the pyramid level sampled with nearest filtering at the receiver's texel shifted by
//! `Δ·2^ℓ` texels. Where a map's block lies outside level `ℓ` (or holds no covered texel) it
//! reads 0.
//!
//! The bake ([`crate::bake::multires`]) chooses for every receiver a partition of its senders
//! into pyramid blocks, coarse where the transfer varies little across a block and down to
//! single texels near the receiver; the map value is the transfer summed over the block, so the
//! only approximation is the first-order light taken as its block mean.
//!
//! # Receiver blocks
//! A map of receiver level `r > 0` ([`TransferMap::receiver_level`], `r ≤ ℓ`) holds one value
//! per `2^r × 2^r` block of receivers: its grid is `⌈W/2^r⌉ × ⌈H/2^r⌉` and its value at block `c`
//! adds `map(c) · P_ℓ(⌊c / 2^(ℓ−r)⌋ + Δ)` into every *covered* texel `t` of the block
//! (`⌊t / 2^r⌋ = c`). Coverage rule: a texel is covered when its pyramid weight (its area) is
//! positive, the same texels the GPU marks with first-order alpha > 0; uncovered texels of the
//! block receive nothing. The bake's [`crate::bake::multires::coarsen_receivers`] makes such maps.
//!
//! # Determinism
//! Each texel is accumulated by one thread in map order, in f64, rounded once (as [`super::apply`]).

use rayon::prelude::*;

use super::MapsError;
use super::transfer_map::{TransferMap, check_lightmap};
use crate::Lightmap;

/// The area-weighted pyramid of a first-order lightmap (module docs).
#[derive(Clone, Debug)]
pub struct Pyramid {
    /// Per level (0 = the lightmap itself): width, height, mean radiosity (W/m²) per block and
    /// the block's summed weight (m²).
    pub levels: Vec<PyramidLevel>,
}

/// One level of a [`Pyramid`].
#[derive(Clone, Debug)]
pub struct PyramidLevel {
    /// Width in blocks: `⌈W / 2^ℓ⌉`.
    pub width: u32,
    /// Height in blocks: `⌈H / 2^ℓ⌉`.
    pub height: u32,
    /// Area-weighted mean radiosity of each block (0 where the block's weight is 0), row-major.
    pub mean: Vec<[f32; 3]>,
    /// Summed weight (texel areas, m²) of each block, row-major.
    pub weight: Vec<f64>,
}

impl PyramidLevel {
    /// The block value at `(x, y)`, 0 outside the level.
    #[inline]
    pub fn get(&self, x: i64, y: i64) -> [f32; 3] {
        if x < 0 || y < 0 || x >= self.width as i64 || y >= self.height as i64 {
            return [0.0; 3];
        }
        self.mean[(y * self.width as i64 + x) as usize]
    }
}

/// One level's block sums: width, height, `Σ value · weight` and `Σ weight` per block.
type Sums = (u32, u32, Vec<[f64; 3]>, Vec<f64>);

/// One level up: the `⌈w/2⌉ × ⌈h/2⌉` sums of the 2×2 blocks of a `w × h` row-major image
/// (`add` adds a value into a sum that starts at `zero`). Repeated, it gives exactly the sums
/// over each level's blocks of texels; the bake's partition uses it too.
pub(crate) fn halve<T: Copy>(
    (w, h): (u32, u32),
    data: &[T],
    zero: T,
    add: impl Fn(&mut T, &T),
) -> Vec<T> {
    let nw = w.div_ceil(2);
    let mut out = vec![zero; (nw * h.div_ceil(2)) as usize];
    for y in 0..h {
        for x in 0..w {
            add(
                &mut out[((y / 2) * nw + x / 2) as usize],
                &data[(y * w + x) as usize],
            );
        }
    }
    out
}

/// Adds RGB sums.
pub(crate) fn add3(a: &mut [f64; 3], b: &[f64; 3]) {
    for c in 0..3 {
        a[c] += b[c];
    }
}

/// Block sums of `value · weight` and `weight` at every level up to `levels − 1`.
fn reduce(first: Sums, levels: u32) -> Vec<Sums> {
    let mut out = vec![first];
    for _ in 1..levels {
        let (w, h, s, a) = out.last().unwrap();
        let ns = halve((*w, *h), s, [0.0; 3], add3);
        let na = halve((*w, *h), a, 0.0, |x, y| *x += y);
        out.push((w.div_ceil(2), h.div_ceil(2), ns, na));
    }
    out
}

/// Number of levels needed for a `width × height` lightmap to reach one block.
pub fn level_count(width: u32, height: u32) -> u32 {
    32 - (width.max(height).max(1) - 1).leading_zeros() + 1
}

impl Pyramid {
    /// The pyramid of `first_order` with per-texel weights `weight` (texel area in m², 0 where
    /// uncovered; row-major `W × H`), `levels` levels (at least 1).
    ///
    /// # Errors
    /// [`MapsError::LightmapSize`] / [`MapsError::LightmapDataLength`] for a malformed
    /// lightmap, [`MapsError::SizeMismatch`] when `weight` is not `W × H`.
    pub fn new(first_order: &Lightmap, weight: &[f32], levels: u32) -> Result<Self, MapsError> {
        check_lightmap("first-order lightmap", first_order)?;
        if weight.len() != first_order.data.len() {
            return Err(MapsError::SizeMismatch {
                what: "pyramid weights vs. first-order lightmap".to_owned(),
                expected: (first_order.width, first_order.height),
                found: (weight.len() as u32, 1),
            });
        }
        let weighted = first_order
            .data
            .iter()
            .zip(weight)
            .map(|(v, &a)| v.map(|c| c as f64 * a as f64))
            .collect();
        let weight = weight.iter().map(|&a| a as f64).collect();
        let levels = reduce(
            (first_order.width, first_order.height, weighted, weight),
            levels.max(1),
        )
        .into_iter()
        .map(|(w, h, s, a)| PyramidLevel {
            width: w,
            height: h,
            mean: s
                .iter()
                .zip(&a)
                .map(|(s, &a)| {
                    if a > 0.0 {
                        s.map(|c| (c / a) as f32)
                    } else {
                        [0.0; 3]
                    }
                })
                .collect(),
            weight: a,
        })
        .collect();
        Ok(Self { levels })
    }
}

/// The indirect light `Σ_maps map(t) · P_ℓ(⌊t/2^ℓ⌋ + Δ)` (module docs); a map of receiver
/// level `r > 0` adds `map(c) · P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)` into every covered texel `t` of its block
/// `c = ⌊t/2^r⌋` (covered: the pyramid's level-0 weight is > 0), and nothing into uncovered ones.
///
/// # Errors
/// [`MapsError::SizeMismatch`] when a map's lightmap size differs from the pyramid's level 0 or
/// its level is beyond the pyramid.
pub fn apply_levels_indirect(
    maps: &[TransferMap],
    pyramid: &Pyramid,
) -> Result<Lightmap, MapsError> {
    let base = &pyramid.levels[0];
    let (w, h) = (base.width, base.height);
    for (i, m) in maps.iter().enumerate() {
        if m.lightmap_size() != (w, h) || m.level() as usize >= pyramid.levels.len() {
            return Err(MapsError::SizeMismatch {
                what: format!(
                    "level-{} map {i} (offset {:?}, receiver level {}) vs. the {}-level pyramid",
                    m.level(),
                    m.offset.to_array(),
                    m.receiver_level(),
                    pyramid.levels.len()
                ),
                expected: (w, h),
                found: m.lightmap_size(),
            });
        }
    }
    let rows: Vec<Vec<[f32; 3]>> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut acc = vec![[0.0f64; 3]; w as usize];
            let covered = &base.weight[(y * w) as usize..((y + 1) * w) as usize];
            for m in maps {
                let l = m.level();
                let rl = m.receiver_level();
                let lv = &pyramid.levels[l as usize];
                let (dx, dy) = (m.offset.x as i64, m.offset.y as i64);
                // The map's grid row holding lightmap row `y`.
                let gy = y >> rl;
                for crop in m.crops() {
                    let r = crop.rect;
                    if gy < r.y || gy >= r.y + r.h {
                        continue;
                    }
                    let row =
                        &crop.data[((gy - r.y) * r.w) as usize..((gy - r.y + 1) * r.w) as usize];
                    let by = (i64::from(gy) >> (l - rl)) + dy;
                    for (k, v) in row.iter().enumerate() {
                        let gx = r.x + k as u32;
                        let s = lv.get((i64::from(gx) >> (l - rl)) + dx, by);
                        let x0 = gx << rl;
                        let x1 = ((gx + 1) << rl).min(w);
                        for x in x0..x1 {
                            if rl > 0 && covered[x as usize] <= 0.0 {
                                continue;
                            }
                            for c in 0..3 {
                                acc[x as usize][c] += v[c] as f64 * s[c] as f64;
                            }
                        }
                    }
                }
            }
            acc.into_iter().map(|a| a.map(|c| c as f32)).collect()
        })
        .collect();
    Ok(Lightmap {
        width: w,
        height: h,
        data: rows.into_iter().flatten().collect(),
    })
}

/// Final radiosity `B_o + Σ_maps map(t) · P_ℓ(⌊t/2^ℓ⌋ + Δ)`, the pyramid built from `first_order`
/// with texel weights `weight` (texel areas, 0 where uncovered).
///
/// # Errors
/// As [`Pyramid::new`] and [`apply_levels_indirect`].
pub fn apply_levels(
    maps: &[TransferMap],
    first_order: &Lightmap,
    weight: &[f32],
) -> Result<Lightmap, MapsError> {
    let levels = level_count(first_order.width, first_order.height);
    let pyramid = Pyramid::new(first_order, weight, levels)?;
    let mut out = apply_levels_indirect(maps, &pyramid)?;
    for (o, b) in out.data.iter_mut().zip(&first_order.data) {
        for c in 0..3 {
            o[c] += b[c];
        }
    }
    Ok(out)
}

/// Map-texel contributions per frame: the stored texels of every map (the GPU's work).
pub fn stored_texels(maps: &[TransferMap]) -> u64 {
    maps.iter().map(|m| m.stored_texels()).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_counts() {
        assert_eq!(level_count(1, 1), 1);
        assert_eq!(level_count(2, 2), 2);
        assert_eq!(level_count(3, 2), 3);
        assert_eq!(level_count(64, 64), 7);
        assert_eq!(level_count(65, 8), 8);
    }

    /// Block means weigh texels by area and ignore uncovered ones; the top level is the
    /// area-weighted mean of the whole map.
    #[test]
    fn pyramid_means_are_area_weighted() {
        let mut lm = Lightmap::new(3, 2);
        let mut wt = vec![0.0f32; 6];
        for (i, (v, a)) in [
            (1.0, 1.0),
            (3.0, 3.0),
            (5.0, 0.0),
            (7.0, 2.0),
            (0.0, 0.0),
            (2.0, 1.0),
        ]
        .into_iter()
        .enumerate()
        {
            lm.data[i] = [v; 3];
            wt[i] = a;
        }
        let p = Pyramid::new(&lm, &wt, level_count(3, 2)).unwrap();
        assert_eq!(p.levels.len(), 3);
        // Level 1: blocks {0,1,3,4} and {2,5}.
        let l1 = &p.levels[1];
        assert_eq!((l1.width, l1.height), (2, 1));
        let m0 = (1.0 + 9.0 + 14.0) / 6.0;
        assert!((l1.mean[0][0] as f64 - m0).abs() < 1e-6);
        assert!(
            (l1.mean[1][0] - 2.0).abs() < 1e-6,
            "the uncovered 5.0 weighs nothing"
        );
        let top = (1.0 + 9.0 + 14.0 + 2.0) / 7.0;
        assert!((p.levels[2].mean[0][0] as f64 - top).abs() < 1e-6);
    }

    /// A receiver-block map (level 1, receiver level 1) adds its block's value times the sender
    /// block's mean into the covered texels of the block only; a block beyond the pyramid reads 0.
    #[test]
    fn receiver_blocks_add_into_covered_texels() {
        use crate::maps::{Crop, CropRect};
        let mut lm = Lightmap::new(4, 2);
        let mut wt = vec![1.0f32; 8];
        wt[1] = 0.0; // texel (1, 0) uncovered
        wt[6] = 3.0; // texel (2, 1) weighs 3
        for (i, v) in lm.data.iter_mut().enumerate() {
            *v = [i as f32, 1.0, 0.0];
        }
        let map = TransferMap::from_crops(
            "t",
            glam::IVec2::new(1, 0),
            0.0,
            0.0,
            4,
            2,
            vec![Crop {
                rect: CropRect {
                    x: 0,
                    y: 0,
                    w: 2,
                    h: 1,
                },
                data: vec![[2.0, 0.5, 1.0], [7.0, 7.0, 7.0]],
            }],
        )
        .unwrap()
        .with_level(1)
        .unwrap()
        .with_receiver_level(1)
        .unwrap();
        assert_eq!((map.width(), map.height()), (2, 1));
        let p = Pyramid::new(&lm, &wt, level_count(4, 2)).unwrap();
        let out = apply_levels_indirect(std::slice::from_ref(&map), &p).unwrap();
        // Sender block (1, 0) of level 1: texels 2, 3, 6 (weight 3), 7.
        let mean = (2.0 + 3.0 + 3.0 * 6.0 + 7.0) / 6.0;
        for (i, v) in out.data.iter().enumerate() {
            let want = match i {
                0 | 4 | 5 => [2.0 * mean, 0.5, 0.0],
                _ => [0.0; 3],
            };
            for c in 0..3 {
                assert!(
                    (v[c] - want[c]).abs() < 1e-5,
                    "texel {i}: {v:?} vs {want:?}"
                );
            }
        }
    }
}
