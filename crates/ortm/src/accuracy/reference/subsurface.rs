//! Importance sampling of a subsurface profile's exit (or entry) points: the BSSRDF probe
//! technique of King, Kulla, Conty and Fajardo (2013) and Christensen (2015).
//!
//! The translucent exitance `B(x) = ∫ R_d(|x − y|) E(y) dA(y)` (over the surface of `x`'s
//! material within the profile's support radius `R`) is estimated by one point `y` per sample:
//! 1. an axis: the shading normal at `x` (probability [`NORMAL_AXIS_PROBABILITY`]) or one of its
//!    two tangents (half the rest each), and a channel (⅓ each), from one number (so that
//!    stratified numbers stratify both);
//! 2. a radius `r ∈ [0, R]` with density `∝ R_d(r)·2πr` (the disk
//!    integral is closed-form, [`crate::scene::subsurface::ChannelProfile::disk_integral`], and
//!    is inverted by bisection), and an angle, uniform: a point on the disc through `x`
//!    orthogonal to the axis;
//! 3. a probe ray along the axis through that point, spanning the support sphere's chord; one
//!    of its hits `y_k` on the same material, chosen with probability `π_k` ∝ the channel sum of
//!    its weight `R_d(|x − y_k|) / q(y_k)` (below).
//!
//! The area density of a hit `y` by the probe that found it is the one-sample
//! multiple-importance (balance heuristic) density over the three axes and three channels,
//! `q(y) = Σ_a P_a Σ_c ⅓ p_c(r_a(y))·|n_y·a|`, with `r_a` the distance from `x` to `y`
//! projected on the plane orthogonal to `a`, `p_c(r) = R_d,c(r) / D_c` the disc density
//! (`D_c = ∫₀^R R_d,c 2πr dr`) and `n_y` the geometric normal. The estimate's weight is
//! `R_d(|x − y_k|) / (q(y_k) π_k)` per channel: unbiased for any choice `π` that depends only on
//! the traced chord (the sum over a chord's hits of `π_k · weight / π_k` is what the chord
//! brings, and `Σ_a P_a ∫ … ` over the discs covers every point of the surface with density
//! `q`). Choosing by weight rather than uniformly keeps the far hits of a chord (the other side
//! of a nose, a fold), whose `R_d` is tiny, from taking half the samples and doubling the near
//! hit's weight on the others. The normal gets the larger share because on the head, a smooth
//! surface at the profile's scale, tangent probes mostly miss; the tangents keep folds reached.
//! Distances in metres, `R_d` in m⁻², densities in m⁻².

use glam::Vec3;

use super::sampler::PathSampler;
use crate::bake::raycast::{RayHit, Visibility};
use crate::bake::transport::form_factor::tangent_frame;
use crate::scene::subsurface::Profile;

/// Probability of probing along the normal; each tangent gets half the rest. Measured on the
/// head at 64², 256 paths per texel (`ortm reference head --size 64 --spp 256 --replicates
/// 256`): noise 8.4 % of the final at ½ with a uniform choice of hit; with the choice by weight
/// 7.2 % at ½, 5.4 % at 0.8, 5.05 % at 0.9, 5.2 % at 0.95. 0.9 also put more texels within 3σ
/// of the exact solve away from the light's edges than 0.75 (97.8 % against 96.5 %,
/// `accuracy_reference.rs`'s `head_64_agrees_with_the_exact_solve`): there the tangents find
/// lit skin across folds, and fewer tangent probes find it more rarely, with larger weights.
pub const NORMAL_AXIS_PROBABILITY: f64 = 0.9;

