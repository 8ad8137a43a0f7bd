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

/// A 1 m × 1 m square whose UVs stretch unevenly: vertical strips a quarter of a texel wide,
/// alternately mapped to 0.5 and 1.5 times their share of the square's width, each strip two
/// triangles. The covering triangle's Jacobian at a texel centre is 0.5 or 1.5 times the mean;
/// the surface inside every texel's square (two strips of each kind) is exactly the mean. Areas
/// and footprints must be that average, and the area must sum to the square's 1 m².
#[test]
fn areas_average_the_stretch_inside_each_texel() {
    let size = 8u32;
    let strips = 4 * size as usize;
    // Strip i spans u ∈ [i/strips, (i+1)/strips]; its x extent is 0.5 or 1.5 of 1/strips.
    let mut xs = vec![0.0f32];
    for i in 0..strips {
        let w = if i % 2 == 0 { 0.5 } else { 1.5 };
        xs.push(xs[i] + w / strips as f32);
    }
    let mut positions_m = Vec::new();
    let mut uvs = Vec::new();
    for (i, &x) in xs.iter().enumerate() {
        let u = i as f32 / strips as f32;
        positions_m.extend([Vec3::new(x, 0.0, 0.0), Vec3::new(x, 1.0, 0.0)]);
        uvs.extend([Vec2::new(u, 0.0), Vec2::new(u, 1.0)]);
    }
    let tri = |p: [u32; 3]| MeshTriangle {
        position: p,
        uv: p,
        normal: [0; 3],
        material: 0,
    };
    let mut triangles = Vec::new();
    for i in 0..strips as u32 {
        let (a, b, c, d) = (2 * i, 2 * i + 2, 2 * i + 3, 2 * i + 1);
        triangles.extend([tri([a, b, c]), tri([a, c, d])]);
    }
    let mesh = Mesh {
        positions_m,
        uvs,
        normals: vec![Vec3::Z],
        triangles,
    };
    let grid = TexelGrid::build(&scene_with(mesh, size)).unwrap();
    assert_eq!(grid.texels.len(), (size * size) as usize);
    let texel_area = 1.0 / (size * size) as f32;
    for t in &grid.texels {
        assert!(
            (t.area_m2 / texel_area - 1.0).abs() < 1e-5,
            "texel ({}, {}): area {} against {texel_area}",
            t.x,
            t.y,
            t.area_m2
        );
        let [fx, fy] = t.footprint_m;
        // The secants across the square: one texel of x is 1/size m, one of y is −1/size m.
        let step = 1.0 / size as f32;
        assert!(
            (fx - Vec3::new(step, 0.0, 0.0)).length() < 1e-5 * step,
            "{fx:?}"
        );
        assert!(
            (fy - Vec3::new(0.0, -step, 0.0)).length() < 1e-5 * step,
            "{fy:?}"
        );
        assert!((fx.cross(fy).length() / t.area_m2 - 1.0).abs() < 1e-5);
    }
    let area: f64 = grid.texels.iter().map(|t| t.area_m2 as f64).sum();
    assert!((area - 1.0).abs() < 1e-5, "area {area}");
}

/// An affinely mapped chart keeps its covering triangle's Jacobian (both triangles share it).
#[test]
fn affine_charts_keep_the_covering_triangles_jacobian() {
    let size = 16u32;
    let grid = TexelGrid::build(&scene_with(rectangle(), size)).unwrap();
    // The rectangle's two triangles: ∂P/∂x = (2/size, 0, 0), ∂P/∂y = (0, −1/size, 0).
    let step = 1.0 / size as f32;
    for t in &grid.texels {
        assert!((t.footprint_m[0] - Vec3::new(2.0 * step, 0.0, 0.0)).length() < 1e-6 * step);
        assert!((t.footprint_m[1] - Vec3::new(0.0, -step, 0.0)).length() < 1e-6 * step);
        assert!((t.area_m2 / (2.0 * step * step) - 1.0).abs() < 1e-6);
    }
}
