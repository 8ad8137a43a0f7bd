//! The built-in Cornell box, made in code, with its lightmap charts packed in code.
//!
//! # Geometry (metres, right-handed, y up)
//! The box is the cube `[0, 0.555]³`. The **open side faces +z** (the plane z = 0.555 has no
//! wall): a camera at z > 0.555 looking towards −z sees the back wall (z = 0), the red wall
//! on its left (x = 0), the green wall on its right (x = 0.555), the floor (y = 0) and the
//! ceiling (y = 0.555). The two white blocks follow the classic scene (coordinates of the
//! Cornell data rotated 180° about the vertical axis so that the open side faces +z): a
//! short block (0.165 m cube, rotated ≈ 17°) front right and a tall block (0.165 × 0.33 ×
//! 0.165 m, rotated ≈ −17°) back left. Their bottom faces (on the floor) are omitted.
//!
//! Every face is a separate planar rectangle with its own four vertices (flat normals; no
//! vertex is shared between faces) and its normal points into the air: walls inward, block
//! faces outward. Each rectangle is two triangles `(0,1,2)`, `(0,2,3)`, counter-clockwise
//! seen from the air side.
//!
//! # Materials and light
//! `white` ρ = 0.73 (floor, ceiling, back wall, blocks), `red` ρ = (0.63, 0.065, 0.05),
//! `green` ρ = (0.14, 0.45, 0.09). One white point light of [`LIGHT_INTENSITY_W_SR`] W/sr
//! 2 cm under the centre of the ceiling: the floor gets ≈ 28 W/m² directly below it and
//! ≈ 15 W/m² in the corners (before shadowing).
//!
//! # Lightmap charts
//! Every face is one chart, laid out and packed by [`super::charts`] (one texel density,
//! skyline packing with [`GUTTER_TEXELS`] gutters, the densest layout that fits).
//!
//! # Limits
//! Only square lightmaps; sizes are clamped to [[`MIN_LIGHTMAP_SIZE`], 8192] (below 32
//! texels the charts and gutters do not fit; the returned scene states the size used).

use glam::{Vec2, Vec3};

use super::charts::{Face, charted_mesh};
use super::{Albedo, Light, Material, Scene};

pub use super::charts::{GUTTER_TEXELS, MIN_CHART_TEXELS};

/// Edge length of the box, metres.
pub const BOX_SIZE_M: f32 = 0.555;
/// Smallest lightmap size [`cornell_box`] builds.
pub const MIN_LIGHTMAP_SIZE: u32 = 32;
/// Intensity of the default point light, W/sr.
pub const LIGHT_INTENSITY_W_SR: f32 = 8.0;

/// A block of the Cornell box: an upright box standing on the floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornellBlock {
    /// Centre of the footprint (x, z), metres.
    pub centre_xz: Vec2,
    /// Half the footprint's side, metres.
    pub half_side_m: f32,
    /// Height, metres.
    pub height_m: f32,
    /// Rotation about +y, radians (counter-clockwise seen from above).
    pub angle_rad: f32,
}

impl CornellBlock {
    /// Footprint corners (x, z), counter-clockwise seen from above (+y).
    pub fn footprint(&self) -> [Vec2; 4] {
        // Rotation about +y by θ maps (x, z) to (x cosθ + z sinθ, −x sinθ + z cosθ);
        // counter-clockwise seen from +y means increasing angle from +z towards +x.
        let (s, c) = self.angle_rad.sin_cos();
        let rot = |p: Vec2| Vec2::new(p.x * c + p.y * s, -p.x * s + p.y * c);
        let h = self.half_side_m;
        [
            Vec2::new(-h, -h),
            Vec2::new(-h, h),
            Vec2::new(h, h),
            Vec2::new(h, -h),
        ]
        .map(|p| self.centre_xz + rot(p))
    }

    /// Whether point `p` lies strictly inside the block.
    pub fn contains(&self, p: Vec3) -> bool {
        let (s, c) = self.angle_rad.sin_cos();
        let d = Vec2::new(p.x, p.z) - self.centre_xz;
        // Inverse rotation.
        let local = Vec2::new(d.x * c - d.y * s, d.x * s + d.y * c);
        local.abs().max_element() < self.half_side_m && p.y > 0.0 && p.y < self.height_m
    }
}

/// The two blocks: short (front right) and tall (back left).
pub fn cornell_blocks() -> [CornellBlock; 2] {
    // Classic Cornell data (mm, open side at z = 0, red wall at x ≈ 555):
    // short block footprint centre (185.5, 169), tall (368.5, 351.25); sides 165 mm,
    // edges rotated ≈ ±17°. Rotated 180° about y: (x, z) → (555 − x, 555 − z).
    let l = BOX_SIZE_M;
    [
        CornellBlock {
            centre_xz: Vec2::new(l - 0.1855, l - 0.169),
            half_side_m: 0.0825,
            height_m: 0.165,
            angle_rad: (-17.0f32).to_radians(),
        },
        CornellBlock {
            centre_xz: Vec2::new(l - 0.3685, l - 0.35125),
            half_side_m: 0.0825,
            height_m: 0.33,
            angle_rad: 17.0f32.to_radians(),
        },
    ]
}

