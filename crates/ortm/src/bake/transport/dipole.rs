//! `R_d(r)` of a subsurface [`Profile`] ([`crate::scene::subsurface`]) tabulated for the bake:
//! distances in metres, values in m⁻².

use crate::scene::subsurface::Profile;

/// `R_d(r)` of a [`Profile`] tabulated on `[0, r_max]` metres and linearly interpolated: the bake
/// evaluates the profile for tens of millions of texel pairs, and each exact evaluation costs six
/// `exp`s. With [`RdTable::SAMPLES`] samples the step is far below the profile's smallest length
/// (`z_r`), and the interpolation error is below 1e-4 of the value wherever the value is above
/// 1e-4 of the peak (tested); beyond `r_max` the exact profile is used.
#[derive(Clone, Debug)]
pub struct RdTable {
    profile: Profile,
    r_max_m: f64,
    inv_step: f64,
    values: Vec<[f64; 3]>,
    /// `R_d'(r)` and `R_d''(r)` per channel at the same samples (m⁻³, m⁻⁴): central differences
    /// of the exact profile, which is even in `r`.
    slopes: Vec<[[f64; 3]; 2]>,
    /// `max_c ⅙ D₃(ρ) R_d(ρ)` at the same samples (m⁻⁵; [`RdTable::cluster_mean`]'s remainder
    /// bound per unit `r·tr M`), infinite at `ρ = 0`.
    third: Vec<f64>,
    /// `∫₀^r R_d(s) s ds = disk_integral(r) / 2π` at the same samples (the primitive that
    /// [`super::footprint`] integrates the profile with).
    primitive: Vec<[f64; 3]>,
    /// The largest effective transport coefficient σ_tr over the channels, m⁻¹.
    decay_per_m: f64,
    /// σ_tr per channel, m⁻¹.
    decay_per_channel: [f64; 3],
    /// The total diffuse reflectance ρ̄ per channel.
    reflectance: [f64; 3],
    /// `H(∞)` in the largest channel (the profile's total reflectance / 2π).
    primitive_total: f64,
}

impl RdTable {
    /// Samples of the table.
    pub const SAMPLES: usize = 8192;

    /// Tabulates `profile` on `[0, r_max_m]`.
    pub fn new(profile: &Profile, r_max_m: f64) -> Self {
        let r_max_m = r_max_m.max(1e-9);
        let step = r_max_m / (Self::SAMPLES - 1) as f64;
        let values = (0..Self::SAMPLES)
            .map(|n| profile.rd(n as f64 * step))
            .collect();
        let h = 0.5 * step;
        let slopes = (0..Self::SAMPLES)
            .map(|n| {
                let r = n as f64 * step;
                let (a, m, b) = (profile.rd((r - h).abs()), profile.rd(r), profile.rd(r + h));
                [
                    [0, 1, 2].map(|c| (b[c] - a[c]) / (2.0 * h)),
                    [0, 1, 2].map(|c| (b[c] - 2.0 * m[c] + a[c]) / (h * h)),
                ]
            })
            .collect();
        let sigma = profile.channels.map(|c| c.sigma_tr);
        let third = (0..Self::SAMPLES)
            .map(|n| {
                let rho = n as f64 * step;
                let v = profile.rd(rho);
                (0..3)
                    .map(|c| third_bound(sigma[c], rho) * v[c] / 6.0)
                    .fold(0.0f64, f64::max)
            })
            .map(|b| if b.is_finite() { b } else { f64::INFINITY })
            .collect();
        let primitive = (0..Self::SAMPLES)
            .map(|n| {
                profile
                    .disk_integral(n as f64 * step)
                    .map(|v| v / std::f64::consts::TAU)
            })
            .collect();
        let decay_per_m = profile
            .channels
            .iter()
            .map(|c| c.sigma_tr)
            .fold(0.0f64, f64::max);
        let primitive_total = profile
            .channels
            .iter()
            .map(|c| c.total_reflectance() / std::f64::consts::TAU)
            .fold(0.0f64, f64::max);
        Self {
            profile: *profile,
            r_max_m,
            inv_step: 1.0 / step,
            values,
            slopes,
            third,
            primitive,
            decay_per_m,
            decay_per_channel: profile.channels.map(|c| c.sigma_tr),
            reflectance: profile.channels.map(|c| c.total_reflectance()),
            primitive_total,
        }
    }

    /// The largest effective transport coefficient σ_tr of the profile's channels (m⁻¹): the
    /// profile falls by `e` within `1/σ_tr` in its tail.
    pub fn decay_per_m(&self) -> f64 {
        self.decay_per_m
    }

