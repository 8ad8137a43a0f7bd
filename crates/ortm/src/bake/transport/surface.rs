//! The continuous surface's re-emission: `Q(x) = ∫_S R_d(|x − y|) dA(y)` per channel, the
//! subsurface profile integrated over every triangle of the mesh of one material, seen from a
//! point `x` on it (dimensionless; metres and m⁻² in). This is what the continuous model — the
//! one the path-traced reference samples — re-emits per unit of power entering at `x`.
//!
//! # Why
//! On a plane `Q = ρ̄`, the profile's total diffuse reflectance. Distances are Euclidean, so on
//! a curved surface `Q` differs: a sphere keeps ρ̄ exactly (the cap within chord `r` has area
//! `πr²`), but a fold, a crease or the skin between the lips brings more surface within the
//! profile's reach and `Q > ρ̄`; at the neck's open edge `Q < ρ̄`. The discrete weights must not
//! re-emit more than this (where texel footprints overlap, at seams, they would), and they must
//! not be held to ρ̄ where the model itself re-emits more ([`super::Kernels::scale_subsurface`]).
//!
//! # Method
//! A Barnes–Hut walk over a cluster tree of the triangles ([`super::hier::tree::Tree`], built
//! over one patch per triangle): a node of one material, radius `r` around its centroid at
//! distance `d > r` from `x`, is taken whole at the profile's second-order mean over its
//! triangles times its area ([`RdTable::cluster_mean`], from the node's second-moment tensor)
//! when the remainder's bound is within [`TOLERANCE`] in every channel; nodes beyond the
//! support are skipped;
//! other nodes are refined down to single triangles, integrated as a texel's footprint is
//! ([`super::footprint::triangle_weight`]: polar form near, Gauss–Legendre far).

use glam::Vec3;

use super::Patch;
use super::dipole::RdTable;
use super::footprint::triangle_weight;
use super::hier::subsurface::{MIXED, Moment, ProfileWalk, outer, second_moments_with};
use super::hier::tree::Tree;
use crate::scene::Mesh;

/// Error allowed per node taken whole (a fraction of the power entering at `x`; ρ̄ is
/// 0.13–0.44 for skin, and a query takes a few hundred nodes).
pub const TOLERANCE: f64 = 1e-6;

/// The mesh's translucent triangles and their cluster tree, for [`SurfaceReemission::at`].
pub struct SurfaceReemission {
    /// Corners (metres) and material of each translucent triangle.
    triangles: Vec<([Vec3; 3], u32)>,
    /// The tree over the triangles (one patch per triangle at its centroid); `None` when there
    /// are none.
    tree: Option<Tree>,
    /// Per node: the radius around its centroid that holds its triangles' corners, metres.
    radius_m: Vec<f32>,
    /// Per node: the material of all its triangles, or [`MIXED`].
    material: Vec<u32>,
    /// Per node: the second-moment tensor of its triangles about its centroid.
    moment: Vec<Moment>,
}

