//! Accuracy figures of a lightmap against a reference: relative RMSE of the total `B` and of the
//! indirect term `B − B_o`, over *interior* covered texels (a covered texel whose four
//! neighbours are covered too: texels at chart borders are bilinearly blended with gutters on
//! the GPU and carry the rasterisation's own error, so the figures leave them out), the energy
//! ratio (area-weighted power of the test over the reference) and the worst texels.
//!
//! Values are per covered texel of a [`TexelGrid`] (grid order), radiosity in W/m², RGB.
//! Relative RMSE is `sqrt(Σ|a − b|²) / sqrt(Σ|b|²)` over the interior texels and the three
//! channels (`b` the reference).
//!
//! [`error_image`] draws the per-texel error `|test − reference|` (RGB length) over a stated
//! scale as a false-colour picture (viridis ramp, uncovered texels grey, a colour bar under the
//! map); `ortm compare` writes it with the reference's RMS over interior texels as the scale.

use std::collections::HashMap;

use glam::{DVec3, Vec3};
use image::{Rgb, RgbImage};

use crate::bake::texels::{NO_TEXEL, TexelGrid};

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

/// Per covered texel of `grid`: true when it lies within 2.5 texel sizes (3D distance, the
/// larger texel's `sqrt(area)`; across charts and seams too) of a texel whose first-order light
/// (`first_order`, summed over the channels) differs from its own by more than 2× either way —
/// shadow edges and terminators that the lightmap resolves over a couple of texels. Every
/// per-texel solver holds a texel's first-order light constant over it while the light gathered
/// around its centre (bounces, subsurface exit points) varies there, so a comparison of a
/// lightmap with a continuous reference reads the discretisation near these texels and the
/// transport away from them.
///
/// # Panics
/// When `first_order`'s length is not the grid's texel count.
pub fn near_first_order_edges(grid: &TexelGrid, first_order: &[Vec3]) -> Vec<bool> {
    assert_eq!(first_order.len(), grid.texels.len(), "first-order length");
    let t = &grid.texels;
    let reach = 2.5
        * t.iter()
            .map(|x| x.area_m2.max(0.0).sqrt())
            .fold(0.0f32, f32::max);
    if t.is_empty() || reach <= 0.0 {
        return vec![false; t.len()];
    }
    // Texels hashed into cubes of side `reach`: every pair within it lies in neighbouring cubes.
    let key = |p: Vec3| {
        let q = (p / reach).floor();
        (q.x as i64, q.y as i64, q.z as i64)
    };
    let mut cells: HashMap<(i64, i64, i64), Vec<usize>> = HashMap::new();
    for (i, x) in t.iter().enumerate() {
        cells.entry(key(x.position_m)).or_default().push(i);
    }
    let light: Vec<f32> = first_order.iter().map(|v| v.element_sum()).collect();
    let around = |(x, y, z): (i64, i64, i64)| {
        (-1..=1).flat_map(move |dz| {
            (-1..=1).flat_map(move |dy| (-1..=1).map(move |dx| (x + dx, y + dy, z + dz)))
        })
    };
    t.iter()
        .enumerate()
        .map(|(i, a)| {
            let own = light[i];
            around(key(a.position_m))
                .filter_map(|c| cells.get(&c))
                .flatten()
                .any(|&j| {
                    let o = light[j];
                    (o > 2.0 * own || own > 2.0 * o)
                        && (a.position_m - t[j].position_m).length()
                            < 2.5 * a.area_m2.max(t[j].area_m2).sqrt()
                })
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
    /// Root mean square of the reference's RGB length over interior texels, W/m²: the unit of
    /// [`WorstTexel::relative_error`] (see [`reference_rms`]).
    pub reference_rms: f64,
    /// Interior texels with the largest errors, largest first.
    pub worst: Vec<WorstTexel>,
    /// With both first orders: the interior texels away from the reference's first-order edges
    /// ([`near_first_order_edges`]) and the relative RMSE of the total and of the indirect term
    /// over them.
    pub away_from_edges: Option<(usize, f64, f64)>,
}

/// Root mean square of `|b|` (RGB length, W/m²) over the texels where `mask` is true; 0 when
/// there are none.
pub fn reference_rms(reference: &[Vec3], mask: &[bool]) -> f64 {
    let (sum, count) = reference
        .iter()
        .zip(mask)
        .filter(|(_, m)| **m)
        .fold((0.0f64, 0usize), |(s, c), (b, _)| {
            (s + b.as_dvec3().length_squared(), c + 1)
        });
    if count == 0 {
        0.0
    } else {
        (sum / count as f64).sqrt()
    }
}

/// Compares `test` with `reference` (final lightmaps, per covered texel of `grid`); with
/// `first = Some((reference_first, test_first))` also the indirect terms. `worst` is how many of
/// the worst texels to list.
///
/// # Panics
/// When a slice's length is not the grid's texel count (a caller's bug: gather the values with
/// [`crate::bake::lighting::from_lightmap`] on the same grid).
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
    let (indirect, away_from_edges) = match first {
        Some((rf, tf)) => {
            assert_eq!(rf.len(), grid.texels.len(), "reference first-order length");
            assert_eq!(tf.len(), grid.texels.len(), "test first-order length");
            let sub =
                |a: &[Vec3], b: &[Vec3]| a.iter().zip(b).map(|(x, y)| *x - *y).collect::<Vec<_>>();
            let (test_ind, ref_ind) = (sub(test, tf), sub(reference, rf));
            let edges = near_first_order_edges(grid, rf);
            let away: Vec<bool> = mask.iter().zip(&edges).map(|(m, e)| *m && !e).collect();
            (
                Some(relative_rmse(&test_ind, &ref_ind, Some(&mask))),
                Some((
                    away.iter().filter(|&&a| a).count(),
                    relative_rmse(test, reference, Some(&away)),
                    relative_rmse(&test_ind, &ref_ind, Some(&away)),
                )),
            )
        }
        None => (None, None),
    };
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
    let rms = reference_rms(reference, &mask);
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
        reference_rms: rms,
        worst: ranked,
        away_from_edges,
    }
}

