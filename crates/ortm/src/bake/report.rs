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
/// compare) and `indirect.png` (at its own) into `dir`, enlarged and with a legend
/// ([`lightmap_picture`]): the pictures of a solution that
/// `ortm solve` and `ortm reference` write beside their OpenEXRs.
pub fn save_solution_pngs(
    dir: &Path,
    first_order: &Lightmap,
    final_map: &Lightmap,
    indirect: &Lightmap,
) -> Result<(), ReportError> {
    let white = percentile_99(final_map);
    let white_indirect = percentile_99(indirect);
    for (map, name, what, white) in [
        (first_order, "first_order.png", "FIRST ORDER", white),
        (final_map, "final.png", "FINAL", white),
        (indirect, "indirect.png", "INDIRECT", white_indirect),
    ] {
        let img = lightmap_image(map, white);
        save_png(&lightmap_picture(&img, what, white), &dir.join(name))?;
    }
    Ok(())
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
    let offsets = with_log_legend(
        &offsets_picture(&sites, importance),
        "IMPORTANCE OF EACH OFFSET (LOG); DOTS: OFFSETS",
        log_range(importance),
    );
    save_png(&offsets, &dir.join("report_offsets.png"))?;
    let values: Vec<f64> = data_points.iter().map(|p| p[2]).collect();
    let density = with_log_legend(
        &density_picture(w, h, data_points),
        "IMPORTANCE DENSITY (LOG); DOTS: DATA POINTS",
        log_range(&values),
    );
    save_png(&density, &dir.join("report_density.png"))
}

