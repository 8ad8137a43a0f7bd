//! Visibility by ray casting: a compressed wide BVH (`obvhs` CWBVH, built in parallel) over the
//! scene's triangles, answering "is the segment p → q unobstructed?".
//!
//! `obvhs` builds a SAH-quality PLOC BVH and traverses an 8-wide compressed BVH with SIMD node
//! tests; `ortm bench transport` reports the shadow-ray throughput.
//!
//! Positions are in metres. Segment end points should already be lifted off their surfaces
//! (see [`Visibility::visible`]'s `epsilon_m`), so a texel does not occlude itself.

use std::time::Duration;

use glam::{Vec3, Vec3A};
use obvhs::{
    BvhBuildParams, cwbvh::CwBvh, cwbvh::builder::build_cwbvh_from_tris, ray::Ray,
    triangle::Triangle,
};

use crate::scene::Mesh;

/// A ray-casting acceleration structure over a mesh's triangles.
pub struct Visibility {
    bvh: CwBvh,
    triangles: Vec<Triangle>,
}

impl Visibility {
    /// Builds the BVH over every triangle of `mesh` (positions in metres).
    pub fn new(mesh: &Mesh) -> Self {
        let triangles: Vec<Triangle> = mesh
            .triangles
            .iter()
            .map(|t| Triangle {
                v0: mesh.positions_m[t.position[0] as usize].into(),
                v1: mesh.positions_m[t.position[1] as usize].into(),
                v2: mesh.positions_m[t.position[2] as usize].into(),
            })
            .collect();
        Self::from_triangles(triangles)
    }

    /// Builds the BVH over the given triangles.
    pub fn from_triangles(triangles: Vec<Triangle>) -> Self {
        let bvh = if triangles.is_empty() {
            CwBvh::default()
        } else {
            build_cwbvh_from_tris(
                &triangles,
                BvhBuildParams::medium_build(),
                &mut Duration::default(),
            )
        };
        Self { bvh, triangles }
    }

    /// True when the open segment from `p` to `q` (metres) hits no triangle.
    ///
    /// The segment is shortened by `epsilon_m` at both ends so that the surfaces `p` and `q` lie
    /// on do not count as occluders; pass a small fraction of the texel size.
    #[inline]
    pub fn visible(&self, p: Vec3, q: Vec3, epsilon_m: f32) -> bool {
        if self.triangles.is_empty() {
            return true;
        }
        let d = q - p;
        let len = d.length();
        if len <= 2.0 * epsilon_m {
            return true;
        }
        let dir = d / len;
        let ray = Ray::new(Vec3A::from(p), Vec3A::from(dir), epsilon_m, len - epsilon_m);
        self.bvh.ray_traverse_miss(ray, |ray, id| {
            self.triangles[self.bvh.primitive_indices[id] as usize].intersect(ray)
        })
    }

    /// Distance to the closest hit along a ray from `origin` in unit direction `dir`, within
    /// `[t_min, t_max]` metres; `None` when nothing is hit (a test's reference).
    #[cfg(test)]
    pub fn closest_hit(&self, origin: Vec3, dir: Vec3, t_min: f32, t_max: f32) -> Option<f32> {
        if self.triangles.is_empty() {
            return None;
        }
        let ray = Ray::new(Vec3A::from(origin), Vec3A::from(dir), t_min, t_max);
        let mut hit = obvhs::ray::RayHit::none();
        if self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            self.triangles[self.bvh.primitive_indices[id] as usize].intersect(ray)
        }) {
            Some(hit.t)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn quad(z: f32, half: f32) -> [Triangle; 2] {
        let a = Vec3A::new(-half, -half, z);
        let b = Vec3A::new(half, -half, z);
        let c = Vec3A::new(half, half, z);
        let d = Vec3A::new(-half, half, z);
        [
            Triangle {
                v0: a,
                v1: b,
                v2: c,
            },
            Triangle {
                v0: a,
                v1: c,
                v2: d,
            },
        ]
    }

    #[test]
    fn occluder_between_points_blocks() {
        let vis = Visibility::from_triangles(quad(0.0, 1.0).to_vec());
        let p = Vec3::new(0.1, 0.2, -1.0);
        assert!(!vis.visible(p, Vec3::new(0.0, 0.0, 1.0), 1e-4));
        // Passing beside the quad.
        // The segment from (0.1,0.2,-1) to (3,0,1) crosses z=0 at x=1.55: outside the quad.
        assert!(vis.visible(p, Vec3::new(3.0, 0.0, 1.0), 1e-4));
        // Both points on the same side.
        assert!(vis.visible(p, Vec3::new(0.5, 0.5, -0.2), 1e-4));
        assert_eq!(vis.closest_hit(p, Vec3::Z, 0.0, 10.0), Some(1.0));
        assert_eq!(vis.closest_hit(p, -Vec3::Z, 0.0, 10.0), None);
    }

    #[test]
    fn brute_force_agreement() {
        // A few hundred random triangles; compare with testing every triangle.
        let mut tris = Vec::new();
        let mut s = 12345u32;
        let mut rnd = || {
            s = s.wrapping_mul(1664525).wrapping_add(1013904223);
            (s >> 8) as f32 / (1u32 << 24) as f32 * 2.0 - 1.0
        };
        for _ in 0..300 {
            let c = Vec3A::new(rnd(), rnd(), rnd());
            tris.push(Triangle {
                v0: c,
                v1: c + Vec3A::new(rnd(), rnd(), rnd()) * 0.2,
                v2: c + Vec3A::new(rnd(), rnd(), rnd()) * 0.2,
            });
        }
        let vis = Visibility::from_triangles(tris.clone());
        let mut disagreements = 0;
        for _ in 0..2000 {
            let p = Vec3::new(rnd(), rnd(), rnd()) * 1.5;
            let q = Vec3::new(rnd(), rnd(), rnd()) * 1.5;
            let d = q - p;
            let len = d.length();
            let ray = Ray::new(p.into(), (d / len).into(), 1e-4, len - 1e-4);
            let brute = tris.iter().all(|t| t.intersect(&ray).is_infinite());
            if brute != vis.visible(p, q, 1e-4) {
                disagreements += 1;
            }
        }
        assert_eq!(disagreements, 0);
    }
}
