//! The tests' scene — a 2 m × 2 m floor with a 0.5 m box on it — with a lightmap layout,
//! three lights and a synthetic blur transfer.
//!
//! # Layout
//! The floor spans `x, z ∈ [−1, 1]` m at `y = 0` (normal +y); the box is centred at
//! `(0, 0.25, 0)` with five faces (top and four sides, no bottom), outward normals, CCW
//! from outside. In a `W×W` lightmap, in units of `W/64` texels: the floor chart is the
//! 32×32 square at (2, 2) (`+x` right, `+z` down the rows), the box faces are 12×12
//! squares at (36, 2) top, (50, 2) +x, (36, 16) −x, (50, 16) +z, (36, 30) −z. With `W` a
//! multiple of 64 every chart border lies on texel borders, so no texel centre sits on a
//! chart's outer edge.

use glam::Vec3;

use passes::frame::{RenderScene, Renderer};
use passes::{AlbedoMap, AtlasData, Gpu, LightDesc, MeshData, TransferPiece};

/// Builds the floor-and-box mesh for a `size×size` lightmap and its per-chart albedo
/// (floor 0.6 grey, box (0.7, 0.35, 0.25)).
pub fn floor_and_box(size: u32) -> (MeshData, AlbedoMap) {
    let mut mesh = MeshData::default();
    let unit = size as f32 / 64.0;
    let mut add_quad = |c: Vec3, t: Vec3, b: Vec3, origin: [f32; 2], chart: f32| {
        // Corners c + (±t ±b); t × b is the outward normal.
        let n = t.cross(b).normalize();
        let base = mesh.positions_m.len() as u32;
        for (s, r) in [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
            let p = c + t * (2.0 * s - 1.0) + b * (2.0 * r - 1.0);
            mesh.positions_m.push(p.into());
            mesh.normals.push(n.into());
            // Texel space (x right, y down), then UV (v = 1 − y/H).
            let tx = (origin[0] + s * chart) * unit;
            let ty = (origin[1] + (1.0 - r) * chart) * unit;
            mesh.lightmap_uvs
                .push([tx / size as f32, 1.0 - ty / size as f32]);
        }
        mesh.indices
            .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
    };
    // Floor: t = +x, b = −z so t × b = +y; r = 1 at z = −1 → top rows.
    add_quad(Vec3::ZERO, Vec3::X, Vec3::NEG_Z, [2.0, 2.0], 32.0);
    let h = 0.25;
    let c = Vec3::new(0.0, h, 0.0);
    let faces: [(Vec3, Vec3, Vec3, [f32; 2]); 5] = [
        (Vec3::Y, Vec3::X, Vec3::NEG_Z, [36.0, 2.0]),
        (Vec3::X, Vec3::NEG_Z, Vec3::Y, [50.0, 2.0]),
        (Vec3::NEG_X, Vec3::Z, Vec3::Y, [36.0, 16.0]),
        (Vec3::Z, Vec3::X, Vec3::Y, [50.0, 16.0]),
        (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y, [36.0, 30.0]),
    ];
    for (n, t, b, origin) in faces {
        add_quad(c + n * h, t * h, b * h, origin, 12.0);
    }
    let mut albedo = AlbedoMap::uniform(size, size, [0.6, 0.6, 0.6]);
    for y in 0..size {
        for x in 0..size {
            if x as f32 >= 35.0 * unit {
                albedo.rgb[(y * size + x) as usize] = [0.7, 0.35, 0.25];
            }
        }
    }
    (mesh, albedo)
}

/// Three lights around the box: a point light, a directional light and a spot light,
/// placed so that no lit face is grazed by its light.
pub fn demo_lights() -> Vec<LightDesc> {
    vec![
        LightDesc::Point {
            position_m: [1.2, 1.4, 0.7],
            color: [1.0, 0.9, 0.8],
            intensity_w_sr: 3.0,
        },
        LightDesc::Directional {
            direction: [-0.5, -1.0, 0.3],
            color: [0.8, 0.9, 1.0],
            irradiance_w_m2: 1.5,
        },
        LightDesc::Spot {
            position_m: [-1.0, 1.3, -0.8],
            direction: [1.0, -1.3, 0.8],
            color: [1.0, 1.0, 1.0],
            intensity_w_sr: 4.0,
            inner_deg: 25.0,
            outer_deg: 40.0,
        },
    ]
}

/// A synthetic transfer for tests and benchmarks: one constant-valued atlas the size of
/// the lightmap and one full-map piece per offset `Δt ∈ {−radius, …, radius}²` (step
/// `step`, excluding 0), each transferring `weight` — a box blur of the first-order light,
/// `(2·radius/step + 1)² − 1` pieces of `W×H` texels (pieces are cropped so their reads
/// stay inside the map).
pub fn blur_transfer(
    size: [u32; 2],
    radius: i32,
    step: i32,
    weight: f32,
) -> (Vec<AtlasData>, Vec<TransferPiece>) {
    let [w, h] = size;
    let atlas = AtlasData {
        width: w,
        height: h,
        rgb: vec![[weight; 3]; w as usize * h as usize],
    };
    let mut pieces = Vec::new();
    let step = step.max(1);
    let mut dy = -radius;
    while dy <= radius {
        let mut dx = -radius;
        while dx <= radius {
            if (dx, dy) != (0, 0) && dx.unsigned_abs() < w && dy.unsigned_abs() < h {
                // Receivers t with t + Δt inside the map.
                let x0 = (-dx).max(0) as u32;
                let y0 = (-dy).max(0) as u32;
                pieces.push(TransferPiece {
                    atlas: 0,
                    src_x: x0,
                    src_y: y0,
                    w: w - dx.unsigned_abs(),
                    h: h - dy.unsigned_abs(),
                    dst_x: x0,
                    dst_y: y0,
                    offset: [dx, dy],
                    level: 0,
                    receiver_level: 0,
                });
            }
            dx += step;
        }
        dy += step;
    }
    (vec![atlas], pieces)
}

/// The frame tests' scene: [`floor_and_box`] on a `size²` lightmap with the blur transfer
/// of radius 2 (weight 0.02 per piece), prepared for `renderer`; returns it and the atlases.
pub fn prepare_demo(gpu: &Gpu, renderer: &Renderer, size: u32) -> (RenderScene, Vec<AtlasData>) {
    let (mesh, albedo) = floor_and_box(size);
    let (atlases, pieces) = blur_transfer([size, size], 2, 1, 0.02);
    let scene = renderer
        .prepare(gpu, &mesh, &albedo, &atlases, &pieces)
        .unwrap();
    (scene, atlases)
}
