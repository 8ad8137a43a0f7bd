//! glTF 2.0 scenes: files the tests write (a `.gltf` with a `.bin`, one with an embedded
//! buffer, a `.glb`, nested node transforms, `KHR_lights_punctual`) load to the same texels and
//! bake to the same transfer maps as the equivalent OBJ + TOML; light units are converted from
//! candela and lux by 683 lm/W (checked against hand-computed values).

mod common;

use std::path::{Path, PathBuf};

use common::{ok, ortm};
use glam::Vec3;
use ortm::bake::texels::TexelGrid;
use ortm::bake_dir::read_map_file;
use ortm::scene::charts::{Face, charted_mesh};
use ortm::scene::gltf_write::{BufferMode, GltfWrite, write_gltf};
use ortm::scene::obj::write_obj;
use ortm::scene::{Albedo, Light, Material, Mesh, Scene, load_scene_with_warnings};

/// Lightmap side of the room.
const SIZE: u32 = 32;

/// A room corner (floor, two walls) with a box on the floor, every coordinate a multiple of
/// 1/8 m so node transforms by powers of two and such translations are exact in f32.
fn room() -> (Mesh, Vec<Material>, Vec<Light>) {
    let f = |o: [f32; 3], e1: [f32; 3], e2: [f32; 3], air: [f32; 3], m: u32| {
        Face::oriented(
            Vec3::from(o),
            Vec3::from(e1),
            Vec3::from(e2),
            Vec3::from(air),
            m,
        )
    };
    let faces = [
        f(
            [0.0; 3],
            [2.0, 0.0, 0.0],
            [0.0, 0.0, 2.0],
            [0.0, 1.0, 0.0],
            0,
        ),
        f(
            [0.0; 3],
            [2.0, 0.0, 0.0],
            [0.0, 1.5, 0.0],
            [0.0, 0.0, 1.0],
            0,
        ),
        f(
            [0.0; 3],
            [0.0, 0.0, 2.0],
            [0.0, 1.5, 0.0],
            [1.0, 0.0, 0.0],
            0,
        ),
        // The box [0.75, 1.25] × [0, 0.5] × [0.75, 1.25]: top and four sides.
        f(
            [0.75, 0.5, 0.75],
            [0.5, 0.0, 0.0],
            [0.0, 0.0, 0.5],
            [0.0, 1.0, 0.0],
            1,
        ),
        f(
            [0.75, 0.0, 1.25],
            [0.5, 0.0, 0.0],
            [0.0, 0.5, 0.0],
            [0.0, 0.0, 1.0],
            1,
        ),
        f(
            [0.75, 0.0, 0.75],
            [0.5, 0.0, 0.0],
            [0.0, 0.5, 0.0],
            [0.0, 0.0, -1.0],
            1,
        ),
        f(
            [0.75, 0.0, 0.75],
            [0.0, 0.0, 0.5],
            [0.0, 0.5, 0.0],
            [-1.0, 0.0, 0.0],
            1,
        ),
        f(
            [1.25, 0.0, 0.75],
            [0.0, 0.0, 0.5],
            [0.0, 0.5, 0.0],
            [1.0, 0.0, 0.0],
            1,
        ),
    ];
    let mesh = charted_mesh(&faces, SIZE);
    let mat = |name: &str, c: [f32; 3]| Material {
        name: name.into(),
        albedo: Albedo::Constant(Vec3::from(c)),
        subsurface: None,
    };
    let materials = vec![
        mat("walls", [0.5, 0.5, 0.5]),
        mat("box", [0.75, 0.25, 0.125]),
    ];
    let lights = vec![
        Light::Point {
            position_m: Vec3::new(1.0, 1.25, 1.5),
            color: Vec3::ONE,
            intensity_w_sr: 0.5,
        },
        Light::Directional {
            direction: Vec3::new(0.0, -1.0, 0.0),
            color: Vec3::new(1.0, 0.875, 0.75),
            irradiance_w_m2: 2.0,
        },
    ];
    (mesh, materials, lights)
}

