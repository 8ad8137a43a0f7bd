//! Voronoi weights of a set of offsets: continuous clipped cells (Sec. 5.1) and discrete
//! integer cells with the total-Voronoi-area map `TVA` (Eq. 8).
//!
//! # Data flow
//! The final offsets `O` (distinct integer texel vectors, `|dx| ≤ W−1`, `|dy| ≤ H−1`) of a
//! `W×H` lightmap are placed in *normalised* texture coordinates `(dx/W, dy/H)`. Four
//! **hull sentinels** at the corner offsets `(±W, ±H)` — normalised `(±1, ±1)` — are added:
//! for them `t + Δt` is outside the map for every texel `t`, so they carry no map and
//! contribute nothing (paper Sec. 3: the hull of `O` must be made of offsets that contribute
//! 0). Every real offset therefore lies strictly inside the hull, so its cell is bounded.
//!
//! - [`clipped_cell_polygons`]: each site's Voronoi cell clipped to the square `[−1, 1]²` by
//!   half-plane clipping (O(K²), fine for K ≤ a few thousand). Real and sentinel cells tile
//!   the square, so all areas sum to 4.
//! - [`discrete_cells`]: every integer offset `v` with `|v.x| ≤ W−1`, `|v.y| ≤ H−1` (exactly
//!   the offsets that can pair two texels) is assigned to the site nearest in normalised
//!   coordinates, ties broken by the lowest site index (real offsets in input order, then the
//!   sentinels). The comparison is done in exact integer arithmetic on
//!   `W²H²·d² = H²(v.x − s.x)² + W²(v.y − s.y)²`, so **each valid integer offset lands in
//!   exactly one cell**. Because a cell is the intersection of half-planes (each tie-broken
//!   pairwise comparison is a half-line along a row), its members on one row form one
//!   contiguous run; cells are returned as [`RowRun`]s sorted by `dy`. If `O` holds *all*
//!   valid integer offsets, each cell is exactly `{Δt}` (distance 0 beats everything) and
//!   Eq. 9 with [`tva_map`] is the exact Eq. 4.
//! - [`tva_map`]: `TVA(t, Δt) = Σ_{v ∈ V(Δt)} A(t + v)` for every *receiving* texel `t`,
//!   summing the areas of the sending texels `t + v` (`A = 0` outside the map). Per-row
//!   prefix sums make each run O(1); rows run in parallel (rayon).
//!
//! # Units and conventions
//! Offsets are integer texel vectors, `+dy` goes down the image (rows). Polygon areas are in
//! normalised units (the square has area 4); `TVA` has the units of the texel areas given
//! (m²). Texel `(x, y)` of a `W×H` map is at index `y·W + x`.

use glam::{DVec2, IVec2};
use rayon::prelude::*;

use super::OffsetError;

/// Number of hull sentinels added around the real offsets.
pub const SENTINEL_COUNT: usize = 4;

/// The four hull-sentinel offsets `(−W, −H), (W, −H), (W, H), (−W, H)` of a `W×H` map.
pub fn sentinel_offsets(w: u32, h: u32) -> [IVec2; SENTINEL_COUNT] {
    let (w, h) = (w as i32, h as i32);
    [
        IVec2::new(-w, -h),
        IVec2::new(w, -h),
        IVec2::new(w, h),
        IVec2::new(-w, h),
    ]
}

/// An offset in normalised texture coordinates `(dx / W, dy / H)`.
pub fn normalise(offset: IVec2, w: u32, h: u32) -> DVec2 {
    DVec2::new(
        f64::from(offset.x) / f64::from(w),
        f64::from(offset.y) / f64::from(h),
    )
}

/// The sites of a partition: `offsets` in order, then the four [`sentinel_offsets`].
fn sites_with_sentinels(offsets: &[IVec2], w: u32, h: u32) -> Vec<IVec2> {
    offsets
        .iter()
        .copied()
        .chain(sentinel_offsets(w, h))
        .collect()
}

