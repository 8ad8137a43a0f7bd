//! Measured subsurface-scattering coefficients and the two falloff models of the paper.
//!
//! Source: Jensen, Marschner, Levoy & Hanrahan, *A Practical Model for Subsurface Light
//! Transport* (SIGGRAPH 2001), table of measured parameters: reduced scattering coefficient
//! σ_s' and absorption coefficient σ_a in **mm⁻¹** for the R, G, B channels; the relative index
//! of refraction is η = 1.3 for all of them. "skin1" and "skin2" are the two skin samples; the
//! other eight materials are kept beside them so that scene files can name any of the table.
//!
//! Falloffs (Sunshine-Hill & Faloutsos 2006, Sec. 4.2: "Jensen's dipole approximation as well
//! as a simple exponential falloff"): [`Falloff::Dipole`] is Jensen's diffusion dipole;
//! [`Falloff::Exponential`] is `R_d(r) = R_total·e^{−r/ℓ}/(2πℓ²)` with mean free path
//! `ℓ = 1/σ_tr`, `σ_tr = √(3σ_a(σ_a + σ_s'))` ([`MeasuredMaterial::exponential_length_mm`]) and
//! `R_total` the dipole's total diffuse reflectance, so both falloffs reflect the same power.

/// Relative index of refraction of every measured material (Jensen et al. 2001).
pub const SKIN_ETA: f32 = 1.3;

/// Which radial profile turns irradiance into subsurface exitance.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Falloff {
    /// Jensen et al. 2001 dipole diffusion profile.
    Dipole,
    /// Normalised exponential falloff with mean free path `1/σ_tr` (same total reflectance as
    /// the dipole).
    Exponential,
}

/// One row of Jensen et al. 2001's table of measured coefficients.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeasuredMaterial {
    /// Name as used in scene files (`"skin1"`, …).
    pub name: &'static str,
    /// Reduced scattering coefficient σ_s' per RGB channel, mm⁻¹.
    pub sigma_s_prime_per_mm: [f32; 3],
    /// Absorption coefficient σ_a per RGB channel, mm⁻¹.
    pub sigma_a_per_mm: [f32; 3],
    /// Relative index of refraction η.
    pub eta: f32,
}

impl MeasuredMaterial {
    /// Effective transport coefficient `σ_tr = √(3σ_a(σ_a + σ_s'))` per channel, mm⁻¹.
    pub fn sigma_tr_per_mm(&self) -> [f32; 3] {
        std::array::from_fn(|c| {
            let a = self.sigma_a_per_mm[c];
            (3.0 * a * (a + self.sigma_s_prime_per_mm[c])).sqrt()
        })
    }

    /// The exponential falloff's mean free path `ℓ = 1/σ_tr` per channel, mm: the distance over
    /// which subsurface light falls by `1/e` (skin1: ≈ 3.7 mm red, 0.7 mm blue).
    pub fn exponential_length_mm(&self) -> [f32; 3] {
        self.sigma_tr_per_mm().map(|s| 1.0 / s.max(1e-12))
    }
}

const fn row(name: &'static str, s: [f32; 3], a: [f32; 3]) -> MeasuredMaterial {
    MeasuredMaterial {
        name,
        sigma_s_prime_per_mm: s,
        sigma_a_per_mm: a,
        eta: SKIN_ETA,
    }
}

/// Jensen et al. 2001's measured materials, in the paper's order.
pub const MEASURED: [MeasuredMaterial; 10] = [
    row("apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
    row("chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
    row("cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
    row("ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    row("marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
    row("potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
    row("skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    row("skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    row("skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
    row("wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
];

/// The two skin samples of the table.
pub const SKIN_NAMES: [&str; 2] = ["skin1", "skin2"];

/// The measured material named `name` (case-sensitive), or `None`.
pub fn measured(name: &str) -> Option<MeasuredMaterial> {
    MEASURED.iter().copied().find(|m| m.name == name)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn skin_rows_are_jensens() {
        let s1 = measured("skin1").unwrap();
        assert_eq!(s1.sigma_s_prime_per_mm, [0.74, 0.88, 1.01]);
        assert_eq!(s1.sigma_a_per_mm, [0.032, 0.17, 0.48]);
        let s2 = measured("skin2").unwrap();
        assert_eq!(s2.sigma_s_prime_per_mm, [1.09, 1.59, 1.79]);
        assert_eq!(s2.sigma_a_per_mm, [0.013, 0.070, 0.145]);
        for n in SKIN_NAMES {
            assert_eq!(measured(n).unwrap().eta, 1.3);
        }
        assert!(measured("Skin1").is_none());
        let mut names: Vec<_> = MEASURED.iter().map(|m| m.name).collect();
        names.dedup();
        assert_eq!(names.len(), MEASURED.len());
    }

    #[test]
    fn exponential_length_is_inverse_sigma_tr() {
        // skin1 red: σ_tr = √(3·0.032·0.772) = 0.2722 mm⁻¹ → ℓ = 3.674 mm.
        let l = measured("skin1").unwrap().exponential_length_mm();
        assert!((l[0] - 3.674).abs() < 0.01, "{l:?}");
        // Red light travels further than blue in skin.
        assert!(l[0] > l[1] && l[1] > l[2]);
    }
}
