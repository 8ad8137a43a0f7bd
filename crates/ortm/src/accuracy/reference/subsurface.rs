//! Importance sampling of a subsurface profile's exit (or entry) points: the BSSRDF probe
//! technique of King, Kulla, Conty and Fajardo (2013) and Christensen (2015).
//!
//! The translucent exitance `B(x) = ∫ R_d(|x − y|) E(y) dA(y)` (over the surface of `x`'s
//! material within the profile's support radius `R`) is estimated by one point `y` per sample:
//! 1. an axis: the shading normal at `x` (probability ½) or one of its two tangents (¼ each);
//! 2. a channel (⅓ each) and a radius `r ∈ [0, R]` with density `∝ R_d(r)·2πr` (the disk
//!    integral is closed-form, [`crate::scene::subsurface::ChannelProfile::disk_integral`], and
//!    is inverted by bisection), and an angle, uniform: a point on the disc through `x`
//!    orthogonal to the axis;
//! 3. a probe ray along the axis through that point, spanning the support sphere's chord; one
//!    of its hits on the same material, uniformly.
//!
//! The area density of `y` is the one-sample multiple-importance (balance heuristic) density
//! over the three axes and three channels, `Σ_a P_a Σ_c ⅓ p_c(r_a(y))·|n_y·a|`, with `r_a` the
//! distance from `x` to `y` projected on the plane orthogonal to `a`, `p_c(r) = R_d,c(r) / D_c`
//! the disc density (`D_c = ∫₀^R R_d,c 2πr dr`) and `n_y` the geometric normal; divided by the
//! number of hits of the probe ray that was traced (unbiased: the other axes' hit counts cancel
//! in the expectation). The estimate's weight is `R_d(|x − y|) / pdf(y)` per channel.
//! Distances in metres, `R_d` in m⁻², densities in m⁻².

use glam::Vec3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

use crate::bake::raycast::{RayHit, Visibility};
use crate::bake::transport::form_factor::tangent_frame;
use crate::scene::subsurface::Profile;

/// Probability of probing along the normal; each tangent gets half the rest.
const NORMAL_AXIS_PROBABILITY: f64 = 0.5;

/// One translucent material's profile, ready for sampling.
#[derive(Clone, Copy, Debug)]
pub struct ProfileSampler {
    /// The profile.
    pub profile: Profile,
    /// Support radius, metres (the Kernels' `support_radius(1e-4)`; `R_d = 0` beyond).
    pub support_m: f64,
    /// Per channel, `D_c = ∫₀^R R_d,c(r) 2πr dr`.
    norm: [f64; 3],
}

/// A sampled exit/entry point: the hit, and the per-channel weight `R_d(|x − y|) / pdf(y)`.
#[derive(Clone, Copy, Debug)]
pub struct ExitSample {
    /// The probe ray's hit chosen.
    pub hit: RayHit,
    /// Surface point of the hit, metres.
    pub position_m: Vec3,
    /// Weight per channel (dimensionless).
    pub weight: Vec3,
}

impl ProfileSampler {
    /// A sampler of `profile` truncated to its support (the transport's, `R_d < 10⁻⁴ R_d(0)`).
    pub fn new(profile: Profile) -> Self {
        let support_m = profile.support_radius(1e-4);
        Self {
            profile,
            support_m,
            norm: profile.disk_integral(support_m),
        }
    }

