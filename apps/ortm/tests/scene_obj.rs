//! OBJ loading: counts, triangulation order, welding, materials, normals, and the head scan.

mod common;

use std::path::PathBuf;

use common::{data, head_obj};

use glam::Vec3;
use ortm::scene::obj::{ObjOptions, load_obj_with, smooth_normals};
use ortm::scene::{MeshTriangle, load_obj};

/// Writes `text` to a fresh temporary OBJ file.
fn temp_obj(text: &str) -> (tempfile::TempDir, PathBuf) {
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("mesh.obj");
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

#[test]
fn head_scan_counts() {
    let (mesh, names, warnings) = load_obj(&head_obj(), 0.34).expect("head.obj loads");
    assert_eq!(mesh.positions_m.len(), 8_844);
    assert_eq!(mesh.uvs.len(), 35_368);
    assert_eq!(mesh.triangles.len(), 17_684);
    // No `vn` in the file: one computed normal per position, unit length.
    assert_eq!(mesh.normals.len(), 8_844);
    assert!(mesh.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    assert!(mesh.triangles.iter().all(|t| t.normal == t.position));
    // One `usemtl defaultMat`; its `mtllib head.mtl` is missing → a warning.
    assert_eq!(names, vec!["defaultMat".to_string()]);
    assert!(
        warnings.iter().any(|w| w.contains("head.mtl")),
        "{warnings:?}"
    );
    // 16 triangles whose UVs collapse to a line at the file's 5-decimal precision (found
    // with an independent scan of the file) are kept, with a warning.
    assert!(
        warnings
            .iter()
            .any(|w| w.contains("16 triangles have zero UV area")),
        "{warnings:?}"
    );
    // Extent in metres is the README's model-unit extent × 0.34.
    let max_x = mesh
        .positions_m
        .iter()
        .map(|p| p.x)
        .fold(f32::MIN, f32::max);
    assert!((max_x - 0.232 * 0.34).abs() < 0.001 * 0.34, "max x {max_x}");
    // Every UV inside the unit square.
    assert!(
        mesh.uvs
            .iter()
            .all(|uv| uv.min_element() >= 0.0 && uv.max_element() <= 1.0)
    );
}

#[test]
fn quads_split_into_fans_with_materials_in_first_use_order() {
    let (mesh, names, warnings) = load_obj(&data("scene/two_quads.obj"), 2.0).unwrap();
    // 6 positions (welded across the two groups), 8 UVs, 2 quads → 4 triangles.
    assert_eq!(mesh.positions_m.len(), 6);
    assert_eq!(mesh.uvs.len(), 8);
    assert_eq!(mesh.triangles.len(), 4);
    assert_eq!(names, vec!["paint".to_string(), "wood".to_string()]);
    let mats: Vec<u32> = mesh.triangles.iter().map(|t| t.material).collect();
    assert_eq!(mats, vec![0, 0, 1, 1]);
    // Quad a b c d → (a b c), (a c d), checked through the positions (model units × 2).
    let corners = |t: &MeshTriangle| t.position.map(|i| mesh.positions_m[i as usize] / 2.0);
    assert_eq!(
        corners(&mesh.triangles[0]),
        [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0)]
    );
    assert_eq!(
        corners(&mesh.triangles[1]),
        [Vec3::ZERO, Vec3::new(1.0, 1.0, 0.0), Vec3::Y]
    );
    // Shared edge 2–5 is the same welded position in both groups.
    assert_eq!(mesh.triangles[0].position[1], mesh.triangles[2].position[0]);
    // The UVs follow the corners.
    let uv = |t: usize, k: usize| mesh.uvs[mesh.triangles[t].uv[k] as usize];
    assert_eq!(uv(2, 1).to_array(), [1.0, 0.0]);
    assert_eq!(uv(3, 2).to_array(), [0.5, 1.0]);
    // Flat quads facing +z: all normals +z.
    assert!(mesh.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    assert!(warnings.iter().any(|w| w.contains("two_quads_missing.mtl")));
}

#[test]
fn polygons_negative_indices_and_file_normals() {
    // A pentagon written with negative (relative) indices and explicit normals.
    let obj = "v 0 0 0\nv 2 0 0\nv 3 1 0\nv 1 2 0\nv -1 1 0\n\
               vt 0 0\nvt 1 0\nvt 1 1\nvt 0.5 1\nvt 0 1\n\
               vn 0 0 5\n\
               f -5/-5/1 -4/-4/1 -3/-3/1 -2/-2/1 -1/-1/1\n";
    let (_dir, p) = temp_obj(obj);
    let (mesh, names, _) = load_obj(&p, 1.0).unwrap();
    assert_eq!(mesh.triangles.len(), 3);
    assert_eq!(names, vec![String::new()]);
    // Fan from the first corner: (0,1,2), (0,2,3), (0,3,4).
    let expected = [[0, 1, 2], [0, 2, 3], [0, 3, 4]];
    for (t, e) in mesh.triangles.iter().zip(expected) {
        let got = t.position.map(|i| mesh.positions_m[i as usize]);
        let want = e.map(|k: usize| {
            [
                Vec3::ZERO,
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(3.0, 1.0, 0.0),
                Vec3::new(1.0, 2.0, 0.0),
                Vec3::new(-1.0, 1.0, 0.0),
            ][k]
        });
        assert_eq!(got, want);
    }
    // The file's normal (0, 0, 5) is used, normalised.
    assert_eq!(mesh.normals, vec![Vec3::Z]);
    assert!(mesh.triangles.iter().all(|t| t.normal == [0, 0, 0]));
}

#[test]
fn smooth_normals_of_an_octahedron_point_along_the_vertices() {
    // Closed regular octahedron: by symmetry the area-weighted normal at each vertex is
    // the vertex direction.
    let v = [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ];
    let mut obj = String::new();
    for p in v {
        obj += &format!("v {} {} {}\n", p.x, p.y, p.z);
    }
    obj += "vt 0.1 0.1\nvt 0.9 0.1\nvt 0.5 0.9\n";
    // Faces counter-clockwise seen from outside.
    let faces = [
        [1, 3, 5],
        [3, 2, 5],
        [2, 4, 5],
        [4, 1, 5],
        [3, 1, 6],
        [2, 3, 6],
        [4, 2, 6],
        [1, 4, 6],
    ];
    for f in faces {
        obj += &format!("f {}/1 {}/2 {}/3\n", f[0], f[1], f[2]);
    }
    let (_dir, p) = temp_obj(&obj);
    let (mesh, _, _) = load_obj(&p, 1.0).unwrap();
    for (i, n) in mesh.normals.iter().enumerate() {
        let p = mesh.positions_m[i];
        assert!((*n - p).length() < 1e-6, "vertex {p}: normal {n}");
    }
    // Each face is counter-clockwise seen from outside: geometric normal points outward.
    for t in &mesh.triangles {
        let [a, b, c] = t.position.map(|i| mesh.positions_m[i as usize]);
        assert!((b - a).cross(c - a).dot(a + b + c) > 0.0);
    }
}

#[test]
fn smooth_normals_weight_by_area() {
    // Two triangles meeting at vertex 0 with normals +z (area 2) and +x (area 0.5): the
    // area-weighted normal is (0.5, 0, 2)/|…|.
    let positions = vec![
        Vec3::ZERO,
        Vec3::new(2.0, 0.0, 0.0),
        Vec3::new(0.0, 2.0, 0.0),
        Vec3::new(0.0, 1.0, 0.0),
        Vec3::new(0.0, 0.0, 1.0),
    ];
    let tri = |p: [u32; 3]| MeshTriangle {
        position: p,
        uv: [0; 3],
        normal: p,
        material: 0,
    };
    let n = smooth_normals(&positions, &[tri([0, 1, 2]), tri([0, 3, 4])]);
    let want = Vec3::new(0.5, 0.0, 2.0).normalize();
    assert!((n[0] - want).length() < 1e-6, "{}", n[0]);
    assert!((n[1] - Vec3::Z).length() < 1e-6);
    assert!((n[4] - Vec3::X).length() < 1e-6);
}

#[test]
fn degenerate_faces_can_be_skipped_with_a_warning() {
    let p = data("bad/degenerate.obj");
    let options = ObjOptions {
        skip_degenerate_faces: true,
    };
    let (mesh, _, warnings) = load_obj_with(&p, 1.0, &options).unwrap();
    assert_eq!(mesh.triangles.len(), 1);
    let w = warnings.join("\n");
    assert!(
        w.contains("skipped 2 triangles") && w.contains("face 2 (line 11)"),
        "{w}"
    );
}

#[test]
fn zero_uv_area_faces_are_kept_with_a_warning() {
    let (mesh, _, warnings) = load_obj(&data("bad/zero_uv_area.obj"), 1.0).unwrap();
    assert_eq!(mesh.triangles.len(), 2);
    let w = warnings.join("\n");
    assert!(
        w.contains("1 triangles have zero UV area") && w.contains("face 2 (line 11)"),
        "{w}"
    );
}

#[test]
fn overlapping_uvs_are_left_to_the_rasterizer() {
    let (mesh, _, _) = load_obj(&data("bad/overlapping_uvs.obj"), 1.0).unwrap();
    assert_eq!(mesh.triangles.len(), 2);
    let uv = |t: usize| mesh.triangles[t].uv.map(|i| mesh.uvs[i as usize]);
    assert_eq!(uv(0), uv(1));
}

#[test]
fn uvs_within_tolerance_are_clamped() {
    let obj = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt -0.0000005 0\nvt 1.0000005 0\nvt 0 1\n\
               f 1/1 2/2 3/3\n";
    let (_dir, p) = temp_obj(obj);
    let (mesh, _, _) = load_obj(&p, 1.0).unwrap();
    assert_eq!(mesh.uvs[0].x, 0.0);
    assert_eq!(mesh.uvs[1].x, 1.0);
}