impl SurfaceReemission {
    /// The triangles of `mesh` whose material satisfies `translucent`.
    pub fn new(mesh: &Mesh, translucent: impl Fn(u32) -> bool) -> Self {
        let triangles: Vec<([Vec3; 3], u32)> = (mesh.triangles.iter())
            .filter(|t| translucent(t.material))
            .map(|t| (t.position.map(|i| mesh.positions_m[i as usize]), t.material))
            .collect();
        let patches: Vec<Patch> = (triangles.iter())
            .map(|(c, m)| {
                let n = (c[1] - c[0]).cross(c[2] - c[0]);
                Patch {
                    position_m: (c[0] + c[1] + c[2]) / 3.0,
                    normal: n.normalize_or_zero(),
                    lift_normal: n.normalize_or_zero(),
                    area_m2: 0.5 * n.length(),
                    rho: Vec3::ONE,
                    material: *m,
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: None,
                }
            })
            .collect();
        let tree = (!patches.is_empty()).then(|| Tree::build(&patches));
        let (mut radius_m, mut material) = (Vec::new(), Vec::new());
        if let Some(tree) = &tree {
            radius_m = vec![0.0f32; tree.nodes.len()];
            material = vec![MIXED; tree.nodes.len()];
            for (id, n) in tree.nodes.iter().enumerate() {
                let members = tree.members(id as u32);
                radius_m[id] = (members.iter())
                    .flat_map(|&t| triangles[t as usize].0)
                    .map(|p| (p - n.centroid).length())
                    .fold(0.0f32, f32::max);
                let m = triangles[members[0] as usize].1;
                if members.iter().all(|&t| triangles[t as usize].1 == m) {
                    material[id] = m;
                }
            }
        }
        // A triangle's tensor about its centroid g: (A/12)·Σ (v − g)(v − g)ᵀ over its corners.
        let moment = tree.as_ref().map_or_else(Vec::new, |tree| {
            second_moments_with(tree, |t| {
                let c = triangles[t as usize].0.map(|p| p.as_dvec3());
                let g = (c[0] + c[1] + c[2]) / 3.0;
                let a = 0.5 * (c[1] - c[0]).cross(c[2] - c[0]).length();
                let parts = c.map(|v| outer(v - g, a / 12.0));
                std::array::from_fn(|k| parts[0][k] + parts[1][k] + parts[2][k])
            })
        });
        Self {
            triangles,
            tree,
            radius_m,
            material,
            moment,
        }
    }

    /// `Q(x)` per channel for material `material` with its profile `table` whose support is
    /// `support_m`: the triangles of that material within the support (module docs).
    pub fn at(&self, table: &RdTable, material: u32, x: Vec3, support_m: f64) -> [f64; 3] {
        let mut q = [0.0f64; 3];
        let Some(tree) = &self.tree else {
            return q;
        };
        let walk = ProfileWalk {
            tree,
            material: &self.material,
            table,
            tolerance: TOLERANCE,
            moment: Some(&self.moment),
        };
        let radius = |s: u32| self.radius_m[s as usize] as f64;
        walk.walk(material, x, support_m, radius, |s, whole| {
            let n = &tree.nodes[s as usize];
            let w = match whole {
                Some(mid) => {
                    let area = n.area_m2 as f64;
                    mid.map(|v| v * area)
                }
                None => triangle_weight(
                    table,
                    x,
                    &self.triangles[tree.order[n.first as usize] as usize].0,
                ),
            };
            for c in 0..3 {
                q[c] += w[c];
            }
        });
        q
    }

    /// `Q(x)` summed over every triangle of `material` within the support one by one (what
    /// [`Self::at`] approximates; for tests).
    #[cfg(test)]
    fn every_triangle(&self, table: &RdTable, material: u32, x: Vec3, support_m: f64) -> [f64; 3] {
        let mut q = [0.0f64; 3];
        for (c, m) in &self.triangles {
            let centroid = (c[0] + c[1] + c[2]) / 3.0;
            let r = c
                .iter()
                .map(|p| (*p - centroid).length())
                .fold(0.0f32, f32::max);
            if *m == material && ((x - centroid).length() - r) as f64 <= support_m {
                let w = triangle_weight(table, x, c);
                for k in 0..3 {
                    q[k] += w[k];
                }
            }
        }
        q
    }
}

#[cfg(test)]
mod tests {
    use glam::Vec2;

    use super::*;
    use crate::scene::subsurface::skin1;
    use crate::scene::{MeshTriangle, SubsurfaceModel};

    fn mesh(positions_m: Vec<Vec3>, tris: &[[u32; 3]]) -> Mesh {
        Mesh {
            uvs: vec![Vec2::ZERO; positions_m.len()],
            normals: vec![Vec3::Z; positions_m.len()],
            positions_m,
            triangles: tris
                .iter()
                .map(|&p| MeshTriangle {
                    position: p,
                    uv: p,
                    normal: p,
                    material: 0,
                })
                .collect(),
        }
    }

