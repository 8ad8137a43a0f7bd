//! Offset selection by importance sampling (paper Sec. 3.1, 5.1) and the jittered-grid
//! baseline the paper rejects.
//!
//! # Data flow
//! [`select_importance`] works in continuous *texel-offset* coordinates `(dx, dy)` over the
//! valid range `|dx| ≤ W−1`, `|dy| ≤ H−1` (the offsets that can pair two texels):
//! 1. **Seed**: a regular `g×g` grid over the valid range (`g = seed_grid`, corners
//!    included, rounded to integers, duplicates dropped) plus the offset `(0, 0)`. Their
//!    transference values (from the caller's closure, called with batches of at most
//!    `rebuild_every` offsets so it can evaluate a batch in parallel) become the data points
//!    of a [`PiecewiseLinearDensity`]. Because the grid contains the four corners, the
//!    density's hull is the whole valid range.
//! 2. **Refine**: `refinement_iterations` offsets in total are drawn, in batches of
//!    `rebuild_every` from the same tables (the paper rebuilds after every 20th sample),
//!    rounded to the nearest integer offset, evaluated as one batch and inserted as data
//!    points; the tables are then rebuilt. The transference of an integer offset is
//!    deterministic, so a draw that rounds to an already-evaluated offset (or repeats one
//!    in its batch) is *not* re-evaluated and adds no data point; it still counts as an
//!    iteration, so the loop always ends.
//! 3. **Draw**: `(0, 0)` is always selected first (local transfer and subsurface scattering
//!    peak there); then offsets are drawn from the converged density, rounded, and repeats
//!    rejected, until `final_count` distinct offsets are found. If that takes more than
//!    `64·final_count + 1024` draws (the density reaches too few distinct integer offsets,
//!    e.g. it is zero over most of the range), the rest is **filled deterministically**:
//!    the unselected valid offsets ranked by the density's value at them (descending), then
//!    by `dx² + dy²`, `dy`, `dx` (ascending). Asking for more offsets than exist is an error.
//!
//! The returned order is `(0, 0)` first, then draw order (then fill order). Everything is
//! deterministic for a given seed (`ChaCha8Rng::seed_from_u64`) and closure.
//!
//! # Units
//! Offsets are integer texel vectors (`+dy` down the image). Transference values are
//! whatever the caller's metric yields ([`ImportanceMetric`]); they must be finite and ≥ 0.

use std::collections::HashSet;

use glam::{DVec2, IVec2};
use rand::RngExt;
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use super::OffsetError;
use super::density::PiecewiseLinearDensity;

/// How the caller reduces one offset's transfer map to an importance value (Sec. 3.1).
/// This module only carries it; the bake orchestrator computes it.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum ImportanceMetric {
    /// Maximum transference over all texels: keeps distant objects from being ignored
    /// (the paper's default).
    #[default]
    Max,
    /// Average transference over all texels: less aliasing for a single contiguous chart.
    Average,
}

/// Parameters of [`select_importance`].
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SelectionSettings {
    /// Seed grid resolution per axis (≥ 2): `seed_grid²` regular seed offsets (default 10,
    /// about 100 as in the paper), plus `(0, 0)`.
    pub seed_grid: u32,
    /// Total number of refinement draws (default 1000, the paper's "more than sufficient").
    pub refinement_iterations: usize,
    /// Draws per batch between rebuilds of the sampling tables (≥ 1, default 20); also the
    /// maximum batch size passed to the transference closure.
    pub rebuild_every: usize,
    /// Number of offsets to select, `(0, 0)` included (≥ 1, default 100).
    pub final_count: usize,
    /// Importance metric the caller's closure uses (carried only).
    pub metric: ImportanceMetric,
    /// Random seed.
    pub seed: u64,
}

impl Default for SelectionSettings {
    fn default() -> Self {
        Self {
            seed_grid: 10,
            refinement_iterations: 1000,
            rebuild_every: 20,
            final_count: 100,
            metric: ImportanceMetric::Max,
            seed: 0,
        }
    }
}

/// Stage reported to the progress callback.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// Evaluating the seed grid: `(evaluated, total seeds)`.
    Seeding,
    /// Refining the density: `(draws done, refinement_iterations)`.
    Refining,
    /// Drawing the final offsets: `(selected, final_count)`.
    Drawing,
}

