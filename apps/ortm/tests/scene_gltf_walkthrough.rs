//! The README's "Bake your own mesh" walkthrough, run as written: this test writes the small
//! glTF it starts from (`target/tmp/walkthrough/room.glb`: a room corner with a box, two
//! materials, a point light, all made in code; no external asset), then runs the walkthrough's
//! `ortm` commands on it (all but the interactive `ortm view`) and checks that the bake records
//! the scene `ortm view --scene room.glb` will load.

mod common;

use std::path::PathBuf;

use common::{ok, ortm};
use glam::Vec3;
use ortm::scene::charts::{Face, charted_mesh};
use ortm::scene::gltf_write::{BufferMode, GltfWrite, write_gltf};
use ortm::scene::{Albedo, Light, Material};

/// The walkthrough's commands after `cd target/tmp/walkthrough` (README, "Bake your own mesh").
const COMMANDS: [&str; 3] = [
    "inspect room.glb -o coverage.png",
    "bake room.glb -o bake --size 64 --offsets 16",
    "bin bake --atlas 256",
];

/// Writes `room.glb` into `dir`: a 2 × 1.5 × 2 m room corner (floor and two walls, grey) with a
/// 0.5 m box (red), a 0.5 W/sr point light, lightmap UVs as TEXCOORD_1.
fn write_room(dir: &std::path::Path) -> PathBuf {
    let f = |o: [f32; 3], e1: [f32; 3], e2: [f32; 3], air: [f32; 3], m: u32| {
        Face::oriented(o.into(), e1.into(), e2.into(), air.into(), m)
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
    let mesh = charted_mesh(&faces, 64);
    let mat = |name: &str, c: [f32; 3]| Material {
        name: name.into(),
        albedo: Albedo::Constant(Vec3::from(c)),
        subsurface: None,
    };
    let path = dir.join("room.glb");
    let w = GltfWrite {
        mesh: &mesh,
        materials: &[mat("walls", [0.7, 0.7, 0.7]), mat("box", [0.8, 0.2, 0.1])],
        lights: &[Light::Point {
            position_m: Vec3::new(1.5, 1.25, 1.5),
            color: Vec3::ONE,
            intensity_w_sr: 0.5,
        }],
        node_chain: Vec::new(),
        buffer: BufferMode::External,
    };
    write_gltf(&path, &w).unwrap();
    path
}

#[test]
fn the_readme_walkthrough_bakes_and_bins_a_gltf() {
    let dir = PathBuf::from(env!("CARGO_TARGET_TMPDIR")).join("walkthrough");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let glb = write_room(&dir);
    for c in COMMANDS {
        let args: Vec<&str> = c.split(' ').collect();
        ok(ortm(&args, &dir));
    }
    assert!(dir.join("coverage.png").is_file());
    assert!(dir.join("bake/atlases.json").is_file());
    // `ortm view bake --scene room.glb` (and `ortm render`) accept the scene: it hashes to the
    // bake's record.
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.join("bake/index.json")).unwrap()).unwrap();
    let scene = ortm::scene::load_scene(&glb).unwrap();
    assert_eq!(
        index["scene_hash"].as_str().unwrap(),
        ortm::scene::scene_hash(&scene)
    );
}
