//! Generated lightmap UVs (`ortm::scene::unwrap`, `ortm unwrap`, and the scene loader when a
//! mesh has no UVs or overlapping ones): no overlapping texels, gutters of at least 2 texels
//! between charts at the chosen size, every triangle with UV area, one texel density for all
//! charts (within 2×); meshes without UVs or with a fully overlapping layout bake.

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::{ok, ortm, output_text};
use glam::Vec3;
use ortm::bake::texels::TexelGrid;
use ortm::scene::{Albedo, Material, Mesh, Scene, load_obj, load_scene_with_warnings};

/// A UV sphere of radius 0.5 m (`rings` × `segments`), shared positions, no `vt`.
fn sphere_obj(rings: usize, segments: usize) -> String {
    let mut s = String::from("v 0 0.5 0\nv 0 -0.5 0\n");
    for r in 1..rings {
        let th = std::f32::consts::PI * r as f32 / rings as f32;
        for k in 0..segments {
            let ph = std::f32::consts::TAU * k as f32 / segments as f32;
            let p = 0.5 * Vec3::new(th.sin() * ph.cos(), th.cos(), -th.sin() * ph.sin());
            s += &format!("v {} {} {}\n", p.x, p.y, p.z);
        }
    }
    let at = |r: usize, k: usize| 3 + (r - 1) * segments + k % segments;
    for k in 0..segments {
        s += &format!("f 1 {} {}\n", at(1, k), at(1, k + 1));
        s += &format!("f 2 {} {}\n", at(rings - 1, k + 1), at(rings - 1, k));
        for r in 1..rings - 1 {
            let (a, b, c, d) = (at(r, k), at(r + 1, k), at(r + 1, k + 1), at(r, k + 1));
            s += &format!("f {a} {b} {c}\nf {a} {c} {d}\n");
        }
    }
    s
}

/// The unit box seen from inside (a closed room: faces counter-clockwise seen from inside, so
/// texels light each other), 8 shared positions, 6 quads; with `uvs`, every face maps to the
/// whole UV square (a fully overlapping texture layout), else no `vt`.
fn box_obj(uvs: bool) -> String {
    let mut s = String::new();
    for p in [
        [0, 0, 0],
        [1, 0, 0],
        [1, 1, 0],
        [0, 1, 0],
        [0, 0, 1],
        [1, 0, 1],
        [1, 1, 1],
        [0, 1, 1],
    ] {
        s += &format!("v {} {} {}\n", p[0], p[1], p[2]);
    }
    if uvs {
        s += "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n";
    }
    for f in [
        [2, 3, 4, 1],
        [8, 7, 6, 5],
        [5, 6, 2, 1],
        [3, 7, 8, 4],
        [4, 8, 5, 1],
        [6, 7, 3, 2],
    ] {
        s += "f";
        for (k, v) in f.iter().enumerate() {
            if uvs {
                s += &format!(" {v}/{}", k + 1);
            } else {
                s += &format!(" {v}");
            }
        }
        s += "\n";
    }
    s
}

/// A one-material scene around `mesh` at `size`².
fn scene_of(mesh: Mesh, size: u32) -> Scene {
    Scene {
        name: "unwrapped".into(),
        mesh,
        materials: vec![Material {
            name: "grey".into(),
            albedo: Albedo::Constant(Vec3::splat(0.5)),
            subsurface: None,
        }],
        lights: Vec::new(),
        lightmap_size: (size, size),
        allow_uv_overlap: false,
    }
}

/// Checks the four properties of `scene`'s lightmap UVs; returns (charts, smallest
/// gap between charts in texels (Chebyshev distance − 1), density ratio).
fn check_layout(scene: &Scene, all_triangles_covered: bool) -> (usize, u32, f64) {
    let grid = TexelGrid::build(scene).unwrap();
    // 1. No texel centre inside two triangles.
    assert_eq!(grid.stats.overlapping, 0);
    // 2. Gutters: between texels of different charts at least 2 empty texels.
    let mut gap = u32::MAX;
    for t in &grid.texels {
        for dy in -3..=3 {
            for dx in -3..=3 {
                if let Some(o) = grid.at(t.x as i32 + dx, t.y as i32 + dy) {
                    let o = &grid.texels[o as usize];
                    if o.chart != t.chart {
                        gap = gap.min(dx.abs().max(dy.abs()) as u32 - 1);
                    }
                }
            }
        }
    }
    assert!(gap >= 2, "gutter of {gap} texels");
    // 3. Every triangle has UV area (and, for meshes coarse enough, covers a texel centre).
    let m = &scene.mesh;
    let mut chart_area: HashMap<u32, (f64, f64)> = HashMap::new();
    for (i, t) in m.triangles.iter().enumerate() {
        let [a, b, c] =
            t.uv.map(|k| m.uvs[k as usize].as_dvec2() * grid.width as f64);
        let uv_area = 0.5 * (b - a).perp_dot(c - a).abs();
        let [p, q, r] = t.position.map(|k| m.positions_m[k as usize].as_dvec3());
        let world = 0.5 * (q - p).cross(r - p).length();
        assert!(uv_area > 0.0, "triangle {i} has no UV area");
        let e = chart_area.entry(grid.triangle_chart[i]).or_default();
        e.0 += uv_area;
        e.1 += world;
    }
    if all_triangles_covered {
        assert_eq!(grid.stats.triangles_without_texels, 0);
    }
    // 4. Texel density (texels per metre) per chart within 2× of each other.
    let d: Vec<f64> = chart_area.values().map(|(uv, w)| (uv / w).sqrt()).collect();
    let ratio = d.iter().cloned().fold(0.0, f64::max) / d.iter().cloned().fold(f64::MAX, f64::min);
    assert!(ratio <= 2.0, "densities {:?}", d);
    (chart_area.len(), gap, ratio)
}