/// How noisy a path-traced reference is, from its per-texel standard error (`ortm reference`'s
/// `std_error.exr`), and how a test sits within it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ReferenceNoise {
    /// The standard error as a relative RMSE of the reference's total over interior texels,
    /// `sqrt(Σ|σ|²) / sqrt(Σ|b|²)`: the error an exact test would measure on average.
    pub total: f64,
    /// The same against the reference's indirect term `B − B_o` (its first order carries no
    /// noise), when the reference's first order is given.
    pub indirect: Option<f64>,
    /// Fraction of covered texels where the test is within 3 standard errors of the reference
    /// in every channel (`|test − b| ≤ 3σ`).
    pub within_three_sigma: f64,
    /// Of the covered texels outside 3σ, those where the reference is `0 ± 0` in every
    /// channel: none of its paths found light there, so its standard error says nothing and
    /// any test value but an exact 0 counts as a miss.
    pub unlit_misses: usize,
    /// The largest `|test|` over those texels, W/m² (0 without any).
    pub unlit_largest: f64,
    /// With the reference's first order: the covered texels it lights at their centre (first
    /// order above 0 in some channel) and the fraction of them within 3σ.
    pub within_lit: Option<(usize, f64)>,
}

/// The reference's noise ([`ReferenceNoise`]) from `std_error` (per covered texel of `grid`, as
/// the values), against `test`; `reference_first` gives the indirect figure.
///
/// # Panics
/// When a slice's length is not the grid's texel count.
pub fn reference_noise(
    grid: &TexelGrid,
    reference: &[Vec3],
    std_error: &[Vec3],
    test: &[Vec3],
    reference_first: Option<&[Vec3]>,
) -> ReferenceNoise {
    let n = grid.texels.len();
    assert!(
        reference.len() == n && std_error.len() == n && test.len() == n,
        "one value per covered texel"
    );
    let mask = interior_mask(grid);
    // The standard error as an "error" of a test equal to the reference plus σ.
    let shifted: Vec<Vec3> = reference
        .iter()
        .zip(std_error)
        .map(|(b, s)| *b + *s)
        .collect();
    let total = relative_rmse(&shifted, reference, Some(&mask));
    let indirect = reference_first.map(|f| {
        assert_eq!(f.len(), n, "reference first-order length");
        let ind: Vec<Vec3> = reference.iter().zip(f).map(|(b, f)| *b - *f).collect();
        let ind_shifted: Vec<Vec3> = ind.iter().zip(std_error).map(|(b, s)| *b + *s).collect();
        relative_rmse(&ind_shifted, &ind, Some(&mask))
    });
    let (mut within, mut unlit_misses, mut unlit_largest) = (0usize, 0usize, 0f64);
    let (mut lit, mut lit_within) = (0usize, 0usize);
    for i in 0..n {
        let d = (test[i] - reference[i]).abs();
        let ok = d.cmple(std_error[i] * 3.0).all();
        if reference_first.is_some_and(|f| f[i].max_element() > 0.0) {
            lit += 1;
            lit_within += usize::from(ok);
        }
        if ok {
            within += 1;
        } else if reference[i] == Vec3::ZERO && std_error[i] == Vec3::ZERO {
            unlit_misses += 1;
            unlit_largest = unlit_largest.max(d.max_element() as f64);
        }
    }
    ReferenceNoise {
        total,
        indirect,
        within_three_sigma: if n == 0 {
            1.0
        } else {
            within as f64 / n as f64
        },
        unlit_misses,
        unlit_largest,
        within_lit: reference_first.map(|_| {
            (
                lit,
                if lit == 0 {
                    1.0
                } else {
                    lit_within as f64 / lit as f64
                },
            )
        }),
    }
}