/// Material indices.
const WHITE: u32 = 0;
const RED: u32 = 1;
const GREEN: u32 = 2;

/// The 15 faces: 5 walls, then 5 faces per block.
fn faces() -> Vec<Face> {
    let l = BOX_SIZE_M;
    let (x, y, z) = (Vec3::X * l, Vec3::Y * l, Vec3::Z * l);
    let o = Vec3::ZERO;
    let centre = Vec3::splat(l / 2.0);
    let wall = |origin: Vec3, e1: Vec3, e2: Vec3, m: u32| {
        let mid = origin + 0.5 * (e1 + e2);
        Face::oriented(origin, e1, e2, centre - mid, m)
    };
    let mut out = vec![
        wall(o, x, z, WHITE), // floor, y = 0
        wall(y, x, z, WHITE), // ceiling, y = L
        wall(o, x, y, WHITE), // back, z = 0
        wall(o, y, z, RED),   // left, x = 0
        wall(x, y, z, GREEN), // right, x = L
    ];
    for b in cornell_blocks() {
        let fp = b.footprint();
        let c3 = Vec3::new(b.centre_xz.x, b.height_m / 2.0, b.centre_xz.y);
        let up = Vec3::Y * b.height_m;
        for k in 0..4 {
            let p = Vec3::new(fp[k].x, 0.0, fp[k].y);
            let q = Vec3::new(fp[(k + 1) % 4].x, 0.0, fp[(k + 1) % 4].y);
            let mid = 0.5 * (p + q) + 0.5 * up;
            out.push(Face::oriented(p, q - p, up, mid - c3, WHITE));
        }
        let top = Vec3::new(fp[0].x, b.height_m, fp[0].y);
        let e1 = Vec3::new(fp[1].x - fp[0].x, 0.0, fp[1].y - fp[0].y);
        let e2 = Vec3::new(fp[3].x - fp[0].x, 0.0, fp[3].y - fp[0].y);
        out.push(Face::oriented(top, e1, e2, Vec3::Y, WHITE));
    }
    out
}

/// The Cornell box (see the module docs) with a `lightmap_size × lightmap_size` chart layout
/// (clamped to `[32, 8192]`).
pub fn cornell_box(lightmap_size: u32) -> Scene {
    let size = lightmap_size.clamp(MIN_LIGHTMAP_SIZE, super::file::MAX_LIGHTMAP_SIZE);
    let mesh = charted_mesh(&faces(), size);
    let materials = vec![
        Material {
            name: "white".into(),
            albedo: Albedo::Constant(Vec3::splat(0.73)),
            subsurface: None,
        },
        Material {
            name: "red".into(),
            albedo: Albedo::Constant(Vec3::new(0.63, 0.065, 0.05)),
            subsurface: None,
        },
        Material {
            name: "green".into(),
            albedo: Albedo::Constant(Vec3::new(0.14, 0.45, 0.09)),
            subsurface: None,
        },
    ];
    let l = BOX_SIZE_M;
    Scene {
        name: "cornell".into(),
        mesh,
        materials,
        lights: vec![Light::Point {
            position_m: Vec3::new(l / 2.0, l - 0.02, l / 2.0),
            color: Vec3::ONE,
            intensity_w_sr: LIGHT_INTENSITY_W_SR,
        }],
        lightmap_size: (size, size),
        allow_uv_overlap: false,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn block_footprints_are_counter_clockwise_squares() {
        for b in cornell_blocks() {
            let fp = b.footprint();
            for k in 0..4 {
                let e = fp[(k + 1) % 4] - fp[k];
                assert!((e.length() - 2.0 * b.half_side_m).abs() < 1e-5);
            }
            // Counter-clockwise seen from +y (z × x = y): the signed area in the (z, x)
            // plane, Σ (z_k x_{k+1} − x_k z_{k+1}) / 2, is +side².
            let area: f32 = (0..4)
                .map(|k| {
                    let (p, q) = (fp[k], fp[(k + 1) % 4]);
                    p.y * q.x - p.x * q.y
                })
                .sum::<f32>()
                / 2.0;
            assert!(
                (area - (2.0 * b.half_side_m).powi(2)).abs() < 1e-5,
                "area {area}"
            );
            assert!(b.contains(Vec3::new(b.centre_xz.x, 0.01, b.centre_xz.y)));
        }
    }
}