#[test]
fn unwrapped_sphere_box_and_head_have_clean_layouts() {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("sphere.obj");
    std::fs::write(&p, sphere_obj(12, 24)).unwrap();
    let options = ortm::scene::obj::MeshOptions {
        normals: Default::default(),
        allow_missing_uvs: true,
    };
    let load = |p: &Path| {
        ortm::scene::obj::load_obj_mesh(p, 1.0, &Default::default(), &options)
            .unwrap()
            .mesh
    };
    let mut sphere = load(&p);
    let report = ortm::scene::unwrap::unwrap(&mut sphere, (128, 128), &p).unwrap();
    let (charts, gap, ratio) = check_layout(&scene_of(sphere, 128), true);
    println!(
        "UV sphere 128²: {charts} charts, smallest gap {gap} texels, density ratio {ratio:.3}"
    );
    assert_eq!(charts, report.charts);
    // Every triangle lies within 40° of its chart's projection plane, so a chart's UV area per
    // world area is d²·cos θ with cos θ ∈ [cos 40°, 1]: chart densities differ by at most
    // 1/√cos 40° = 1.143 (measured: 22 charts, 2-texel gutters, ratio 1.059).
    assert!(
        ratio <= 1.143,
        "{charts} charts, gap {gap}, density ratio {ratio}"
    );

    let p = dir.path().join("box.obj");
    std::fs::write(&p, box_obj(false)).unwrap();
    let mut cube = load(&p);
    ortm::scene::unwrap::unwrap(&mut cube, (64, 64), &p).unwrap();
    // Six faces, six charts, all of one density (ratio 1 up to float rounding).
    let (charts, gap, ratio) = check_layout(&scene_of(cube, 64), true);
    println!("box 64²: {charts} charts, smallest gap {gap} texels, density ratio {ratio:.3}");
    assert_eq!(charts, 6);
    assert!(ratio < 1.0001, "{ratio}");

    // The head scan (its own UVs replaced): 17k triangles at 512².
    let (mut head, _, _) = load_obj(&common::head_obj(), 0.88).unwrap();
    let report = ortm::scene::unwrap::unwrap(&mut head, (512, 512), &common::head_obj()).unwrap();
    let (charts, gap, ratio) = check_layout(&scene_of(head, 512), false);
    println!("head 512²: {charts} charts, smallest gap {gap} texels, density ratio {ratio:.3}");
    assert_eq!(charts, report.charts);
    // Measured: 4386 charts (the scan's normals are noisy), 2-texel gutters, ratio 1.099.
    assert!(
        ratio <= 1.143,
        "{charts} charts, gap {gap}, density ratio {ratio}"
    );
}

#[test]
fn a_fully_overlapping_layout_is_unwrapped_and_bakes() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.obj"), box_obj(true)).unwrap();
    let toml = "mesh = \"box.obj\"\nmetres_per_unit = 1.0\n[lightmap]\nwidth = 32\nheight = 32\n\
                [[material]]\nname = \"grey\"\nalbedo = [0.5, 0.5, 0.5]\n";
    std::fs::write(dir.path().join("box.toml"), toml).unwrap();
    let (scene, warnings) = load_scene_with_warnings(&dir.path().join("box.toml")).unwrap();
    let w = warnings.join("\n");
    assert!(
        w.contains("box.obj") && w.contains("overlap") && w.contains("generated lightmap UVs"),
        "{w}"
    );
    check_layout(&scene, true);
    let out = ortm(
        &["bake", "box.toml", "--offsets", "4", "-o", "bake"],
        dir.path(),
    );
    let text = output_text(&out);
    assert!(out.status.success(), "{text}");
    assert!(text.contains("generated lightmap UVs"), "{text}");
}

#[test]
fn a_bare_obj_without_uvs_is_a_scene_and_ortm_unwrap_writes_its_uvs() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("room.obj"), box_obj(false)).unwrap();
    // `ortm bake room.obj`: the OBJ is the scene (metres, grey, default light), UVs generated.
    let text = ok(ortm(
        &[
            "bake",
            "room.obj",
            "--size",
            "32",
            "--offsets",
            "4",
            "-o",
            "bake",
        ],
        dir.path(),
    ));
    assert!(
        text.contains("has no lightmap UVs") && text.contains("scene file"),
        "{text}"
    );
    // The UVs were made for the bake's size (2-texel gutters at 32²), and `ortm view` /
    // `ortm render`, which load the scene at the bake's size, make the same ones.
    let obj = dir.path().join("room.obj");
    let scene = ortm::scene::file::load_scene_sized(&obj, Some(32)).unwrap();
    check_layout(&scene, true);
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("bake/index.json")).unwrap())
            .unwrap();
    assert_eq!(
        index["scene_hash"],
        ortm::scene::scene_hash(&scene).as_str()
    );
    // `ortm unwrap` writes them: the OBJ and the glTF read back as scenes whose UVs are used
    // as they are (no warning about generated UVs) and cover the same texels.
    for out in ["room_uv.obj", "room_uv.glb"] {
        let text = ok(ortm(
            &["unwrap", "room.obj", "-o", out, "--size", "64"],
            dir.path(),
        ));
        assert!(text.contains("6 charts"), "{text}");
        let (mut scene, warnings) = load_scene_with_warnings(&dir.path().join(out)).unwrap();
        assert!(
            !warnings
                .iter()
                .any(|w| w.contains("generated lightmap UVs")),
            "{out}: {warnings:?}"
        );
        scene.lightmap_size = (64, 64);
        check_layout(&scene, true);
    }
}
