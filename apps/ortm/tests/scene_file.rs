//! Scene files: values, units, material assignment, lights, textures.

mod common;

use common::{data, head_obj};

use glam::{Vec2, Vec3};
use ortm::scene::file::srgb_to_linear;
use ortm::scene::{
    Albedo, Light, SubsurfaceModel, load_scene, load_scene_with_warnings, subsurface_preset,
};

#[test]
fn two_quads_scene_loads_with_units_materials_and_lights() {
    let (scene, warnings) = load_scene_with_warnings(&data("scene/two_quads.toml")).unwrap();
    assert_eq!(scene.name, "two quads");
    assert_eq!(scene.lightmap_size, (64, 32));
    assert!(!scene.allow_uv_overlap);
    // 0.02 m per unit: the mesh spans 2 × 1 units = 0.04 × 0.02 m.
    let max = scene
        .mesh
        .positions_m
        .iter()
        .fold(Vec3::ZERO, |m, p| m.max(*p));
    assert!((max - Vec3::new(0.04, 0.02, 0.0)).length() < 1e-7, "{max}");
    // usemtl paint → material[1], usemtl wood → material[0].
    assert_eq!(scene.materials[0].name, "wood");
    assert_eq!(scene.materials[1].name, "paint");
    let mats: Vec<u32> = scene.mesh.triangles.iter().map(|t| t.material).collect();
    assert_eq!(mats, vec![1, 1, 0, 0]);
    match scene.materials[0].albedo {
        Albedo::Constant(c) => assert_eq!(c, Vec3::new(0.5, 0.25, 0.125)),
        Albedo::Texture(_) => panic!("constant albedo expected"),
    }
    // Preset with an overridden model.
    let marble = subsurface_preset("marble").unwrap();
    let ss = scene.materials[1].subsurface.expect("subsurface");
    assert_eq!(ss.sigma_a_per_mm, marble.sigma_a_per_mm);
    assert_eq!(ss.sigma_s_prime_per_mm, marble.sigma_s_prime_per_mm);
    assert_eq!(ss.model, SubsurfaceModel::Exponential);
    assert!(scene.materials[0].subsurface.is_none());
    // Lights: metres as written, directions normalised, default colour white.
    assert_eq!(scene.lights.len(), 3);
    assert_eq!(
        scene.lights[0],
        Light::Point {
            position_m: Vec3::new(0.01, 0.01, 0.05),
            color: Vec3::ONE,
            intensity_w_sr: 2.5
        }
    );
    match scene.lights[1] {
        Light::Spot {
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
            ..
        } => {
            assert!((direction - Vec3::NEG_Z).length() < 1e-7);
            assert_eq!(color, Vec3::new(1.0, 0.5, 0.25));
            assert_eq!((intensity_w_sr, inner_deg, outer_deg), (4.0, 20.0, 30.0));
        }
        other => panic!("spot expected, got {other:?}"),
    }
    match scene.lights[2] {
        Light::Directional {
            direction,
            irradiance_w_m2,
            ..
        } => {
            let want = Vec3::new(0.0, -1.0, -1.0) / 2f32.sqrt();
            assert!((direction - want).length() < 1e-6);
            assert_eq!(irradiance_w_m2, 100.0);
        }
        other => panic!("directional expected, got {other:?}"),
    }
    // The OBJ's missing mtllib is a warning, not an error.
    assert!(warnings.iter().any(|w| w.contains("two_quads_missing.mtl")));
}