    /// σ_tr per channel (m⁻¹).
    pub fn decay_per_channel(&self) -> [f64; 3] {
        self.decay_per_channel
    }

    /// The profile's total diffuse reflectance ρ̄ per channel.
    pub fn reflectance(&self) -> [f64; 3] {
        self.reflectance
    }

    /// `H(∞)` in the profile's largest channel: its total reflectance ρ̄ / 2π.
    pub fn primitive_total(&self) -> f64 {
        self.primitive_total
    }

    /// `H(r) = ∫₀^r R_d(s) s ds` per channel (dimensionless): the profile gathered from a disk
    /// of radius `r` metres is `2π·H(r)`. Tabulated like [`RdTable::rd`]; closed form beyond
    /// the table.
    #[inline]
    pub fn primitive(&self, r: f64) -> [f64; 3] {
        if r >= self.r_max_m {
            return self
                .profile
                .disk_integral(r)
                .map(|v| v / std::f64::consts::TAU);
        }
        let (n, f) = self.sample(r);
        lerp(self.primitive[n], self.primitive[n + 1], f)
    }

    /// `R_d(d)` (m⁻², per channel) for a cluster of `area_m2` whose members lie within
    /// `radius_m` of its centroid, `d > radius_m` away, when the profile varies little enough
    /// across it to be taken whole: `(|R_d(d − r) − R_d(d)| + |R_d(d) − R_d(d + r)|)·A ≤
    /// tolerance` in every channel (the profile falls monotonically, so this bounds the error of
    /// every member's weight, summed by area; truncated at the table's range as
    /// [`RdTable::rd_within`]). `None` where the cluster must be refined. The Barnes–Hut walks
    /// of the subsurface term ([`super::hier::subsurface`]) and of the surface's re-emission
    /// ([`super::surface`]) share it.
    pub fn cluster_value(
        &self,
        d: f64,
        radius_m: f64,
        area_m2: f64,
        tolerance: f64,
    ) -> Option<[f64; 3]> {
        if d <= radius_m {
            return None;
        }
        let (near, mid, far) = (
            self.rd_within(d - radius_m),
            self.rd_within(d),
            self.rd_within(d + radius_m),
        );
        (0..3)
            .all(|c| ((near[c] - mid[c]).abs() + (mid[c] - far[c]).abs()) * area_m2 <= tolerance)
            .then_some(mid)
    }

    /// The mean of `R_d(|x − y|)` (m⁻², per channel) over a cluster of `area_m2` seen from a
    /// point `x` at `d` metres from its area-weighted centroid `c`, its members within
    /// `radius_m` of `c` (`d > radius_m`), to second order, when its error is within
    /// `tolerance` in every channel. `m_tr` is the trace of the cluster's second-moment tensor
    /// about `c`, `∫ |y − c|² dA` over its members' footprints, and `m_uu()` its component
    /// along the direction `u = (x − c)/d`, `∫ ((y − c)·u)² dA` (m⁴).
    ///
    /// Taylor about `c`: the linear term integrates to 0, and the Hessian of `R_d(|x − y|)` is
    /// `R_d''(d) uuᵀ + R_d'(d)/d (I − uuᵀ)`, so the cluster's integral is
    /// `R_d(d)·A + ½ (R_d''(d) m_uu + R_d'(d)/d (m_tr − m_uu))`; the value returned is that over
    /// `A`. The remainder is at most `⅙ D₃(d − r) r m_tr`, `D₃` a bound on the third
    /// derivative of the radial function (`|R'''| + 3|R''|/ρ + 3|R'|/ρ²`) from the rate at
    /// which the dipole's tail `e^{−σ_tr ρ}/ρ³` falls, `κ = σ_tr + 3/ρ`:
    /// `|R'| ≤ κR`, `|R''| ≤ (κ² + 3/ρ²)R`, `|R'''| ≤ (κ³ + 9κ/ρ² + 6/ρ³)R` at `ρ = d − r`.
    /// Where the cluster reaches past the table's range, the truncation's jump, at most
    /// `R_d(d − r)·A`, is added to the error. `None` where the cluster must be refined.
    ///
    /// The bound is tabulated (its largest channel) and interpolated linearly, which
    /// overestimates it between samples (it is convex); `m_uu` is asked for only when the
    /// cluster is taken.
    pub fn cluster_mean(
        &self,
        d: f64,
        radius_m: f64,
        area_m2: f64,
        m_tr: f64,
        m_uu: impl FnOnce() -> f64,
        tolerance: f64,
    ) -> Option<[f64; 3]> {
        if d <= radius_m || area_m2 <= 0.0 {
            return None;
        }
        let rho = d - radius_m;
        if rho >= self.r_max_m {
            return Some([0.0; 3]);
        }
        let (n, f) = self.sample(rho);
        let bound = self.third[n] + (self.third[n + 1] - self.third[n]) * f;
        let error = bound * radius_m * m_tr;
        // Also refined where the bound is not a number (∞ at ρ = 0 times a zero moment).
        if error.is_nan() || error > tolerance {
            return None;
        }
        if d + radius_m >= self.r_max_m {
            let near = self.rd_within(rho);
            if (0..3).any(|c| error + near[c] * area_m2 > tolerance) {
                return None;
            }
        }
        // Taken whole: the mean (most nodes tested are refined, so the slopes are read here).
        let m_uu = m_uu();
        let (mid, [d1, d2]) = self.rd_and_slopes(d);
        Some([0, 1, 2].map(|c| {
            let correction = 0.5 * (d2[c] * m_uu + d1[c] / d * (m_tr - m_uu));
            (mid[c] + correction / area_m2).max(0.0)
        }))
    }

