//! PNG pictures for people: tone-mapped lightmaps, the texel coverage / chart layout, and
//! (for the bake report) offset plots. Written atomically (temporary name, then rename).

use std::path::Path;

use image::{Rgb, RgbImage};

use crate::Lightmap;
use crate::bake::texels::{NO_TEXEL, TexelGrid};

/// Errors writing a picture.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// The PNG could not be written.
    #[error("cannot write '{path}': {source}. Check that the folder exists and is writable")]
    Write {
        /// Target path.
        path: String,
        /// Cause.
        source: Box<dyn std::error::Error + Send + Sync>,
    },
}

/// Saves `img` as PNG at `path` atomically.
pub fn save_png(img: &RgbImage, path: &Path) -> Result<(), ReportError> {
    let err = |e: Box<dyn std::error::Error + Send + Sync>| ReportError::Write {
        path: path.display().to_string(),
        source: e,
    };
    crate::io::write_png_atomic(img, path).map_err(|e| err(Box::new(e)))
}

/// Writes `first_order.png`, `final.png` (both at the final map's 99th percentile, so they
/// compare) and `indirect.png` (at its own) into `dir`: the pictures of a solution that
/// `ortm solve` and `ortm reference` write beside their OpenEXRs.
pub fn save_solution_pngs(
    dir: &Path,
    first_order: &Lightmap,
    final_map: &Lightmap,
    indirect: &Lightmap,
) -> Result<(), ReportError> {
    let white = percentile_99(final_map);
    save_png(
        &lightmap_image(first_order, white),
        &dir.join("first_order.png"),
    )?;
    save_png(&lightmap_image(final_map, white), &dir.join("final.png"))?;
    save_png(
        &lightmap_image(indirect, percentile_99(indirect)),
        &dir.join("indirect.png"),
    )
}

/// Linear → sRGB-encoded 8-bit.
pub fn srgb8(x: f32) -> u8 {
    let x = x.clamp(0.0, 1.0);
    let s = if x <= 0.003_130_8 {
        12.92 * x
    } else {
        1.055 * x.powf(1.0 / 2.4) - 0.055
    };
    (s * 255.0 + 0.5) as u8
}

/// The 99th-percentile channel value of the non-zero texels (an automatic exposure reference).
pub fn percentile_99(map: &Lightmap) -> f32 {
    let mut v: Vec<f32> = map
        .data
        .iter()
        .map(|p| p[0].max(p[1]).max(p[2]))
        .filter(|&x| x > 0.0 && x.is_finite())
        .collect();
    if v.is_empty() {
        return 1.0;
    }
    v.sort_by(f32::total_cmp);
    v[(v.len() - 1) * 99 / 100]
}

/// Tone-maps a lightmap (W/m²) to an sRGB image: `value / white`, clamped.
pub fn lightmap_image(map: &Lightmap, white: f32) -> RgbImage {
    let white = if white > 0.0 { white } else { 1.0 };
    RgbImage::from_fn(map.width, map.height, |x, y| {
        let p = map.get(x, y);
        Rgb([
            srgb8(p[0] / white),
            srgb8(p[1] / white),
            srgb8(p[2] / white),
        ])
    })
}

/// A distinct colour per chart id.
pub fn chart_color(chart: u32) -> Rgb<u8> {
    let h = chart.wrapping_mul(2_654_435_761);
    Rgb([
        96 + (h & 0x7f) as u8,
        96 + ((h >> 8) & 0x7f) as u8,
        96 + ((h >> 16) & 0x7f) as u8,
    ])
}

/// The coverage picture: each covered texel coloured by its chart, uncovered texels black.
pub fn coverage_image(grid: &TexelGrid) -> RgbImage {
    RgbImage::from_fn(grid.width, grid.height, |x, y| {
        let s = grid.slot[(y * grid.width + x) as usize];
        if s == NO_TEXEL {
            Rgb([0, 0, 0])
        } else {
            chart_color(grid.texels[s as usize].chart)
        }
    })
}

/// A perceptual-ish colour ramp for `t ∈ [0, 1]` (dark blue → red → yellow).
pub fn heat(t: f32) -> Rgb<u8> {
    let t = t.clamp(0.0, 1.0);
    let r = (1.5 * t).min(1.0);
    let g = (2.0 * t - 0.8).clamp(0.0, 1.0);
    let b = (0.5 - t).max(0.0) * 1.2 + 0.15 * (1.0 - t);
    Rgb([srgb8(r), srgb8(g), srgb8(b)])
}

/// Side of the bake-report pictures, pixels.
const REPORT_PX: u32 = 512;

