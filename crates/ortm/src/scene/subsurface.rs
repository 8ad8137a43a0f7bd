//! Subsurface scattering profiles: Jensen et al. 2001's dipole diffusion profile `R_d(r)` and
//! a normalised exponential falloff.
//!
//! Units: coefficients are stored per metre (scene files give them per mm; [`Profile::new`]
//! converts), distances `r` in metres, `R_d(r)` in m⁻² (fraction of incident power per unit
//! exit area). Outgoing radiosity of a translucent surface is the convolution
//! `B(x) = ∫ R_d(|x − x'|) E(x') dA'` with the irradiance `E`, `r` the Euclidean distance
//! (so light crosses thin features such as ears, and UV seams). The Fresnel transmission
//! factors of Jensen's full BSSRDF are folded into `R_d` (diffuse approximation): the
//! profile's integral, [`Profile::total_reflectance`], is the material's effective albedo.
//!
//! Formulas (Jensen, Marschner, Levoy, Hanrahan 2001, Eq. 4–5 and the total diffuse
//! reflectance): `σ_t' = σ_a + σ_s'`, `α' = σ_s'/σ_t'`, `σ_tr = √(3σ_aσ_t')`,
//! `F_dr = −1.440/η² + 0.710/η + 0.668 + 0.0636η`, `A = (1+F_dr)/(1−F_dr)`, `z_r = 1/σ_t'`,
//! `z_v = z_r(1 + 4A/3)`, `d = √(r² + z²)`,
//! `R_d(r) = α'/(4π) Σ_{z∈{z_r,z_v}} z(σ_tr d + 1)e^{−σ_tr d}/d³`,
//! `R_d = α'/2 (1 + e^{−(4/3)A√(3(1−α'))}) e^{−√(3(1−α'))}`.

use glam::Vec3;

use crate::scene::{Subsurface, SubsurfaceModel};

/// One channel of a subsurface profile, in SI units.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ChannelProfile {
    /// Reduced albedo α' = σ_s'/σ_t'.
    pub alpha_prime: f64,
    /// Effective transport coefficient σ_tr, m⁻¹.
    pub sigma_tr: f64,
    /// Depth of the real source z_r = 1/σ_t', metres.
    pub z_r: f64,
    /// Height of the virtual source z_v, metres.
    pub z_v: f64,
    /// Which profile shape.
    pub model: SubsurfaceModel,
}

/// A three-channel (RGB) subsurface profile.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Profile {
    /// Per-channel parameters.
    pub channels: [ChannelProfile; 3],
}

/// Fresnel diffuse reflectance approximation F_dr(η) (Jensen et al. 2001, Eq. 1 of the dipole).
pub fn fresnel_diffuse_reflectance(eta: f64) -> f64 {
    -1.440 / (eta * eta) + 0.710 / eta + 0.668 + 0.0636 * eta
}

impl ChannelProfile {
    /// Builds one channel from σ_a and σ_s' in m⁻¹ and η.
    pub fn new(
        sigma_a_per_m: f64,
        sigma_s_prime_per_m: f64,
        eta: f64,
        model: SubsurfaceModel,
    ) -> Self {
        let sigma_t = sigma_a_per_m + sigma_s_prime_per_m;
        let alpha_prime = sigma_s_prime_per_m / sigma_t;
        let sigma_tr = (3.0 * sigma_a_per_m * sigma_t).sqrt();
        let f_dr = fresnel_diffuse_reflectance(eta);
        let a = (1.0 + f_dr) / (1.0 - f_dr);
        let z_r = 1.0 / sigma_t;
        let z_v = z_r * (1.0 + 4.0 * a / 3.0);
        Self {
            alpha_prime,
            sigma_tr,
            z_r,
            z_v,
            model,
        }
    }

