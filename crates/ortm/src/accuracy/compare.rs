//! Accuracy figures of a lightmap against a reference: relative RMSE of the total `B` and of the
//! indirect term `B − B_o`, over *interior* covered texels (a covered texel whose four
//! neighbours are covered too: texels at chart borders are bilinearly blended with gutters on
//! the GPU and carry the rasterisation's own error, so the figures leave them out), the energy
//! ratio (area-weighted power of the test over the reference) and the worst texels.
//!
//! Values are per covered texel of a [`TexelGrid`] (grid order), radiosity in W/m², RGB.
//! Relative RMSE is `sqrt(Σ|a − b|²) / sqrt(Σ|b|²)` over the interior texels and the three
//! channels (`b` the reference).

use glam::{DVec3, Vec3};

use crate::bake::texels::TexelGrid;

/// Per covered texel of `grid`: true when its four neighbours (±x, ±y) are covered.
pub fn interior_mask(grid: &TexelGrid) -> Vec<bool> {
    grid.texels
        .iter()
        .map(|t| {
            let (x, y) = (t.x as i32, t.y as i32);
            [(1, 0), (-1, 0), (0, 1), (0, -1)]
                .iter()
                .all(|(dx, dy)| grid.at(x + dx, y + dy).is_some())
        })
        .collect()
}

/// Relative RMSE `sqrt(Σ|a − b|²) / sqrt(Σ|b|²)` over the texels where `mask` is true (all
/// texels when `mask` is `None`); `b` is the reference. 0 when both are 0, infinite when only
/// the reference is 0.
pub fn relative_rmse(test: &[Vec3], reference: &[Vec3], mask: Option<&[bool]>) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (i, (a, b)) in test.iter().zip(reference).enumerate() {
        if mask.is_some_and(|m| !m[i]) {
            continue;
        }
        num += (*a - *b).as_dvec3().length_squared();
        den += b.as_dvec3().length_squared();
    }
    if num == 0.0 {
        0.0
    } else if den == 0.0 {
        f64::INFINITY
    } else {
        (num / den).sqrt()
    }
}

/// Area-weighted power `Σ B·A` (W, RGB) over every covered texel.
pub fn power_w(grid: &TexelGrid, values: &[Vec3]) -> DVec3 {
    grid.texels
        .iter()
        .zip(values)
        .map(|(t, v)| v.as_dvec3() * t.area_m2 as f64)
        .sum()
}

/// One texel with a large error, for reports.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WorstTexel {
    /// Column and row in the lightmap.
    pub x: u32,
    /// Row (row 0 is v = 1).
    pub y: u32,
    /// Reference value, W/m².
    pub reference: Vec3,
    /// Tested value, W/m².
    pub test: Vec3,
    /// `|test − reference|` (RGB length) over the reference's RMS over interior texels.
    pub relative_error: f64,
}

/// The figures of one comparison.
#[derive(Clone, Debug)]
pub struct Comparison {
    /// Covered texels.
    pub covered: usize,
    /// Interior covered texels (the ones the RMSE figures use).
    pub interior: usize,
    /// Relative RMSE of the total `B` over interior texels.
    pub total: f64,
    /// Relative RMSE of the indirect term `B − B_o` over interior texels (when both first
    /// orders were given).
    pub indirect: Option<f64>,
    /// Power of the test over the reference's, per channel, over every covered texel.
    pub energy_ratio: DVec3,
    /// Interior texels with the largest errors, largest first.
    pub worst: Vec<WorstTexel>,
}

/// Compares `test` with `reference` (final lightmaps, per covered texel of `grid`); with
/// `first = Some((reference_first, test_first))` also the indirect terms. `worst` is how many of
/// the worst texels to list.
pub fn compare(
    grid: &TexelGrid,
    reference: &[Vec3],
    test: &[Vec3],
    first: Option<(&[Vec3], &[Vec3])>,
    worst: usize,
) -> Comparison {
    assert_eq!(reference.len(), grid.texels.len(), "reference length");
    assert_eq!(test.len(), grid.texels.len(), "test length");
    let mask = interior_mask(grid);
    let interior = mask.iter().filter(|&&m| m).count();
    let total = relative_rmse(test, reference, Some(&mask));
    let indirect = first.map(|(rf, tf)| {
        let sub =
            |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).map(|(x, y)| *x - *y).collect::<Vec<_>>();
        relative_rmse(&sub(test, tf), &sub(reference, rf), Some(&mask))
    });
    let (p_ref, p_test) = (power_w(grid, reference), power_w(grid, test));
    let ratio = |a: f64, b: f64| {
        if b == 0.0 {
            if a == 0.0 { 1.0 } else { f64::INFINITY }
        } else {
            a / b
        }
    };
    let energy_ratio = DVec3::new(
        ratio(p_test.x, p_ref.x),
        ratio(p_test.y, p_ref.y),
        ratio(p_test.z, p_ref.z),
    );
    let rms = {
        let s: f64 = reference
            .iter()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .map(|(b, _)| b.as_dvec3().length_squared())
            .sum();
        (s / interior.max(1) as f64).sqrt()
    };
    let mut ranked: Vec<WorstTexel> = grid
        .texels
        .iter()
        .enumerate()
        .filter(|(i, _)| mask[*i])
        .map(|(i, t)| WorstTexel {
            x: t.x,
            y: t.y,
            reference: reference[i],
            test: test[i],
            relative_error: (test[i] - reference[i]).as_dvec3().length() / rms.max(1e-300),
        })
        .collect();
    ranked.sort_by(|a, b| b.relative_error.total_cmp(&a.relative_error));
    ranked.truncate(worst);
    Comparison {
        covered: grid.texels.len(),
        interior,
        total,
        indirect,
        energy_ratio,
        worst: ranked,
    }
}
