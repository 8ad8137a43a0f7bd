//! Normals of meshes without `vn`: the crease angle (default 60°) and OBJ smoothing groups keep
//! hard edges hard; `crease_angle_deg = 180` smooths every shared position (the old rule).

mod common;

use std::path::Path;

use ortm::bake::texels::TexelGrid;
use ortm::scene::normals::{NormalRule, crease_normals};
use ortm::scene::obj::smooth_normals;
use ortm::scene::{load_obj, load_scene_with_warnings};

/// The unit box as OBJ: 8 shared positions, 6 quads (counter-clockwise from outside), each
/// with its own UV rectangle in a 3 × 2 grid; `groups` writes an `s` line before each face.
fn box_obj(groups: Option<[&str; 6]>) -> String {
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
    let faces = [
        [1, 4, 3, 2],
        [5, 6, 7, 8],
        [1, 2, 6, 5],
        [4, 8, 7, 3],
        [1, 5, 8, 4],
        [2, 3, 7, 6],
    ];
    for i in 0..6 {
        let (u0, v0) = ((i % 3) as f32 / 3.0 + 0.03, (i / 3) as f32 / 2.0 + 0.03);
        let (u1, v1) = (u0 + 1.0 / 3.0 - 0.06, v0 + 0.5 - 0.06);
        s += &format!("vt {u0} {v0}\nvt {u1} {v0}\nvt {u1} {v1}\nvt {u0} {v1}\n");
    }
    for (i, f) in faces.iter().enumerate() {
        if let Some(g) = groups {
            s += &format!("s {}\n", g[i]);
        }
        s += "f";
        for (k, v) in f.iter().enumerate() {
            s += &format!(" {v}/{}", 4 * i + k + 1);
        }
        s += "\n";
    }
    s
}

/// Loads the box through a scene file with `extra` lines at 64² and returns, per face, the
/// largest angle (degrees) between a texel's normal and the face's geometric normal.
fn face_normal_spread(dir: &Path, obj: &str, extra: &str) -> [f32; 6] {
    std::fs::write(dir.join("box.obj"), obj).unwrap();
    let toml = format!(
        "mesh = \"box.obj\"\nmetres_per_unit = 1.0\n{extra}\n[lightmap]\nwidth = 64\n\
         height = 64\n[[material]]\nname = \"grey\"\nalbedo = [0.5, 0.5, 0.5]\n"
    );
    std::fs::write(dir.join("box.toml"), toml).unwrap();
    let (scene, _) = load_scene_with_warnings(&dir.join("box.toml")).unwrap();
    let grid = TexelGrid::build(&scene).unwrap();
    let mut spread = [0.0f32; 6];
    let mut seen = [0usize; 6];
    for t in &grid.texels {
        let face = t.triangle as usize / 2; // each quad is two triangles, in file order
        let angle = t
            .normal
            .dot(t.face_normal)
            .clamp(-1.0, 1.0)
            .acos()
            .to_degrees();
        spread[face] = spread[face].max(angle);
        seen[face] += 1;
    }
    assert!(seen.iter().all(|&n| n > 50), "texels per face {seen:?}");
    spread
}

#[test]
fn a_box_without_normals_keeps_flat_faces() {
    let dir = tempfile::tempdir().unwrap();
    // Default crease angle (60°): the box's 90° edges are hard, every texel normal of a face is
    // the face normal (measured: 0° on every face).
    let flat = face_normal_spread(dir.path(), &box_obj(None), "");
    assert!(flat.iter().all(|&a| a < 1e-3), "{flat:?}");
    // 180° smooths every shared position: at the corners the normal is the corner's diagonal,
    // 54.7° off every face normal, and interpolation spreads it over the face (measured:
    // ~50° at the texels nearest the corners of a 64² map).
    let round = face_normal_spread(dir.path(), &box_obj(None), "crease_angle_deg = 180");
    assert!(round.iter().all(|&a| a > 35.0), "{round:?}");
    // Smoothing groups win over the angle: all faces in group 1 shade round, each face in its
    // own group (or `s off`) stays flat.
    let one = face_normal_spread(dir.path(), &box_obj(Some(["1"; 6])), "");
    assert!(one.iter().all(|&a| a > 35.0), "{one:?}");
    let own = ["1", "2", "3", "4", "off", "0"];
    let split = face_normal_spread(dir.path(), &box_obj(Some(own)), "");
    assert!(split.iter().all(|&a| a < 1e-3), "{split:?}");
}

#[test]
fn a_bad_crease_angle_names_the_field() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("box.obj"), box_obj(None)).unwrap();
    let toml = "mesh = \"box.obj\"\nmetres_per_unit = 1.0\ncrease_angle_deg = 200\n\
                [[material]]\nname = \"grey\"\nalbedo = [0.5, 0.5, 0.5]\n";
    std::fs::write(dir.path().join("box.toml"), toml).unwrap();
    let e = load_scene_with_warnings(&dir.path().join("box.toml"))
        .unwrap_err()
        .to_string();
    assert!(
        e.contains("box.toml:3") && e.contains("crease_angle_deg") && e.contains("180"),
        "{e}"
    );
}

/// The head scan has no `vn` and no `s`: its normals (and so its `scene_hash` and every head
/// figure) are those of smoothing every shared position. The default crease splits 766 of its
/// corners (measured), so the head's scene files say `crease_angle_deg = 180`; this checks
/// that they load with exactly the built-in head's normals.
#[test]
fn the_head_scene_files_keep_the_built_in_heads_normals() {
    let path = common::head_obj();
    let (mesh, _, _) = load_obj(&path, 0.88).unwrap();
    let (_, index) = crease_normals(
        &mesh.positions_m,
        &mesh.triangles,
        None,
        NormalRule::default(),
    );
    let split = index
        .iter()
        .zip(&mesh.triangles)
        .filter(|(i, t)| **i != t.position)
        .count();
    assert!(
        split > 0,
        "the default crease would change the head's normals"
    );
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    for file in [
        "../../crates/faces/head.toml",
        "tests/data/render/head.toml",
    ] {
        let (scene, _) = load_scene_with_warnings(&root.join(file)).unwrap();
        let m = &scene.mesh;
        let plain = smooth_normals(&m.positions_m, &m.triangles);
        assert!(
            m.normals == plain,
            "{file}: normals differ from the plain rule"
        );
        assert!(m.triangles.iter().all(|t| t.normal == t.position), "{file}");
        assert_eq!(m.triangles.len(), mesh.triangles.len(), "{file}");
    }
}
