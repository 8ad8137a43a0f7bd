//! The path estimator of the reference: one sample of a texel's final radiosity `B(x)`.
//!
//! Continuous model (the transport's, [`crate::bake::transport`], without its discretisation):
//! - opaque diffuse point: `B(x) = ρ(x)·E(x)`;
//! - translucent point (subsurface on): `B(x) = ∫ R_d(|x − y|) E(y) dA(y)` over the surface of
//!   the same material ([`super::subsurface`] samples `y`);
//! - `E(x) = E_direct(x) + ∫ L_in cosθ dω` with `L_in = B(z)/π` from the first surface `z` hit
//!   along the direction, 0 when `z` faces away (its shading normal), as the form factor's
//!   cosine clamp does.
//!
//! A path alternates exitance steps (multiply by ρ, or move to a sampled `y` and multiply by
//! the profile weight) and irradiance steps (add the direct light `E_direct` by next-event
//! estimation to every light, the models and lifted shadow rays of [`crate::bake::lighting`];
//! then one cosine-sampled bounce, whose estimate of `∫ L cosθ dω` is `π·L = B(z)`). When the
//! first order is sampled as a light ([`super::emitters`]), the bounce's integral is split as
//! `∫ B_o(z)/π cosθ dω + ∫ (B(z) − B_o(z))/π cosθ dω` for opaque `z` (`B_o = ρ·E_direct`, the
//! exitance step's direct term): the first part gets two samples, one from a point drawn by the
//! light and one from the bounce, weighted by the balance heuristic
//! `w = p_technique / (p_cos + p_light)` in solid angle (`p_cos = cosθ/π`,
//! `p_light = p_A·d²/|cos θ_z|`); the rest comes from the bounce as before. A translucent
//! `z` takes the same split with `B_o(z) = ρ̄·E_direct(z)`: its exit step estimates all of
//! `B(z)`, so the bounce subtracts the light sample's share `(1 − w)·B_o(z)` there (one more
//! set of shadow rays at `z`; the sample can be negative, the estimate stays unbiased). Russian
//! roulette after [`ROULETTE_AFTER`] bounces, once the throughput is below [`ROULETTE_WEIGHT`],
//! keeps it unbiased. Positions in metres, `B` and
//! `E` in W/m², linear RGB.

use glam::Vec3;

use super::emitters::FirstOrderLight;
use super::sampler::{PathSampler, Slot};
use super::subsurface::{ProfileSampler, WeighedHit};
use crate::bake::lighting::{direct_at, lift_m};
use crate::bake::raycast::{RayHit, Visibility};
use crate::bake::texels::Texel;
use crate::bake::transport::Effects;
use crate::bake::transport::form_factor::tangent_frame;
use crate::scene::subsurface::Profile;
use crate::scene::{Light, Scene, SurfaceAlbedo};

/// Bounces before Russian roulette starts.
pub const ROULETTE_AFTER: u32 = 3;

/// Russian roulette plays only once the path's throughput (largest channel) falls below this
/// weight, and a survivor's throughput is raised back to it: paths keep their bounces while
/// they carry much light, which keeps the variance of bright, high-albedo scenes low (on the
/// closed sphere of albedo 0.8, a roulette that plays at every bounce had 5× the standard
/// error).
pub const ROULETTE_WEIGHT: f32 = 0.25;

/// A safety stop for scenes whose albedo is 1 (the light they trap never decays): the light
/// beyond it is below `ρ^MAX_BOUNCES` of the total.
pub const MAX_BOUNCES: u32 = 10_000;

/// Longest bounce ray, metres.
const FAR_M: f32 = 1.0e4;

/// A point on the scene's surface where a path stops.
#[derive(Clone, Copy, Debug)]
pub struct SurfacePoint {
    /// Position, metres.
    pub position_m: Vec3,
    /// Unit shading normal (cosines).
    pub normal: Vec3,
    /// Unit geometric normal (lifts rays off the surface).
    pub face_normal: Vec3,
    /// Lift of rays leaving the point, metres.
    pub eps_m: f32,
    /// Effective albedo ρ̄ (material albedo or texture at the UV; a profile's total diffuse
    /// reflectance for translucent materials), as the texels carry it.
    pub albedo: Vec3,
    /// Material index.
    pub material: u32,
    /// Triangle index.
    pub triangle: u32,
}

