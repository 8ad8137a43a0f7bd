//! First-order lighting on the CPU: irradiance `E` (W/m²) from point, spot and directional
//! lights at every covered texel, with ray-cast shadows, and the first-order lightmap
//! `B_o = ρ·E` (W/m²).
//!
//! This is the reference the GPU first-order pass is checked against, and the input of the
//! exact solve. Light models (all linear RGB, `color` multiplies the power quantity):
//! - point: `E = I·cosθ / d²` (I in W/sr);
//! - spot: as point, times `smoothstep(cos θ_outer, cos θ_inner, cos ψ)` with ψ the angle from the
//!   spot axis;
//! - directional: `E = E⊥·cosθ` (E⊥ in W/m²).
//!
//! `cosθ` uses the texel's shading normal; shadow rays start from the texel lifted by 0.1% of
//! its size along the face normal.

use glam::Vec3;
use rayon::prelude::*;

use crate::Lightmap;
use crate::bake::raycast::Visibility;
use crate::bake::texels::{Texel, TexelGrid};
use crate::scene::Light;

/// Distance used for the shadow rays of directional lights, metres.
const FAR_M: f32 = 1.0e4;

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    if e1 <= e0 {
        return if x >= e1 { 1.0 } else { 0.0 };
    }
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Irradiance (W/m², RGB) at texel `t` from `light`, unshadowed.
pub fn irradiance_unshadowed(t: &Texel, light: &Light) -> Vec3 {
    irradiance_unshadowed_at(t.position_m, t.normal, light)
}

/// Irradiance (W/m², RGB) from `light`, unshadowed, at a surface point `position_m` (metres)
/// with unit shading normal `normal` (the light models of the module docs).
pub fn irradiance_unshadowed_at(position_m: Vec3, normal: Vec3, light: &Light) -> Vec3 {
    match *light {
        Light::Point {
            position_m: light_m,
            color,
            intensity_w_sr,
        } => {
            let d = light_m - position_m;
            let r2 = d.length_squared();
            let cos = normal.dot(d) / r2.sqrt();
            if cos <= 0.0 || r2 <= 0.0 {
                return Vec3::ZERO;
            }
            color * intensity_w_sr * cos / r2
        }
        Light::Spot {
            position_m: light_m,
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
        } => {
            let d = light_m - position_m;
            let r2 = d.length_squared();
            let r = r2.sqrt();
            let cos = normal.dot(d) / r;
            if cos <= 0.0 || r2 <= 0.0 {
                return Vec3::ZERO;
            }
            let cos_psi = (-d / r).dot(direction.normalize());
            let cone = smoothstep(
                outer_deg.to_radians().cos(),
                inner_deg.to_radians().cos(),
                cos_psi,
            );
            color * intensity_w_sr * cone * cos / r2
        }
        Light::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => {
            let cos = normal.dot(-direction.normalize());
            if cos <= 0.0 {
                return Vec3::ZERO;
            }
            color * irradiance_w_m2 * cos
        }
    }
}

/// How far a ray leaving a texel of area `area_m2` (m²) starts off its surface, metres: 10⁻³
/// of the texel's size (at least 10⁻⁹ m), so that the texel does not occlude itself.
pub fn lift_m(area_m2: f32) -> f32 {
    1e-3 * area_m2.sqrt().max(1e-6)
}

/// True when `light` reaches texel `t` unobstructed.
pub fn light_visible(t: &Texel, light: &Light, vis: &Visibility) -> bool {
    let eps = lift_m(t.area_m2);
    light_visible_from(t.position_m + t.face_normal * eps, eps, light, vis)
}