    /// Jensen's closed-form total diffuse reflectance `R_d = ∫₀^∞ R_d(r) 2πr dr`.
    pub fn total_reflectance(&self) -> f64 {
        let s = (3.0 * (1.0 - self.alpha_prime)).sqrt();
        let a = (self.z_v / self.z_r - 1.0) * 0.75;
        0.5 * self.alpha_prime * (1.0 + (-(4.0 / 3.0) * a * s).exp()) * (-s).exp()
    }

    /// Mean free path of the exponential profile, ℓ = 1/σ_tr (metres).
    fn exp_length(&self) -> f64 {
        1.0 / self.sigma_tr.max(1e-12)
    }

    /// The profile `R_d(r)` at distance `r` metres, in m⁻².
    pub fn rd(&self, r: f64) -> f64 {
        match self.model {
            SubsurfaceModel::Dipole => {
                let pole = |z: f64| {
                    let d = (r * r + z * z).sqrt();
                    z * (self.sigma_tr * d + 1.0) * (-self.sigma_tr * d).exp() / (d * d * d)
                };
                self.alpha_prime / (4.0 * std::f64::consts::PI) * (pole(self.z_r) + pole(self.z_v))
            }
            SubsurfaceModel::Exponential => {
                let l = self.exp_length();
                self.total_reflectance() * (-r / l).exp() / (2.0 * std::f64::consts::PI * l * l)
            }
        }
    }

    /// `∫₀^a R_d(r) 2πr dr`: the reflectance gathered from a disk of radius `a` metres around
    /// the exit point, in closed form (used for a texel's own, near-singular, contribution).
    ///
    /// Dipole: with `d = √(r²+z²)`, `r dr = d dd` and `d/dd(−e^{−σd}/d) = (σd+1)e^{−σd}/d²`,
    /// so each pole integrates to `z (e^{−σz}/z − e^{−σd_a}/d_a)`.
    pub fn disk_integral(&self, a: f64) -> f64 {
        match self.model {
            SubsurfaceModel::Dipole => {
                let pole = |z: f64| {
                    let da = (a * a + z * z).sqrt();
                    (-self.sigma_tr * z).exp() - z * (-self.sigma_tr * da).exp() / da
                };
                0.5 * self.alpha_prime * (pole(self.z_r) + pole(self.z_v))
            }
            SubsurfaceModel::Exponential => {
                let l = self.exp_length();
                let x = a / l;
                self.total_reflectance() * (1.0 - (1.0 + x) * (-x).exp())
            }
        }
    }
}

impl Profile {
    /// Builds the profile of a scene material's subsurface coefficients (given per mm).
    pub fn new(s: &Subsurface) -> Self {
        let ch = |c: usize| {
            ChannelProfile::new(
                s.sigma_a_per_mm[c] as f64 * 1000.0,
                s.sigma_s_prime_per_mm[c] as f64 * 1000.0,
                s.eta as f64,
                s.model,
            )
        };
        Self {
            channels: [ch(0), ch(1), ch(2)],
        }
    }

    /// Total diffuse reflectance per channel: the material's effective albedo.
    pub fn total_reflectance(&self) -> Vec3 {
        Vec3::new(
            self.channels[0].total_reflectance() as f32,
            self.channels[1].total_reflectance() as f32,
            self.channels[2].total_reflectance() as f32,
        )
    }

    /// `R_d(r)` per channel at `r` metres (m⁻²).
    pub fn rd(&self, r: f64) -> [f64; 3] {
        [
            self.channels[0].rd(r),
            self.channels[1].rd(r),
            self.channels[2].rd(r),
        ]
    }

    /// Disk integral per channel (see [`ChannelProfile::disk_integral`]).
    pub fn disk_integral(&self, a: f64) -> [f64; 3] {
        [
            self.channels[0].disk_integral(a),
            self.channels[1].disk_integral(a),
            self.channels[2].disk_integral(a),
        ]
    }

