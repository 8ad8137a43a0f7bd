//! CPU mirror of the display pass's shading (`shaders/display.wgsl`): bilinear or cubic
//! B-spline lightmap lookup, `L = B/π` (+ optional Blinn-Phong specular), the per-pixel
//! direct light ([`pixel_radiance`]: shadowed `ρ·E/π` at the pixel's own surface point, the
//! subsurface share, the transferred light from the lightmap), exposure, Reinhard, sRGB (the
//! shader's fitted encoding, [`srgb_encode`]), 8-bit.
//! The rasterisation of the mesh itself is not mirrored: callers give the surface point of a
//! pixel (e.g. from a ray cast through its centre), and the shadow test as a function (e.g.
//! exact ray-cast visibility, [`crate::cpu::first_order::occluded`]).

use glam::Vec3;

use crate::cpu::first_order::light_incident;
use crate::display::LightmapSampling;
use crate::first_order::GpuLight;
use crate::types::TexelImage;

/// Uniform cubic B-spline weights of the texels at offsets −1, 0, 1, 2 from `floor(s)`
/// for the fraction `f` (`bspline_weights` in display.wgsl).
pub fn bspline_weights(f: f32) -> [f32; 4] {
    let (f2, f3, g) = (f * f, f * f * f, 1.0 - f);
    [
        g * g * g / 6.0,
        (4.0 - 6.0 * f2 + 3.0 * f3) / 6.0,
        (1.0 + 3.0 * f + 3.0 * f2 - 3.0 * f3) / 6.0,
        f3 / 6.0,
    ]
}

/// Texel-space coordinates `[s, t]` of a UV on a `width × height` map, texel centres at
/// integers (`texel_coords` in display.wgsl): texel `(x, y)` has its centre at
/// `u = (x+0.5)/W`, `v = 1 − (y+0.5)/H`. A bilinear lookup reads `floor` and `floor + 1`.
pub fn texel_coords(uv: [f32; 2], width: u32, height: u32) -> [f32; 2] {
    [
        uv[0] * width as f32 - 0.5,
        (1.0 - uv[1]) * height as f32 - 0.5,
    ]
}

/// Cubic B-spline lookup of RGBA between texel centres, indices clamped at the border
/// (`bicubic_of` in display.wgsl; the hardware path `bicubic_filtered_of` takes four
/// bilinear samples, the same function up to the sampler's weight precision).
pub fn bicubic_rgba(map: &TexelImage, uv: [f32; 2]) -> [f32; 4] {
    let [s, t] = texel_coords(uv, map.width, map.height);
    let (i0, j0) = (s.floor(), t.floor());
    let (wx, wy) = (bspline_weights(s - i0), bspline_weights(t - j0));
    let cx = |i: i32| i.clamp(0, map.width as i32 - 1) as u32;
    let cy = |j: i32| j.clamp(0, map.height as i32 - 1) as u32;
    let mut out = [0.0; 4];
    for (j, wj) in wy.iter().enumerate() {
        for (i, wi) in wx.iter().enumerate() {
            let texel = map.get(cx(i0 as i32 - 1 + i as i32), cy(j0 as i32 - 1 + j as i32));
            for c in 0..4 {
                out[c] += wj * wi * texel[c];
            }
        }
    }
    out
}

/// Bilinear lookup of RGBA (see [`bilinear`]).
pub fn bilinear_rgba(map: &TexelImage, uv: [f32; 2]) -> [f32; 4] {
    let [s, t] = texel_coords(uv, map.width, map.height);
    let (i0, j0) = (s.floor(), t.floor());
    let (fx, fy) = (s - i0, t - j0);
    let cx = |i: f32| (i as i32).clamp(0, map.width as i32 - 1) as u32;
    let cy = |j: f32| (j as i32).clamp(0, map.height as i32 - 1) as u32;
    let (ax, ay, bx, by) = (cx(i0), cy(j0), cx(i0 + 1.0), cy(j0 + 1.0));
    let mut out = [0.0; 4];
    for (c, o) in out.iter_mut().enumerate() {
        let lerp = |a: f32, b: f32, f: f32| a + (b - a) * f;
        let top = lerp(map.get(ax, ay)[c], map.get(bx, ay)[c], fx);
        let bot = lerp(map.get(ax, by)[c], map.get(bx, by)[c], fx);
        *o = lerp(top, bot, fy);
    }
    out
}