    /// A radius in `[0, R]` with density `∝ R_d,c(r)·2πr` for channel `c`, from `u ∈ [0, 1)`.
    pub fn sample_radius(&self, c: usize, u: f64) -> f64 {
        let ch = &self.profile.channels[c];
        let target = u * self.norm[c];
        let (mut lo, mut hi) = (0.0f64, self.support_m);
        for _ in 0..48 {
            let mid = 0.5 * (lo + hi);
            if ch.disk_integral(mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        0.5 * (lo + hi)
    }

    /// The disc density (m⁻², averaged over the channels) of a point at radius `r`.
    pub fn disc_density(&self, r: f64) -> f64 {
        if r > self.support_m {
            return 0.0;
        }
        let rd = self.profile.rd(r);
        (0..3)
            .map(|c| {
                if self.norm[c] > 0.0 {
                    rd[c] / self.norm[c]
                } else {
                    0.0
                }
            })
            .sum::<f64>()
            / 3.0
    }

    /// Samples a point `y` of triangles for which `same_material` holds, around the surface
    /// point `x` with shading normal `normal` (module docs). `None` when the probe ray finds
    /// no such surface (the sample contributes nothing). `hits` is scratch space; `rays`
    /// counts the rays cast; `face_normal(triangle)` is a hit triangle's unit geometric normal.
    #[allow(
        clippy::too_many_arguments,
        reason = "the query's parts, each used once"
    )]
    pub fn sample_exit(
        &self,
        vis: &Visibility,
        x: Vec3,
        normal: Vec3,
        same_material: impl Fn(u32) -> bool,
        face_normal: impl Fn(u32) -> Vec3,
        rng: &mut ChaCha8Rng,
        hits: &mut Vec<RayHit>,
        rays: &mut u64,
    ) -> Option<ExitSample> {
        let (t1, t2) = tangent_frame(normal);
        let axes = [normal, t1, t2];
        let u_axis: f64 = rng.random();
        let a = if u_axis < NORMAL_AXIS_PROBABILITY {
            0
        } else if u_axis < 0.5 * (1.0 + NORMAL_AXIS_PROBABILITY) {
            1
        } else {
            2
        };
        let c = (rng.random::<f64>() * 3.0).min(2.0) as usize;
        let r = self.sample_radius(c, rng.random());
        let phi = std::f64::consts::TAU * rng.random::<f64>();
        let (axis, u, v) = (axes[a], axes[(a + 1) % 3], axes[(a + 2) % 3]);
        let h = (self.support_m * self.support_m - r * r).max(0.0).sqrt();
        let offset = (u * phi.cos() as f32 + v * phi.sin() as f32) * r as f32;
        let origin = x + offset + axis * h as f32;
        hits.clear();
        *rays += 1;
        vis.for_each_hit(origin, -axis, (0.0, 2.0 * h as f32), |hit| {
            if same_material(hit.triangle) {
                hits.push(hit);
            }
        });
        if hits.is_empty() {
            return None;
        }
        // Traversal order depends on the BVH; sort so the choice depends on the geometry only.
        hits.sort_by(|p, q| p.t.total_cmp(&q.t).then(p.triangle.cmp(&q.triangle)));
        let k = ((rng.random::<f64>() * hits.len() as f64) as usize).min(hits.len() - 1);
        let hit = hits[k];
        let y = origin - axis * hit.t;
        let d = (y - x).as_dvec3();
        let dist = d.length();
        if dist > self.support_m {
            return None;
        }
        let n_y = face_normal(hit.triangle).as_dvec3();
        let probs = [
            NORMAL_AXIS_PROBABILITY,
            0.5 * (1.0 - NORMAL_AXIS_PROBABILITY),
            0.5 * (1.0 - NORMAL_AXIS_PROBABILITY),
        ];
        let mut pdf = 0.0;
        for (b, axis_b) in axes.iter().enumerate() {
            let ab = axis_b.as_dvec3();
            let r_b = (d - ab * ab.dot(d)).length();
            pdf += probs[b] * self.disc_density(r_b) * n_y.dot(ab).abs();
        }
        pdf /= hits.len() as f64;
        if pdf <= 0.0 || !pdf.is_finite() {
            return None;
        }
        let rd = self.profile.rd(dist);
        Some(ExitSample {
            hit,
            position_m: y,
            weight: Vec3::new(
                (rd[0] / pdf) as f32,
                (rd[1] / pdf) as f32,
                (rd[2] / pdf) as f32,
            ),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SubsurfaceModel;
    use crate::scene::subsurface::skin1;
    use glam::Vec3A;
    use obvhs::triangle::Triangle;
    use rand::SeedableRng;

    /// On a large flat plane, the estimator of `∫ R_d(|x−y|) dA(y)` (irradiance 1) must give
    /// the disk integral over the support, `D_c`, per channel, within its standard error.
    #[test]
    fn flat_plane_integrates_the_profile() {
        for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
            let s = ProfileSampler::new(skin1(model));
            let half = 1.0f32;
            let (a, b, c, d) = (
                Vec3A::new(-half, -half, 0.0),
                Vec3A::new(half, -half, 0.0),
                Vec3A::new(half, half, 0.0),
                Vec3A::new(-half, half, 0.0),
            );
            let vis = Visibility::from_triangles(vec![
                Triangle {
                    v0: a,
                    v1: b,
                    v2: c,
                },
                Triangle {
                    v0: a,
                    v1: c,
                    v2: d,
                },
            ]);
            let mut rng = ChaCha8Rng::seed_from_u64(7);
            let (mut sum, mut sum2) = ([0.0f64; 3], [0.0f64; 3]);
            let n = 20_000;
            let (mut hits, mut rays) = (Vec::new(), 0u64);
            for _ in 0..n {
                let w = s
                    .sample_exit(
                        &vis,
                        Vec3::new(0.1, 0.2, 0.0),
                        Vec3::Z,
                        |_| true,
                        |_| Vec3::Z,
                        &mut rng,
                        &mut hits,
                        &mut rays,
                    )
                    .map_or(Vec3::ZERO, |e| e.weight);
                for ch in 0..3 {
                    sum[ch] += w[ch] as f64;
                    sum2[ch] += (w[ch] as f64).powi(2);
                }
            }
            for ch in 0..3 {
                let mean = sum[ch] / n as f64;
                let se = ((sum2[ch] / n as f64 - mean * mean) / n as f64).sqrt();
                println!(
                    "{model:?} ch {ch}: {mean:.5} ± {se:.5} vs {:.5}",
                    s.norm[ch]
                );
                assert!(
                    (mean - s.norm[ch]).abs() < 4.0 * se + 1e-9,
                    "{model:?} {ch}"
                );
            }
        }
    }
}