/// Result of [`select_importance`].
#[derive(Clone, Debug)]
pub struct Selection {
    /// The selected distinct integer offsets, `(0, 0)` first.
    pub offsets: Vec<IVec2>,
    /// Every evaluated data point `(offset as (dx, dy), transference)` (for the report).
    pub data_points: Vec<(DVec2, f64)>,
    /// The converged density (texel-offset coordinates).
    pub density: PiecewiseLinearDensity,
}

/// Number of valid integer offsets `(2W−1)(2H−1)` of a `W×H` map.
fn valid_offset_count(w: u32, h: u32) -> usize {
    (2 * w as usize - 1) * (2 * h as usize - 1)
}

/// Checks that a `W×H` map has a 2-D range of offsets.
fn check_map(w: u32, h: u32) -> Result<(), OffsetError> {
    if w < 2 || h < 2 || w > i32::MAX as u32 / 4 || h > i32::MAX as u32 / 4 {
        return Err(OffsetError::InvalidMapSize {
            width: w,
            height: h,
            reason: "offset selection needs at least 2×2 texels (and at most 2^29 per side)",
        });
    }
    Ok(())
}

/// Rounds a continuous offset to the nearest valid integer offset.
fn round_offset(p: DVec2, w: u32, h: u32) -> IVec2 {
    let (mx, my) = (f64::from(w - 1), f64::from(h - 1));
    IVec2::new(
        p.x.round().clamp(-mx, mx) as i32,
        p.y.round().clamp(-my, my) as i32,
    )
}

/// Integer offset as a density-plane point.
fn to_point(o: IVec2) -> DVec2 {
    DVec2::new(f64::from(o.x), f64::from(o.y))
}

/// Calls the closure on one batch and validates the answer.
fn evaluate(
    batch: &[IVec2],
    transference: &mut impl FnMut(&[IVec2]) -> Vec<f64>,
) -> Result<Vec<f64>, OffsetError> {
    let values = transference(batch);
    if values.len() != batch.len() {
        return Err(OffsetError::TransferenceLength {
            expected: batch.len(),
            got: values.len(),
        });
    }
    for (o, &v) in batch.iter().zip(&values) {
        if !v.is_finite() || v < 0.0 {
            return Err(OffsetError::InvalidTransference {
                dx: o.x,
                dy: o.y,
                value: v,
            });
        }
    }
    Ok(values)
}

/// The regular seed grid (`g×g` over the valid range, corners included, rounded,
/// deduplicated) plus `(0, 0)`, in row-major order.
fn seed_offsets(g: u32, w: u32, h: u32) -> Vec<IVec2> {
    let axis = |n: u32| -> Vec<i32> {
        let m = f64::from(n - 1);
        (0..g)
            .map(|i| (-m + 2.0 * m * f64::from(i) / f64::from(g - 1)).round() as i32)
            .collect()
    };
    let (xs, ys) = (axis(w), axis(h));
    let mut seen = HashSet::new();
    let mut out = Vec::new();
    for &y in &ys {
        for &x in &xs {
            let o = IVec2::new(x, y);
            if seen.insert(o) {
                out.push(o);
            }
        }
    }
    if seen.insert(IVec2::ZERO) {
        out.push(IVec2::ZERO);
    }
    out
}

/// Selects `settings.final_count` distinct offsets of a `W×H` map by importance sampling a
/// piecewise-linear density of the transference (see the module docs for the algorithm).
///
/// `transference(batch)` must return one finite, non-negative importance value per offset
/// of the batch (the caller's [`ImportanceMetric`] of the transfer map at that offset).
/// `progress(phase, done, total)` is called after every batch.
///
/// Errors: map smaller than 2×2, invalid settings, more offsets requested than the
/// `(2W−1)(2H−1)` valid ones, a closure answer of the wrong length or with a negative /
/// non-finite value, or zero transference at every seed offset.
pub fn select_importance(
    settings: &SelectionSettings,
    w: u32,
    h: u32,
    mut transference: impl FnMut(&[IVec2]) -> Vec<f64>,
    mut progress: impl FnMut(Phase, usize, usize),
) -> Result<Selection, OffsetError> {
    check_selection_settings(settings, w, h)?;
    let mut rng = ChaCha8Rng::seed_from_u64(settings.seed);
    let mut evaluated: HashSet<IVec2> = HashSet::new();
    let mut density = seed_density(
        settings,
        w,
        h,
        &mut evaluated,
        &mut transference,
        &mut progress,
    )?;
    refine(
        settings,
        (w, h),
        &mut density,
        &mut evaluated,
        &mut rng,
        &mut transference,
        &mut progress,
    )?;
    let offsets = draw(settings, w, h, &density, &mut rng, &mut progress);
    Ok(Selection {
        offsets,
        data_points: density.data_points(),
        density,
    })
}

