//! CPU-made lightmaps for the viewer's debug, CPU-mirror and error views: the covered-texel
//! mask with chart borders, texel density, the contribution of one offset map, the CPU mirror
//! of the first-order / final / indirect lightmaps for the viewer's lights, and the error of a
//! lightmap against the reference ([`super::reference`]) in false colour.
//!
//! # How they are shown
//! Each is a [`TexelImage`] (RGB W/m², alpha = coverage) that goes through the same dilation
//! and display passes as the GPU lightmaps. False-colour views store
//! [`radiosity_for_colour`] values, i.e. the radiosity that the display pass (radiance
//! `B/π` × exposure, Reinhard, sRGB) turns into the wanted colour, so they look the same at
//! any exposure.
//!
//! # The CPU mirror
//! [`cpu_mirror()`] computes the first order on the CPU with ray-cast shadows
//! ([`ortm::bake::lighting::first_order_and_input`], exact point-to-light visibility instead of
//! shadow maps; the transfer's input averaged over the texels' squares as the viewer's
//! `--first-order-samples` asks) and applies the *same* atlas pieces on the CPU ([`ortm::atlas::apply_atlas_pieces`], Eq. 9
//! in f64): it shows what the GPU should display, up to shadow-map aliasing and float
//! rounding — the bake's approximation, not the truth (a check of the GPU passes).
//!
//! # The error view
//! [`error_values`]: per covered texel `|test − reference|` (RGB length) over the reference's
//! RMS over interior texels, the definition of [`ortm::accuracy::compare`] (whose figures the
//! stats print); [`error_view`] shows it on a blue → green → red ramp from 0 to a chosen
//! scale (red: at or above the scale).

use glam::Vec3;
use ortm::atlas::{AtlasPiece, AtlasSet, apply_atlas_pieces};
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::{NO_TEXEL, TexelGrid};
use ortm::bake::transport::Effects;
use ortm::lightmap::Lightmap;
use ortm::scene::Light;
use passes::TexelImage;

/// Largest displayable colour component (Reinhard never reaches 1).
const MAX_COLOUR: f32 = 0.95;

/// Radiosity `B` (W/m²) that the display pass shows as linear colour `c` (0–1 per channel)
/// at `exposure`: inverts `x/(1+x)` with `x = exposure·B/π`.
pub fn radiosity_for_colour(c: [f32; 3], exposure: f32) -> [f32; 3] {
    c.map(|v| {
        let v = v.clamp(0.0, MAX_COLOUR);
        std::f32::consts::PI * v / (1.0 - v) / exposure.max(1e-12)
    })
}

/// A colour per chart index: hashed hue, mid-bright (linear RGB).
fn chart_colour(chart: u32) -> [f32; 3] {
    let h = chart.wrapping_mul(0x9E37_79B9).rotate_left(7);
    let f = |s: u32| 0.15 + 0.45 * ((h >> s) & 0xff) as f32 / 255.0;
    [f(0), f(8), f(16)]
}

/// Whether covered texel `(x, y)` lies on its chart's border: a 4-neighbour is uncovered,
/// outside the lightmap, or in another chart.
pub fn is_chart_border(grid: &TexelGrid, x: u32, y: u32) -> bool {
    let Some(i) = grid.at(x as i32, y as i32) else {
        return false;
    };
    let chart = grid.texels[i as usize].chart;
    [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|(dx, dy)| {
        grid.at(x as i32 + dx, y as i32 + dy)
            .is_none_or(|j| grid.texels[j as usize].chart != chart)
    })
}

/// Covered texels in their chart's colour, chart borders in red; uncovered texels are black
/// with alpha 0 (shown without dilation, so holes in the coverage stay visible).
pub fn coverage_view(grid: &TexelGrid, exposure: f32) -> TexelImage {
    let mut img = TexelImage::new(grid.width, grid.height);
    for t in &grid.texels {
        let c = if is_chart_border(grid, t.x, t.y) {
            [0.9, 0.05, 0.05]
        } else {
            chart_colour(t.chart)
        };
        let b = radiosity_for_colour(c, exposure);
        img.rgba[(t.y * grid.width + t.x) as usize] = [b[0], b[1], b[2], 1.0];
    }
    img
}