/// [`sites_with_sentinels`] in normalised coordinates ([`normalise`]).
fn normalised_sites(offsets: &[IVec2], w: u32, h: u32) -> Vec<DVec2> {
    sites_with_sentinels(offsets, w, h)
        .into_iter()
        .map(|o| normalise(o, w, h))
        .collect()
}

/// Area of a simple polygon (shoelace formula, absolute value).
pub fn polygon_area(poly: &[DVec2]) -> f64 {
    let n = poly.len();
    if n < 3 {
        return 0.0;
    }
    let twice: f64 = (0..n).map(|i| poly[i].perp_dot(poly[(i + 1) % n])).sum();
    0.5 * twice.abs()
}

/// Checks the map size and that `offsets` are distinct and within the valid range.
pub(crate) fn validate_offsets(offsets: &[IVec2], w: u32, h: u32) -> Result<(), OffsetError> {
    if w == 0 || h == 0 || w > i32::MAX as u32 / 4 || h > i32::MAX as u32 / 4 {
        return Err(OffsetError::InvalidMapSize {
            width: w,
            height: h,
            reason: "each side must be between 1 and 2^29 texels",
        });
    }
    let (wi, hi) = (w as i32, h as i32);
    let mut seen = std::collections::HashSet::with_capacity(offsets.len());
    for &o in offsets {
        if o.x.abs() > wi - 1 || o.y.abs() > hi - 1 {
            return Err(OffsetError::OffsetOutOfRange {
                dx: o.x,
                dy: o.y,
                width: w,
                height: h,
            });
        }
        if !seen.insert(o) {
            return Err(OffsetError::DuplicateOffset { dx: o.x, dy: o.y });
        }
    }
    Ok(())
}

/// Voronoi cells of the real offsets and of the four sentinels, clipped to `[−1, 1]²`
/// (normalised coordinates), as counter-clockwise convex polygons.
#[derive(Clone, Debug, PartialEq)]
pub struct ClippedCells {
    /// One polygon per real offset, in input order.
    pub real: Vec<Vec<DVec2>>,
    /// One polygon per sentinel, in [`sentinel_offsets`] order.
    pub sentinel: Vec<Vec<DVec2>>,
}

impl ClippedCells {
    /// Areas of the real offsets' cells (normalised units; the square has area 4). These are
    /// the `|V(Δt, O)|` of Eq. 5 (up to the constant factor `W·H/4` to integer-offset counts).
    pub fn real_areas(&self) -> Vec<f64> {
        self.real.iter().map(|p| polygon_area(p)).collect()
    }

    /// Areas of the sentinels' cells (a test's reference).
    #[cfg(test)]
    pub fn sentinel_areas(&self) -> Vec<f64> {
        self.sentinel.iter().map(|p| polygon_area(p)).collect()
    }
}

/// Clips the convex polygon `poly` to the half-plane `{x : (x − m)·n ≤ 0}`.
fn clip_half_plane(poly: &[DVec2], m: DVec2, n: DVec2) -> Vec<DVec2> {
    let side: Vec<f64> = poly.iter().map(|&p| (p - m).dot(n)).collect();
    if side.iter().all(|&s| s <= 0.0) {
        return poly.to_vec();
    }
    let mut out = Vec::with_capacity(poly.len() + 1);
    for i in 0..poly.len() {
        let j = (i + 1) % poly.len();
        let (a, b, sa, sb) = (poly[i], poly[j], side[i], side[j]);
        if sa <= 0.0 {
            out.push(a);
        }
        if (sa < 0.0 && sb > 0.0) || (sa > 0.0 && sb < 0.0) {
            out.push(a + (b - a) * (sa / (sa - sb)));
        }
    }
    out
}