    /// `R_d(r)`, `R_d'(r)` and `R_d''(r)` per channel within the table's range (linearly
    /// interpolated), all 0 beyond it.
    #[inline]
    fn rd_and_slopes(&self, r: f64) -> ([f64; 3], [[f64; 3]; 2]) {
        if r >= self.r_max_m {
            return ([0.0; 3], [[0.0; 3]; 2]);
        }
        let (n, f) = self.sample(r);
        let (s0, s1) = (self.slopes[n], self.slopes[n + 1]);
        (
            lerp(self.values[n], self.values[n + 1], f),
            [lerp(s0[0], s1[0], f), lerp(s0[1], s1[1], f)],
        )
    }

    /// `R_d(r)` within the table's range, 0 beyond it (the support's truncation, as the pair
    /// weights make it).
    #[inline]
    pub fn rd_within(&self, r: f64) -> [f64; 3] {
        if r >= self.r_max_m {
            [0.0; 3]
        } else {
            self.rd(r)
        }
    }

    /// `R_d(r)` per channel at `r` metres (m⁻²).
    #[inline]
    pub fn rd(&self, r: f64) -> [f64; 3] {
        if r >= self.r_max_m {
            return self.profile.rd(r);
        }
        let (n, f) = self.sample(r);
        lerp(self.values[n], self.values[n + 1], f)
    }

    /// The sample below `r` (metres, within the table's range) and `r`'s fraction of the way
    /// to the next one: the tables are read at `(n, f)` by [`lerp`].
    #[inline]
    fn sample(&self, r: f64) -> (usize, f64) {
        let x = r.max(0.0) * self.inv_step;
        let n = (x as usize).min(Self::SAMPLES - 2);
        (n, x - n as f64)
    }
}

/// `a + (b − a)·f` per channel.
#[inline]
fn lerp(a: [f64; 3], b: [f64; 3], f: f64) -> [f64; 3] {
    [0, 1, 2].map(|c| a[c] + (b[c] - a[c]) * f)
}

/// `D₃(ρ)/R_d(ρ)` for a channel of effective transport coefficient `sigma` (m⁻¹): the bound
/// on the third derivative of `R_d(|v|)` in any direction (`|R'''| + 3|R''|/ρ + 3|R'|/ρ²`)
/// from the dipole's tail `e^{−σ ρ}/ρ³` ([`RdTable::cluster_mean`]), m⁻³; infinite at 0.
fn third_bound(sigma: f64, rho: f64) -> f64 {
    let (i1, i2) = (1.0 / rho, 1.0 / (rho * rho));
    let k = sigma + 3.0 * i1;
    let third = k * k * k + 9.0 * k * i2 + 6.0 * i2 * i1;
    third + 3.0 * (k * k + 3.0 * i2) * i1 + 3.0 * k * i2
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::SubsurfaceModel;
    use crate::scene::subsurface::skin1;

    #[test]
    fn tabulated_profile_matches_the_exact_one() {
        for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
            let p = skin1(model);
            let support = p.support_radius(1e-4);
            let table = RdTable::new(&p, support);
            let peak = p.rd(0.0);
            let mut worst: f64 = 0.0;
            for n in 0..=100_000 {
                // Off-grid points across the table and a little beyond it.
                let r = support * 1.01 * (n as f64 + 0.37) / 100_000.0;
                let (t, e) = (table.rd(r), p.rd(r));
                for c in 0..3 {
                    if e[c] > 1e-4 * peak[c] {
                        worst = worst.max((t[c] - e[c]).abs() / e[c]);
                    }
                }
            }
            assert!(worst < 1e-4, "{model:?}: worst relative error {worst:e}");
        }
    }
}