#[test]
fn unmatched_usemtl_uses_default_then_first_material() {
    let dir = tempfile::tempdir().unwrap();
    let obj = data("scene/two_quads.obj");
    let write = |name: &str, materials: &str| {
        let p = dir.path().join(name);
        let text = format!(
            "mesh = {:?}\nmetres_per_unit = 1\n{materials}",
            obj.to_str().unwrap()
        );
        std::fs::write(&p, text).unwrap();
        p
    };
    // `paint` matches material 2; `wood` has no match → `default` (material 1).
    let p = write(
        "with_default.toml",
        "[[material]]\nname = \"x\"\nalbedo = [1, 1, 1]\n\
         [[material]]\nname = \"default\"\nalbedo = [1, 1, 1]\n\
         [[material]]\nname = \"paint\"\nalbedo = [1, 1, 1]\n",
    );
    let (scene, warnings) = load_scene_with_warnings(&p).unwrap();
    let mats: Vec<u32> = scene.mesh.triangles.iter().map(|t| t.material).collect();
    assert_eq!(mats, vec![2, 2, 1, 1]);
    assert!(
        warnings.iter().any(|w| w.contains("usemtl wood")),
        "{warnings:?}"
    );
    // Without `default`, unmatched names use the first material.
    let p = write(
        "without_default.toml",
        "[[material]]\nname = \"x\"\nalbedo = [1, 1, 1]\n\
         [[material]]\nname = \"wood\"\nalbedo = [1, 1, 1]\n",
    );
    let scene = load_scene(&p).unwrap();
    let mats: Vec<u32> = scene.mesh.triangles.iter().map(|t| t.material).collect();
    assert_eq!(mats, vec![0, 0, 1, 1]);
    // Default lightmap size and scene name from the file stem.
    assert_eq!(scene.lightmap_size, (256, 256));
    assert_eq!(scene.name, "without_default");
}

#[test]
fn albedo_texture_is_decoded_from_srgb_to_linear() {
    let dir = tempfile::tempdir().unwrap();
    // 2×1 sRGB image: left pixel (255, 128, 0), right pixel (10, 200, 64).
    let img = image::RgbImage::from_raw(2, 1, vec![255, 128, 0, 10, 200, 64]).unwrap();
    img.save(dir.path().join("albedo.png")).unwrap();
    let obj = data("scene/two_quads.obj");
    let scene_path = dir.path().join("tex.toml");
    std::fs::write(
        &scene_path,
        format!(
            "mesh = {:?}\nmetres_per_unit = 1\n[[material]]\nname = \"default\"\n\
             albedo_texture = \"albedo.png\"\n",
            obj.to_str().unwrap()
        ),
    )
    .unwrap();
    let scene = load_scene(&scene_path).unwrap();
    let Albedo::Texture(t) = &scene.materials[0].albedo else {
        panic!("texture expected");
    };
    assert_eq!((t.width, t.height), (2, 1));
    let expect = |c: [u8; 3]| Vec3::from_array(c.map(|x| srgb_to_linear(x as f32 / 255.0)));
    assert!((t.data[0] - expect([255, 128, 0])).length() < 1e-6);
    assert!((t.data[1] - expect([10, 200, 64])).length() < 1e-6);
    // Mid-grey 128 is about 0.2159 linear (sRGB definition).
    assert!((t.data[0].y - 0.2159).abs() < 1e-3);
    // Sampling at the right texel's centre returns it.
    let at = scene.materials[0].albedo.at(Vec2::new(0.75, 0.5));
    assert!((at - t.data[1]).length() < 1e-6);
}

#[test]
fn explicit_subsurface_coefficients_and_head_style_scene() {
    let dir = tempfile::tempdir().unwrap();
    let head = head_obj();
    let p = dir.path().join("head.toml");
    std::fs::write(
        &p,
        format!(
            "mesh = {:?}\nmetres_per_unit = 0.34\n[lightmap]\nwidth = 512\nheight = 512\n\
             [[material]]\nname = \"skin\"\nalbedo = [0.8, 0.6, 0.5]\n\
             subsurface = {{ sigma_a = [0.032, 0.17, 0.48], sigma_s_prime = [0.74, 0.88, 1.01], \
             eta = 1.4 }}\n",
            head.to_str().unwrap()
        ),
    )
    .unwrap();
    let (scene, warnings) = load_scene_with_warnings(&p).unwrap();
    assert_eq!(scene.mesh.triangles.len(), 17_684);
    assert!(scene.mesh.triangles.iter().all(|t| t.material == 0));
    let ss = scene.materials[0].subsurface.unwrap();
    let skin1 = subsurface_preset("skin1").unwrap();
    assert_eq!(ss.sigma_a_per_mm, skin1.sigma_a_per_mm);
    assert_eq!(ss.eta, 1.4);
    assert_eq!(ss.model, SubsurfaceModel::Dipole);
    // `usemtl defaultMat` has no [[material]] of that name → warning, falls back to `skin`.
    assert!(
        warnings.iter().any(|w| w.contains("defaultMat")),
        "{warnings:?}"
    );
}
