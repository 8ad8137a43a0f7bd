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

/// True when `light` reaches texel `t` unobstructed.
pub fn light_visible(t: &Texel, light: &Light, vis: &Visibility) -> bool {
    let eps = 1e-3 * t.area_m2.sqrt().max(1e-6);
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

/// Irradiance (W/m², RGB) at every covered texel from all `lights`, with shadows.
pub fn irradiance(grid: &TexelGrid, lights: &[Light], vis: &Visibility) -> Vec<Vec3> {
    grid.texels
        .par_iter()
        .map(|t| {
            lights
                .iter()
                .map(|l| {
                    let e = irradiance_unshadowed(t, l);
                    if e == Vec3::ZERO || !light_visible(t, l, vis) {
                        Vec3::ZERO
                    } else {
                        e
                    }
                })
                .sum()
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
