//! Measured subsurface-scattering coefficients (named presets for the scene file).
//!
//! Source: Jensen, Marschner, Levoy & Hanrahan, *A Practical Model for Subsurface Light
//! Transport* (SIGGRAPH 2001), table of measured parameters: reduced scattering coefficient
//! σ_s' and absorption coefficient σ_a in **mm⁻¹** for the R, G, B channels. The relative
//! index of refraction is η = 1.3 for every preset (as in the paper).
//!
//! Data flow: the scene file's `subsurface = { preset = "skin1" }` is looked up here by
//! [`subsurface_preset`]; an unknown name is reported with the list [`PRESET_NAMES`].
//! Presets use the dipole profile ([`SubsurfaceModel::Dipole`]); the scene file may override
//! the model and η.

use glam::Vec3;

use super::{Subsurface, SubsurfaceModel};

/// Relative index of refraction used by every preset.
pub const PRESET_ETA: f32 = 1.3;

/// `(name, σ_s' [mm⁻¹] RGB, σ_a [mm⁻¹] RGB)`, in the paper's order.
const PRESETS: [(&str, [f32; 3], [f32; 3]); 10] = [
    ("apple", [2.29, 2.39, 1.97], [0.0030, 0.0034, 0.046]),
    ("chicken1", [0.15, 0.21, 0.38], [0.015, 0.077, 0.19]),
    ("cream", [7.38, 5.47, 3.15], [0.0002, 0.0028, 0.0163]),
    ("ketchup", [0.18, 0.07, 0.03], [0.061, 0.97, 1.45]),
    ("marble", [2.19, 2.62, 3.00], [0.0021, 0.0041, 0.0071]),
    ("potato", [0.68, 0.70, 0.55], [0.0024, 0.0090, 0.12]),
    ("skimmilk", [0.70, 1.22, 1.90], [0.0014, 0.0025, 0.0142]),
    ("skin1", [0.74, 0.88, 1.01], [0.032, 0.17, 0.48]),
    ("skin2", [1.09, 1.59, 1.79], [0.013, 0.070, 0.145]),
    ("wholemilk", [2.55, 3.21, 3.77], [0.0011, 0.0024, 0.014]),
];

/// Names of all presets, for error messages and documentation.
pub const PRESET_NAMES: [&str; 10] = [
    "apple",
    "chicken1",
    "cream",
    "ketchup",
    "marble",
    "potato",
    "skimmilk",
    "skin1",
    "skin2",
    "wholemilk",
];

/// The measured coefficients named `name` (case-sensitive, e.g. `"skin1"`), with η = 1.3 and
/// the dipole model; `None` for an unknown name (see [`PRESET_NAMES`]).
pub fn subsurface_preset(name: &str) -> Option<Subsurface> {
    PRESETS
        .iter()
        .find(|(n, _, _)| *n == name)
        .map(|&(_, s, a)| Subsurface {
            sigma_a_per_mm: Vec3::from_array(a),
            sigma_s_prime_per_mm: Vec3::from_array(s),
            eta: PRESET_ETA,
            model: SubsurfaceModel::Dipole,
        })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_name_resolves_and_table_matches_list() {
        assert_eq!(PRESETS.len(), PRESET_NAMES.len());
        for (i, name) in PRESET_NAMES.iter().enumerate() {
            assert_eq!(PRESETS[i].0, *name);
            let p = subsurface_preset(name).expect("listed preset resolves");
            assert_eq!(p.eta, PRESET_ETA);
            // Physical sanity: strictly positive coefficients.
            assert!(p.sigma_a_per_mm.min_element() > 0.0);
            assert!(p.sigma_s_prime_per_mm.min_element() > 0.0);
        }
        assert!(subsurface_preset("Skin1").is_none());
        assert!(subsurface_preset("").is_none());
    }

    #[test]
    fn skin1_values_are_the_papers() {
        let p = subsurface_preset("skin1").unwrap();
        assert_eq!(p.sigma_s_prime_per_mm, Vec3::new(0.74, 0.88, 1.01));
        assert_eq!(p.sigma_a_per_mm, Vec3::new(0.032, 0.17, 0.48));
        assert_eq!(p.model, SubsurfaceModel::Dipole);
    }
}