/// The errors of [`select_importance`] that its settings and the map size alone decide.
fn check_selection_settings(
    settings: &SelectionSettings,
    w: u32,
    h: u32,
) -> Result<(), OffsetError> {
    check_map(w, h)?;
    if settings.seed_grid < 2 {
        return Err(OffsetError::InvalidSettings {
            field: "seed_grid",
            reason: format!("is {}, must be at least 2", settings.seed_grid),
        });
    }
    if settings.rebuild_every == 0 {
        return Err(OffsetError::InvalidSettings {
            field: "rebuild_every",
            reason: "is 0, must be at least 1".to_owned(),
        });
    }
    if settings.final_count == 0 {
        return Err(OffsetError::InvalidSettings {
            field: "final_count",
            reason: "is 0, must be at least 1 (offset (0, 0) is always selected)".to_owned(),
        });
    }
    let available = valid_offset_count(w, h);
    if settings.final_count > available {
        return Err(OffsetError::TooManyOffsets {
            requested: settings.final_count,
            available,
            width: w,
            height: h,
        });
    }
    Ok(())
}

/// Step 1: the density through the transference at the seed offsets (added to `evaluated`),
/// evaluated in batches of `rebuild_every`.
fn seed_density(
    settings: &SelectionSettings,
    w: u32,
    h: u32,
    evaluated: &mut HashSet<IVec2>,
    transference: &mut impl FnMut(&[IVec2]) -> Vec<f64>,
    progress: &mut impl FnMut(Phase, usize, usize),
) -> Result<PiecewiseLinearDensity, OffsetError> {
    let seeds = seed_offsets(settings.seed_grid, w, h);
    let mut points = Vec::with_capacity(seeds.len());
    for chunk in seeds.chunks(settings.rebuild_every) {
        let values = evaluate(chunk, transference)?;
        for (&o, v) in chunk.iter().zip(values) {
            evaluated.insert(o);
            points.push((to_point(o), v));
        }
        progress(Phase::Seeding, points.len(), seeds.len());
    }
    PiecewiseLinearDensity::new(&points).map_err(|e| match e {
        OffsetError::ZeroMass { .. } => OffsetError::ZeroTransference { seeds: seeds.len() },
        other => other,
    })
}

/// Step 2: `refinement_iterations` draws from the density, in batches of `rebuild_every`;
/// the offsets not yet `evaluated` are evaluated and inserted, then the density is rebuilt.
fn refine(
    settings: &SelectionSettings,
    (w, h): (u32, u32),
    density: &mut PiecewiseLinearDensity,
    evaluated: &mut HashSet<IVec2>,
    rng: &mut ChaCha8Rng,
    transference: &mut impl FnMut(&[IVec2]) -> Vec<f64>,
    progress: &mut impl FnMut(Phase, usize, usize),
) -> Result<(), OffsetError> {
    let batch = settings.rebuild_every;
    let total = settings.refinement_iterations;
    let mut done = 0;
    while done < total {
        let n = batch.min(total - done);
        let mut new = Vec::with_capacity(n);
        for _ in 0..n {
            let o = round_offset(density.sample(rng), w, h);
            if evaluated.insert(o) {
                new.push(o);
            }
        }
        if !new.is_empty() {
            let values = evaluate(&new, transference)?;
            for (&o, v) in new.iter().zip(values) {
                density.insert(to_point(o), v)?;
            }
            density.rebuild()?;
        }
        done += n;
        progress(Phase::Refining, done, total);
    }
    Ok(())
}