/// Texel density (texels per m² of surface, `1/area`) in false colour on a log scale from
/// blue (sparsest) to red (densest); returns the image and the `(min, max)` density.
pub fn density_view(grid: &TexelGrid, exposure: f32) -> (TexelImage, (f64, f64)) {
    let mut img = TexelImage::new(grid.width, grid.height);
    let dens: Vec<f64> = grid
        .texels
        .iter()
        .map(|t| 1.0 / f64::from(t.area_m2).max(1e-30))
        .collect();
    let lo = dens.iter().copied().fold(f64::INFINITY, f64::min);
    let hi = dens.iter().copied().fold(0.0, f64::max);
    if dens.is_empty() {
        return (img, (0.0, 0.0));
    }
    let span = (hi / lo).ln().max(1e-12);
    for (t, d) in grid.texels.iter().zip(&dens) {
        let s = ((d / lo).ln() / span) as f32;
        let c = ramp(s);
        let b = radiosity_for_colour(c, exposure);
        img.rgba[(t.y * grid.width + t.x) as usize] = [b[0], b[1], b[2], 1.0];
    }
    (img, (lo, hi))
}

/// Blue → green → red ramp for `s` in 0–1.
pub fn ramp(s: f32) -> [f32; 3] {
    let s = s.clamp(0.0, 1.0);
    if s < 0.5 {
        let u = s * 2.0;
        [0.0, u * 0.8, 0.9 * (1.0 - u)]
    } else {
        let u = (s - 0.5) * 2.0;
        [0.9 * u, 0.8 * (1.0 - u), 0.0]
    }
}

/// A lightmap as a texel image with the grid's coverage in alpha.
pub fn with_coverage(grid: &TexelGrid, map: &Lightmap) -> TexelImage {
    let mut img = TexelImage::new(grid.width, grid.height);
    for (i, (px, v)) in img.rgba.iter_mut().zip(&map.data).enumerate() {
        let covered = grid.slot.get(i).is_some_and(|&s| s != NO_TEXEL);
        *px = [v[0], v[1], v[2], if covered { 1.0 } else { 0.0 }];
    }
    img
}

/// A texel image's RGB as a lightmap.
pub fn to_lightmap(img: &TexelImage) -> Lightmap {
    ortm::render::to_lightmap(img)
}

/// The transfer term of one map (`Σ pieces of map m: atlas · B_o(t + Δt)`, or the pyramid
/// level's block for a multi-resolution map; W/m²) for the first-order lightmap `first_order`
/// and the grid's texel areas `weights`.
pub fn map_contribution(
    set: &AtlasSet,
    map_index: u32,
    first_order: &Lightmap,
    weights: &[f32],
) -> Result<Lightmap, ortm::atlas::AtlasError> {
    let with = apply_atlas_pieces(
        set,
        |p: &AtlasPiece| p.map_index == map_index,
        first_order,
        Some(weights),
    )?;
    Ok(difference(&with, first_order))
}

/// `a − b` texel by texel (same size).
pub fn difference(a: &Lightmap, b: &Lightmap) -> Lightmap {
    Lightmap {
        width: a.width,
        height: a.height,
        data: a
            .data
            .iter()
            .zip(&b.data)
            .map(|(x, y)| [x[0] - y[0], x[1] - y[1], x[2] - y[2]])
            .collect(),
    }
}

/// CPU mirror lightmaps for `lights` with the maps for which `keep_map` is true.
#[derive(Clone, Debug)]
pub struct CpuMirror {
    /// First order `B_o = ρ·E` with ray-cast shadows, W/m².
    pub first_order: Lightmap,
    /// `B_o + Σ transfer terms`, W/m².
    pub final_map: Lightmap,
}