impl SurfacePoint {
    /// A texel's surface point: its centre, normals and the first order's lift.
    pub fn of_texel(t: &Texel) -> Self {
        Self {
            position_m: t.position_m,
            normal: t.normal,
            face_normal: t.face_normal,
            eps_m: lift_m(t.area_m2),
            albedo: t.albedo,
            material: t.material,
            triangle: t.triangle,
        }
    }
}

/// The scene as the path estimator sees it.
pub struct SceneView<'a> {
    scene: &'a Scene,
    vis: &'a Visibility,
    lights: &'a [Light],
    effects: Effects,
    /// Per material: the profile sampler when the material is translucent and subsurface is on.
    samplers: Vec<Option<ProfileSampler>>,
    /// The albedo of a hit point, the texels' rule (translucent materials: the profile's total
    /// diffuse reflectance, whatever the effects).
    albedo: SurfaceAlbedo<'a>,
    /// Lift of rays leaving a hit point, metres (10⁻⁵ of the scene's bounding radius).
    hit_eps_m: f32,
    /// The first order as a light, sampled at the first [`SceneView::light_vertices`] path
    /// vertices (none: cosine-sampled bounces only).
    light: Option<FirstOrderLight>,
    /// Path vertices (irradiance steps, from the first) that sample [`SceneView::light`].
    light_vertices: u32,
}

/// Counters and scratch space of one worker.
#[derive(Default)]
pub struct Scratch {
    /// Rays cast.
    pub rays: u64,
    /// Probe hits and their weights.
    hits: Vec<WeighedHit>,
}

impl<'a> SceneView<'a> {
    /// The view of `scene` lit by `lights`, with `effects`.
    pub fn new(
        scene: &'a Scene,
        vis: &'a Visibility,
        lights: &'a [Light],
        effects: Effects,
    ) -> Self {
        let profiles: Vec<Option<Profile>> = scene
            .materials
            .iter()
            .map(|m| m.subsurface.as_ref().map(Profile::new))
            .collect();
        let radius = scene.mesh.bounding_sphere().map_or(1.0, |(_, r)| r);
        Self {
            scene,
            vis,
            lights,
            effects,
            samplers: profiles
                .iter()
                .map(|p| p.filter(|_| effects.subsurface).map(ProfileSampler::new))
                .collect(),
            albedo: scene.surface_albedo(),
            hit_eps_m: (1e-5 * radius).max(1e-7),
            light: None,
            light_vertices: 0,
        }
    }

    /// Samples the first order as a light (module `emitters`) at the first `vertices`
    /// irradiance steps of every path, combined with the cosine-sampled bounce by the balance
    /// heuristic; `vertices = 0` keeps cosine-sampled bounces only.
    pub fn with_first_order_light(mut self, vertices: u32) -> Self {
        self.light = None;
        self.light_vertices = 0;
        if vertices > 0 && self.effects.radiosity {
            self.light = FirstOrderLight::build(&self);
            self.light_vertices = vertices;
        }
        self
    }

    /// The scene.
    pub fn scene(&self) -> &Scene {
        self.scene
    }

    /// True when paths through material `m` scatter under the surface.
    pub fn translucent(&self, m: u32) -> bool {
        self.samplers.get(m as usize).is_some_and(Option::is_some)
    }

    /// Whether any path can go beyond the first order.
    pub fn traces_anything(&self) -> bool {
        self.effects.radiosity || self.samplers.iter().any(Option::is_some)
    }

    /// One sample of the final radiosity `B(x)` at texel point `x` whose exact first order is
    /// `b_o`.
    pub fn sample(
        &self,
        x: &SurfacePoint,
        b_o: Vec3,
        rng: &mut PathSampler,
        s: &mut Scratch,
    ) -> Vec3 {
        if self.translucent(x.material) {
            self.path(*x, Vec3::ONE, false, rng, s)
        } else {
            b_o + self.path(*x, x.albedo, true, rng, s)
        }
    }