/// Step 3: `(0, 0)` and distinct draws from the density up to `final_count`; if the draws
/// give up (`64·count + 1024` of them), the densest remaining offsets fill the rest.
fn draw(
    settings: &SelectionSettings,
    w: u32,
    h: u32,
    density: &PiecewiseLinearDensity,
    rng: &mut ChaCha8Rng,
    progress: &mut impl FnMut(Phase, usize, usize),
) -> Vec<IVec2> {
    let batch = settings.rebuild_every;
    let target = settings.final_count;
    let mut offsets = vec![IVec2::ZERO];
    let mut chosen: HashSet<IVec2> = offsets.iter().copied().collect();
    let max_draws = 64 * target + 1024;
    let mut draws = 0;
    while offsets.len() < target && draws < max_draws {
        draws += 1;
        let o = round_offset(density.sample(rng), w, h);
        if chosen.insert(o) {
            offsets.push(o);
            if offsets.len() % batch == 0 {
                progress(Phase::Drawing, offsets.len(), target);
            }
        }
    }
    if offsets.len() < target {
        let (wi, hi) = (w as i32, h as i32);
        let mut rest: Vec<(f64, IVec2)> = (-(hi - 1)..hi)
            .flat_map(|y| (-(wi - 1)..wi).map(move |x| IVec2::new(x, y)))
            .filter(|o| !chosen.contains(o))
            .map(|o| (density.value(to_point(o)), o))
            .collect();
        rest.sort_by(|a, b| {
            b.0.total_cmp(&a.0)
                .then(a.1.length_squared().cmp(&b.1.length_squared()))
                .then(a.1.y.cmp(&b.1.y))
                .then(a.1.x.cmp(&b.1.x))
        });
        offsets.extend(
            rest.into_iter()
                .take(target - offsets.len())
                .map(|(_, o)| o),
        );
    }
    progress(Phase::Drawing, offsets.len(), target);
    offsets
}

/// The paper's rejected baseline: `count` distinct offsets, one uniformly jittered integer
/// offset per cell of a `gx×gy` grid over the valid range (`gx·gy ≥ count`, aspect matched
/// to the range); the cell containing `(0, 0)` takes `(0, 0)` itself. If the grid has more
/// cells than `count`, a seeded random subset of the other cells is dropped. Cells are
/// disjoint integer ranges, so the offsets are distinct. Order: `(0, 0)` first, then
/// row-major by cell.
///
/// Errors: map smaller than 2×2, `count == 0`, or `count > (2W−1)(2H−1)`.
pub fn select_jittered_grid(
    w: u32,
    h: u32,
    count: usize,
    seed: u64,
) -> Result<Vec<IVec2>, OffsetError> {
    check_map(w, h)?;
    let available = valid_offset_count(w, h);
    if count == 0 {
        return Err(OffsetError::InvalidSettings {
            field: "count",
            reason: "is 0, must be at least 1".to_owned(),
        });
    }
    if count > available {
        return Err(OffsetError::TooManyOffsets {
            requested: count,
            available,
            width: w,
            height: h,
        });
    }
    let (rx, ry) = (2 * w as usize - 1, 2 * h as usize - 1);
    let (gx, gy) = jitter_grid_dims(count, rx, ry);
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (wi, hi) = (w as i32, h as i32);
    let mut others = Vec::with_capacity(gx * gy);
    for cy in 0..gy {
        let (y0, y1) = cell_range(cy, gy, ry, hi);
        for cx in 0..gx {
            let (x0, x1) = cell_range(cx, gx, rx, wi);
            if (x0..x1).contains(&0) && (y0..y1).contains(&0) {
                continue;
            }
            others.push(IVec2::new(
                rng.random_range(x0..x1),
                rng.random_range(y0..y1),
            ));
        }
    }
    if others.len() > count - 1 {
        let mut idx: Vec<usize> = (0..others.len()).collect();
        idx.shuffle(&mut rng);
        idx.truncate(count - 1);
        idx.sort_unstable();
        others = idx.into_iter().map(|i| others[i]).collect();
    }
    let mut out = Vec::with_capacity(count);
    out.push(IVec2::ZERO);
    out.extend(others);
    Ok(out)
}