/// A lightmap lookup with `sampling` (RGB).
pub fn lookup(map: &TexelImage, uv: [f32; 2], sampling: LightmapSampling) -> [f32; 3] {
    let v = match sampling {
        LightmapSampling::Bilinear => bilinear_rgba(map, uv),
        LightmapSampling::Bicubic => bicubic_rgba(map, uv),
    };
    [v[0], v[1], v[2]]
}

/// Share `w` of per-pixel direct light for a diffusion length `ell_m` and a pixel footprint
/// `footprint_m` (`direct_share` in display.wgsl): `clamp(1 − ℓ/footprint, 0, 1)`.
pub fn direct_share(ell_m: f32, footprint_m: f32) -> f32 {
    (1.0 - ell_m / footprint_m.max(1e-12)).clamp(0.0, 1.0)
}

/// The surface point a pixel sees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PixelSurface {
    /// World position (m).
    pub position: Vec3,
    /// Interpolated normal (normalised here).
    pub normal: Vec3,
    /// Lightmap UV.
    pub uv: [f32; 2],
    /// The larger side of the pixel's footprint on the surface (m).
    pub footprint_m: f32,
}

/// The maps the per-pixel direct light reads (all of the lightmap's size, dilated).
#[derive(Clone, Copy, Debug)]
pub struct PixelMaps<'a> {
    /// RGB albedo, alpha diffusion length (m) ([`crate::display::surface_texels`]).
    pub surface: &'a TexelImage,
    /// First-order lightmap (read where the diffusion length is > 0).
    pub first_order: &'a TexelImage,
    /// The lightmap added: the transferred light `T = final − first order`, or with
    /// `subsurface` the final light `B`; `None`: direct light only.
    pub lightmap: Option<&'a TexelImage>,
    /// The scene has subsurface texels (the `SUBSURFACE` pipelines): `lightmap` is `B`.
    pub subsurface: bool,
    /// Lightmap filter.
    pub sampling: LightmapSampling,
}

/// Radiance (W/(m²·sr)) a pixel shows with per-pixel direct light (`fs_direct_*` in
/// display.wgsl, without specular): `w·ρ·E/π + (1 − w)·B_o/π + T/π`, with `E` the irradiance
/// of `lights` at the pixel's surface point scaled by `visibility(light index)` (1 lit, 0
/// shadowed), ρ bilinear from the surface map, `w` = [`direct_share`] (1 without the
/// lightmap: the direct-only view; 1 without `subsurface`), computed as the shader does:
/// `ρ·E/π + T/π` without `subsurface`, `w·ρ·E/π + (B − w·B_o)/π` with it.
pub fn pixel_radiance(
    lights: &[GpuLight],
    px: &PixelSurface,
    maps: &PixelMaps<'_>,
    visibility: impl Fn(usize) -> f32,
) -> Vec3 {
    let pi = std::f32::consts::PI;
    let n = px.normal.normalize();
    let s = bilinear_rgba(maps.surface, px.uv);
    // The direct-only view is the unscattered first order: per pixel everywhere.
    let w = if maps.lightmap.is_some() && maps.subsurface {
        direct_share(s[3], px.footprint_m)
    } else {
        1.0
    };
    let mut e = Vec3::ZERO;
    for (i, l) in lights.iter().enumerate() {
        let (to_light, e_n) = light_incident(l, px.position);
        let cos_i = n.dot(to_light);
        if cos_i > 0.0 && e_n.max_element() > 0.0 {
            e += e_n * cos_i * visibility(i);
        }
    }
    let mut out = Vec3::new(s[0], s[1], s[2]) * e * (w / pi);
    if let Some(map) = maps.lightmap {
        let added = Vec3::from(lookup(map, px.uv, maps.sampling));
        out += if maps.subsurface {
            (added - w * Vec3::from(lookup(maps.first_order, px.uv, maps.sampling))) / pi
        } else {
            added / pi
        };
    }
    out
}

/// Bilinear lookup between texel centres with clamping (`bilinear` in display.wgsl; the
/// hardware path `filtered` samples `(u, 1 − v)` with a clamp-to-edge linear sampler, the
/// same function up to the sampler's weight precision).
pub fn bilinear(map: &TexelImage, uv: [f32; 2]) -> [f32; 3] {
    let v = bilinear_rgba(map, uv);
    [v[0], v[1], v[2]]
}

