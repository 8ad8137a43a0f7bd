//! The built-in maze: a closed room split by three partitions into four bays joined by
//! doorways at alternate ends, so that a lamp in the first bay lights the others only by light
//! that goes around the walls (the kind of scene of Kontkanen et al. 2006 and Hašan et al.
//! 2006: all light in the far bays is indirect). Made in code, with its lightmap charts
//! packed in code ([`super::charts`]).
//!
//! # Geometry (metres, right-handed, y up)
//! The room is the box `[0, 2] × [0, 1] × [0, 2]` (x, y, z), closed on all six sides; its
//! walls' normals point inward. Three partitions, thin upright boxes
//! [`PARTITION_THICKNESS_M`] thick and as high as the room, stand at x = 0.5, 1.0 and 1.5 and
//! run along z from one wall, leaving a doorway [`DOORWAY_M`] wide at the other: the first and
//! the third start at the back wall (z = 0, doorway at z ≈ 2), the second at the front wall
//! (z = 2, doorway at z ≈ 0). The four bays, numbered by increasing x, form one winding
//! corridor. A partition has three faces, its normals outward: its two long sides and its free
//! end; its top, bottom and attached end touch the ceiling, the floor and a wall and are left
//! out, so the air is sealed (the partition's sides meet those surfaces edge to edge).
//!
//! Every face is a separate planar rectangle (6 walls + 3 × 3 partition faces = 15 charts),
//! two triangles counter-clockwise seen from the air. Floor texels under a partition's
//! footprint lie inside the partition and receive no light.
//!
//! # Materials and light
//! `white` ρ = 0.7 (floor, ceiling, outer walls), `ochre` ρ = (0.75, 0.6, 0.45) (first and
//! third partitions), `blue` ρ = (0.45, 0.6, 0.75) (second partition). One white point light of
//! [`LIGHT_INTENSITY_W_SR`] W/sr at [`LIGHT_POSITION_M`], in the first bay, 0.2 m under the
//! ceiling: the floor under it gets 10 W/sr / (0.8 m)² = 15.6 W/m². It sees part of the second
//! bay through the first doorway; the third and fourth bays get no direct light at all.
//!
//! # Limits
//! Only square lightmaps; sizes are clamped to [[`MIN_LIGHTMAP_SIZE`], 8192] (the returned
//! scene states the size used). The default is [`DEFAULT_LIGHTMAP_SIZE`].

use glam::{Vec2, Vec3};

use super::charts::{Face, charted_mesh};
use super::{Albedo, Light, Material, Scene};

pub use super::charts::{GUTTER_TEXELS, MIN_CHART_TEXELS};

/// The room's inner size (x, y, z), metres.
pub const ROOM_SIZE_M: Vec3 = Vec3::new(2.0, 1.0, 2.0);
/// Thickness of a partition, metres.
pub const PARTITION_THICKNESS_M: f32 = 0.05;
/// Width of the doorway a partition leaves at its free end, metres.
pub const DOORWAY_M: f32 = 0.4;
/// Smallest lightmap size [`maze`] builds (15 minimum-size charts with gutters fit).
pub const MIN_LIGHTMAP_SIZE: u32 = 32;
/// The lightmap size of the built-in scene when none is given.
pub const DEFAULT_LIGHTMAP_SIZE: u32 = 128;
/// Intensity of the default point light, W/sr.
pub const LIGHT_INTENSITY_W_SR: f32 = 10.0;
/// Position of the default point light (in the first bay), metres.
pub const LIGHT_POSITION_M: Vec3 = Vec3::new(0.25, 0.8, 0.6);

/// A partition: an upright box from the floor to the ceiling over the footprint
/// `[lo.x, hi.x] × [lo.y, hi.y]` in (x, z), metres.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Partition {
    /// Footprint corner with the smallest (x, z), metres.
    pub lo: Vec2,
    /// Footprint corner with the largest (x, z), metres.
    pub hi: Vec2,
}

impl Partition {
    /// Whether point `p` lies strictly inside the partition.
    pub fn contains(&self, p: Vec3) -> bool {
        let q = Vec2::new(p.x, p.z);
        q.cmpgt(self.lo).all() && q.cmplt(self.hi).all() && p.y > 0.0 && p.y < ROOM_SIZE_M.y
    }

    /// Whether the partition is attached to the back wall (z = 0); otherwise to the front
    /// wall (z = room depth).
    pub fn attached_at_back(&self) -> bool {
        self.lo.y == 0.0
    }
}