/// Writes the room as OBJ + TOML (positions in metres, normals as `vn`) and returns the
/// scene file.
fn write_obj_scene(dir: &Path, mesh: &Mesh, materials: &[Material], lights: &[Light]) -> PathBuf {
    let names: Vec<String> = materials.iter().map(|m| m.name.clone()).collect();
    write_obj(&dir.join("room.obj"), mesh, &names).unwrap();
    let mut toml = format!(
        "mesh = \"room.obj\"\nmetres_per_unit = 1.0\n[lightmap]\nwidth = {SIZE}\nheight = {SIZE}\n"
    );
    for m in materials {
        let Albedo::Constant(c) = m.albedo else {
            unreachable!()
        };
        toml += &format!(
            "[[material]]\nname = \"{}\"\nalbedo = [{}, {}, {}]\n",
            m.name, c.x, c.y, c.z
        );
    }
    toml += &ortm::scene::file::lights_to_toml(lights);
    let path = dir.join("room.toml");
    std::fs::write(&path, toml).unwrap();
    path
}

/// Loads a scene and sets its lightmap to SIZE² (as `--size` does).
fn load(path: &Path) -> (Scene, Vec<String>) {
    let (mut s, w) = load_scene_with_warnings(path).unwrap();
    s.lightmap_size = (SIZE, SIZE);
    (s, w)
}

/// Nodes from the root inwards: (translation, uniform scale).
type NodeChain = Vec<(Vec3, f32)>;

/// The room's glTF variants: (file name, node chain, buffer placement). The node chains
/// compose to the identity (2 · (t2 + 0.5 · p) + t1 = p for t1 = −2 t2), so world positions
/// are the OBJ's exactly.
fn variants() -> Vec<(&'static str, NodeChain, BufferMode)> {
    let t2 = Vec3::new(0.25, -0.5, 1.0);
    let chain = vec![(-2.0 * t2, 2.0), (t2, 0.5)];
    vec![
        ("room.gltf", chain.clone(), BufferMode::External),
        ("room_embedded.gltf", Vec::new(), BufferMode::Embedded),
        ("room.glb", chain, BufferMode::External),
    ]
}

/// Writes the mesh in the innermost node's frame for `chain` (exact for the chains used).
fn local_mesh(mesh: &Mesh, chain: &[(Vec3, f32)]) -> Mesh {
    let mut m = mesh.clone();
    for p in &mut m.positions_m {
        for &(t, s) in chain {
            *p = (*p - t) / s;
        }
    }
    m
}

/// Asserts two scenes have the same texels (position, normal, area, albedo, material) at
/// SIZE² and the same lights within `light_tol`.
fn assert_same_texels(a: &Scene, b: &Scene, what: &str, light_tol: f32) {
    let (ga, gb) = (TexelGrid::build(a).unwrap(), TexelGrid::build(b).unwrap());
    assert_eq!(ga.texels.len(), gb.texels.len(), "{what}: covered texels");
    for (x, y) in ga.texels.iter().zip(&gb.texels) {
        assert_eq!((x.x, x.y), (y.x, y.y), "{what}");
        assert_eq!(
            x.position_m, y.position_m,
            "{what}: texel ({}, {})",
            x.x, x.y
        );
        assert_eq!(x.normal, y.normal, "{what}: texel ({}, {})", x.x, x.y);
        assert_eq!(x.area_m2, y.area_m2, "{what}");
        assert_eq!(x.albedo, y.albedo, "{what}");
        assert_eq!(x.material, y.material, "{what}");
    }
    assert_eq!(a.lights.len(), b.lights.len(), "{what}: lights");
    for (la, lb) in a.lights.iter().zip(&b.lights) {
        let (ta, tb) = (
            ortm::scene::file::lights_to_toml(&[*la]),
            ortm::scene::file::lights_to_toml(&[*lb]),
        );
        let nums = |t: &str| -> Vec<f32> {
            t.split(|c: char| !(c.is_ascii_digit() || c == '.' || c == '-' || c == 'e'))
                .filter_map(|w| w.parse().ok())
                .collect()
        };
        let (na, nb) = (nums(&ta), nums(&tb));
        assert_eq!(na.len(), nb.len(), "{what}: {ta} vs {tb}");
        for (p, q) in na.iter().zip(&nb) {
            assert!(
                (p - q).abs() <= light_tol * p.abs().max(1.0),
                "{what}: {ta} vs {tb}"
            );
        }
    }
}

