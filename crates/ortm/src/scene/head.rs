//! The face: the scanned head as an ortm [`Scene`] and the paper's face figures as
//! ortm [`Light`]s, from the plain data of the `faces` crate.
//!
//! - [`head_scene`]: `head.obj` (from [`faces::head_obj_path`]: `$ORTM_HEAD_OBJ` or
//!   `../shared/faces/head.obj`) at [`faces::HEAD_METRES_PER_UNIT`] metres per unit, one skin
//!   material (Jensen et al. 2001 "skin1", dipole or exponential falloff), a 256² lightmap and
//!   the light of the paper's Fig. 5 as its default light;
//! - [`light`] / [`figure_lights`]: a figure's lights in ortm's types (metres, W/sr, W/m²).
//!
//! Images made from the head must carry [`faces::HEAD_CREDIT`].

use glam::Vec3;

use crate::scene::presets::{from_measured, model_of};
use crate::scene::{Albedo, Light, Material, Scene, SceneError};

/// The head scene with the given skin falloff (see the module docs).
pub fn head_scene_with(falloff: faces::Falloff) -> Result<Scene, SceneError> {
    let path = faces::head_obj_path();
    let (mesh, _names, _warnings) =
        crate::scene::obj::load_obj(&path, faces::HEAD_METRES_PER_UNIT as f64)?;
    let skin = faces::measured(faces::HEAD_SKIN)
        .map(|m| from_measured(&m, model_of(falloff)))
        .ok_or_else(|| SceneError::InvalidField {
            path: path.clone(),
            line: None,
            field: "faces::HEAD_SKIN".into(),
            problem: format!("`{}` is not a measured material", faces::HEAD_SKIN),
            fix: "name a row of faces::MEASURED".into(),
        })?;
    let fig5 = faces::figures::figure("fig5_point_light");
    Ok(Scene {
        name: "head".into(),
        mesh,
        materials: vec![Material {
            name: "skin".into(),
            albedo: Albedo::Constant(Vec3::from_array(faces::HEAD_ALBEDO)),
            subsurface: Some(skin),
        }],
        lights: fig5.map(figure_lights).unwrap_or_default(),
        lightmap_size: (
            faces::head::HEAD_LIGHTMAP_SIDE,
            faces::head::HEAD_LIGHTMAP_SIDE,
        ),
        allow_uv_overlap: false,
    })
}

/// The head scene with Jensen's dipole (the default).
pub fn head_scene() -> Result<Scene, SceneError> {
    head_scene_with(faces::Falloff::Dipole)
}

/// A figure light as an ortm light (directions normalised).
pub fn light(l: &faces::FigLight) -> Light {
    match *l {
        faces::FigLight::Point {
            position_m,
            color,
            intensity_w_sr,
        } => Light::Point {
            position_m,
            color,
            intensity_w_sr,
        },
        faces::FigLight::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => Light::Directional {
            direction: direction.normalize(),
            color,
            irradiance_w_m2,
        },
    }
}

/// All lights of a figure.
pub fn figure_lights(f: &faces::Figure) -> Vec<Light> {
    f.lights.iter().map(light).collect()
}
