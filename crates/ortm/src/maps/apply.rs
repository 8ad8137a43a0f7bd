//! CPU reference for applying transfer maps (paper Eq. 9 plus the first-order term):
//!
//! `B(t) = B_o(t) + Σ_maps map(t) · B_o(t + Δt)` per RGB channel, with `B_o = 0` outside the
//! lightmap. This is what the GPU renderer is checked against.
//!
//! # Data flow and units
//! Input: the first-order radiosity `B_o` (W/m², a [`Lightmap`]) and the transfer maps
//! (dimensionless). Output: a lightmap of the same size in W/m². [`apply_indirect`] returns only
//! the sum (Eq. 9's `TB_f`), [`apply`] adds `B_o`.
//!
//! # Determinism
//! Rows are processed in parallel (rayon), but each texel is accumulated by one thread in a fixed
//! order: an f64 accumulator starts at `B_o(t)` ([`apply`]) or 0 ([`apply_indirect`]), then adds
//! `f64(map(t)) · f64(B_o(t+Δt))` for the maps in slice order (each map contributes at most once
//! per texel because its crops are disjoint), and is rounded to f32 once at the end. The result is
//! therefore bit-identical for any thread count.
//!
//! # Cost
//! O(Σ stored texels of all maps + W·H); memory one f64 row per worker.

use rayon::prelude::*;

use super::MapsError;
use super::transfer_map::{TransferMap, check_lightmap};
use crate::Lightmap;

/// Final radiosity `B_o + Σ map·B_o(·+Δt)` (see the module doc).
///
/// # Errors
/// [`MapsError::LightmapSize`] / [`MapsError::LightmapDataLength`] for a malformed
/// `first_order`, [`MapsError::SizeMismatch`] if a map's lightmap size differs from it.
pub fn apply(maps: &[TransferMap], first_order: &Lightmap) -> Result<Lightmap, MapsError> {
    apply_impl(maps, first_order, true)
}

/// Indirect part only, `Σ map·B_o(·+Δt)` (Eq. 9's `TB_f`).
///
/// # Errors
/// As [`apply`].
pub fn apply_indirect(maps: &[TransferMap], first_order: &Lightmap) -> Result<Lightmap, MapsError> {
    apply_impl(maps, first_order, false)
}

