//! The built-in Cornell box: chart layout (no overlap, gutters, coverage, proportional
//! areas), UV range, normals toward the air, materials and the light.

use glam::{Vec2, Vec3};
use ortm::lightmap::uv_to_texel_space;
use ortm::scene::cornell::{BOX_SIZE_M, GUTTER_TEXELS, cornell_blocks};
use ortm::scene::{Albedo, Light, Scene, cornell_box};

/// Chart rectangles in texel space (min, max), one per face (faces are 4 consecutive
/// vertices, 2 triangles each).
fn charts(scene: &Scene) -> Vec<(Vec2, Vec2)> {
    let (w, h) = scene.lightmap_size;
    scene
        .mesh
        .triangles
        .chunks(2)
        .map(|pair| {
            let pts: Vec<Vec2> = pair
                .iter()
                .flat_map(|t| t.uv)
                .map(|i| uv_to_texel_space(scene.mesh.uvs[i as usize], w, h))
                .collect();
            let lo = pts.iter().fold(Vec2::splat(f32::MAX), |a, p| a.min(*p));
            let hi = pts.iter().fold(Vec2::splat(f32::MIN), |a, p| a.max(*p));
            (lo, hi)
        })
        .collect()
}

/// Whether a point is in the air: inside the box and outside both blocks.
fn in_air(p: Vec3) -> bool {
    let inside_box = p.min_element() > 0.0 && p.max_element() < BOX_SIZE_M;
    inside_box && cornell_blocks().iter().all(|b| !b.contains(p))
}

#[test]
fn charts_never_overlap_and_keep_gutters_at_several_sizes() {
    for size in [32u32, 64, 100, 256, 1024] {
        let scene = cornell_box(size);
        assert_eq!(scene.lightmap_size, (size, size));
        let rects = charts(&scene);
        assert_eq!(rects.len(), 15, "5 walls + 2 × 5 block faces");
        let g = GUTTER_TEXELS as f32;
        let eps = 1e-3;
        for (i, (lo, hi)) in rects.iter().enumerate() {
            // Inside the map with the border gutter.
            assert!(lo.min_element() >= g - eps, "size {size} chart {i}: {lo}");
            assert!(
                hi.max_element() <= size as f32 - g + eps,
                "size {size} chart {i}: {hi}"
            );
            // Every chart covers at least a few texel centres.
            let covered = ((hi.x - lo.x).round() * (hi.y - lo.y).round()) as u32;
            assert!(
                covered >= 9,
                "size {size} chart {i} covers {covered} texels"
            );
            for (j, (lo2, hi2)) in rects.iter().enumerate().skip(i + 1) {
                // Separated by at least the gutter along x or along y.
                let gap_x = (lo2.x - hi.x).max(lo.x - hi2.x);
                let gap_y = (lo2.y - hi.y).max(lo.y - hi2.y);
                assert!(
                    gap_x.max(gap_y) >= g - eps,
                    "size {size}: charts {i} and {j} closer than the gutter"
                );
            }
        }
    }
}

#[test]
fn chart_corners_lie_on_texel_edges_and_uvs_in_unit_square() {
    for size in [32u32, 64, 512] {
        let scene = cornell_box(size);
        for uv in &scene.mesh.uvs {
            assert!(uv.min_element() >= 0.0 && uv.max_element() <= 1.0);
            let t = uv_to_texel_space(*uv, size, size);
            assert!((t - t.round()).abs().max_element() < 1e-3, "{t}");
        }
    }
}

#[test]
fn coverage_and_area_proportionality() {
    let scene = cornell_box(64);
    let rects = charts(&scene);
    let texels: f32 = rects
        .iter()
        .map(|(lo, hi)| (hi.x - lo.x) * (hi.y - lo.y))
        .sum();
    let coverage = texels / (64.0 * 64.0);
    assert!(coverage >= 0.5, "coverage {coverage}");
    // Texel area / world area is nearly the same for all charts (sides are rounded up to
    // whole texels, so small charts may be somewhat denser).
    let big = cornell_box(1024);
    let m = &big.mesh;
    let ratios: Vec<f32> = charts(&big)
        .iter()
        .zip(m.triangles.chunks(2))
        .map(|((lo, hi), pair)| {
            let world: f32 = pair
                .iter()
                .map(|t| {
                    let [a, b, c] = t.position.map(|i| m.positions_m[i as usize]);
                    0.5 * (b - a).cross(c - a).length()
                })
                .sum();
            (hi.x - lo.x) * (hi.y - lo.y) / world
        })
        .collect();
    let (min, max) = ratios
        .iter()
        .fold((f32::MAX, f32::MIN), |(a, b), r| (a.min(*r), b.max(*r)));
    assert!(max / min < 1.05, "texel density varies {min}..{max}");
}