/// True when `light` reaches the point `lifted_m` (a surface point already lifted off its
/// surface by `eps_m` metres) unobstructed; `eps_m` also shortens the shadow ray at both ends.
pub fn light_visible_from(lifted_m: Vec3, eps_m: f32, light: &Light, vis: &Visibility) -> bool {
    let p = lifted_m;
    match *light {
        Light::Point { position_m, .. } | Light::Spot { position_m, .. } => {
            vis.visible(p, position_m, eps_m)
        }
        Light::Directional { direction, .. } => {
            vis.visible(p, p - direction.normalize() * FAR_M, eps_m)
        }
    }
}

/// Direct irradiance (W/m², RGB) at a surface point from all `lights`, with shadows: the
/// unshadowed irradiance at `position_m` (metres) with unit shading normal `normal`
/// ([`irradiance_unshadowed_at`]) of every light that reaches `lifted_m`, the point lifted off
/// its surface by `eps_m` metres ([`light_visible_from`]). Also returns the number of shadow
/// rays cast (one per light that would light the point unshadowed).
pub fn direct_at(
    position_m: Vec3,
    normal: Vec3,
    (lifted_m, eps_m): (Vec3, f32),
    lights: &[Light],
    vis: &Visibility,
) -> (Vec3, u64) {
    let mut e = Vec3::ZERO;
    let mut rays = 0;
    for l in lights {
        let el = irradiance_unshadowed_at(position_m, normal, l);
        if el == Vec3::ZERO {
            continue;
        }
        rays += 1;
        if light_visible_from(lifted_m, eps_m, l, vis) {
            e += el;
        }
    }
    (e, rays)
}

/// Irradiance (W/m², RGB) at every covered texel from all `lights`, with shadows.
pub fn irradiance(grid: &TexelGrid, lights: &[Light], vis: &Visibility) -> Vec<Vec3> {
    grid.texels
        .par_iter()
        .map(|t| {
            let eps = lift_m(t.area_m2);
            let lifted = t.position_m + t.face_normal * eps;
            direct_at(t.position_m, t.normal, (lifted, eps), lights, vis).0
        })
        .collect()
}

/// First-order radiosity `B_o = ρ·E` (W/m²) per covered texel.
pub fn first_order(grid: &TexelGrid, lights: &[Light], vis: &Visibility) -> Vec<Vec3> {
    irradiance(grid, lights, vis)
        .into_iter()
        .zip(&grid.texels)
        .map(|(e, t)| e * t.albedo)
        .collect()
}

/// The first-order light of every texel of `grid` averaged over its square: `grid`'s scene
/// rasterised at `n ×` its size (`n` odd, so the centre of each texel's square is a sub-texel
/// centre and every covered texel has a covered sub-texel), lit there ([`first_order`]), and
/// each texel's covered sub-texels averaged by their area. W/m², in `grid`'s texel order
/// (`grid` rasterised from `scene`). `n = 1` is [`first_order`].
///
/// # Panics
/// When `n` is even.
pub fn first_order_averaged(
    scene: &crate::scene::Scene,
    grid: &TexelGrid,
    lights: &[Light],
    vis: &Visibility,
    n: u32,
) -> Result<Vec<Vec3>, crate::bake::texels::TexelError> {
    assert!(!n.is_multiple_of(2), "first_order_averaged: n must be odd");
    if n == 1 {
        return Ok(first_order(grid, lights, vis));
    }
    let fine = TexelGrid::build_with_size(scene, grid.width * n, grid.height * n)?;
    let b = first_order(&fine, lights, vis);
    let mut sum = vec![(Vec3::ZERO, 0.0f64); grid.width as usize * grid.height as usize];
    for (t, v) in fine.texels.iter().zip(&b) {
        let slot = (t.y / n) as usize * grid.width as usize + (t.x / n) as usize;
        let a = t.area_m2 as f64;
        sum[slot].0 += *v * a as f32;
        sum[slot].1 += a;
    }
    Ok(grid
        .texels
        .iter()
        .map(|t| {
            let (v, a) = sum[t.y as usize * grid.width as usize + t.x as usize];
            if a > 0.0 { v / a as f32 } else { Vec3::ZERO }
        })
        .collect())
}