/// Computes the [`CpuMirror`] (see the module docs) of `scene`'s texels `grid`, the transfer's
/// input averaged over `samples × samples` sub-texels per texel as the GPU's first-order pass
/// averages it (translucent texels: those of a subsurface material when the bake's `effects`
/// hold the subsurface term, as `ortm render` takes them).
pub fn cpu_mirror(
    (scene, grid): (&ortm::scene::Scene, &TexelGrid),
    effects: Effects,
    vis: &Visibility,
    set: &AtlasSet,
    (lights, samples): (&[Light], u32),
    keep_map: impl Fn(u32) -> bool,
) -> anyhow::Result<CpuMirror> {
    use ortm::bake::lighting;
    let (values, input) =
        lighting::first_order_and_input(scene, grid, lights, vis, samples, |m| {
            effects.subsurface && scene.is_translucent(m)
        })?;
    let first_order = lighting::to_lightmap(grid, &values);
    let applied = apply_atlas_pieces(
        set,
        |p| keep_map(p.map_index),
        &lighting::to_lightmap(grid, &input),
        Some(&grid.area_map()),
    )?;
    let mut final_values = lighting::from_lightmap(grid, &applied);
    lighting::with_first_order(&mut final_values, &values, &input);
    Ok(CpuMirror {
        first_order,
        final_map: lighting::to_lightmap(grid, &final_values),
    })
}

/// Per covered texel (grid order) `|test − reference|` (RGB length) divided by the RMS of the
/// reference's RGB length over interior texels ([`ortm::accuracy::compare::interior_mask`]),
/// and that RMS (W/m²): the relative error of [`ortm::accuracy::compare`]'s worst texels, for
/// every texel. Over interior texels, the RMS of these values is `compare`'s relative RMSE.
pub fn error_values(grid: &TexelGrid, reference: &[Vec3], test: &[Vec3]) -> (Vec<f64>, f64) {
    let mask = ortm::accuracy::compare::interior_mask(grid);
    let (sum, n) = reference
        .iter()
        .zip(&mask)
        .filter(|(_, m)| **m)
        .fold((0.0f64, 0usize), |(s, n), (b, _)| {
            (s + b.as_dvec3().length_squared(), n + 1)
        });
    let rms = (sum / n.max(1) as f64).sqrt();
    let values = test
        .iter()
        .zip(reference)
        .map(|(a, b)| (*a - *b).as_dvec3().length() / rms.max(1e-300))
        .collect();
    (values, rms)
}

/// The error values of [`error_values`] in false colour: [`ramp`] from 0 (blue) to `scale`
/// (red; larger errors red too); uncovered texels transparent.
pub fn error_view(grid: &TexelGrid, values: &[f64], scale: f64, exposure: f32) -> TexelImage {
    let mut img = TexelImage::new(grid.width, grid.height);
    for (t, v) in grid.texels.iter().zip(values) {
        let c = ramp((v / scale.max(1e-12)) as f32);
        let b = radiosity_for_colour(c, exposure);
        img.rgba[(t.y * grid.width + t.x) as usize] = [b[0], b[1], b[2], 1.0];
    }
    img
}

