//! Measured subsurface-scattering coefficients (named presets for the scene file).
//!
//! The data lives in the `faces` crate ([`faces::skin::MEASURED`]): Jensen, Marschner, Levoy &
//! Hanrahan, *A Practical Model for Subsurface Light Transport* (SIGGRAPH 2001), reduced
//! scattering coefficient σ_s' and absorption coefficient σ_a in **mm⁻¹** for the R, G, B
//! channels, η = 1.3 for every preset. This module turns a row into the scene's [`Subsurface`].
//!
//! Data flow: the scene file's `subsurface = { preset = "skin1" }` is looked up here by
//! [`subsurface_preset`]; an unknown name is reported with the list [`PRESET_NAMES`].
//! Presets use the dipole profile ([`SubsurfaceModel::Dipole`]); the scene file may override
//! the model (`model = "exponential"`, the paper's alternative falloff) and η.

use glam::Vec3;

use super::{Subsurface, SubsurfaceModel};

/// Relative index of refraction used by every preset.
pub const PRESET_ETA: f32 = faces::SKIN_ETA;

const N_PRESETS: usize = faces::MEASURED.len();

/// Names of all presets, for error messages and documentation (the order of Jensen's table).
pub const PRESET_NAMES: [&str; N_PRESETS] = {
    let mut names = [""; N_PRESETS];
    let mut i = 0;
    while i < N_PRESETS {
        names[i] = faces::MEASURED[i].name;
        i += 1;
    }
    names
};

/// The measured coefficients named `name` (case-sensitive, e.g. `"skin1"`), with η = 1.3 and
/// the dipole model; `None` for an unknown name (see [`PRESET_NAMES`]).
pub fn subsurface_preset(name: &str) -> Option<Subsurface> {
    faces::measured(name).map(|m| from_measured(&m, SubsurfaceModel::Dipole))
}

/// A scene [`Subsurface`] from a measured row of the `faces` crate with the given falloff.
pub fn from_measured(m: &faces::MeasuredMaterial, model: SubsurfaceModel) -> Subsurface {
    Subsurface {
        sigma_a_per_mm: Vec3::from_array(m.sigma_a_per_mm),
        sigma_s_prime_per_mm: Vec3::from_array(m.sigma_s_prime_per_mm),
        eta: m.eta,
        model,
    }
}

/// The scene's model for a `faces` falloff.
pub fn model_of(f: faces::Falloff) -> SubsurfaceModel {
    match f {
        faces::Falloff::Dipole => SubsurfaceModel::Dipole,
        faces::Falloff::Exponential => SubsurfaceModel::Exponential,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_listed_name_resolves_and_table_matches_list() {
        assert_eq!(faces::MEASURED.len(), PRESET_NAMES.len());
        for (i, name) in PRESET_NAMES.iter().enumerate() {
            assert_eq!(faces::MEASURED[i].name, *name);
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