    /// Distance (metres) beyond which `R_d(r)` is below `fraction` of `R_d(0)` in every channel:
    /// the support used to skip negligible pairs.
    pub fn support_radius(&self, fraction: f64) -> f64 {
        let mut r_max: f64 = 0.0;
        for c in &self.channels {
            let peak = c.rd(0.0);
            let mut r = c.z_r.max(1e-6);
            while c.rd(r) > fraction * peak && r < 10.0 {
                r *= 1.25;
            }
            r_max = r_max.max(r);
        }
        r_max
    }
}

/// Skin1 of Jensen et al. 2001 (per mm): the tests' reference profile.
#[cfg(test)]
pub(crate) fn skin1(model: SubsurfaceModel) -> Profile {
    Profile::new(&Subsurface {
        sigma_a_per_mm: Vec3::new(0.032, 0.17, 0.48),
        sigma_s_prime_per_mm: Vec3::new(0.74, 0.88, 1.01),
        eta: 1.3,
        model,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// ∫₀^∞ R_d(r) 2πr dr by composite Simpson on a log-spaced grid.
    fn numeric_total(c: &ChannelProfile) -> f64 {
        // Substitute r = e^s: ∫ R_d(e^s) 2π e^{2s} ds.
        let (s0, s1, n) = (-25.0f64, 2.0f64, 20_000usize);
        let h = (s1 - s0) / n as f64;
        let f = |s: f64| {
            let r = s.exp();
            c.rd(r) * 2.0 * std::f64::consts::PI * r * r
        };
        let mut sum = f(s0) + f(s1);
        for i in 1..n {
            sum += f(s0 + i as f64 * h) * if i % 2 == 1 { 4.0 } else { 2.0 };
        }
        sum * h / 3.0
    }

    #[test]
    fn dipole_integral_matches_jensen_closed_form() {
        for p in [skin1(SubsurfaceModel::Dipole), {
            // Marble: very different albedo.
            Profile::new(&Subsurface {
                sigma_a_per_mm: Vec3::new(0.0021, 0.0041, 0.0071),
                sigma_s_prime_per_mm: Vec3::new(2.19, 2.62, 3.00),
                eta: 1.3,
                model: SubsurfaceModel::Dipole,
            })
        }] {
            for c in &p.channels {
                let numeric = numeric_total(c);
                let closed = c.total_reflectance();
                assert!(
                    (numeric - closed).abs() < 0.01 * closed,
                    "numeric {numeric} vs closed form {closed}"
                );
                // The disk integral tends to the total and matches quadrature at finite radius.
                assert!((c.disk_integral(100.0) - closed).abs() < 1e-6 * closed);
            }
        }
    }

    #[test]
    fn exponential_is_normalised_to_dipole_reflectance() {
        let e = skin1(SubsurfaceModel::Exponential);
        let d = skin1(SubsurfaceModel::Dipole);
        for c in 0..3 {
            let numeric = numeric_total(&e.channels[c]);
            let target = d.channels[c].total_reflectance();
            assert!((numeric - target).abs() < 0.01 * target);
        }
    }

    #[test]
    fn disk_integral_matches_quadrature() {
        let p = skin1(SubsurfaceModel::Dipole);
        let a = 0.0015; // 1.5 mm
        for c in &p.channels {
            let n = 200_000;
            let h = a / n as f64;
            let mut sum = 0.0;
            for i in 0..n {
                let r = (i as f64 + 0.5) * h;
                sum += c.rd(r) * 2.0 * std::f64::consts::PI * r * h;
            }
            let closed = c.disk_integral(a);
            assert!((sum - closed).abs() < 1e-3 * closed, "{sum} vs {closed}");
        }
    }

    #[test]
    fn skin_reflectance_is_plausible() {
        // Skin reflects much more red than blue.
        let r = skin1(SubsurfaceModel::Dipole).total_reflectance();
        assert!(r.x > r.y && r.y > r.z && r.x < 1.0 && r.z > 0.0);
    }
}
