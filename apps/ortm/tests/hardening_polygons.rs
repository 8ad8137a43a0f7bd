//! Polygon triangulation of OBJ faces: ear clipping (concave, star and collinear polygons come
//! out inside the polygon, where the fan from the first corner does not) and the sliver
//! policy (a convex 100,000-corner polygon is accepted with one warning; a quad's sliver is
//! dropped, a zero-area quad stays an error).

use std::f64::consts::PI;
use std::path::PathBuf;

use glam::{DVec2, Vec3};
use ortm::bake::texels::TexelGrid;
use ortm::scene::obj::load_obj;
use ortm::scene::{Albedo, Material, Mesh, Scene};

/// Writes a planar (z = 0) polygon OBJ with UVs = positions scaled by `uv_scale`.
fn polygon_obj(corners: &[DVec2], uv_scale: f64) -> (tempfile::TempDir, PathBuf) {
    let mut text = String::new();
    for c in corners {
        text += &format!("v {} {} 0\n", c.x as f32, c.y as f32);
    }
    for c in corners {
        let uv = *c * uv_scale;
        text += &format!("vt {} {}\n", uv.x as f32, uv.y as f32);
    }
    text += "f";
    for k in 1..=corners.len() {
        text += &format!(" {k}/{k}");
    }
    text += "\n";
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("polygon.obj");
    std::fs::write(&p, text).unwrap();
    (dir, p)
}

/// Polygon area by the shoelace formula (counter-clockwise > 0).
fn shoelace(c: &[DVec2]) -> f64 {
    (0..c.len())
        .map(|i| c[i].perp_dot(c[(i + 1) % c.len()]))
        .sum::<f64>()
        / 2.0
}

/// Whether `q` lies inside the polygon `c` (crossing number).
fn inside(c: &[DVec2], q: DVec2) -> bool {
    let mut odd = false;
    for i in 0..c.len() {
        let (a, b) = (c[i], c[(i + 1) % c.len()]);
        if (a.y > q.y) != (b.y > q.y) && q.x < a.x + (q.y - a.y) / (b.y - a.y) * (b.x - a.x) {
            odd = !odd;
        }
    }
    odd
}

/// The mesh's triangles as 2D corner triples (z = 0).
fn triangles_2d(mesh: &Mesh) -> Vec<[DVec2; 3]> {
    mesh.triangles
        .iter()
        .map(|t| {
            t.position
                .map(|i| mesh.positions_m[i as usize].truncate().as_dvec2())
        })
        .collect()
}

/// Signed area of a 2D triangle.
fn area(t: &[DVec2; 3]) -> f64 {
    (t[1] - t[0]).perp_dot(t[2] - t[0]) / 2.0
}

/// Whether every triangle is counter-clockwise and 15 interior sample points of each lie
/// inside the polygon.
fn all_inside(c: &[DVec2], tris: &[[DVec2; 3]]) -> bool {
    tris.iter().all(|t| {
        area(t) > 0.0
            && (1..6).all(|i| {
                (1..6 - i).all(|j| {
                    let (a, b) = (i as f64 / 6.0, j as f64 / 6.0);
                    inside(c, t[0] + (t[1] - t[0]) * a + (t[2] - t[0]) * b)
                })
            })
    })
}

/// The fan from corner 0 that `tobj` (and this loader before ear clipping) produces.
fn fan(c: &[DVec2]) -> Vec<[DVec2; 3]> {
    (1..c.len() - 1).map(|k| [c[0], c[k], c[k + 1]]).collect()
}

/// Loads `corners` as one face and checks the triangulation against the polygon: n − 2
/// triangles (`expected`), all inside, areas summing to the shoelace area; and that the fan
/// is wrong for it (so the check can fail).
fn check_polygon(corners: &[DVec2], expected: usize) {
    assert!(!all_inside(corners, &fan(corners)), "the fan is right here");
    let (_dir, p) = polygon_obj(corners, 0.1);
    let (mesh, _, warnings) = load_obj(&p, 1.0).unwrap();
    assert!(warnings.is_empty(), "{warnings:?}");
    let tris = triangles_2d(&mesh);
    assert_eq!(tris.len(), expected);
    assert!(all_inside(corners, &tris), "{tris:?}");
    let sum: f64 = tris.iter().map(area).sum();
    let want = shoelace(corners);
    assert!((sum - want).abs() < 1e-6 * want, "{sum} vs {want}");
}

#[test]
fn an_l_shaped_hexagon_is_ear_clipped_inside_itself() {
    // Starts at the corner next to the reflex one: the fan's first triangle fills the notch.
    let l = [(2., 1.), (1., 1.), (1., 2.), (0., 2.), (0., 0.), (2., 0.)].map(DVec2::from);
    check_polygon(&l, 4);
}

#[test]
fn a_star_is_ear_clipped_inside_itself() {
    // Five points, starting at an inner (reflex) corner: the fan crosses the outside.
    let star: Vec<DVec2> = (0..10)
        .map(|k| {
            let r = if k % 2 == 0 { 1.5 } else { 4.0 };
            let a = PI / 2.0 + k as f64 * PI / 5.0;
            DVec2::new(5.0 + r * a.cos(), 5.0 + r * a.sin())
        })
        .collect();
    check_polygon(&star, 8);
}