/// A measured relative RMSE `error` less a reference noise `noise` of the same kind, in
/// quadrature, `sqrt(max(error² − noise², 0))`: the test's own error, since the reference's
/// noise is independent of it and their squares add on average.
pub fn noise_corrected(error: f64, noise: f64) -> f64 {
    (error * error - noise * noise).max(0.0).sqrt()
}

/// Viridis (perceptually uniform, readable in grey and by colour-blind viewers) at t = 0, 1/8,
/// …, 1, sRGB 8-bit.
const VIRIDIS: [[u8; 3]; 9] = [
    [68, 1, 84],
    [71, 45, 123],
    [59, 82, 139],
    [44, 114, 142],
    [33, 145, 140],
    [40, 174, 128],
    [94, 201, 98],
    [170, 220, 50],
    [253, 231, 37],
];

/// Colour of uncovered texels in [`error_image`].
pub const UNCOVERED_GREY: Rgb<u8> = Rgb([128, 128, 128]);

/// The viridis ramp at `t`, clamped to `[0, 1]` (NaN → 1, the alarming end).
pub fn viridis(t: f64) -> Rgb<u8> {
    let t = if t.is_nan() { 1.0 } else { t.clamp(0.0, 1.0) };
    let x = t * (VIRIDIS.len() - 1) as f64;
    let i = (x.floor() as usize).min(VIRIDIS.len() - 2);
    let f = x - i as f64;
    let (a, b) = (VIRIDIS[i], VIRIDIS[i + 1]);
    Rgb(std::array::from_fn(|c| {
        (a[c] as f64 + f * (b[c] as f64 - a[c] as f64)).round() as u8
    }))
}

/// Side the error picture's map is enlarged towards (whole pixels per texel), pixels.
const ERROR_IMAGE_PX: u32 = 512;

/// The false-colour error picture of `test` against `reference` (per covered texel of `grid`):
/// texel `(x, y)` shows `|test − reference|` (RGB length, W/m²) over `scale_w_m2` on the
/// [`viridis`] ramp — dark purple 0, yellow `scale_w_m2` and above; uncovered texels are
/// [`UNCOVERED_GREY`]. Each texel is a square of `max(1, 512 / side)` pixels, and a colour bar
/// (0 on the left to `scale_w_m2` on the right) runs under the map, one grey row apart.
///
/// # Panics
/// When a slice's length is not the grid's texel count.
pub fn error_image(
    grid: &TexelGrid,
    reference: &[Vec3],
    test: &[Vec3],
    scale_w_m2: f64,
) -> RgbImage {
    assert_eq!(reference.len(), grid.texels.len(), "reference length");
    assert_eq!(test.len(), grid.texels.len(), "test length");
    let k = (ERROR_IMAGE_PX / grid.width.max(grid.height).max(1)).max(1);
    let (w, h) = (grid.width * k, grid.height * k);
    let bar = (h / 16).max(4);
    let scale = if scale_w_m2 > 0.0 { scale_w_m2 } else { 1.0 };
    RgbImage::from_fn(w, h + k + bar, |px, py| {
        if py >= h + k {
            return viridis(px as f64 / (w - 1).max(1) as f64);
        }
        if py >= h {
            return UNCOVERED_GREY;
        }
        let s = grid.slot[((py / k) * grid.width + px / k) as usize];
        if s == NO_TEXEL {
            return UNCOVERED_GREY;
        }
        let i = s as usize;
        viridis((test[i] - reference[i]).as_dvec3().length() / scale)
    })
}