/// The point where `below` turns false in `[lo, hi]` (`below(lo)` true, `below(hi)` false), by
/// 48 bisections.
fn bisect(below: impl Fn(f64) -> bool, mut lo: f64, mut hi: f64) -> f64 {
    for _ in 0..48 {
        let mid = 0.5 * (lo + hi);
        if below(mid) {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Probability of each probe axis: the normal, then its two tangents.
const AXIS_PROBABILITIES: [f64; 3] = [
    NORMAL_AXIS_PROBABILITY,
    0.5 * (1.0 - NORMAL_AXIS_PROBABILITY),
    0.5 * (1.0 - NORMAL_AXIS_PROBABILITY),
];

/// A probe's hit and, once computed, its weight `R_d / q` per channel if it were chosen alone
/// (`None`: beyond the support or of zero density).
pub type WeighedHit = (RayHit, Option<[f64; 3]>);

/// One translucent material's profile, ready for sampling.
#[derive(Clone, Copy, Debug)]
pub struct ProfileSampler {
    /// The profile.
    pub profile: Profile,
    /// Support radius, metres (the Kernels' `support_radius(1e-4)`; `R_d = 0` beyond).
    pub support_m: f64,
    /// Per channel, `D_c = ∫₀^R R_d,c(r) 2πr dr`.
    norm: [f64; 3],
    /// Per channel, the radii `r_k` at which the radius's distribution reaches `k / K`
    /// (`K =` [`RADIUS_BRACKETS`]; `r_0 = 0`, `r_K = R`): the bracket a draw's root lies in.
    brackets: [[f64; RADIUS_BRACKETS + 1]; 3],
}

/// Brackets per channel of [`ProfileSampler::sample_radius`]'s root finding.
const RADIUS_BRACKETS: usize = 64;

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
        let norm = profile.disk_integral(support_m);
        let brackets = std::array::from_fn(|c| {
            let ch = &profile.channels[c];
            std::array::from_fn(|k| match k {
                0 => 0.0,
                RADIUS_BRACKETS => support_m,
                _ => {
                    let target = k as f64 / RADIUS_BRACKETS as f64 * norm[c];
                    bisect(|r| ch.disk_integral(r) < target, 0.0, support_m)
                }
            })
        });
        Self {
            profile,
            support_m,
            norm,
            brackets,
        }
    }

    /// A radius in `[0, R]` with density `∝ R_d,c(r)·2πr` for channel `c`, from `u ∈ [0, 1)`:
    /// the root of `D_c(r) = u·D_c(R)` (`D_c` the closed-form disk integral), by Newton's method
    /// on its derivative `R_d,c(r)·2πr`, kept inside the bracket of [`Self::brackets`] that
    /// holds it and bisecting where a step would leave it, to a step of `10⁻¹³ R`: the same
    /// root as 48 bisections of `[0, R]` (`R / 2⁴⁸ ≈ 3.6·10⁻¹⁵ R`) in a few evaluations
    /// instead of 48, whose `exp`s were a fifth of the reference's time on the head (`ortm
    /// reference head --size 256 --spp 256`: 34.2 → 20.1 s with the cells' guide table,
    /// [`super::emitters`], the same values).
    pub fn sample_radius(&self, c: usize, u: f64) -> f64 {
        let ch = &self.profile.channels[c];
        let target = u * self.norm[c];
        let k = ((u * RADIUS_BRACKETS as f64) as usize).min(RADIUS_BRACKETS - 1);
        let (mut lo, mut hi) = (self.brackets[c][k], self.brackets[c][k + 1]);
        let tolerance = 1e-13 * self.support_m;
        let mut r = 0.5 * (lo + hi);
        for _ in 0..64 {
            let f = ch.disk_integral(r) - target;
            if f < 0.0 {
                lo = r;
            } else {
                hi = r;
            }
            let slope = ch.rd(r) * std::f64::consts::TAU * r;
            let newton = r - f / slope;
            let next = if newton > lo && newton < hi {
                newton
            } else {
                0.5 * (lo + hi)
            };
            let step = (next - r).abs();
            r = next;
            if step <= tolerance || hi - lo <= tolerance {
                break;
            }
        }
        r
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
    /// no such surface (the sample contributes nothing). Reads four numbers from `u` (axis and
    /// channel, radius, angle, hit). `hits` is scratch space (the probe's hits and their
    /// weights); `rays` counts the rays cast;
    /// `face_normal(triangle)` is a hit triangle's unit geometric normal.
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
        u: &mut PathSampler,
        hits: &mut Vec<WeighedHit>,
        rays: &mut u64,
    ) -> Option<ExitSample> {
        let (t1, t2) = tangent_frame(normal);
        let axes = [normal, t1, t2];
        let (a, c) = axis_and_channel(&AXIS_PROBABILITIES, u.uniform());
        let r = self.sample_radius(c, u.uniform());
        let phi = std::f64::consts::TAU * u.uniform();
        let (axis, t_u, t_v) = (axes[a], axes[(a + 1) % 3], axes[(a + 2) % 3]);
        let h = (self.support_m * self.support_m - r * r).max(0.0).sqrt();
        let offset = (t_u * phi.cos() as f32 + t_v * phi.sin() as f32) * r as f32;
        let origin = x + offset + axis * h as f32;
        hits.clear();
        *rays += 1;
        vis.for_each_hit(origin, -axis, (0.0, 2.0 * h as f32), |hit| {
            if same_material(hit.triangle) {
                hits.push((hit, None));
            }
        });
        if hits.is_empty() {
            return None;
        }
        // Traversal order depends on the BVH; sort so the choice depends on the geometry only.
        hits.sort_by(|(p, _), (q, _)| p.t.total_cmp(&q.t).then(p.triangle.cmp(&q.triangle)));
        // Each hit's weight `R_d / pdf` if it were chosen alone; the hit is chosen with
        // probability ∝ its weight's channel sum, so the far hits of a chord (the other side
        // of a nose, a fold), whose `R_d` is tiny, are rarely taken and never double the near
        // one's weight as a uniform choice would.
        let weight_of = |hit: &RayHit| -> Option<[f64; 3]> {
            let y = origin - axis * hit.t;
            let d = (y - x).as_dvec3();
            let dist = d.length();
            if dist > self.support_m {
                return None;
            }
            let n_y = face_normal(hit.triangle).as_dvec3();
            let mut pdf = 0.0;
            for (b, axis_b) in axes.iter().enumerate() {
                let ab = axis_b.as_dvec3();
                let r_b = (d - ab * ab.dot(d)).length();
                pdf += AXIS_PROBABILITIES[b] * self.disc_density(r_b) * n_y.dot(ab).abs();
            }
            if pdf <= 0.0 || !pdf.is_finite() {
                return None;
            }
            let rd = self.profile.rd(dist);
            let w = [rd[0] / pdf, rd[1] / pdf, rd[2] / pdf];
            let sum = w[0] + w[1] + w[2];
            (sum > 0.0 && sum.is_finite()).then_some(w)
        };
        let mut total = 0.0f64;
        for (hit, w) in hits.iter_mut() {
            *w = weight_of(hit);
            total += w.map_or(0.0, |w| w[0] + w[1] + w[2]);
        }
        if total <= 0.0 {
            return None;
        }
        let target = u.uniform() * total;
        let (mut run, mut chosen) = (0.0, None);
        for (k, (_, w)) in hits.iter().enumerate() {
            if let Some(w) = *w {
                chosen = Some((k, w));
                run += w[0] + w[1] + w[2];
                if target < run {
                    break;
                }
            }
        }
        let (k, w) = chosen?;
        let hit = hits[k].0;
        // Probability of the choice: the hit's share of the total.
        let share = (w[0] + w[1] + w[2]) / total;
        Some(ExitSample {
            hit,
            position_m: origin - axis * hit.t,
            weight: Vec3::new(
                (w[0] / share) as f32,
                (w[1] / share) as f32,
                (w[2] / share) as f32,
            ),
        })
    }
}

/// The axis (by `probs`) and the channel (⅓ each) that `u ∈ [0, 1)` selects: the axis by the
/// interval `u` falls in, the channel by `u`'s place within it.
fn axis_and_channel(probs: &[f64; 3], u: f64) -> (usize, usize) {
    let mut start = 0.0;
    for (a, &p) in probs.iter().enumerate() {
        if u < start + p || a == 2 {
            let within = ((u - start) / p).clamp(0.0, 1.0);
            return (a, ((within * 3.0) as usize).min(2));
        }
        start += p;
    }
    unreachable!("the loop returns at the last axis")
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::bake::raycast::test_square;
    use crate::scene::SubsurfaceModel;
    use crate::scene::subsurface::skin1;
    use rand::SeedableRng;
    use rand_chacha::ChaCha8Rng;

    /// Mean and standard error per channel of `n` independent exit weights at `(0.1, 0.2, 0)`
    /// (normal +z) on `vis`, and how many chose a hit on triangle 2 or later.
    fn exit_weights(
        s: &ProfileSampler,
        vis: &Visibility,
        n: usize,
        seed: u64,
    ) -> ([f64; 3], [f64; 3], usize) {
        let mut u = PathSampler::new(ChaCha8Rng::seed_from_u64(seed));
        let (mut sum, mut sum2, mut later) = ([0.0f64; 3], [0.0f64; 3], 0usize);
        let (mut hits, mut rays) = (Vec::new(), 0u64);
        for _ in 0..n {
            // One path per replicate: independent samples, so the sample variance holds.
            u.start_replicate();
            u.start_path(0);
            let e = s.sample_exit(
                vis,
                Vec3::new(0.1, 0.2, 0.0),
                Vec3::Z,
                |_| true,
                |_| Vec3::Z,
                &mut u,
                &mut hits,
                &mut rays,
            );
            later += usize::from(e.is_some_and(|e| e.hit.triangle >= 2));
            let w = e.map_or(Vec3::ZERO, |e| e.weight);
            for ch in 0..3 {
                sum[ch] += w[ch] as f64;
                sum2[ch] += (w[ch] as f64).powi(2);
            }
        }
        let nf = n as f64;
        let mean = sum.map(|x| x / nf);
        let se = [0, 1, 2].map(|c| ((sum2[c] / nf - mean[c] * mean[c]) / nf).max(0.0).sqrt());
        (mean, se, later)
    }

    /// The bracketed Newton iteration finds the radius 48 bisections of `[0, R]` find (the
    /// root of the disk integral's equation) within 10⁻¹² R, in every channel of both
    /// profiles, at the ends of the unit interval and at the brackets' edges; or, where the
    /// disk integral's rounding blurs the root (radii of nanometres, `u` ≈ 10⁻¹²), a root as
    /// good as the bisection's within 10⁻⁹ R.
    #[test]
    fn newton_radius_equals_the_bisection() {
        for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
            let s = ProfileSampler::new(skin1(model));
            for c in 0..3 {
                let ch = &s.profile.channels[c];
                let mut us: Vec<f64> = (0..4001).map(|k| k as f64 / 4001.0).collect();
                us.extend([
                    1e-12,
                    0.5 / super::RADIUS_BRACKETS as f64,
                    1.0f64.next_down(),
                ]);
                for k in 1..super::RADIUS_BRACKETS {
                    let u = k as f64 / super::RADIUS_BRACKETS as f64;
                    us.extend([u.next_down(), u, u.next_up()]);
                }
                for u in us {
                    let target = u * s.norm[c];
                    let want = super::bisect(|r| ch.disk_integral(r) < target, 0.0, s.support_m);
                    let got = s.sample_radius(c, u);
                    let residual = |r: f64| (ch.disk_integral(r) - target).abs();
                    let close = (got - want).abs() <= 1e-12 * s.support_m;
                    let as_good = (got - want).abs() <= 1e-9 * s.support_m
                        && residual(got) <= residual(want).max(1e-15 * s.norm[c]);
                    assert!(
                        close || as_good,
                        "{model:?} channel {c}, u = {u}: {got} against {want}"
                    );
                }
            }
        }
    }

    /// On a large flat plane, the estimator of `∫ R_d(|x−y|) dA(y)` (irradiance 1) must give
    /// the disk integral over the support, `D_c`, per channel, within its standard error.
    #[test]
    fn flat_plane_integrates_the_profile() {
        for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
            let s = ProfileSampler::new(skin1(model));
            let vis = Visibility::from_triangles(test_square(0.0, 1.0).to_vec());
            let (mean, se, _) = exit_weights(&s, &vis, 20_000, 7);
            for ch in 0..3 {
                let (mean, se) = (mean[ch], se[ch]);
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

    /// Two parallel planes `h` apart (a slab's faces, one material): the normal probes cross
    /// both, and the hit is chosen by its weight. The estimate of `∫ R_d(|x−y|) dA(y)` over
    /// both must give the near plane's `D(R)` plus the far plane's `∫_h^R R_d(s) 2πs ds =
    /// D(R) − D(h)`, per channel, within its standard error; and the weighted choice must beat
    /// a uniform one (which, on these chords, gives the near hit twice its weight half the
    /// time): measured by the far plane's share of the chosen hits.
    #[test]
    fn two_planes_within_the_support_integrate_the_profile() {
        let s = ProfileSampler::new(skin1(SubsurfaceModel::Dipole));
        let h = 0.004f32;
        let mut tris = test_square(0.0, 1.0).to_vec();
        tris.extend(test_square(h, 1.0));
        let vis = Visibility::from_triangles(tris);
        let n = 40_000;
        let (mean, se, far) = exit_weights(&s, &vis, n, 11);
        let d_r = s.profile.disk_integral(s.support_m);
        let d_h = s.profile.disk_integral(f64::from(h));
        for ch in 0..3 {
            let (mean, se) = (mean[ch], se[ch]);
            let expected = 2.0 * d_r[ch] - d_h[ch];
            println!("channel {ch}: {mean:.5} ± {se:.5} against {expected:.5}");
            assert!((mean - expected).abs() < 4.0 * se + 1e-9, "channel {ch}");
        }
        // Every normal probe (90 % of the samples) crosses both planes, so a uniform choice takes
        // the far hit in ~45 % of the samples; by weight, about its share of the integral
        // (measured 7.5 %).
        let share = far as f64 / n as f64;
        println!("far plane chosen in {share:.3} of the samples");
        assert!(share < 0.2, "far hits chosen in {share:.3} of the samples");
    }
}