/// Voronoi cells of `offsets` plus the four hull sentinels, clipped to the square
/// `[−1, 1]²` in normalised coordinates (`O(K²)` half-plane clipping, parallel over cells).
///
/// Errors: zero map size, an offset outside `|dx| ≤ W−1, |dy| ≤ H−1`, or a repeated offset.
pub fn clipped_cell_polygons(
    offsets: &[IVec2],
    w: u32,
    h: u32,
) -> Result<ClippedCells, OffsetError> {
    validate_offsets(offsets, w, h)?;
    let sites = normalised_sites(offsets, w, h);
    let square = vec![
        DVec2::new(-1.0, -1.0),
        DVec2::new(1.0, -1.0),
        DVec2::new(1.0, 1.0),
        DVec2::new(-1.0, 1.0),
    ];
    let mut cells: Vec<Vec<DVec2>> = (0..sites.len())
        .into_par_iter()
        .map(|i| {
            let mut poly = square.clone();
            for (j, &q) in sites.iter().enumerate() {
                if j == i || poly.is_empty() {
                    continue;
                }
                let p = sites[i];
                poly = clip_half_plane(&poly, 0.5 * (p + q), q - p);
            }
            poly
        })
        .collect();
    let sentinel = cells.split_off(offsets.len());
    Ok(ClippedCells {
        real: cells,
        sentinel,
    })
}

/// A horizontal run of integer offsets `{(dx, dy) : dx_start ≤ dx ≤ dx_end_inclusive}`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct RowRun {
    /// Row offset (`+dy` goes down the image).
    pub dy: i32,
    /// First column offset of the run.
    pub dx_start: i32,
    /// Last column offset of the run (inclusive).
    pub dx_end_inclusive: i32,
}

impl RowRun {
    /// Number of integer offsets in the run.
    pub fn len(&self) -> usize {
        (self.dx_end_inclusive - self.dx_start + 1).max(0) as usize
    }

    /// Whether the run holds no offset.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// Discrete Voronoi cells: the valid integer offsets assigned to each site, as row runs
/// sorted by `dy` (at most one run per row and site).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DiscreteCells {
    /// Runs of each real offset, in input order.
    pub real: Vec<Vec<RowRun>>,
    /// Runs of each sentinel, in [`sentinel_offsets`] order.
    pub sentinel: Vec<Vec<RowRun>>,
}

/// Partitions every valid integer offset (`|v.x| ≤ W−1`, `|v.y| ≤ H−1`) among `offsets`
/// and the four sentinels by nearest site in normalised coordinates, ties to the lowest
/// index (exact integer arithmetic; see the module docs). Cost: per row, one `O(K)` scan
/// per run; rows in parallel.
///
/// Errors: as [`clipped_cell_polygons`].
pub fn discrete_cells(offsets: &[IVec2], w: u32, h: u32) -> Result<DiscreteCells, OffsetError> {
    validate_offsets(offsets, w, h)?;
    let sites = sites_with_sentinels(offsets, w, h);
    let hi = h as i32;
    let rows: Vec<Vec<(usize, RowRun)>> = (-(hi - 1)..=hi - 1)
        .into_par_iter()
        .map(|dy| row_runs(&sites, dy, w, h))
        .collect();
    let mut cells = vec![Vec::new(); sites.len()];
    for row in rows {
        for (site, run) in row {
            cells[site].push(run);
        }
    }
    let sentinel = cells.split_off(offsets.len());
    Ok(DiscreteCells {
        real: cells,
        sentinel,
    })
}