/// A report picture with its legend: what the colours mean, the [`heat`] ramp between the
/// values `exp(lo)` and `exp(hi)`, and the square's axes.
fn with_log_legend(img: &RgbImage, title: &str, (lo, hi): (f64, f64)) -> RgbImage {
    let (low, high) = if hi >= lo {
        (legend_number(lo.exp()), legend_number(hi.exp()))
    } else {
        ("-".to_owned(), "-".to_owned())
    };
    with_legend(
        img,
        &[
            Legend::Ramp {
                title,
                colour: &heat,
                low: &low,
                high: &high,
            },
            Legend::Swatch(
                LEGEND_BG,
                "SQUARE: OFFSET X, Y FROM -1 TO 1 LIGHTMAP SIDE; +Y DOWN",
            ),
        ],
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

/// Smallest longer side, pixels, of the pictures of lightmaps and charts: a smaller map is
/// enlarged by a whole factor, one square of pixels per texel (nearest), so that a 64² map
/// can be read.
pub const READABLE_PX: u32 = 512;

/// `img` enlarged by the smallest whole factor that brings its longer side to
/// [`READABLE_PX`] or more (nearest: each texel a square); unchanged when already that large.
pub fn upscale_readable(img: &RgbImage) -> RgbImage {
    let k = readable_factor(img.width(), img.height());
    if k == 1 {
        return img.clone();
    }
    RgbImage::from_fn(img.width() * k, img.height() * k, |x, y| {
        *img.get_pixel(x / k, y / k)
    })
}

/// The factor [`upscale_readable`] enlarges a `width × height` picture by.
pub fn readable_factor(width: u32, height: u32) -> u32 {
    READABLE_PX.div_ceil(width.max(height).max(1)).max(1)
}

/// One line of a picture's legend ([`with_legend`]).
pub enum Legend<'a> {
    /// A colour swatch and what it means.
    Swatch(Rgb<u8>, &'a str),
    /// A colour ramp from `t = 0` (left, labelled `low`) to `t = 1` (right, `high`) under a
    /// title.
    Ramp {
        /// What the colours mean.
        title: &'a str,
        /// The colour at `t ∈ [0, 1]`.
        colour: &'a dyn Fn(f32) -> Rgb<u8>,
        /// Label of the left end.
        low: &'a str,
        /// Label of the right end.
        high: &'a str,
    },
}

/// Pixels per font pixel of legend text.
const TEXT_SCALE: u32 = 2;
/// Margin and line spacing of a legend, pixels.
const LEGEND_MARGIN: u32 = 6;
/// Background of the legend strip.
const LEGEND_BG: Rgb<u8> = Rgb([40, 40, 44]);
/// Legend text colour.
const LEGEND_TEXT: Rgb<u8> = Rgb([235, 235, 235]);

/// `img` with a legend strip below it: one row per [`Legend`] line (text in upper case, a
/// 3×5-pixel font drawn at [`TEXT_SCALE`]; characters outside the font are drawn as `?`).
pub fn with_legend(img: &RgbImage, lines: &[Legend]) -> RgbImage {
    let glyph_h = 5 * TEXT_SCALE;
    let line_h = |l: &Legend| match l {
        Legend::Swatch(..) => glyph_h + LEGEND_MARGIN,
        Legend::Ramp { .. } => 3 * glyph_h + 4 * LEGEND_MARGIN,
    };
    let strip_h: u32 = LEGEND_MARGIN + lines.iter().map(line_h).sum::<u32>();
    let w = img.width();
    let mut out = RgbImage::from_pixel(w, img.height() + strip_h, LEGEND_BG);
    image::imageops::replace(&mut out, img, 0, 0);
    let mut y = img.height() + LEGEND_MARGIN;
    for l in lines {
        match l {
            Legend::Swatch(c, text) => {
                fill_rect(&mut out, (LEGEND_MARGIN, y), (glyph_h, glyph_h), *c);
                draw_text(&mut out, (2 * LEGEND_MARGIN + glyph_h, y), text);
            }
            Legend::Ramp {
                title,
                colour,
                low,
                high,
            } => {
                draw_text(&mut out, (LEGEND_MARGIN, y), title);
                let bar_y = y + glyph_h + LEGEND_MARGIN;
                let bar_w = w.saturating_sub(2 * LEGEND_MARGIN).max(1);
                for x in 0..bar_w {
                    let t = x as f32 / (bar_w - 1).max(1) as f32;
                    fill_rect(
                        &mut out,
                        (LEGEND_MARGIN + x, bar_y),
                        (1, glyph_h),
                        colour(t),
                    );
                }
                let label_y = bar_y + glyph_h + LEGEND_MARGIN;
                draw_text(&mut out, (LEGEND_MARGIN, label_y), low);
                let high_w = text_width(high);
                let right = w.saturating_sub(LEGEND_MARGIN + high_w);
                draw_text(&mut out, (right.max(LEGEND_MARGIN), label_y), high);
            }
        }
        y += line_h(l);
    }
    out
}

/// Fills the rectangle at `(x, y)` of size `(w, h)` with `c`, clipped to the image.
fn fill_rect(img: &mut RgbImage, (x, y): (u32, u32), (w, h): (u32, u32), c: Rgb<u8>) {
    for yy in y..(y + h).min(img.height()) {
        for xx in x..(x + w).min(img.width()) {
            img.put_pixel(xx, yy, c);
        }
    }
}

/// Width in pixels of `text` drawn by [`draw_text`].
fn text_width(text: &str) -> u32 {
    text.chars().count() as u32 * 4 * TEXT_SCALE
}

/// Draws `text` (upper-cased) with its top-left corner at `(x, y)`, clipped to the image.
fn draw_text(img: &mut RgbImage, (x, y): (u32, u32), text: &str) {
    for (i, ch) in text.chars().flat_map(char::to_uppercase).enumerate() {
        let rows = glyph(ch);
        let gx = x + i as u32 * 4 * TEXT_SCALE;
        for (r, row) in rows.iter().enumerate() {
            for (c, on) in row.bytes().enumerate() {
                if on == b'#' {
                    fill_rect(
                        img,
                        (gx + c as u32 * TEXT_SCALE, y + r as u32 * TEXT_SCALE),
                        (TEXT_SCALE, TEXT_SCALE),
                        LEGEND_TEXT,
                    );
                }
            }
        }
    }
}

/// The 3×5 pixel pattern of a character (rows top to bottom, `#` lit).
fn glyph(ch: char) -> [&'static str; 5] {
    match ch {
        'A' => ["###", "#.#", "###", "#.#", "#.#"],
        'B' => ["##.", "#.#", "##.", "#.#", "##."],
        'C' => ["###", "#..", "#..", "#..", "###"],
        'D' => ["##.", "#.#", "#.#", "#.#", "##."],
        'E' => ["###", "#..", "##.", "#..", "###"],
        'F' => ["###", "#..", "##.", "#..", "#.."],
        'G' => ["###", "#..", "#.#", "#.#", "###"],
        'H' => ["#.#", "#.#", "###", "#.#", "#.#"],
        'I' => ["###", ".#.", ".#.", ".#.", "###"],
        'J' => ["..#", "..#", "..#", "#.#", "###"],
        'K' => ["#.#", "#.#", "##.", "#.#", "#.#"],
        'L' => ["#..", "#..", "#..", "#..", "###"],
        'M' => ["#.#", "###", "###", "#.#", "#.#"],
        'N' => ["##.", "#.#", "#.#", "#.#", "#.#"],
        'O' => ["###", "#.#", "#.#", "#.#", "###"],
        'P' => ["###", "#.#", "###", "#..", "#.."],
        'Q' => ["###", "#.#", "#.#", "###", "..#"],
        'R' => ["##.", "#.#", "##.", "#.#", "#.#"],
        'S' => ["###", "#..", "###", "..#", "###"],
        'T' => ["###", ".#.", ".#.", ".#.", ".#."],
        'U' => ["#.#", "#.#", "#.#", "#.#", "###"],
        'V' => ["#.#", "#.#", "#.#", "#.#", ".#."],
        'W' => ["#.#", "#.#", "###", "###", "#.#"],
        'X' => ["#.#", "#.#", ".#.", "#.#", "#.#"],
        'Y' => ["#.#", "#.#", ".#.", ".#.", ".#."],
        'Z' => ["###", "..#", ".#.", "#..", "###"],
        '0' => ["###", "#.#", "#.#", "#.#", "###"],
        '1' => [".#.", "##.", ".#.", ".#.", "###"],
        '2' | '²' => ["###", "..#", "###", "#..", "###"],
        '3' => ["###", "..#", "###", "..#", "###"],
        '4' => ["#.#", "#.#", "###", "..#", "..#"],
        '5' => ["###", "#..", "###", "..#", "###"],
        '6' => ["###", "#..", "###", "#.#", "###"],
        '7' => ["###", "..#", "..#", "..#", "..#"],
        '8' => ["###", "#.#", "###", "#.#", "###"],
        '9' => ["###", "#.#", "###", "..#", "###"],
        ' ' => ["...", "...", "...", "...", "..."],
        '.' => ["...", "...", "...", "...", ".#."],
        ',' => ["...", "...", "...", ".#.", "#.."],
        ':' => ["...", ".#.", "...", ".#.", "..."],
        ';' => ["...", ".#.", "...", ".#.", "#.."],
        '-' | '−' => ["...", "...", "###", "...", "..."],
        '+' => ["...", ".#.", "###", ".#.", "..."],
        '=' => ["...", "###", "...", "###", "..."],
        '/' => ["..#", "..#", ".#.", "#..", "#.."],
        '(' => [".#.", "#..", "#..", "#..", ".#."],
        ')' => [".#.", "..#", "..#", "..#", ".#."],
        '%' => ["#.#", "..#", ".#.", "#..", "#.#"],
        '×' => ["...", "#.#", ".#.", "#.#", "..."],
        '≥' => ["#..", ".#.", "..#", ".#.", "###"],
        _ => ["###", "..#", ".##", "...", ".#."],
    }
}

/// A short label of a number for legends: 3 significant digits, scientific outside
/// `[0.01, 10000)`.
pub fn legend_number(v: f64) -> String {
    let a = v.abs();
    if v == 0.0 {
        "0".into()
    } else if !(0.01..10_000.0).contains(&a) {
        format!("{v:.2e}")
    } else {
        let decimals = (2 - a.log10().floor() as i32).max(0) as usize;
        format!("{v:.decimals$}")
    }
}

/// The grey ramp of [`lightmap_image`] at `t` of the white value.
fn grey(t: f32) -> Rgb<u8> {
    let g = srgb8(t);
    Rgb([g, g, g])
}

/// `img` of a lightmap tone-mapped at `white` W/m²: enlarged ([`upscale_readable`]) with a
/// legend naming `what` and the scale.
pub fn lightmap_picture(img: &RgbImage, what: &str, white: f32) -> RgbImage {
    let high = format!("{} W/M2 OR MORE", legend_number(white as f64));
    let title = format!("{what}: W/M2 PER TEXEL, LINEAR (SRGB)");
    let big = upscale_readable(img);
    with_legend(
        &big,
        &[
            Legend::Ramp {
                title: &title,
                colour: &grey,
                low: "0",
                high: &high,
            },
            Legend::Swatch(Rgb([0, 0, 0]), "ALSO BLACK: NO TEXEL"),
        ],
    )
}

/// The picture `ortm inspect` writes: [`coverage_image`] with the texels of `overlaps` (per
/// slot, [`crate::bake::texels::overlapping_slots`]) red, enlarged, with a legend.
pub fn coverage_picture(grid: &TexelGrid, overlaps: &[bool]) -> RgbImage {
    let mut img = coverage_image(grid);
    for (i, _) in overlaps.iter().enumerate().filter(|(_, o)| **o) {
        let (x, y) = (i as u32 % grid.width, i as u32 / grid.width);
        img.put_pixel(x, y, OVERLAP_RED);
    }
    let big = upscale_readable(&img);
    with_legend(
        &big,
        &[
            Legend::Swatch(Rgb([0, 0, 0]), "NO TEXEL (NOT COVERED)"),
            Legend::Swatch(chart_color(0), "ONE COLOUR PER CHART (UV ISLAND)"),
            Legend::Swatch(OVERLAP_RED, "OVERLAPPING UVS (2+ TRIANGLES)"),
        ],
    )
}

/// The colour of overlapping texels in [`coverage_picture`].
pub const OVERLAP_RED: Rgb<u8> = Rgb([255, 0, 0]);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn legend_numbers_keep_three_significant_digits() {
        assert_eq!(legend_number(210.173), "210");
        assert_eq!(legend_number(1.4709), "1.47");
        assert_eq!(legend_number(0.2613), "0.261");
        assert_eq!(legend_number(0.0), "0");
        assert_eq!(legend_number(12345.0), "1.23e4");
        assert_eq!(legend_number(0.00123), "1.23e-3");
    }

    #[test]
    fn enlarged_pictures_repeat_each_texel_as_a_square() {
        let img = RgbImage::from_fn(3, 2, |x, y| Rgb([x as u8, y as u8, 7]));
        let big = upscale_readable(&img);
        let k = READABLE_PX.div_ceil(3);
        assert_eq!((big.width(), big.height()), (3 * k, 2 * k));
        for (x, y, p) in big.enumerate_pixels() {
            assert_eq!(*p, *img.get_pixel(x / k, y / k));
        }
        let legend = with_legend(&img, &[Legend::Swatch(Rgb([1, 2, 3]), "A")]);
        assert_eq!(legend.width(), 3);
        assert!(legend.height() > 2);
    }
}