/// Grid dimensions `(gx, gy)` with `gx ≤ rx`, `gy ≤ ry`, `gx·gy ≥ count`, aspect ≈ `rx:ry`.
pub(crate) fn jitter_grid_dims(count: usize, rx: usize, ry: usize) -> (usize, usize) {
    let ideal = (count as f64 * rx as f64 / ry as f64).sqrt();
    let gx = (ideal.round() as usize).clamp(1, rx);
    let gy = count.div_ceil(gx).clamp(1, ry);
    let gx = if gx * gy < count {
        count.div_ceil(gy).min(rx)
    } else {
        gx
    };
    (gx, gy)
}

/// Integer half-open range `[lo, hi)` of cell `i` of `g` cells over the `r = 2n−1` valid
/// offsets `−(n−1) ..= n−1`.
pub(crate) fn cell_range(i: usize, g: usize, r: usize, n: i32) -> (i32, i32) {
    let lo = (i * r / g) as i32 - (n - 1);
    let hi = ((i + 1) * r / g) as i32 - (n - 1);
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashMap;

    /// A smooth synthetic transference: a bump at `c` plus a small floor.
    fn bump(o: IVec2, c: IVec2, sigma: f64) -> f64 {
        let d2 = (o - c).as_dvec2().length_squared();
        (-d2 / (sigma * sigma)).exp() + 1e-3
    }

    fn settings(final_count: usize, seed: u64) -> SelectionSettings {
        SelectionSettings {
            refinement_iterations: 200,
            final_count,
            seed,
            ..SelectionSettings::default()
        }
    }

    fn run(s: &SelectionSettings, w: u32, h: u32, c: IVec2) -> (Selection, usize) {
        let mut calls: HashMap<IVec2, usize> = HashMap::new();
        let sel = select_importance(
            s,
            w,
            h,
            |batch| {
                assert!(!batch.is_empty() && batch.len() <= s.rebuild_every);
                batch
                    .iter()
                    .map(|&o| {
                        *calls.entry(o).or_default() += 1;
                        bump(o, c, 4.0)
                    })
                    .collect()
            },
            |_, done, total| assert!(done <= total),
        )
        .unwrap();
        assert!(
            calls.values().all(|&n| n == 1),
            "an offset was evaluated twice"
        );
        (sel, calls.len())
    }

    #[test]
    fn selection_is_deterministic_distinct_and_contains_origin() {
        let c = IVec2::new(9, -6);
        let (a, evals) = run(&settings(40, 5), 32, 24, c);
        let (b, _) = run(&settings(40, 5), 32, 24, c);
        let (other, _) = run(&settings(40, 6), 32, 24, c);
        assert_eq!(a.offsets, b.offsets);
        assert_ne!(a.offsets, other.offsets);
        assert_eq!(a.offsets.len(), 40);
        assert_eq!(a.offsets[0], IVec2::ZERO);
        let set: HashSet<_> = a.offsets.iter().collect();
        assert_eq!(set.len(), 40);
        assert!(a.offsets.iter().all(|o| o.x.abs() <= 31 && o.y.abs() <= 23));
        // Seeds (100 + origin) plus at most 200 refinement evaluations, each recorded once.
        assert!(evals > 101 && evals <= 301, "{evals} evaluations");
        assert_eq!(a.data_points.len(), evals);
    }

    #[test]
    fn selection_concentrates_where_transference_is_high() {
        let (w, h) = (40u32, 40u32);
        let c = IVec2::new(-15, 12);
        let (sel, _) = run(&settings(60, 11), w, h, c);
        // The bump (σ = 4) has mass πσ² ≈ 50 against ≈ 6 for the floor (1e-3 × 79²), and
        // 1 − e⁻⁴ ≈ 98 % of the bump lies within 2σ = 8 of c: ≈ 85 % of the draws should
        // land in a disc that covers 3 % of the range (uniform draws: ≈ 2 of 60).
        let near = sel
            .offsets
            .iter()
            .filter(|o| (**o - c).as_dvec2().length() <= 8.0)
            .count();
        assert!(near >= 25, "only {near} of 60 offsets near the peak");
        // The density itself must peak near c: compare with the far corner.
        let d = &sel.density;
        assert!(d.pdf(c.as_dvec2()) > 100.0 * d.pdf(DVec2::new(30.0, -30.0)));
    }

    #[test]
    fn fills_deterministically_when_density_reaches_too_few_offsets() {
        // 3×2 map: 5×3 = 15 valid offsets; ask for all of them. Transference is 0 except at
        // the seed (2, 1), so the density is a small tent and most offsets are unreachable.
        let s = SelectionSettings {
            refinement_iterations: 40,
            final_count: 15,
            ..SelectionSettings::default()
        };
        let f = |batch: &[IVec2]| -> Vec<f64> {
            batch
                .iter()
                .map(|&o| if o == IVec2::new(2, 1) { 1.0 } else { 0.0 })
                .collect()
        };
        let a = select_importance(&s, 3, 2, f, |_, _, _| {}).unwrap();
        let b = select_importance(&s, 3, 2, f, |_, _, _| {}).unwrap();
        assert_eq!(a.offsets, b.offsets);
        let set: HashSet<_> = a.offsets.iter().copied().collect();
        assert_eq!(set.len(), 15);
        assert_eq!(a.offsets[0], IVec2::ZERO);
    }

    #[test]
    fn bad_closure_answers_and_settings_are_errors() {
        let s = settings(10, 0);
        let none = |_: Phase, _: usize, _: usize| {};
        assert!(matches!(
            select_importance(&s, 8, 8, |b| vec![1.0; b.len() + 1], none),
            Err(OffsetError::TransferenceLength { .. })
        ));
        assert!(matches!(
            select_importance(&s, 8, 8, |b| vec![-1.0; b.len()], none),
            Err(OffsetError::InvalidTransference { .. })
        ));
        assert!(matches!(
            select_importance(&s, 8, 8, |b| vec![f64::NAN; b.len()], none),
            Err(OffsetError::InvalidTransference { .. })
        ));
        assert!(matches!(
            select_importance(&s, 8, 8, |b| vec![0.0; b.len()], none),
            Err(OffsetError::ZeroTransference { .. })
        ));
        assert!(matches!(
            select_importance(&settings(16, 0), 2, 2, |b| vec![1.0; b.len()], none),
            Err(OffsetError::TooManyOffsets { .. })
        ));
        assert!(matches!(
            select_importance(&s, 1, 8, |b| vec![1.0; b.len()], none),
            Err(OffsetError::InvalidMapSize { .. })
        ));
        let zero_batch = SelectionSettings {
            rebuild_every: 0,
            ..s.clone()
        };
        assert!(select_importance(&zero_batch, 8, 8, |b| vec![1.0; b.len()], none).is_err());
    }

    #[test]
    fn jittered_grid_one_per_cell_distinct_with_origin() {
        for (w, h, count, seed) in [(20u32, 20u32, 16usize, 1u64), (33, 9, 50, 2), (3, 2, 15, 3)] {
            let offs = select_jittered_grid(w, h, count, seed).unwrap();
            assert_eq!(offs, select_jittered_grid(w, h, count, seed).unwrap());
            assert_eq!(offs.len(), count);
            assert_eq!(offs[0], IVec2::ZERO);
            let set: HashSet<_> = offs.iter().collect();
            assert_eq!(set.len(), count);
            let (rx, ry) = (2 * w as usize - 1, 2 * h as usize - 1);
            let (gx, gy) = jitter_grid_dims(count, rx, ry);
            assert!(gx * gy >= count && gx <= rx && gy <= ry);
            // No two offsets share a cell (brute-force cell lookup).
            let mut cells = HashSet::new();
            for o in &offs {
                assert!(o.x.unsigned_abs() < w && o.y.unsigned_abs() < h);
                let cx = (0..gx)
                    .find(|&i| {
                        let (a, b) = cell_range(i, gx, rx, w as i32);
                        (a..b).contains(&o.x)
                    })
                    .unwrap();
                let cy = (0..gy)
                    .find(|&i| {
                        let (a, b) = cell_range(i, gy, ry, h as i32);
                        (a..b).contains(&o.y)
                    })
                    .unwrap();
                assert!(cells.insert((cx, cy)), "two offsets in cell ({cx}, {cy})");
            }
        }
        assert!(select_jittered_grid(2, 2, 10, 0).is_err());
        assert!(select_jittered_grid(4, 4, 0, 0).is_err());
    }
}
