//! Exposure: the factor multiplying the radiance `L = B/π` (B in W/m²) before the display's
//! Reinhard tonemapping, so an exposure of `e` shows `L = 1/e` at half white (Reinhard 0.5).
//! [`auto_exposure`] picks it from a final lightmap; [`parse_exposure`] reads the
//! `--exposure` option of `ortm render` and `ortm view`.

use passes::TexelImage;

use super::RenderError;

/// Parses `--exposure`: `auto` gives `None` (the caller runs [`auto_exposure`]), otherwise a
/// finite positive number.
pub fn parse_exposure(spec: &str) -> Result<Option<f32>, RenderError> {
    match spec {
        "auto" => Ok(None),
        s => s
            .parse::<f32>()
            .ok()
            .filter(|e| e.is_finite() && *e > 0.0)
            .map(Some)
            .ok_or_else(|| RenderError::BadExposure { spec: s.to_owned() }),
    }
}

/// An exposure that maps the 95th percentile of the radiance `L = B/π` over covered texels
/// (alpha > 0) of `lightmap` to 1 (Reinhard 0.5), or 1 when nothing is lit.
///
/// Every covered texel counts, unlit ones (`L ≤ 0`, e.g. a shadowed texel whose subsurface
/// terms cancel to ±1e-9 W/m²) as 0: counting only `L > 0` let rounding noise in the dark
/// texels move the percentile (the blend and compute paths differed by 4 % on the head).
pub fn auto_exposure(lightmap: &TexelImage) -> f32 {
    let mut l: Vec<f32> = lightmap
        .rgba
        .iter()
        .filter(|p| p[3] > 0.0)
        .map(|p| p[0].max(p[1]).max(p[2]) / std::f32::consts::PI)
        .filter(|v| v.is_finite())
        .map(|v| v.max(0.0))
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let k = ((l.len() - 1) as f64 * 0.95).round() as usize;
    let (_, p95, _) = l.select_nth_unstable_by(k, f32::total_cmp);
    if *p95 > 0.0 { 1.0 / *p95 } else { 1.0 }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn auto_exposure_is_the_95th_percentile_over_covered_texels_and_ignores_dark_noise() {
        // 100 covered texels: 50 dark, 50 lit with L = B/π = 1, …, 50 (max over RGB); 20
        // uncovered ones at 1000. Sorted covered values: 50 zeros, then 1…50; the 95th
        // percentile is element round(99·0.95) = 94, i.e. L = 45.
        let mut img = TexelImage::new(12, 10);
        for (i, p) in img.rgba.iter_mut().enumerate() {
            *p = match i {
                0..50 => [0.0, 0.0, 0.0, 1.0],
                50..100 => {
                    let b = (i - 49) as f32 * std::f32::consts::PI;
                    [0.5 * b, b, 0.25 * b, 1.0]
                }
                _ => [1000.0, 1000.0, 1000.0, 0.0],
            };
        }
        let e = auto_exposure(&img);
        assert!((e - 1.0 / 45.0).abs() < 1e-6, "{e}");
        // Rounding noise of either sign in the dark texels changes nothing (counting only
        // L > 0 gave 1/48 without the noise and 1/45 with positive noise).
        for noise in [1e-9f32, -1e-9] {
            for p in &mut img.rgba[..50] {
                *p = [noise, noise, noise, 1.0];
            }
            assert_eq!(auto_exposure(&img), e, "noise {noise}");
        }
        // Nothing lit → 1.
        let dark = TexelImage::new(4, 4);
        assert_eq!(auto_exposure(&dark), 1.0);
    }

    #[test]
    fn auto_exposure_maps_the_95th_percentile_to_one() {
        let mut img = TexelImage::new(100, 1);
        for (i, p) in img.rgba.iter_mut().enumerate() {
            let b = (i + 1) as f32 * std::f32::consts::PI;
            *p = [b, 0.5 * b, 0.0, 1.0];
        }
        // An uncovered texel, however bright, does not count.
        img.rgba[0] = [1e9, 1e9, 1e9, 0.0];
        // Covered L values are 2..=100; the 95th percentile of those 99 values is index 93 → 95.
        let e = auto_exposure(&img);
        assert!((e - 1.0 / 95.0).abs() < 1e-6, "{e}");
        assert_eq!(auto_exposure(&TexelImage::new(4, 4)), 1.0);
    }

    #[test]
    fn exposure_option_is_auto_or_a_positive_number() {
        assert_eq!(parse_exposure("auto").unwrap(), None);
        assert_eq!(parse_exposure("0.25").unwrap(), Some(0.25));
        for bad in ["0", "-1", "inf", "NaN", "x", ""] {
            let e = parse_exposure(bad).unwrap_err().to_string();
            assert_eq!(
                e,
                format!("--exposure {bad:?}: use `auto` or a positive number")
            );
        }
    }
}
