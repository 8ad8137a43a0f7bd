//! Visibility by ray casting: a compressed wide BVH (`obvhs` CWBVH, built in parallel) over the
//! scene's triangles, answering "is the segment p → q unobstructed?" and, for the path-traced reference
//! ([`crate::accuracy::reference`]), "which triangle does this ray hit first, and where?".
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

/// `v` with every `-0.0` component made `+0.0`: the traversal picks a node order and inverts
/// the direction by sign, and a ray along `-Vec3::Z` (components `-0.0`) misses everything.
#[inline]
fn positive_zeros(v: Vec3) -> Vec3 {
    v + Vec3::ZERO
}

/// A ray's hit on a triangle.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RayHit {
    /// Triangle index (the mesh's order).
    pub triangle: u32,
    /// Distance along the ray, metres.
    pub t: f32,
    /// Barycentric weights of the triangle's vertices 0, 1, 2 at the hit point.
    pub barycentrics: [f32; 3],
}

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

    /// The closest triangle hit by the ray from `origin` in unit direction `dir` within
    /// `[t_min, t_max]` metres, ignoring triangle `skip` (pass the triangle the ray leaves, or
    /// `u32::MAX`); `None` when nothing is hit. Triangle indices are the mesh's (or the order
    /// given to [`Visibility::from_triangles`]).
    pub fn closest_triangle_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        (t_min, t_max): (f32, f32),
        skip: u32,
    ) -> Option<RayHit> {
        if self.triangles.is_empty() || t_max <= t_min {
            return None;
        }
        let dir = positive_zeros(dir);
        let ray = Ray::new(Vec3A::from(origin), Vec3A::from(dir), t_min, t_max);
        let mut hit = obvhs::ray::RayHit::none();
        let found = self.bvh.ray_traverse(ray, &mut hit, |ray, id| {
            let tri = self.bvh.primitive_indices[id];
            if tri == skip {
                return f32::INFINITY;
            }
            self.triangles[tri as usize].intersect(ray)
        });
        if !found {
            return None;
        }
        let triangle = self.bvh.primitive_indices[hit.primitive_id as usize];
        Some(self.hit_record(triangle, origin, dir, hit.t))
    }

    /// Calls `f` for every triangle the ray from `origin` in unit direction `dir` crosses within
    /// `[t_min, t_max]` metres, in no particular order (the subsurface probe rays).
    pub fn for_each_hit(
        &self,
        origin: Vec3,
        dir: Vec3,
        (t_min, t_max): (f32, f32),
        mut f: impl FnMut(RayHit),
    ) {
        if self.triangles.is_empty() || t_max <= t_min {
            return;
        }
        let dir = positive_zeros(dir);
        let ray = Ray::new(Vec3A::from(origin), Vec3A::from(dir), t_min, t_max);
        self.bvh.ray_traverse_anyhit(ray, |ray, id| {
            let tri = self.bvh.primitive_indices[id];
            let t = self.triangles[tri as usize].intersect(ray);
            if t >= t_min && t <= t_max {
                f(self.hit_record(tri, origin, dir, t));
            }
        });
    }

    /// The hit record of triangle `triangle` at distance `t` along a ray: barycentrics of the
    /// hit point (weights of the triangle's vertices 0, 1, 2).
    fn hit_record(&self, triangle: u32, origin: Vec3, dir: Vec3, t: f32) -> RayHit {
        let tri = &self.triangles[triangle as usize];
        let (v0, v1, v2) = (Vec3::from(tri.v0), Vec3::from(tri.v1), Vec3::from(tri.v2));
        let (e1, e2) = (v1 - v0, v2 - v0);
        let p = dir.cross(e2);
        let det = e1.dot(p);
        let (mut u, mut v) = (0.0, 0.0);
        if det != 0.0 {
            let s = origin - v0;
            u = s.dot(p) / det;
            v = dir.dot(s.cross(e1)) / det;
        }
        let (u, v) = (u.clamp(0.0, 1.0), v.clamp(0.0, 1.0));
        let (u, v) = if u + v > 1.0 {
            (u / (u + v), v / (u + v))
        } else {
            (u, v)
        };
        RayHit {
            triangle,
            t,
            barycentrics: [1.0 - u - v, u, v],
        }
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

/// The square `[−half, half]²` at height `z`, facing +z, as two triangles (tests).
#[cfg(test)]
pub(crate) fn test_square(z: f32, half: f32) -> [Triangle; 2] {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn occluder_between_points_blocks() {
        let vis = Visibility::from_triangles(test_square(0.0, 1.0).to_vec());
        let p = Vec3::new(0.1, 0.2, -1.0);
        assert!(!vis.visible(p, Vec3::new(0.0, 0.0, 1.0), 1e-4));
        // Passing beside the quad.
        // The segment from (0.1,0.2,-1) to (3,0,1) crosses z=0 at x=1.55: outside the quad.
        assert!(vis.visible(p, Vec3::new(3.0, 0.0, 1.0), 1e-4));
        // Both points on the same side.
        assert!(vis.visible(p, Vec3::new(0.5, 0.5, -0.2), 1e-4));
        assert_eq!(vis.closest_hit(p, Vec3::Z, 0.0, 10.0), Some(1.0));
        assert_eq!(vis.closest_hit(p, -Vec3::Z, 0.0, 10.0), None);
        // Straight down from above, along `-Vec3::Z` (signed zeros): the hit's triangle,
        // distance and barycentrics; every crossing for the all-hits query.
        let above = Vec3::new(0.5, 0.25, 0.5);
        let hit = vis
            .closest_triangle_hit(above, -Vec3::Z, (0.0, 1.0), u32::MAX)
            .expect("hits the quad");
        assert_eq!((hit.triangle, hit.t), (0, 0.5));
        // Triangle 0 is a = (−1,−1), b = (1,−1), c = (1,1): (0.5, 0.25) = 0.25a + 0.125b + 0.625c.
        for (got, want) in hit.barycentrics.iter().zip([0.25, 0.125, 0.625]) {
            assert!((got - want).abs() < 1e-6, "{:?}", hit.barycentrics);
        }
        assert_eq!(
            vis.closest_triangle_hit(above, -Vec3::Z, (0.0, 1.0), 0),
            None,
            "the skipped triangle"
        );
        let mut n = 0;
        vis.for_each_hit(above, -Vec3::Z, (0.0, 1.0), |_| n += 1);
        assert_eq!(n, 1);
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