/// Normalised Blinn-Phong specular radiance `k_s·(s+8)/(8π)·(n·h)^s·E` summed over lights
/// (unshadowed), in W/(m²·sr).
pub fn specular(lights: &[GpuLight], p: Vec3, n: Vec3, eye: Vec3, ks: f32, shininess: f32) -> Vec3 {
    let to_eye = (eye - p).normalize();
    let mut out = Vec3::ZERO;
    for l in lights {
        let (to_light, e) = light_incident(l, p);
        let cos_i = n.dot(to_light);
        if cos_i > 0.0 {
            let h = (to_light + to_eye).normalize();
            let lobe = ks * (shininess + 8.0) / (8.0 * std::f32::consts::PI)
                * n.dot(h).max(0.0).powf(shininess);
            out += e * cos_i * lobe;
        }
    }
    out
}

/// Linear → sRGB transfer function as the display shader computes it: the linear segment
/// exactly, above it a minimax fit of `1.055·c^(1/2.4) − 0.055` in `c^(1/2)`, `c^(1/4)`,
/// `c^(1/8)` and `c` (three square roots instead of `pow`; fitted in f64 on
/// `[0.0031308, 1]`), within 0.012/255 of [`srgb_encode_exact`] on `[0, 1]`.
pub fn srgb_encode(c: f32) -> f32 {
    if c <= 0.003_130_8 {
        c * 12.92
    } else {
        let s1 = c.sqrt();
        let s2 = s1.sqrt();
        let s3 = s2.sqrt();
        0.642_383_3 * s1 + 0.712_090_1 * s2 - 0.336_861_5 * s3 - 0.017_568_972 * c
    }
}

/// Linear → sRGB transfer function (IEC 61966-2-1), evaluated with `powf` in f64.
pub fn srgb_encode_exact(c: f32) -> f32 {
    let c = c as f64;
    (if c <= 0.003_130_8 {
        c * 12.92
    } else {
        1.055 * c.powf(1.0 / 2.4) - 0.055
    }) as f32
}

/// Display value of a radiance (W/(m²·sr)): exposure, Reinhard, sRGB, 8 bits.
pub fn tonemap(radiance: [f32; 3], exposure: f32) -> [u8; 4] {
    let mut out = [255u8; 4];
    for c in 0..3 {
        let l = (radiance[c] * exposure).max(0.0);
        out[c] = (srgb_encode(l / (1.0 + l)) * 255.0).round() as u8;
    }
    out
}

/// Display value of a lightmap radiosity `B` (W/m²) without specular: `tonemap(B/π)`.
pub fn shade(b: [f32; 3], exposure: f32) -> [u8; 4] {
    let pi = std::f32::consts::PI;
    tonemap([b[0] / pi, b[1] / pi, b[2] / pi], exposure)
}

#[cfg(test)]
mod tests {
    use super::{srgb_encode, srgb_encode_exact};

    /// The fitted encoding stays within 0.012/255 of the IEC formula everywhere on [0, 1]
    /// (4,000,001 evenly spaced values), so the 8-bit value differs by at most one and only
    /// where the exact value lies within 0.012 of a rounding boundary.
    #[test]
    fn fitted_srgb_encode_matches_iec_formula() {
        let n = 4_000_000u32;
        let (mut worst, mut flips) = (0f64, 0u32);
        for i in 0..=n {
            let c = i as f32 / n as f32;
            let (fit, exact) = (srgb_encode(c) as f64, srgb_encode_exact(c) as f64);
            worst = worst.max((fit - exact).abs() * 255.0);
            let byte = |v: f64| (v.clamp(0.0, 1.0) * 255.0).round();
            let diff = (byte(fit) - byte(exact)).abs();
            assert!(diff <= 1.0, "c = {c}: {fit} vs {exact}");
            flips += u32::from(diff > 0.0);
        }
        assert!(worst < 0.012, "worst |Δ| {worst}/255");
        // A rounding flip needs the exact value within `worst` of a boundary (k + 0.5)/255, so
        // at most a fraction 2·worst of the bytes can flip; the fit's error is mostly well below
        // its worst, and 29,403 of 4,000,001 (0.735 %) flip, as docs/render.md says. Bound: that
        // count + 25 %.
        assert!(
            (flips as f64) < 0.0092 * n as f64,
            "{flips} of {n} bytes differ (docs/render.md: 29,403)"
        );
        eprintln!("fitted sRGB: worst |Δ| {worst:.4}/255, {flips} of {n} bytes off by one");
        // Endpoints and the junction with the linear segment.
        assert_eq!(srgb_encode(0.0), 0.0);
        assert!((srgb_encode(1.0) - 1.0).abs() < 0.012 / 255.0);
        assert!((srgb_encode(0.003_130_9) - 0.003_130_8 * 12.92).abs() < 0.012 / 255.0);
    }
}