/// Per covered texel (grid order) the RGB of a texel image (e.g. a lightmap read back from
/// the GPU).
pub fn texel_values(grid: &TexelGrid, img: &TexelImage) -> Vec<Vec3> {
    grid.texels
        .iter()
        .map(|t| {
            let p = img.rgba[(t.y * img.width + t.x) as usize];
            Vec3::new(p[0], p[1], p[2])
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn false_colours_survive_the_display_tonemap() {
        // The CPU mirror of the display shader must turn the radiosity back into the colour.
        for exposure in [0.01f32, 1.0, 37.0] {
            for c in [[0.0, 0.5, 0.9], [0.2, 0.05, 0.7]] {
                let b = radiosity_for_colour(c, exposure);
                let px = passes::cpu::display::shade(b, exposure);
                for k in 0..3 {
                    let want = passes::cpu::display::srgb_encode(c[k]) * 255.0;
                    assert!(
                        (px[k] as f32 - want).abs() <= 1.0,
                        "exposure {exposure}, colour {c:?}: got {px:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn chart_borders_of_the_cornell_box() {
        let scene = ortm::scene::cornell::cornell_box(64);
        let grid = TexelGrid::build(&scene).unwrap();
        // Independent count: a covered texel whose 4-neighbourhood leaves its chart.
        let mut border = 0;
        let mut interior = 0;
        for t in &grid.texels {
            let b = is_chart_border(&grid, t.x, t.y);
            let own = |x: i64, y: i64| {
                x >= 0
                    && y >= 0
                    && x < i64::from(grid.width)
                    && y < i64::from(grid.height)
                    && grid.slot[(y as u32 * grid.width + x as u32) as usize] != NO_TEXEL
                    && grid.texels[grid.slot[(y as u32 * grid.width + x as u32) as usize] as usize]
                        .chart
                        == t.chart
            };
            let (x, y) = (i64::from(t.x), i64::from(t.y));
            let want = !(own(x + 1, y) && own(x - 1, y) && own(x, y + 1) && own(x, y - 1));
            assert_eq!(b, want, "texel ({}, {})", t.x, t.y);
            if b { border += 1 } else { interior += 1 }
        }
        // Rectangular charts: both kinds exist.
        assert!(border > 0 && interior > 0, "{border} {interior}");
        let img = coverage_view(&grid, 1.0);
        let covered = img.rgba.iter().filter(|p| p[3] > 0.0).count();
        assert_eq!(covered, grid.texels.len());
    }

    #[test]
    fn density_is_inverse_texel_area() {
        let scene = ortm::scene::cornell::cornell_box(64);
        let grid = TexelGrid::build(&scene).unwrap();
        let (_, (lo, hi)) = density_view(&grid, 1.0);
        let areas: Vec<f64> = grid.texels.iter().map(|t| f64::from(t.area_m2)).collect();
        let amax = areas.iter().copied().fold(0.0, f64::max);
        let amin = areas.iter().copied().fold(f64::INFINITY, f64::min);
        assert!((lo * amax - 1.0).abs() < 1e-9 && (hi * amin - 1.0).abs() < 1e-9);
    }

    #[test]
    fn error_values_give_the_figures_of_compare() {
        use ortm::accuracy::compare::{compare, interior_mask};
        let scene = ortm::scene::cornell::cornell_box(24);
        let grid = TexelGrid::build(&scene).unwrap();
        // A reference varying over the map and a test off by a texel-dependent factor and a
        // constant: every texel has its own error.
        let reference: Vec<Vec3> = grid
            .texels
            .iter()
            .map(|t| Vec3::new(1.0 + t.x as f32 * 0.1, 2.0 + t.y as f32 * 0.05, 0.5) * t.albedo)
            .collect();
        let test: Vec<Vec3> = reference
            .iter()
            .enumerate()
            .map(|(i, b)| *b * (1.0 + 0.3 * ((i * 7919) % 13) as f32 / 13.0) + Vec3::splat(0.01))
            .collect();
        let c = compare(&grid, &reference, &test, None, 5);
        let (values, rms) = error_values(&grid, &reference, &test);
        let mask = interior_mask(&grid);
        let n = mask.iter().filter(|m| **m).count();
        let rms_err = (values
            .iter()
            .zip(&mask)
            .filter(|(_, m)| **m)
            .map(|(v, _)| v * v)
            .sum::<f64>()
            / n as f64)
            .sqrt();
        eprintln!(
            "relative RMSE: compare {:.6}, error view {rms_err:.6}",
            c.total
        );
        assert!(c.total > 0.05, "{}", c.total);
        assert!(
            (rms_err - c.total).abs() < 1e-9 * c.total,
            "{rms_err} vs {}",
            c.total
        );
        // The worst texels carry the same relative error as the view's texels.
        for w in &c.worst {
            let i = grid.at(w.x as i32, w.y as i32).unwrap() as usize;
            assert!(
                (values[i] - w.relative_error).abs() < 1e-9,
                "{w:?} vs {}",
                values[i]
            );
        }
        assert!(rms > 0.0);
        // The colours: a texel without error is blue, one at twice the scale red.
        let mut v = vec![0.0; grid.texels.len()];
        v[1] = 2.0;
        let img = error_view(&grid, &v, 1.0, 1.0);
        let px = |i: usize| {
            let t = &grid.texels[i];
            let p = img.rgba[(t.y * grid.width + t.x) as usize];
            passes::cpu::display::shade([p[0], p[1], p[2]], 1.0)
        };
        let (blue, red) = (px(0), px(1));
        assert!(blue[2] > 200 && blue[0] == 0 && blue[1] == 0, "{blue:?}");
        assert!(red[0] > 200 && red[1] == 0 && red[2] == 0, "{red:?}");
    }
}