/// Writes the bake report next to the maps:
/// - `report_offsets.png`: the `[−1, 1]²` offset square (normalised texture coordinates, +x
///   right, +y down), each offset's clipped Voronoi cell coloured by its importance (log scale),
///   cell borders dark, offsets white;
/// - `report_density.png`: the interpolated importance density over the same square (log scale),
///   data points as grey dots (absent for a jittered-grid bake).
pub fn write_bake_report(
    dir: &Path,
    grid: &TexelGrid,
    offsets: &[glam::IVec2],
    importance: &[f64],
    data_points: &[[f64; 3]],
) -> Result<(), ReportError> {
    let (w, h) = (grid.width as f64, grid.height as f64);
    let sites: Vec<glam::DVec2> = offsets
        .iter()
        .map(|o| glam::DVec2::new(o.x as f64 / w, o.y as f64 / h))
        .collect();
    save_png(
        &offsets_picture(&sites, importance),
        &dir.join("report_offsets.png"),
    )?;
    save_png(
        &density_picture(w, h, data_points),
        &dir.join("report_density.png"),
    )
}

/// Normalised offset `[−1, 1]²` of the centre of report pixel `(x, y)`.
fn report_pixel_to_norm(x: u32, y: u32) -> glam::DVec2 {
    let px = REPORT_PX;
    glam::DVec2::new(
        (x as f64 + 0.5) / px as f64 * 2.0 - 1.0,
        (y as f64 + 0.5) / px as f64 * 2.0 - 1.0,
    )
}

/// Natural logs of the smallest and largest positive values of `v` (the smallest clamped to
/// 1e-6 of the largest).
fn log_range(v: &[f64]) -> (f64, f64) {
    let pos: Vec<f64> = v.iter().copied().filter(|x| *x > 0.0).collect();
    let hi = pos.iter().copied().fold(f64::MIN, f64::max);
    let lo = pos.iter().copied().fold(f64::MAX, f64::min).max(hi * 1e-6);
    (lo.max(1e-30).ln(), hi.max(1e-30).ln())
}

/// `v` on the log scale `[lo, hi]` → `[0, 1]` for [`heat`] (0 for non-positive values).
fn log_scale(v: f64, (lo, hi): (f64, f64)) -> f32 {
    if v > 0.0 && hi > lo {
        ((v.ln() - lo) / (hi - lo)) as f32
    } else {
        0.0
    }
}

/// A 3×3 dot of colour `c` at normalised offset `p`.
fn dot(img: &mut RgbImage, p: glam::DVec2, c: Rgb<u8>) {
    let px = REPORT_PX;
    let cx = ((p.x + 1.0) * 0.5 * px as f64) as i64;
    let cy = ((p.y + 1.0) * 0.5 * px as f64) as i64;
    for dy in -1..=1 {
        for dx in -1..=1 {
            let (x, y) = (cx + dx, cy + dy);
            if x >= 0 && y >= 0 && x < px as i64 && y < px as i64 {
                img.put_pixel(x as u32, y as u32, c);
            }
        }
    }
}

/// `report_offsets.png`: each site's (normalised offset's) Voronoi cell coloured by its
/// importance, borders dark, sites white.
fn offsets_picture(sites: &[glam::DVec2], importance: &[f64]) -> RgbImage {
    let px = REPORT_PX;
    let range = log_range(importance);
    let nearest = |p: glam::DVec2| {
        let mut best = (f64::MAX, 0usize);
        for (k, s) in sites.iter().enumerate() {
            let d = (*s - p).length_squared();
            if d < best.0 {
                best = (d, k);
            }
        }
        best.1
    };
    let cells: Vec<usize> = (0..px * px)
        .map(|i| nearest(report_pixel_to_norm(i % px, i / px)))
        .collect();
    let mut img = RgbImage::from_fn(px, px, |x, y| {
        let k = cells[(y * px + x) as usize];
        let v = importance.get(k).copied().unwrap_or(0.0);
        let c = heat(log_scale(v, range));
        let border = (x + 1 < px && cells[(y * px + x + 1) as usize] != k)
            || (y + 1 < px && cells[((y + 1) * px + x) as usize] != k);
        if border { Rgb([20, 20, 20]) } else { c }
    });
    for s in sites {
        dot(&mut img, *s, Rgb([255, 255, 255]));
    }
    img
}

/// `report_density.png`: the importance density through `data_points` (texel offsets and
/// values) of a `w × h` lightmap, data points grey.
fn density_picture(w: f64, h: f64, data_points: &[[f64; 3]]) -> RgbImage {
    let px = REPORT_PX;
    let pts: Vec<(glam::DVec2, f64)> = data_points
        .iter()
        .map(|p| (glam::DVec2::new(p[0], p[1]), p[2]))
        .collect();
    let density = crate::bake::offsets::PiecewiseLinearDensity::new(&pts).ok();
    let values: Vec<f64> = (0..px * px)
        .map(|i| {
            let p = report_pixel_to_norm(i % px, i / px);
            density
                .as_ref()
                .map_or(0.0, |d| d.value(glam::DVec2::new(p.x * w, p.y * h)))
        })
        .collect();
    let range = log_range(&values);
    let mut img = RgbImage::from_fn(px, px, |x, y| {
        heat(log_scale(values[(y * px + x) as usize], range))
    });
    for p in &pts {
        dot(
            &mut img,
            glam::DVec2::new(p.0.x / w, p.0.y / h),
            Rgb([160, 160, 160]),
        );
    }
    img
}