#[test]
fn uv_mapping_is_a_similarity_without_mirroring() {
    // Within each triangle, the world→texel map is a rotation + uniform scale that keeps
    // orientation: UV winding (u right, v up) is counter-clockwise like the world winding.
    let scene = cornell_box(1024);
    let m = &scene.mesh;
    for t in &m.triangles {
        let [a, b, c] = t.position.map(|i| m.positions_m[i as usize]);
        let [ua, ub, uc] = t.uv.map(|i| m.uvs[i as usize]);
        let uv_cross = (ub - ua).perp_dot(uc - ua);
        assert!(uv_cross > 0.0, "UV triangle is clockwise (mirrored chart)");
        let s1 = (ub - ua).length() / (b - a).length();
        let s2 = (uc - ua).length() / (c - a).length();
        assert!(
            (s1 / s2 - 1.0).abs() < 0.05,
            "anisotropic chart: {s1} vs {s2}"
        );
    }
}

#[test]
fn normals_point_into_the_air() {
    let scene = cornell_box(64);
    let m = &scene.mesh;
    for (k, t) in m.triangles.iter().enumerate() {
        let [a, b, c] = t.position.map(|i| m.positions_m[i as usize]);
        let geometric = (b - a).cross(c - a).normalize();
        for &n in &t.normal {
            let n = m.normals[n as usize];
            assert!(
                (n - geometric).length() < 1e-5,
                "triangle {k}: shading ≠ geometric normal"
            );
        }
        let centroid = (a + b + c) / 3.0;
        let eps = 1e-3;
        assert!(
            in_air(centroid + eps * geometric),
            "triangle {k}: front side is not air"
        );
        assert!(
            !in_air(centroid - eps * geometric),
            "triangle {k}: back side is air"
        );
    }
}

#[test]
fn materials_walls_and_light() {
    let scene = cornell_box(128);
    let albedo = |i: u32| match scene.materials[i as usize].albedo {
        Albedo::Constant(c) => c,
        Albedo::Texture(_) => panic!("constant expected"),
    };
    let m = &scene.mesh;
    let mut red_area = 0.0;
    let mut green_area = 0.0;
    for t in &m.triangles {
        let [a, b, c] = t.position.map(|i| m.positions_m[i as usize]);
        let area = 0.5 * (b - a).cross(c - a).length();
        let rho = albedo(t.material);
        if a.x.abs() < 1e-6 && b.x.abs() < 1e-6 && c.x.abs() < 1e-6 {
            assert_eq!(
                rho,
                Vec3::new(0.63, 0.065, 0.05),
                "left wall (x = 0) is red"
            );
            red_area += area;
        } else if [a, b, c].iter().all(|p| (p.x - BOX_SIZE_M).abs() < 1e-6) {
            assert_eq!(rho, Vec3::new(0.14, 0.45, 0.09), "right wall is green");
            green_area += area;
        } else {
            assert_eq!(rho, Vec3::splat(0.73));
        }
    }
    let wall = BOX_SIZE_M * BOX_SIZE_M;
    assert!((red_area - wall).abs() < 1e-5 && (green_area - wall).abs() < 1e-5);
    // No wall at z = L (open front), one at z = 0.
    let at_z = |z: f32| {
        m.triangles.iter().any(|t| {
            t.position
                .iter()
                .all(|&i| (m.positions_m[i as usize].z - z).abs() < 1e-6)
        })
    };
    assert!(at_z(0.0) && !at_z(BOX_SIZE_M));
    // The light: under the ceiling centre; direct irradiance on the floor below it and in
    // a floor corner (inverse square × cosine) within 10..50 W/m².
    let [
        Light::Point {
            position_m,
            intensity_w_sr,
            ..
        },
    ] = scene.lights[..]
    else {
        panic!("one point light expected");
    };
    assert!(in_air(position_m));
    assert!(position_m.y > 0.9 * BOX_SIZE_M);
    for floor_point in [
        Vec3::new(BOX_SIZE_M / 2.0, 0.0, BOX_SIZE_M / 2.0),
        Vec3::new(0.0, 0.0, 0.0),
    ] {
        let d = position_m - floor_point;
        let e = intensity_w_sr * (d.y / d.length()) / d.length_squared();
        assert!((10.0..=50.0).contains(&e), "floor irradiance {e} W/m²");
    }
}