#[test]
fn gltf_files_load_to_the_texels_of_the_equivalent_obj_and_toml() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, materials, lights) = room();
    let (obj_scene, _) = load(&write_obj_scene(dir.path(), &mesh, &materials, &lights));
    for (name, chain, buffer) in variants() {
        let local = local_mesh(&mesh, &chain);
        let w = GltfWrite {
            mesh: &local,
            materials: &materials,
            lights: &lights,
            node_chain: chain,
            buffer,
        };
        let path = dir.path().join(name);
        write_gltf(&path, &w).unwrap();
        let (scene, warnings) = load(&path);
        assert!(warnings.is_empty(), "{name}: {warnings:?}");
        // Lights pass through cd and lux and a rotation quaternion: within 1e-6 (measured:
        // the directional light's direction differs by ~1e-8).
        assert_same_texels(&obj_scene, &scene, name, 1e-6);
        assert_eq!(
            format!("{:?}", scene.materials),
            format!("{:?}", obj_scene.materials),
            "{name}"
        );
    }
    assert!(
        dir.path().join("room.bin").is_file(),
        "the .gltf's buffer file"
    );
}

#[test]
fn a_scene_file_names_a_gltf_and_overrides_its_materials() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, materials, lights) = room();
    let w = GltfWrite {
        mesh: &mesh,
        materials: &materials,
        lights: &lights,
        node_chain: Vec::new(),
        buffer: BufferMode::External,
    };
    write_gltf(&dir.path().join("room.glb"), &w).unwrap();
    // No metres_per_unit (glTF is in metres), no lights (the glTF's are used), the box made
    // translucent; `walls` keeps the glTF's albedo.
    let toml = "mesh = \"room.glb\"\n[[material]]\nname = \"box\"\nalbedo = [0.9, 0.9, 0.9]\n\
                subsurface = { preset = \"skin1\" }\n";
    std::fs::write(dir.path().join("s.toml"), toml).unwrap();
    let (scene, warnings) = load_scene_with_warnings(&dir.path().join("s.toml")).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let names: Vec<&str> = scene.materials.iter().map(|m| m.name.as_str()).collect();
    assert_eq!(names, ["box", "walls"]);
    assert!(scene.materials[0].subsurface.is_some());
    let walls = scene
        .mesh
        .triangles
        .iter()
        .filter(|t| t.material == 1)
        .count();
    let boxes = scene
        .mesh
        .triangles
        .iter()
        .filter(|t| t.material == 0)
        .count();
    assert_eq!((walls, boxes), (3 * 2, 5 * 2));
    assert_eq!(scene.lights.len(), 2);
    assert_eq!(scene.lightmap_size, (256, 256));
}

/// Replaces the lights of a written glTF's JSON with `lights` and `nodes` by hand.
fn with_lights(path: &Path, lights: serde_json::Value, nodes: Vec<serde_json::Value>) {
    let mut doc: serde_json::Value = serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap();
    doc["extensionsUsed"] = serde_json::json!(["KHR_lights_punctual"]);
    doc["extensions"] = serde_json::json!({"KHR_lights_punctual": {"lights": lights}});
    let first = doc["nodes"].as_array().unwrap().len();
    let roots: Vec<usize> = (0..nodes.len()).map(|i| first + i).collect();
    doc["nodes"].as_array_mut().unwrap().extend(nodes);
    doc["scenes"][0]["nodes"]
        .as_array_mut()
        .unwrap()
        .extend(roots.into_iter().map(serde_json::Value::from));
    std::fs::write(path, serde_json::to_vec(&doc).unwrap()).unwrap();
}