/// Row `dy` of [`discrete_cells`]: maximal runs of offsets with the same nearest site (index
/// into `sites`), left to right.
fn row_runs(sites: &[IVec2], dy: i32, w: u32, h: u32) -> Vec<(usize, RowRun)> {
    let wi = w as i32;
    let w2 = i128::from(w) * i128::from(w);
    let h2 = i128::from(h) * i128::from(h);
    // Scaled squared distance minus the common H²x² term: g_i(x) = −2H²s_x·x + c_i.
    let slope: Vec<i128> = sites.iter().map(|s| -2 * h2 * i128::from(s.x)).collect();
    let c: Vec<i128> = sites
        .iter()
        .map(|s| {
            let ey = i128::from(dy - s.y);
            h2 * i128::from(s.x) * i128::from(s.x) + w2 * ey * ey
        })
        .collect();
    let mut runs = Vec::new();
    let mut x = -(wi - 1);
    while x < wi {
        let xx = i128::from(x);
        let mut best = 0usize;
        let mut best_g = slope[0] * xx + c[0];
        for i in 1..sites.len() {
            let g = slope[i] * xx + c[i];
            if g < best_g {
                best = i;
                best_g = g;
            }
        }
        // Largest x' ≥ x at which `best` still beats every other site.
        let mut end = i128::from(wi - 1);
        for j in 0..sites.len() {
            if j == best {
                continue;
            }
            // best beats j at x' iff a·x' + b < 0, or = 0 and best < j.
            let a = slope[best] - slope[j];
            let b = c[best] - c[j];
            if a > 0 {
                let n = -b;
                let bound = if best < j {
                    n.div_euclid(a)
                } else {
                    -((-n).div_euclid(a)) - 1
                };
                end = end.min(bound);
            }
        }
        // `best` beats everyone at x itself, so every bound is ≥ x; the max only guards
        // against an infinite loop should that invariant ever break.
        debug_assert!(end >= xx, "run end {end} < start {x}");
        let end = end.max(xx) as i32;
        runs.push((
            best,
            RowRun {
                dy,
                dx_start: x,
                dx_end_inclusive: end,
            },
        ));
        x = end + 1;
    }
    runs
}

