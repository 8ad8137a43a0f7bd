//! The texel rasterizer: coverage rule, areas, and the UV-overlap error.

mod common;

use glam::{Vec2, Vec3};
use ortm::bake::texels::{TexelError, TexelGrid};
use ortm::scene::{Albedo, Material, Mesh, MeshTriangle, Scene};

fn scene_with(mesh: Mesh, size: u32) -> Scene {
    Scene {
        name: "test".into(),
        mesh,
        materials: vec![Material {
            name: "m".into(),
            albedo: Albedo::Constant(Vec3::splat(0.5)),
            subsurface: None,
        }],
        lights: vec![],
        lightmap_size: (size, size),
        allow_uv_overlap: false,
    }
}

/// A 2 m × 1 m rectangle mapped to the whole UV square as two triangles.
fn rectangle() -> Mesh {
    let tri = |p: [u32; 3]| MeshTriangle {
        position: p,
        uv: p,
        normal: [0; 3],
        material: 0,
    };
    Mesh {
        positions_m: vec![
            Vec3::new(0.0, 0.0, 0.0),
            Vec3::new(2.0, 0.0, 0.0),
            Vec3::new(2.0, 1.0, 0.0),
            Vec3::new(0.0, 1.0, 0.0),
        ],
        uvs: vec![
            Vec2::new(0.0, 0.0),
            Vec2::new(1.0, 0.0),
            Vec2::new(1.0, 1.0),
            Vec2::new(0.0, 1.0),
        ],
        normals: vec![Vec3::Z],
        triangles: vec![tri([0, 1, 2]), tri([0, 2, 3])],
    }
}

#[test]
fn full_square_covers_every_texel_once_with_the_right_area() {
    for size in [1u32, 7, 16, 33] {
        let grid = TexelGrid::build(&scene_with(rectangle(), size)).unwrap();
        // Texel centres on the shared diagonal belong to exactly one triangle (top-left rule).
        assert_eq!(grid.texels.len(), (size * size) as usize);
        assert_eq!(grid.stats.overlapping, 0);
        let area: f64 = grid.texels.iter().map(|t| t.area_m2 as f64).sum();
        assert!((area - 2.0).abs() < 1e-5, "{size}: area {area}");
        for t in &grid.texels {
            // Position matches the texel centre's UV (u → x·2 m, v → y·1 m).
            let u = (t.x as f32 + 0.5) / size as f32;
            let v = 1.0 - (t.y as f32 + 0.5) / size as f32;
            assert!((t.position_m - Vec3::new(2.0 * u, v, 0.0)).length() < 1e-5);
        }
    }
}

#[test]
fn overlapping_uvs_are_an_error_naming_the_overlap() {
    let path = common::data("bad/overlapping_uvs.obj");
    let (mesh, _, _) = ortm::scene::obj::load_obj(&path, 1.0).unwrap();
    let scene = scene_with(mesh.clone(), 32);
    let err = TexelGrid::build(&scene).unwrap_err();
    assert!(matches!(err, TexelError::Overlap { .. }));
    let msg = err.to_string();
    assert!(
        msg.contains("overlap") && msg.contains("allow_uv_overlap"),
        "{msg}"
    );
    // The explicit opt-out accepts it; the later triangle wins.
    let mut ok = scene_with(mesh, 32);
    ok.allow_uv_overlap = true;
    let grid = TexelGrid::build(&ok).unwrap();
    assert!(grid.stats.overlapping > 0);
    assert!(grid.texels.iter().all(|t| t.triangle == 1));
}