#[test]
fn khr_lights_punctual_units_are_converted_by_683_lumens_per_watt() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, materials, _) = room();
    let path = dir.path().join("lights.gltf");
    let w = GltfWrite {
        mesh: &mesh,
        materials: &materials,
        lights: &[],
        node_chain: Vec::new(),
        buffer: BufferMode::Embedded,
    };
    write_gltf(&path, &w).unwrap();
    let h = std::f32::consts::FRAC_1_SQRT_2;
    with_lights(
        &path,
        serde_json::json!([
            {"type": "point", "intensity": 683.0, "color": [1.0, 0.5, 0.25]},
            {"type": "spot", "intensity": 100.0,
             "spot": {"innerConeAngle": 0.25, "outerConeAngle": 0.5}},
            {"type": "directional", "intensity": 100000.0},
        ]),
        vec![
            serde_json::json!({"translation": [1.0, 2.0, 3.0],
                               "extensions": {"KHR_lights_punctual": {"light": 0}}}),
            // Rotated −90° about x: the spot's −z axis points down (−y).
            serde_json::json!({"translation": [0.5, 1.5, 0.5], "rotation": [-h, 0.0, 0.0, h],
                               "extensions": {"KHR_lights_punctual": {"light": 1}}}),
            // A parent scale of 3 moves nothing for a directional light; its −z stays −z.
            serde_json::json!({"scale": [3.0, 3.0, 3.0],
                               "extensions": {"KHR_lights_punctual": {"light": 2}}}),
        ],
    );
    let (scene, _) = load_scene_with_warnings(&path).unwrap();
    let close = |a: f32, b: f32| (a - b).abs() <= 1e-5 * b.abs().max(1.0);
    let v_close = |a: Vec3, b: Vec3| (a - b).length() <= 1e-5;
    match scene.lights[..] {
        [
            Light::Point {
                position_m,
                color,
                intensity_w_sr,
            },
            Light::Spot {
                position_m: sp,
                direction,
                intensity_w_sr: si,
                inner_deg,
                outer_deg,
                ..
            },
            Light::Directional {
                direction: dd,
                irradiance_w_m2,
                ..
            },
        ] => {
            // 683 cd / 683 lm/W = 1 W/sr.
            assert!(close(intensity_w_sr, 1.0), "{intensity_w_sr}");
            assert_eq!(position_m, Vec3::new(1.0, 2.0, 3.0));
            assert_eq!(color, Vec3::new(1.0, 0.5, 0.25));
            // 100 cd / 683 = 0.146413 W/sr; cone half-angles 0.25 rad = 14.3239°, 0.5 rad =
            // 28.6479°.
            assert!(close(si, 0.146_413), "{si}");
            assert!(close(inner_deg, 14.323_945) && close(outer_deg, 28.647_89));
            assert!(v_close(sp, Vec3::new(0.5, 1.5, 0.5)), "{sp}");
            assert!(v_close(direction, Vec3::NEG_Y), "{direction}");
            // Sunlight, 100 000 lux / 683 = 146.4129 W/m².
            assert!(close(irradiance_w_m2, 146.412_89), "{irradiance_w_m2}");
            assert!(v_close(dd, Vec3::NEG_Z), "{dd}");
        }
        ref other => panic!("unexpected lights {other:?}"),
    }
}