fn apply_impl(
    maps: &[TransferMap],
    first_order: &Lightmap,
    include_first_order: bool,
) -> Result<Lightmap, MapsError> {
    check_lightmap("first-order lightmap", first_order)?;
    let (w, h) = (first_order.width, first_order.height);
    for (i, m) in maps.iter().enumerate() {
        if m.level() > 0 {
            return Err(MapsError::NeedsPyramid {
                map: i,
                level: m.level(),
            });
        }
        if (m.width(), m.height()) != (w, h) {
            return Err(MapsError::SizeMismatch {
                what: format!(
                    "transfer map {i} (offset {:?}) vs. first-order lightmap",
                    m.offset.to_array()
                ),
                expected: (w, h),
                found: (m.width(), m.height()),
            });
        }
    }
    let wu = w as usize;
    let mut out = Lightmap::new(w, h);
    out.data.par_chunks_mut(wu).enumerate().for_each_init(
        || vec![[0.0f64; 3]; wu],
        |acc, (y, out_row)| {
            let y = y as i64;
            let bo_row = &first_order.data[y as usize * wu..(y as usize + 1) * wu];
            for (a, b) in acc.iter_mut().zip(bo_row) {
                *a = if include_first_order {
                    b.map(f64::from)
                } else {
                    [0.0; 3]
                };
            }
            for m in maps {
                let sy = y + m.offset.y as i64;
                if sy < 0 || sy >= h as i64 {
                    continue;
                }
                let src_row = &first_order.data[sy as usize * wu..(sy as usize + 1) * wu];
                let dx = m.offset.x as i64;
                for c in m.crops() {
                    let r = c.rect;
                    if y < r.y as i64 || y >= r.y_end() as i64 {
                        continue;
                    }
                    // Columns x in the rect with 0 <= x + dx < w.
                    let x0 = (r.x as i64).max(-dx);
                    let x1 = (r.x_end() as i64).min(w as i64 - dx);
                    if x0 >= x1 {
                        continue;
                    }
                    let vals = &c.data[(y - r.y as i64) as usize * r.w as usize..];
                    for x in x0..x1 {
                        let v = vals[(x - r.x as i64) as usize];
                        let s = src_row[(x + dx) as usize];
                        let a = &mut acc[x as usize];
                        for ch in 0..3 {
                            a[ch] += f64::from(v[ch]) * f64::from(s[ch]);
                        }
                    }
                }
            }
            for (o, a) in out_row.iter_mut().zip(acc.iter()) {
                *o = a.map(|v| v as f32);
            }
        },
    );
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::crop::CropOptions;
    use glam::IVec2;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Random sparse full map.
    fn random_full(rng: &mut ChaCha8Rng, w: u32, h: u32) -> Lightmap {
        let mut m = Lightmap::new(w, h);
        let density: f64 = rng.random_range(0.0..0.5);
        for v in m.data.iter_mut() {
            if rng.random_bool(density) {
                *v = [rng.random(), rng.random(), rng.random_range(0.0..1e-3)];
            }
        }
        m
    }

    /// Brute force straight from the definition, on full (uncropped) maps, with an
    /// independent loop structure: texel-major, offsets checked with `get_checked`.
    fn brute_force(
        offsets: &[IVec2],
        fulls: &[Lightmap],
        bo: &Lightmap,
        with_bo: bool,
    ) -> Vec<[f64; 3]> {
        let mut out = Vec::new();
        for y in 0..bo.height {
            for x in 0..bo.width {
                let mut acc = if with_bo {
                    bo.get(x, y).map(f64::from)
                } else {
                    [0.0; 3]
                };
                for (o, f) in offsets.iter().zip(fulls) {
                    let t = IVec2::new(x as i32, y as i32);
                    let src = bo.get_checked(t + *o).unwrap_or([0.0; 3]);
                    let v = f.get(x, y);
                    for c in 0..3 {
                        acc[c] += f64::from(v[c]) * f64::from(src[c]);
                    }
                }
                out.push(acc);
            }
        }
        out
    }

    #[test]
    fn matches_brute_force_on_random_data() {
        let mut rng = ChaCha8Rng::seed_from_u64(99);
        for case in 0..40 {
            let (w, h) = (rng.random_range(1..40), rng.random_range(1..30));
            let n = rng.random_range(0..12);
            // Offsets up to beyond the map size so t+Δt often leaves the map.
            let offsets: Vec<IVec2> = (0..n)
                .map(|_| {
                    IVec2::new(
                        rng.random_range(-(w as i32) - 2..w as i32 + 2),
                        rng.random_range(-(h as i32) - 2..h as i32 + 2),
                    )
                })
                .collect();
            let fulls: Vec<Lightmap> = (0..n).map(|_| random_full(&mut rng, w, h)).collect();
            let bo = random_full(&mut rng, w, h);
            let k = [0, 64][case % 2];
            let maps: Vec<TransferMap> = offsets
                .iter()
                .zip(&fulls)
                .map(|(o, f)| {
                    let opts = CropOptions {
                        rect_overhead_texels: k,
                    };
                    TransferMap::from_full_with(*o, 1.0, 1.0, f, &opts).unwrap()
                })
                .collect();
            for with_bo in [true, false] {
                let got = if with_bo {
                    apply(&maps, &bo)
                } else {
                    apply_indirect(&maps, &bo)
                }
                .unwrap();
                let want = brute_force(&offsets, &fulls, &bo, with_bo);
                for (i, (g, wv)) in got.data.iter().zip(&want).enumerate() {
                    for c in 0..3 {
                        // Same f64 summation order, so the f32 results agree exactly.
                        assert_eq!(
                            g[c].to_bits(),
                            (wv[c] as f32).to_bits(),
                            "case {case} texel {i} channel {c}"
                        );
                    }
                }
                // And against a naive f32 sum, within rounding.
                for (i, g) in got.data.iter().enumerate() {
                    let (x, y) = (i as u32 % w, i as u32 / w);
                    let mut s = if with_bo { bo.get(x, y) } else { [0.0; 3] };
                    for (o, f) in offsets.iter().zip(&fulls) {
                        let p = IVec2::new(x as i32, y as i32) + *o;
                        if let Some(b) = bo.get_checked(p) {
                            let v = f.get(x, y);
                            for c in 0..3 {
                                s[c] += v[c] * b[c];
                            }
                        }
                    }
                    for c in 0..3 {
                        assert!((g[c] - s[c]).abs() <= 1e-5 * (1.0 + s[c].abs()));
                    }
                }
            }
        }
    }

    #[test]
    fn hand_computed_example() {
        // 3×2 map, B_o = 1 at (2, 0) only. A map with Δt = (1, 0) and value 0.5 at (1, 0)
        // gathers from (2, 0); a map with Δt = (2, 1) at (0, 1) gathers from (2, 2): outside.
        let mut bo = Lightmap::new(3, 2);
        bo.set(2, 0, [1.0, 2.0, 4.0]);
        let mut f1 = Lightmap::new(3, 2);
        f1.set(1, 0, [0.5, 0.5, 0.25]);
        f1.set(2, 0, [9.0, 9.0, 9.0]); // gathers from (3, 0): outside, contributes nothing
        let mut f2 = Lightmap::new(3, 2);
        f2.set(0, 1, [7.0, 7.0, 7.0]);
        let maps = [
            TransferMap::from_full(IVec2::new(1, 0), 1.0, 1.0, &f1).unwrap(),
            TransferMap::from_full(IVec2::new(2, 1), 1.0, 1.0, &f2).unwrap(),
        ];
        let out = apply(&maps, &bo).unwrap();
        let mut want = Lightmap::new(3, 2);
        want.set(1, 0, [0.5, 1.0, 1.0]);
        want.set(2, 0, [1.0, 2.0, 4.0]);
        assert_eq!(out, want);
        let ind = apply_indirect(&maps, &bo).unwrap();
        let mut want = Lightmap::new(3, 2);
        want.set(1, 0, [0.5, 1.0, 1.0]);
        assert_eq!(ind, want);
        // No maps: apply is the identity, apply_indirect is black.
        assert_eq!(apply(&[], &bo).unwrap(), bo);
        assert_eq!(apply_indirect(&[], &bo).unwrap(), Lightmap::new(3, 2));
    }

    #[test]
    fn rejects_size_mismatch() {
        let m = TransferMap::from_full(IVec2::ZERO, 1.0, 1.0, &Lightmap::new(4, 4)).unwrap();
        let e = apply(&[m], &Lightmap::new(4, 5)).unwrap_err();
        assert!(matches!(e, MapsError::SizeMismatch { .. }), "{e}");
        let bad = Lightmap {
            width: 2,
            height: 2,
            data: vec![],
        };
        assert!(matches!(
            apply(&[], &bad),
            Err(MapsError::LightmapDataLength { .. })
        ));
    }
}