#[test]
fn collinear_corners_make_no_zero_area_triangle() {
    // A rectangle with a corner in the middle of its bottom edge, and a concave notch with a
    // collinear corner on its side: the fan's first triangle has zero area (today an error).
    let c = [
        (0., 0.),
        (1., 0.),
        (2., 0.),
        (2., 2.),
        (1.5, 2.),
        (1.5, 1.5),
        (1.5, 1.),
    ]
    .map(DVec2::from);
    let mut c = c.to_vec();
    c.extend([(1., 1.), (1., 2.), (0., 2.)].map(DVec2::from));
    let fan_areas: Vec<f64> = fan(&c).iter().map(area).collect();
    assert_eq!(fan_areas[0], 0.0);
    check_polygon(&c, c.len() - 2);
}

#[test]
fn a_convex_100k_corner_polygon_is_accepted_with_one_sliver_warning() {
    let n = 100_000;
    // Written as f32, read back exactly (Rust prints the shortest round-trip form).
    let corners: Vec<DVec2> = (0..n)
        .map(|k| {
            let a = 2.0 * PI * k as f64 / n as f64;
            DVec2::new(0.5 + 0.5 * a.cos(), 0.5 + 0.5 * a.sin())
                .as_vec2()
                .as_dvec2()
        })
        .collect();
    let (_dir, p) = polygon_obj(&corners, 1.0);
    // Loads in 0.22 s (test profile, this machine).
    let (mesh, _, warnings) = load_obj(&p, 1.0).unwrap();
    assert_eq!(warnings.len(), 1, "{warnings:?}");
    let w = &warnings[0];
    assert!(w.contains(&format!("polygon.obj:{}:", 2 * n + 1)), "{w}");
    assert!(w.contains("sliver"), "{w}");
    let tris = triangles_2d(&mesh);
    let dropped = n - 2 - tris.len();
    assert!(w.contains(&format!("{dropped} sliver")), "{w}");
    // Measured: 210 slivers (fan triangles next to the apex, area ≤ 1e-10 × diagonal²), losing
    // 1.5e-8 of the area.
    assert!((150..=270).contains(&dropped), "{dropped}");
    let sum: f64 = tris.iter().map(area).sum();
    let want = shoelace(&corners);
    assert!((sum - want).abs() < 1e-6 * want, "{sum} vs {want}");
    // No texel centre in two triangles (the UVs are the positions).
    let scene = Scene {
        name: "polygon".into(),
        mesh,
        materials: vec![Material {
            name: String::new(),
            albedo: Albedo::Constant(Vec3::splat(0.5)),
            subsurface: None,
        }],
        lights: vec![],
        lightmap_size: (256, 256),
        allow_uv_overlap: false,
    };
    let grid = TexelGrid::build(&scene).unwrap();
    assert_eq!(grid.stats.overlapping, 0);
    // Texels inside the circle: about π/4 of them.
    let covered = grid.texels.len() as f64 / (256.0 * 256.0);
    assert!((covered - PI / 4.0).abs() < 0.01, "{covered}");
}

#[test]
fn a_sliver_of_a_quad_is_dropped_but_a_zero_area_quad_is_an_error() {
    // `a b c` is collinear (zero area), `a c d` has area 1: the sliver is dropped.
    let quad = [(0., 0.), (1., 0.), (2., 0.), (1., 1.)].map(DVec2::from);
    let (_dir, p) = polygon_obj(&quad, 0.5);
    let (mesh, _, warnings) = load_obj(&p, 1.0).unwrap();
    assert_eq!(triangles_2d(&mesh), vec![[quad[0], quad[2], quad[3]]]);
    let w = warnings.join("\n");
    assert!(
        w.contains("polygon.obj:9:") && w.contains("1 sliver triangle "),
        "{w}"
    );
    // A quad of zero area as a whole keeps the degenerate-face rule (an error).
    let flat = [(0., 0.), (1., 0.), (2., 0.), (3., 0.)].map(DVec2::from);
    let (_dir, p) = polygon_obj(&flat, 0.25);
    let e = load_obj(&p, 1.0).unwrap_err().to_string();
    assert!(e.contains("skip_degenerate_faces"), "{e}");
}

#[test]
fn a_self_intersecting_polygon_falls_back_to_the_fan_with_a_warning() {
    // A square loop whose tail crosses back over itself: no ear can be found.
    let c = [
        (0., 0.),
        (4., 0.),
        (4., 4.),
        (2., 4.),
        (2., 6.),
        (3., 6.),
        (3., 5.),
        (1., 5.),
        (1., 2.),
        (0., 2.),
    ]
    .map(DVec2::from);
    let (_dir, p) = polygon_obj(&c, 0.1);
    let (mesh, _, warnings) = load_obj(&p, 1.0).unwrap();
    let w = warnings.join("\n");
    assert!(
        w.contains("polygon.obj:21:") && w.contains("could not be ear-clipped"),
        "{w}"
    );
    assert_eq!(triangles_2d(&mesh), fan(&c));
}