#[test]
fn gltf_scenes_bake_to_the_same_maps_as_obj_and_toml() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, materials, lights) = room();
    write_obj_scene(dir.path(), &mesh, &materials, &lights);
    let (name, chain, buffer) = variants().swap_remove(2);
    let local = local_mesh(&mesh, &chain);
    let w = GltfWrite {
        mesh: &local,
        materials: &materials,
        lights: &lights,
        node_chain: chain,
        buffer,
    };
    write_gltf(&dir.path().join(name), &w).unwrap();
    let size = SIZE.to_string();
    for (scene, out) in [("room.toml", "a"), (name, "b")] {
        let args = [
            "bake",
            scene,
            "--size",
            &size,
            "--offsets",
            "6",
            "--selector",
            "jittered-grid",
            "-o",
            out,
        ];
        ok(ortm(&args, dir.path()));
    }
    let maps = |out: &str| {
        let mut v: Vec<_> = std::fs::read_dir(dir.path().join(out))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "exr"))
            .collect();
        v.sort();
        v.iter()
            .map(|p| {
                (
                    p.file_name().unwrap().to_owned(),
                    read_map_file(p, None).unwrap().map,
                )
            })
            .collect::<Vec<_>>()
    };
    let (a, b) = (maps("a"), maps("b"));
    assert_eq!(a.len(), 6);
    assert!(
        a == b,
        "the glTF bake's maps differ from the OBJ + TOML bake's"
    );
}

#[test]
fn base_colour_textures_are_linearised_times_the_factor() {
    let dir = tempfile::tempdir().unwrap();
    let floor = Face::oriented(Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::Y, 0);
    let mesh = charted_mesh(&[floor], 16);
    let materials = [Material {
        name: "tiles".into(),
        albedo: Albedo::Constant(Vec3::new(1.0, 0.5, 1.0)),
        subsurface: None,
    }];
    let path = dir.path().join("tiles.gltf");
    let w = GltfWrite {
        mesh: &mesh,
        materials: &materials,
        lights: &[],
        node_chain: Vec::new(),
        buffer: BufferMode::External,
    };
    write_gltf(&path, &w).unwrap();
    // A 2×2 sRGB texture: top row red, green; bottom row blue, sRGB grey 128.
    let px = [[255, 0, 0], [0, 255, 0], [0, 0, 255], [128, 128, 128]];
    let img = image::RgbImage::from_fn(2, 2, |x, y| image::Rgb(px[(2 * y + x) as usize]));
    img.save(dir.path().join("tiles.png")).unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&path).unwrap()).unwrap();
    doc["images"] = serde_json::json!([{"uri": "tiles.png"}]);
    doc["textures"] = serde_json::json!([{"source": 0}]);
    doc["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"] =
        serde_json::json!({"index": 0});
    std::fs::write(&path, serde_json::to_vec(&doc).unwrap()).unwrap();

    let (scene, warnings) = load_scene_with_warnings(&path).unwrap();
    assert!(
        warnings.iter().all(|w| !w.contains("texture")),
        "{warnings:?}"
    );
    let grid = TexelGrid::build(&scene).unwrap();
    // sRGB 128/255 decodes to 0.215861; each texel is the factor × its texture quadrant.
    let grey = 0.215_861;
    let mut seen = [0usize; 4];
    // The UV the test wrote at a surface point (x, 0, z) of the floor, from the mesh itself:
    // the texture is checked against where the surface is, not where the loader put it.
    let written_uv = |p: Vec3| {
        mesh.triangles.iter().find_map(|tri| {
            let [a, b, c] = tri.position.map(|i| {
                let p = mesh.positions_m[i as usize];
                glam::Vec2::new(p.x, p.z)
            });
            let q = glam::Vec2::new(p.x, p.z);
            let d = (b - a).perp_dot(c - a);
            let l1 = (q - a).perp_dot(c - a) / d;
            let l2 = (b - a).perp_dot(q - a) / d;
            let uv = tri.uv.map(|i| mesh.uvs[i as usize]);
            (l1 >= -1e-4 && l2 >= -1e-4 && l1 + l2 <= 1.0 + 1e-4)
                .then(|| uv[0] * (1.0 - l1 - l2) + uv[1] * l1 + uv[2] * l2)
        })
    };
    for t in &grid.texels {
        let uv = written_uv(t.position_m).expect("texel on the floor");
        let (u, v) = (uv.x, uv.y);
        // Inside a quadrant's inner half the bilinear sample is that texel alone.
        let q = match (u, v) {
            (u, v) if u < 0.25 && v > 0.75 => 0,
            (u, v) if u > 0.75 && v > 0.75 => 1,
            (u, v) if u < 0.25 && v < 0.25 => 2,
            (u, v) if u > 0.75 && v < 0.25 => 3,
            _ => continue,
        };
        let want = [
            Vec3::new(1.0, 0.0, 0.0),
            Vec3::new(0.0, 0.5, 0.0),
            Vec3::new(0.0, 0.0, 1.0),
            Vec3::new(grey, 0.5 * grey, grey),
        ][q];
        // The lightmap-space image is sampled at its own texel centres: exact up to float
        // rounding of the centre (measured: 1.5e-5 at a chart's border texel, whose uncovered
        // neighbour is black).
        assert!(
            (t.albedo - want).length() < 1e-4,
            "texel ({}, {}): {} vs {want}",
            t.x,
            t.y,
            t.albedo
        );
        seen[q] += 1;
    }
    assert!(seen.iter().all(|&n| n > 100), "{seen:?}");
}