/// Sub-texels per texel side of the transfer's input by default (`ortm solve`, `ortm render`,
/// the viewer's exact reference): against the path-traced reference 3×3 is as good as or
/// better than the centres on every scene measured, and 5×5 or 7×7 add nothing (README,
/// "The transfer's input").
pub const DEFAULT_FIRST_ORDER_SAMPLES: u32 = 3;

/// Sub-texels (`N²·W·H`) the default averaged input may rasterise on the CPU
/// ([`first_order_averaged`] holds the whole sub-texel grid, ~100 bytes each): 4 Mi, so
/// lightmaps up to 682² at `N = 3`.
pub const DEFAULT_SAMPLES_CPU_BUDGET: u64 = 1 << 22;

/// Sub-texels the default averaged input may rasterise on the GPU (its G-buffer: two RGBA32F
/// maps, 32 bytes each): 16 Mi, 512 MiB, so lightmaps up to 1365² at `N = 3`.
pub const DEFAULT_SAMPLES_GPU_BUDGET: u64 = 1 << 24;

/// The sub-texels per side a tool takes when none is asked for: [`DEFAULT_FIRST_ORDER_SAMPLES`]
/// where its `N²·W·H` sub-texels fit `budget` and its `N·W × N·H` grid fits `max_side`, else
/// 1 (the centres).
pub fn default_first_order_samples(width: u32, height: u32, budget: u64, max_side: u32) -> u32 {
    let n = DEFAULT_FIRST_ORDER_SAMPLES;
    let fits = (n as u64).pow(2) * width as u64 * height as u64 <= budget
        && (n as u64) * (width.max(height) as u64) <= max_side as u64;
    if fits { n } else { 1 }
}

/// The two first orders of a render with `n` sub-texels per side (odd; the GPU's
/// `FirstOrderOptions::samples`): `(first order, transfer input)` per texel. The input is
/// [`first_order_averaged`]; the first order the lightmap holds is the centre's
/// ([`first_order`], what `ortm reference` defines) on opaque texels and the input on those
/// `translucent(material)` names (their transfer holds `−B_in` at the texel itself, so their
/// final is the scattered input). The final is then `first + (apply(maps, input) − input)`
/// ([`with_first_order`]). `n = 1`: both are the centres' first order.
pub fn first_order_and_input(
    scene: &crate::scene::Scene,
    grid: &TexelGrid,
    lights: &[Light],
    vis: &Visibility,
    n: u32,
    translucent: impl Fn(u32) -> bool,
) -> Result<(Vec<Vec3>, Vec<Vec3>), crate::bake::texels::TexelError> {
    let centre = first_order(grid, lights, vis);
    if n == 1 {
        return Ok((centre.clone(), centre));
    }
    let input = first_order_averaged(scene, grid, lights, vis, n)?;
    let first = (centre.into_iter().zip(&input).zip(&grid.texels))
        .map(|((c, &i), t)| if translucent(t.material) { i } else { c })
        .collect();
    Ok((first, input))
}

/// `final + (first − input)` per texel: the final of a transfer applied to `input`
/// (`input + Σ R·input`) turned into one that starts from `first` instead
/// ([`first_order_and_input`]).
pub fn with_first_order(final_b: &mut [Vec3], first: &[Vec3], input: &[Vec3]) {
    for ((b, f), i) in final_b.iter_mut().zip(first).zip(input) {
        *b += *f - *i;
    }
}

/// Scatters per-texel values into a lightmap (uncovered texels 0).
pub fn to_lightmap(grid: &TexelGrid, values: &[Vec3]) -> Lightmap {
    let mut m = Lightmap::new(grid.width, grid.height);
    for (t, v) in grid.texels.iter().zip(values) {
        m.set(t.x, t.y, v.to_array());
    }
    m
}