/// `TVA(t, Δt) = Σ_{v ∈ V(Δt)} A(t + v)` (Eq. 8) for every receiving texel `t` of a `W×H`
/// map, where `V(Δt)` is given as `runs` (one cell of [`discrete_cells`]) and `area_m2`
/// holds the `W·H` texel areas (0 = uncovered; `A = 0` outside the map). Sums are
/// accumulated in f64 from per-row prefix sums (each run O(1)); rows run in parallel.
///
/// Errors: `area_m2.len() != W·H`.
pub fn tva_map(area_m2: &[f32], w: u32, h: u32, runs: &[RowRun]) -> Result<Vec<f32>, OffsetError> {
    let (wu, hu) = (w as usize, h as usize);
    if area_m2.len() != wu * hu {
        return Err(OffsetError::AreaLength {
            expected: wu * hu,
            got: area_m2.len(),
        });
    }
    if wu == 0 || hu == 0 {
        return Ok(Vec::new());
    }
    // prefix[y·(W+1) + x] = Σ_{x' < x} A(x', y).
    let mut prefix = vec![0.0f64; (wu + 1) * hu];
    for (row, p) in area_m2
        .chunks_exact(wu)
        .zip(prefix.chunks_exact_mut(wu + 1))
    {
        for (x, &a) in row.iter().enumerate() {
            p[x + 1] = p[x] + f64::from(a);
        }
    }
    let (wi, hi) = (w as i64, h as i64);
    let mut out = vec![0.0f32; wu * hu];
    out.par_chunks_mut(wu).enumerate().for_each(|(y, out_row)| {
        for (x, o) in out_row.iter_mut().enumerate() {
            let mut sum = 0.0f64;
            for r in runs {
                let ty = y as i64 + i64::from(r.dy);
                if ty < 0 || ty >= hi {
                    continue;
                }
                let lo = (x as i64 + i64::from(r.dx_start)).max(0);
                let hi_x = (x as i64 + i64::from(r.dx_end_inclusive)).min(wi - 1);
                if lo > hi_x {
                    continue;
                }
                let p = &prefix[ty as usize * (wu + 1)..];
                sum += p[hi_x as usize + 1] - p[lo as usize];
            }
            *o = sum as f32;
        }
    });
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Distinct random valid offsets for a `w×h` map.
    fn random_offsets(w: u32, h: u32, k: usize, seed: u64) -> Vec<IVec2> {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut set = std::collections::BTreeSet::new();
        let (wi, hi) = (w as i32, h as i32);
        while set.len() < k {
            set.insert((
                rng.random_range(-(hi - 1)..=hi - 1),
                rng.random_range(-(wi - 1)..=wi - 1),
            ));
        }
        set.into_iter().map(|(y, x)| IVec2::new(x, y)).collect()
    }

    /// Brute-force nearest site (exact integers, lowest index on ties).
    fn nearest(sites: &[IVec2], v: IVec2, w: u32, h: u32) -> usize {
        let (w2, h2) = (i64::from(w).pow(2), i64::from(h).pow(2));
        let d = |s: IVec2| h2 * i64::from(v.x - s.x).pow(2) + w2 * i64::from(v.y - s.y).pow(2);
        (0..sites.len()).min_by_key(|&i| (d(sites[i]), i)).unwrap()
    }

    #[test]
    fn clipped_areas_sum_to_four_and_match_grid_estimate() {
        let (w, h) = (13u32, 7u32);
        let offsets = random_offsets(w, h, 25, 3);
        let cells = clipped_cell_polygons(&offsets, w, h).unwrap();
        let real = cells.real_areas();
        let sent = cells.sentinel_areas();
        let total: f64 = real.iter().chain(&sent).sum();
        assert!((total - 4.0).abs() < 1e-9, "total area {total}");
        assert!(real.iter().all(|&a| a > 0.0));
        // Brute force: nearest site on a fine grid of the square.
        let sites = normalised_sites(&offsets, w, h);
        let n = 600;
        let mut counts = vec![0usize; sites.len()];
        for j in 0..n {
            for i in 0..n {
                let p = DVec2::new(
                    -1.0 + 2.0 * (i as f64 + 0.5) / n as f64,
                    -1.0 + 2.0 * (j as f64 + 0.5) / n as f64,
                );
                let k = (0..sites.len())
                    .min_by(|&a, &b| {
                        p.distance_squared(sites[a])
                            .total_cmp(&p.distance_squared(sites[b]))
                    })
                    .unwrap();
                counts[k] += 1;
            }
        }
        let cell = 4.0 / (n * n) as f64;
        for (k, &a) in real.iter().chain(&sent).enumerate() {
            let est = counts[k] as f64 * cell;
            // Error ≈ perimeter / grid step cells: perimeter ≤ 8, step 2/600.
            assert!((est - a).abs() < 0.02, "cell {k}: polygon {a}, grid {est}");
        }
    }

    #[test]
    fn each_valid_integer_offset_in_exactly_one_cell() {
        for (w, h, k, seed) in [(9u32, 6u32, 12usize, 1u64), (16, 16, 40, 2), (5, 11, 7, 3)] {
            let offsets = random_offsets(w, h, k, seed);
            let cells = discrete_cells(&offsets, w, h).unwrap();
            let sites = sites_with_sentinels(&offsets, w, h);
            let (wi, hi) = (w as i32, h as i32);
            let mut owner = std::collections::HashMap::new();
            for (site, runs) in cells.real.iter().chain(&cells.sentinel).enumerate() {
                let mut last_dy = i32::MIN;
                for r in runs {
                    assert!(r.dy > last_dy, "runs sorted, one per row");
                    last_dy = r.dy;
                    assert!(!r.is_empty());
                    for dx in r.dx_start..=r.dx_end_inclusive {
                        let v = IVec2::new(dx, r.dy);
                        assert!(owner.insert(v, site).is_none(), "{v} in two cells");
                    }
                }
            }
            assert_eq!(owner.len(), ((2 * wi - 1) * (2 * hi - 1)) as usize);
            for (&v, &site) in &owner {
                assert!(v.x.abs() < wi && v.y.abs() < hi);
                assert_eq!(site, nearest(&sites, v, w, h), "offset {v}");
            }
            // Every real offset owns itself.
            for (i, o) in offsets.iter().enumerate() {
                assert_eq!(owner[o], i);
            }
        }
    }

    #[test]
    fn ties_go_to_lowest_index() {
        // (−1, 0) and (1, 0) are equidistant from (0, 0); the first listed wins.
        let cells = discrete_cells(&[IVec2::new(1, 0), IVec2::new(-1, 0)], 4, 3).unwrap();
        let owns_origin = |runs: &[RowRun]| {
            runs.iter()
                .any(|r| r.dy == 0 && r.dx_start <= 0 && r.dx_end_inclusive >= 0)
        };
        assert!(owns_origin(&cells.real[0]));
        assert!(!owns_origin(&cells.real[1]));
    }

    #[test]
    fn all_offsets_selected_gives_singletons() {
        let (w, h) = (4u32, 3u32);
        let all: Vec<IVec2> = (-2..=2)
            .flat_map(|y| (-3..=3).map(move |x| IVec2::new(x, y)))
            .collect();
        let cells = discrete_cells(&all, w, h).unwrap();
        for (o, runs) in all.iter().zip(&cells.real) {
            assert_eq!(
                runs,
                &vec![RowRun {
                    dy: o.y,
                    dx_start: o.x,
                    dx_end_inclusive: o.x
                }]
            );
        }
        assert!(cells.sentinel.iter().all(Vec::is_empty));
        // With singletons, TVA(t, Δt) = A(t + Δt): Eq. 9 is exactly Eq. 4.
        let area: Vec<f32> = (0..12).map(|i| (i * i % 7) as f32 * 0.25).collect();
        for (o, runs) in all.iter().zip(&cells.real) {
            let tva = tva_map(&area, w, h, runs).unwrap();
            for y in 0..3i32 {
                for x in 0..4i32 {
                    let s = IVec2::new(x, y) + *o;
                    let expect = if (0..4).contains(&s.x) && (0..3).contains(&s.y) {
                        area[(s.y * 4 + s.x) as usize]
                    } else {
                        0.0
                    };
                    assert_eq!(tva[(y * 4 + x) as usize], expect);
                }
            }
        }
    }

    #[test]
    fn tva_matches_brute_force() {
        let (w, h) = (11u32, 8u32);
        let offsets = random_offsets(w, h, 9, 5);
        let cells = discrete_cells(&offsets, w, h).unwrap();
        let mut rng = ChaCha8Rng::seed_from_u64(9);
        let area: Vec<f32> = (0..w * h)
            .map(|_| {
                if rng.random::<f64>() < 0.3 {
                    0.0
                } else {
                    rng.random::<f32>()
                }
            })
            .collect();
        let sites = sites_with_sentinels(&offsets, w, h);
        let (wi, hi) = (w as i32, h as i32);
        for (k, runs) in cells.real.iter().enumerate() {
            let tva = tva_map(&area, w, h, runs).unwrap();
            for y in 0..hi {
                for x in 0..wi {
                    let mut expect = 0.0f64;
                    for vy in -(hi - 1)..hi {
                        for vx in -(wi - 1)..wi {
                            let v = IVec2::new(vx, vy);
                            let (sx, sy) = (x + vx, y + vy);
                            if nearest(&sites, v, w, h) == k
                                && (0..wi).contains(&sx)
                                && (0..hi).contains(&sy)
                            {
                                expect += f64::from(area[(sy * wi + sx) as usize]);
                            }
                        }
                    }
                    let got = f64::from(tva[(y * wi + x) as usize]);
                    assert!(
                        (got - expect).abs() <= 1e-5 * (1.0 + expect),
                        "{got} vs {expect}"
                    );
                }
            }
        }
        assert!(matches!(
            tva_map(&area[1..], w, h, &cells.real[0]),
            Err(OffsetError::AreaLength { .. })
        ));
    }

    #[test]
    fn invalid_offsets_are_errors() {
        assert!(matches!(
            clipped_cell_polygons(&[IVec2::new(4, 0)], 4, 3),
            Err(OffsetError::OffsetOutOfRange { .. })
        ));
        assert!(matches!(
            discrete_cells(&[IVec2::new(1, 1), IVec2::new(1, 1)], 4, 3),
            Err(OffsetError::DuplicateOffset { .. })
        ));
        assert!(discrete_cells(&[], 0, 3).is_err());
    }
}