#[test]
fn bad_gltf_files_are_errors_naming_the_file_and_the_fix() {
    let dir = tempfile::tempdir().unwrap();
    let (mesh, materials, _) = room();
    let err = |p: &Path| load_scene_with_warnings(p).unwrap_err().to_string();
    // Not glTF at all.
    let junk = dir.path().join("junk.glb");
    std::fs::write(&junk, b"glTF\x02\0\0\0 not really").unwrap();
    let e = err(&junk);
    assert!(
        e.contains("junk.glb") && e.contains("glTF 2.0") && e.contains("Fix"),
        "{e}"
    );
    // A .gltf whose .bin is missing.
    let w = GltfWrite {
        mesh: &mesh,
        materials: &materials,
        lights: &[],
        node_chain: Vec::new(),
        buffer: BufferMode::External,
    };
    let lost = dir.path().join("lost.gltf");
    write_gltf(&lost, &w).unwrap();
    std::fs::remove_file(dir.path().join("lost.bin")).unwrap();
    let e = err(&lost);
    assert!(
        e.contains("lost.gltf") && e.contains("buffer") && e.contains(".bin"),
        "{e}"
    );
    // Nodes that are each other's child: refused, not walked for ever.
    let cyclic = dir.path().join("cyclic.gltf");
    write_gltf(
        &cyclic,
        &GltfWrite {
            buffer: BufferMode::Embedded,
            ..w.clone()
        },
    )
    .unwrap();
    let mut doc: serde_json::Value =
        serde_json::from_slice(&std::fs::read(&cyclic).unwrap()).unwrap();
    doc["nodes"] = serde_json::json!([{"children": [1]}, {"children": [0], "mesh": 0}]);
    std::fs::write(&cyclic, serde_json::to_vec(&doc).unwrap()).unwrap();
    let e = err(&cyclic);
    assert!(e.contains("cyclic.gltf"), "{e}");
    // `ortm unwrap` names what it reads and writes.
    let text = common::fails(ortm(&["unwrap", "room.txt", "-o", "out.obj"], dir.path()));
    assert!(
        text.contains("room.txt") && text.contains(".obj, .gltf or .glb"),
        "{text}"
    );
    let text = common::fails(ortm(&["unwrap", "junk.glb", "-o", "out.png"], dir.path()));
    assert!(
        text.contains("out.png") && text.contains("output"),
        "{text}"
    );
}