    /// Σ over the path of throughput × direct irradiance, starting at `p` with throughput `t`;
    /// `at_irradiance` skips the first exitance step and its direct light (the exact first
    /// order of an opaque texel).
    fn path(
        &self,
        mut p: SurfacePoint,
        mut t: Vec3,
        mut at_irradiance: bool,
        rng: &mut PathSampler,
        s: &mut Scratch,
    ) -> Vec3 {
        let mut sum = Vec3::ZERO;
        let mut bounce = 0u32;
        // MIS weight of the first order reached by the last bounce (1: no light sampled there).
        let mut emitted_weight = 1.0f32;
        loop {
            let q = if at_irradiance {
                p
            } else {
                let (q, weight) = match &self.samplers[p.material as usize] {
                    Some(sampler) => {
                        if emitted_weight < 1.0 {
                            // Reached by a bounce that shares `B_o(p) = ρ̄·E_direct(p)` with the
                            // light sample: the exit step estimates all of `B(p)`, so the part
                            // of `B_o(p)` the light sample carries, `1 − w`, comes off here.
                            sum -= t * (1.0 - emitted_weight) * p.albedo * self.direct(&p, s);
                        }
                        rng.at(bounce, Slot::Exit);
                        let Some(y) = self.exit_point(sampler, &p, rng, s) else {
                            break;
                        };
                        t *= y.1;
                        (y.0, 1.0)
                    }
                    None => {
                        t *= p.albedo;
                        (p, emitted_weight)
                    }
                };
                if weight > 0.0 {
                    sum += t * weight * self.direct(&q, s);
                }
                q
            };
            at_irradiance = false;
            if !self.effects.radiosity || t.max_element() <= 0.0 {
                break;
            }
            if bounce >= MAX_BOUNCES {
                break;
            }
            let light = self.light.as_ref().filter(|_| bounce < self.light_vertices);
            if let Some(light) = light {
                rng.at(bounce, Slot::Light);
                sum += t * self.first_order_light(light, &q, rng, s);
            }
            if bounce >= ROULETTE_AFTER && t.max_element() < ROULETTE_WEIGHT {
                let survive = (t.max_element() / ROULETTE_WEIGHT).max(1e-3);
                rng.at(bounce, Slot::Roulette);
                if rng.uniform_f32() >= survive {
                    break;
                }
                t /= survive;
            }
            rng.at(bounce, Slot::Bounce);
            let Some((z, weight)) = self.bounce(&q, light, rng, s) else {
                break;
            };
            p = z;
            emitted_weight = weight;
            bounce += 1;
        }
        sum
    }

    /// The first order reaching `q` from a point drawn by `light` (one shadow ray to it, its
    /// first order exactly, `ρ·E_direct`), as a sample of `∫ B_o(z)/π cosθ dω`, weighted
    /// against the cosine-sampled bounce by the balance heuristic:
    /// `B_o(z)·cosθ / (cosθ + π·p_ω)`, `p_ω = p_A·d²/|cos θ_z|` the light's solid-angle density.
    /// 0 when the point is hidden, faces away from `q` or lies below `q`'s horizon. A
    /// translucent point's first order is `ρ̄·E_direct` too (its `B_o`, the transport's first
    /// order); the rest of its `B`, `∫ R_d E dA − ρ̄·E_direct`, comes from the bounce.
    fn first_order_light(
        &self,
        light: &FirstOrderLight,
        q: &SurfacePoint,
        rng: &mut PathSampler,
        s: &mut Scratch,
    ) -> Vec3 {
        let y = light.sample(rng);
        let mesh = &self.scene.mesh;
        let tri = &mesh.triangles[y.triangle as usize];
        let b = y.barycentrics;
        let pos: [Vec3; 3] = std::array::from_fn(|k| mesh.positions_m[tri.position[k] as usize]);
        let target = pos[0] * b[0] + pos[1] * b[1] + pos[2] * b[2];
        let origin = q.position_m + q.face_normal * q.eps_m;
        let Some(dir) = (target - origin).try_normalize() else {
            return Vec3::ZERO;
        };
        let cos_q = q.normal.dot(dir);
        if cos_q <= 0.0 {
            return Vec3::ZERO;
        }
        s.rays += 1;
        let Some(hit) = self
            .vis
            .closest_triangle_hit(origin, dir, (q.eps_m, FAR_M), q.triangle)
        else {
            return Vec3::ZERO;
        };
        if hit.triangle != y.triangle {
            return Vec3::ZERO;
        }
        let z = self.point_of_hit(&hit);
        if z.normal.dot(dir) >= 0.0 {
            return Vec3::ZERO;
        }
        let p_omega = self.solid_angle_density(light, &hit, &z, dir);
        if !p_omega.is_finite() || p_omega <= 0.0 {
            return Vec3::ZERO;
        }
        z.albedo * self.direct(&z, s) * (cos_q / (cos_q + std::f32::consts::PI * p_omega))
    }