/// The three partitions, by increasing x.
pub fn partitions() -> [Partition; 3] {
    let depth = ROOM_SIZE_M.z;
    let half = PARTITION_THICKNESS_M / 2.0;
    std::array::from_fn(|k| {
        let x = ROOM_SIZE_M.x * (k as f32 + 1.0) / 4.0;
        let (z0, z1) = if k % 2 == 0 {
            (0.0, depth - DOORWAY_M)
        } else {
            (DOORWAY_M, depth)
        };
        Partition {
            lo: Vec2::new(x - half, z0),
            hi: Vec2::new(x + half, z1),
        }
    })
}

/// The bay (0..4, by increasing x) a point of the air lies in: the bays are separated by the
/// partitions' centre planes.
pub fn bay(p: Vec3) -> usize {
    let width = ROOM_SIZE_M.x / 4.0;
    ((p.x / width).floor().max(0.0) as usize).min(3)
}

/// Material indices.
const WHITE: u32 = 0;
const OCHRE: u32 = 1;
const BLUE: u32 = 2;

/// The 15 faces: 6 walls (floor, ceiling, back, front, left, right), then per partition its
/// −x side, +x side and free end.
fn faces() -> Vec<Face> {
    let r = ROOM_SIZE_M;
    let (x, y, z) = (Vec3::X * r.x, Vec3::Y * r.y, Vec3::Z * r.z);
    let o = Vec3::ZERO;
    let centre = r / 2.0;
    let wall = |origin: Vec3, e1: Vec3, e2: Vec3| {
        let mid = origin + 0.5 * (e1 + e2);
        Face::oriented(origin, e1, e2, centre - mid, WHITE)
    };
    let mut out = vec![
        wall(o, x, z), // floor, y = 0
        wall(y, x, z), // ceiling, y = 1
        wall(o, x, y), // back, z = 0
        wall(z, x, y), // front, z = 2
        wall(o, y, z), // left, x = 0
        wall(x, y, z), // right, x = 2
    ];
    for (k, p) in partitions().iter().enumerate() {
        let material = if k == 1 { BLUE } else { OCHRE };
        let run = Vec3::Z * (p.hi.y - p.lo.y);
        let across = Vec3::X * (p.hi.x - p.lo.x);
        let lo = Vec3::new(p.lo.x, 0.0, p.lo.y);
        out.push(Face::oriented(lo, run, y, -Vec3::X, material));
        out.push(Face::oriented(lo + across, run, y, Vec3::X, material));
        let (end, outward) = if p.attached_at_back() {
            (lo + run, Vec3::Z)
        } else {
            (lo, -Vec3::Z)
        };
        out.push(Face::oriented(end, across, y, outward, material));
    }
    out
}

/// The maze (see the module docs) with a `lightmap_size × lightmap_size` chart layout
/// (clamped to `[MIN_LIGHTMAP_SIZE, 8192]`).
pub fn maze(lightmap_size: u32) -> Scene {
    let size = lightmap_size.clamp(MIN_LIGHTMAP_SIZE, super::file::MAX_LIGHTMAP_SIZE);
    let constant = |name: &str, albedo: Vec3| Material {
        name: name.into(),
        albedo: Albedo::Constant(albedo),
        subsurface: None,
    };
    Scene {
        name: "maze".into(),
        mesh: charted_mesh(&faces(), size),
        materials: vec![
            constant("white", Vec3::splat(0.7)),
            constant("ochre", Vec3::new(0.75, 0.6, 0.45)),
            constant("blue", Vec3::new(0.45, 0.6, 0.75)),
        ],
        lights: vec![Light::Point {
            position_m: LIGHT_POSITION_M,
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
    fn faces_point_into_the_air_and_partitions_alternate() {
        let parts = partitions();
        assert!(parts[0].attached_at_back() && !parts[1].attached_at_back());
        assert!(parts[2].attached_at_back());
        let in_room = |p: Vec3| p.cmpgt(Vec3::ZERO).all() && p.cmplt(ROOM_SIZE_M).all();
        for (k, f) in faces().iter().enumerate() {
            let n = f.e1.cross(f.e2).normalize();
            let mid = f.origin + 0.5 * (f.e1 + f.e2);
            let (front, back) = (mid + 0.01 * n, mid - 0.01 * n);
            assert!(in_room(front), "face {k} faces out of the room");
            if k < 6 {
                assert!(!in_room(back), "wall {k} has the room behind it");
            } else {
                assert!(parts.iter().all(|p| !p.contains(front)), "face {k}");
                assert!(parts.iter().any(|p| p.contains(back)), "face {k}");
            }
        }
        assert_eq!(bay(LIGHT_POSITION_M), 0);
        assert_eq!(bay(Vec3::new(1.9, 0.5, 1.0)), 3);
    }
}