    /// A square sheet of side `side` metres in `n × n` quads, folded along `x = 0` by the angle
    /// `fold` (radians; 0 is flat), two triangles per quad.
    fn folded_sheet(n: usize, side: f32, fold: f32) -> Mesh {
        let mut p = Vec::new();
        for j in 0..=n {
            for i in 0..=n {
                let x = side * (i as f32 / n as f32 - 0.5);
                let y = side * (j as f32 / n as f32 - 0.5);
                p.push(if x < 0.0 {
                    Vec3::new(x * fold.cos(), y, -x * fold.sin())
                } else {
                    Vec3::new(x, y, 0.0)
                });
            }
        }
        let w = (n + 1) as u32;
        let mut t = Vec::new();
        for j in 0..n as u32 {
            for i in 0..n as u32 {
                let a = j * w + i;
                t.push([a, a + 1, a + w + 1]);
                t.push([a, a + w + 1, a + w]);
            }
        }
        mesh(p, &t)
    }

    /// On a plane `Q = ρ̄` (every channel, 2·10⁻³: triangles beyond the support are not
    /// counted, and the dipole's red tail beyond it holds 1.0·10⁻³ of ρ̄); a fold raises it at the crease (more surface
    /// within reach), and it falls back to ρ̄ far from the crease.
    #[test]
    fn plane_gives_the_total_reflectance_and_a_fold_more() {
        for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
            let profile = skin1(model);
            let support = profile.support_radius(1e-4);
            let table = RdTable::new(&profile, support);
            // The profile over the plane within the support: 2π H(support) (ρ̄ less the tail
            // beyond the support, 2.1·10⁻³ of ρ̄ in the dipole's red).
            let rho = table.primitive(support).map(|h| h * std::f64::consts::TAU);
            let side = 6.0 * support as f32;
            let flat = SurfaceReemission::new(&folded_sheet(36, side, 0.0), |_| true);
            let q = flat.at(&table, 0, Vec3::new(0.1e-3, -0.2e-3, 0.0), support);
            for c in 0..3 {
                assert!(
                    (q[c] / rho[c] - 1.0).abs() < 1e-3,
                    "{model:?} flat: {q:?} vs {rho:?}"
                );
            }
            // Folded by 120°: the two halves face each other at 60°.
            let fold =
                SurfaceReemission::new(&folded_sheet(36, side, 120f32.to_radians()), |_| true);
            let on = fold.at(&table, 0, Vec3::new(0.0, 0.1e-3, 0.0), support);
            let beside = fold.at(&table, 0, Vec3::new(0.5e-3, 0.0, 0.0), support);
            let far = fold.at(
                &table,
                0,
                Vec3::new(1.5 * support as f32, 0.0, 0.0),
                support,
            );
            for c in 0..3 {
                assert!(
                    (on[c] / rho[c] - 1.0).abs() < 1e-3,
                    "{model:?} on: {on:?} vs {rho:?}"
                );
                assert!(
                    beside[c] > 1.04 * rho[c],
                    "{model:?} beside: {beside:?} vs {rho:?}"
                );
                assert!(
                    (far[c] / rho[c] - 1.0).abs() < 1e-3,
                    "{model:?} far: {far:?}"
                );
            }
            // The walk against every triangle one by one.
            for x in [
                Vec3::ZERO,
                Vec3::new(0.5e-3, 0.0, 0.0),
                Vec3::new(-3e-3, 2e-3, 4e-3),
            ] {
                let (walk, all) = (
                    fold.at(&table, 0, x, support),
                    fold.every_triangle(&table, 0, x, support),
                );
                for c in 0..3 {
                    assert!(
                        (walk[c] - all[c]).abs() < 1e-3 * all[c],
                        "{model:?} {x}: {walk:?} vs {all:?}"
                    );
                }
            }
            // Another material's triangles are not counted.
            assert_eq!(flat.at(&table, 1, Vec3::ZERO, support), [0.0; 3]);
        }
    }
}