/// Gathers per-texel values from a lightmap.
pub fn from_lightmap(grid: &TexelGrid, map: &Lightmap) -> Vec<Vec3> {
    grid.texels
        .iter()
        .map(|t| Vec3::from_array(map.get(t.x, t.y)))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn lum(v: Vec3) -> f32 {
        v.x + v.y + v.z
    }

    /// The summed channels of `values` at the covered 4-neighbours of `t`.
    fn neighbours(grid: &TexelGrid, t: &Texel, values: &[Vec3]) -> Vec<f32> {
        [(-1, 0), (1, 0), (0, -1), (0, 1)]
            .iter()
            .filter_map(|(dx, dy)| grid.at(t.x as i32 + dx, t.y as i32 + dy))
            .map(|j| lum(values[j as usize]))
            .collect()
    }

    #[test]
    fn the_default_averages_where_the_sub_texels_fit() {
        let (cpu, gpu) = (DEFAULT_SAMPLES_CPU_BUDGET, DEFAULT_SAMPLES_GPU_BUDGET);
        assert_eq!(default_first_order_samples(256, 256, cpu, u32::MAX), 3);
        assert_eq!(default_first_order_samples(682, 682, cpu, u32::MAX), 3);
        assert_eq!(default_first_order_samples(683, 683, cpu, u32::MAX), 1);
        assert_eq!(default_first_order_samples(1024, 1024, gpu, 8192), 3);
        assert_eq!(default_first_order_samples(1366, 1366, gpu, 8192), 1);
        // The device's texture side: 3 × 1024 > 2048.
        assert_eq!(default_first_order_samples(1024, 64, gpu, 2048), 1);
    }

    /// The Cornell box at 32² with its lamp: centre values, and the averages over 3×3
    /// sub-texels.
    fn cornell() -> (TexelGrid, Vec<Vec3>, Vec<Vec3>) {
        let scene = crate::scene::cornell::cornell_box(32);
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = Visibility::new(&scene.mesh);
        let centre = first_order(&grid, &scene.lights, &vis);
        assert_eq!(
            first_order_averaged(&scene, &grid, &scene.lights, &vis, 1).unwrap(),
            centre,
            "n = 1 is the centres' first order"
        );
        let avg = first_order_averaged(&scene, &grid, &scene.lights, &vis, 3).unwrap();
        (grid, centre, avg)
    }

    /// Where the light is smooth (the texel and its four neighbours lit, within 2× of each
    /// other) the average over the square is the centre's value to second order: within 3 %
    /// (the lamp's `cos/d²` over a 3 cm texel).
    #[test]
    fn averaged_first_order_is_the_centre_value_where_the_light_is_smooth() {
        let (grid, centre, avg) = cornell();
        let (mut smooth, mut worst) = (0, 0.0f32);
        for (i, t) in grid.texels.iter().enumerate() {
            let c = lum(centre[i]);
            let n = neighbours(&grid, t, &centre);
            if c <= 0.0 || n.len() < 4 || n.iter().any(|&v| v < 0.5 * c || v > 2.0 * c) {
                continue;
            }
            smooth += 1;
            let rel = (lum(avg[i]) - c).abs() / c;
            worst = worst.max(rel);
            assert!(
                rel < 0.03,
                "texel ({}, {}): {rel:.4} off its centre",
                t.x,
                t.y
            );
        }
        println!(
            "{smooth} smooth texels of {}, worst {worst:.4}",
            grid.texels.len()
        );
        assert!(smooth >= 50, "{smooth} smooth texels");
    }

    /// Beside a point light the centre's value misses the light's near field: the irradiance
    /// integrated over a plane square is `I·Ω`, `Ω` the solid angle the square subtends from
    /// the light (closed form for a rectangle). The Cornell ceiling texel nearest the lamp:
    /// the average over 7×7 sub-texels is within 1 % of `I·Ω/A`, the centre's value far off.
    #[test]
    fn averaged_first_order_beside_a_point_light_is_the_solid_angle() {
        let scene = crate::scene::cornell::cornell_box(32);
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = Visibility::new(&scene.mesh);
        let Light::Point {
            position_m: lamp,
            color,
            intensity_w_sr,
        } = scene.lights[0]
        else {
            panic!("the Cornell box's light is a point light");
        };
        let (i, t) = (grid.texels.iter().enumerate())
            .filter(|(_, t)| t.normal.dot(lamp - t.position_m) > 0.0)
            .min_by(|a, b| {
                let d = |t: &Texel| (t.position_m - lamp).length();
                d(a.1).total_cmp(&d(b.1))
            })
            .unwrap();
        let [f0, f1] = t.footprint_m;
        let (u, v) = (f0.normalize(), f1.normalize());
        assert!(u.dot(v).abs() < 1e-5 && u.cross(v).dot(t.normal).abs() > 0.99999);
        // The light at height h above the plane; the square [x0, x1] × [y0, y1] about its foot.
        let h = (lamp - t.position_m).dot(t.normal) as f64;
        let rel = t.position_m - lamp;
        let (xc, yc) = (rel.dot(u) as f64, rel.dot(v) as f64);
        let (hx, hy) = (0.5 * f0.length() as f64, 0.5 * f1.length() as f64);
        let f = |x: f64, y: f64| (x * y / (h * (x * x + y * y + h * h).sqrt())).atan();
        let omega =
            f(xc + hx, yc + hy) - f(xc - hx, yc + hy) - f(xc + hx, yc - hy) + f(xc - hx, yc - hy);
        let exact = intensity_w_sr as f64 * omega / (4.0 * hx * hy);
        let e = |b: Vec3| (b / (t.albedo * color)).x as f64;
        let centre = e(first_order(&grid, &scene.lights, &vis)[i]);
        let avg = e(first_order_averaged(&scene, &grid, &scene.lights, &vis, 7).unwrap()[i]);
        println!(
            "texel ({}, {}), lamp {h:.4} m above: E over the square {exact:.2} W/m², 7×7 \
             average {avg:.2}, centre {centre:.2}",
            t.x, t.y
        );
        assert!((avg / exact - 1.0).abs() < 0.01, "{avg} vs {exact}");
        assert!((centre / exact - 1.0).abs() > 0.05, "{centre} vs {exact}");
    }

    /// At the blocks' shadow edges a texel whose centre is dark but whose square is partly lit
    /// gets part of its lit neighbours' light (at most its brightest neighbour's), and one whose
    /// centre is lit but whose square is partly in shadow loses some: both occur in the Cornell
    /// box at 32².
    #[test]
    fn averaged_first_order_sees_shadow_edges_within_a_texel() {
        let (grid, centre, avg) = cornell();
        let (mut lit_in_dark, mut dark_in_lit) = (0, 0);
        for (i, t) in grid.texels.iter().enumerate() {
            let c = lum(centre[i]);
            let a = lum(avg[i]);
            let n = neighbours(&grid, t, &centre);
            let hi = n.iter().copied().fold(c, f32::max);
            if c == 0.0 && n.iter().any(|&v| v > 0.0) {
                // No light from nowhere: a dark centre's square holds at most its brightest
                // neighbour's light.
                assert!(a <= 1.1 * hi, "texel ({}, {}): {a} > {hi}", t.x, t.y);
                if a > 0.05 * hi {
                    lit_in_dark += 1;
                }
            }
            if c > 0.0 && n.contains(&0.0) && a < 0.9 * c {
                dark_in_lit += 1;
            }
        }
        println!(
            "{lit_in_dark} dark centres with light in their square, {dark_in_lit} lit ones with shadow"
        );
        assert!(
            lit_in_dark > 0 && dark_in_lit > 0,
            "{lit_in_dark} / {dark_in_lit}"
        );
    }
}