    /// `light`'s density of the direction `dir` that reached `z` at `hit`, sr⁻¹.
    fn solid_angle_density(
        &self,
        light: &FirstOrderLight,
        hit: &RayHit,
        z: &SurfacePoint,
        dir: Vec3,
    ) -> f32 {
        let cos_z = z.face_normal.dot(dir).abs();
        if cos_z <= 0.0 {
            return f32::INFINITY;
        }
        light.pdf_area(hit) * hit.t * hit.t / cos_z
    }

    /// Direct irradiance `E_direct` (W/m²) at `p` from every light, with lifted shadow rays.
    pub fn direct(&self, p: &SurfacePoint, s: &mut Scratch) -> Vec3 {
        let lifted = p.position_m + p.face_normal * p.eps_m;
        let (e, rays) = direct_at(
            p.position_m,
            p.normal,
            (lifted, p.eps_m),
            self.lights,
            self.vis,
        );
        s.rays += rays;
        e
    }

    /// A cosine-sampled direction about `q`'s shading normal and the surface it reaches, if
    /// that surface faces `q`; with the balance-heuristic weight of the first order found
    /// there, `cosθ / (cosθ + π·p_ω)`, when `light` was sampled at `q` (else 1).
    fn bounce(
        &self,
        q: &SurfacePoint,
        light: Option<&FirstOrderLight>,
        rng: &mut PathSampler,
        s: &mut Scratch,
    ) -> Option<(SurfacePoint, f32)> {
        let (u1, u2): (f32, f32) = (rng.uniform_f32(), rng.uniform_f32());
        let (r, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
        let (t1, t2) = tangent_frame(q.normal);
        let z = (1.0 - u1).max(0.0).sqrt();
        let dir = (t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + q.normal * z).normalize();
        let origin = q.position_m + q.face_normal * q.eps_m;
        s.rays += 1;
        let hit = self
            .vis
            .closest_triangle_hit(origin, dir, (q.eps_m, FAR_M), q.triangle)?;
        let p = self.point_of_hit(&hit);
        if p.normal.dot(dir) >= 0.0 {
            return None;
        }
        let weight = match light {
            Some(light) => {
                let cos_q = q.normal.dot(dir).max(0.0);
                let p_omega = self.solid_angle_density(light, &hit, &p, dir);
                if p_omega.is_finite() {
                    cos_q / (cos_q + std::f32::consts::PI * p_omega)
                } else {
                    0.0
                }
            }
            _ => 1.0,
        };
        Some((p, weight))
    }

    /// The exit point `y` of a subsurface step at `p` and its weight `R_d / pdf`.
    fn exit_point(
        &self,
        sampler: &ProfileSampler,
        p: &SurfacePoint,
        rng: &mut PathSampler,
        s: &mut Scratch,
    ) -> Option<(SurfacePoint, Vec3)> {
        let mesh = &self.scene.mesh;
        let mut hits = std::mem::take(&mut s.hits);
        let exit = sampler.sample_exit(
            self.vis,
            p.position_m,
            p.normal,
            |tri| mesh.triangles[tri as usize].material == p.material,
            |tri| self.face_normal(tri),
            rng,
            &mut hits,
            &mut s.rays,
        );
        s.hits = hits;
        let exit = exit?;
        let mut y = self.point_of_hit(&exit.hit);
        y.position_m = exit.position_m;
        Some((y, exit.weight))
    }

    /// Unit geometric normal of triangle `tri` (as the texels compute it).
    fn face_normal(&self, tri: u32) -> Vec3 {
        let mesh = &self.scene.mesh;
        let t = &mesh.triangles[tri as usize];
        let p: [Vec3; 3] = std::array::from_fn(|k| mesh.positions_m[t.position[k] as usize]);
        (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero()
    }

    /// The surface point of a ray hit: interpolated position, shading normal and UV, the
    /// albedo as [`crate::bake::texels`] computes a texel's.
    pub fn point_of_hit(&self, hit: &RayHit) -> SurfacePoint {
        let at = self.scene.mesh.surface_at(hit.triangle, hit.barycentrics);
        let material = self.scene.mesh.triangles[hit.triangle as usize].material;
        let albedo = self.albedo.at(material, at.uv);
        SurfacePoint {
            position_m: at.position_m,
            normal: at.normal,
            face_normal: at.face_normal,
            eps_m: self.hit_eps_m,
            albedo,
            material,
            triangle: hit.triangle,
        }
    }
}
