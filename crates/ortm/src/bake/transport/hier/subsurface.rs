//! The subsurface term on the cluster tree: for one receiving texel, the senders within the
//! profile's support as tree nodes, each taken whole where the profile barely varies across it
//! and refined down to single texels where it does (a Barnes–Hut walk with error control).
//!
//! # Why
//! The profile's support (18.8 mm for the skin dipole) holds `π r² / A` texels: ~6,400 per
//! receiver at 1024² on the head, 6 G pairs in all, so texel-by-texel sums grow as `N⁴` in the
//! lightmap's side. Beyond a few texels the profile is smooth, so a node of many texels can
//! share one value: the walk visits `O(log n)` nodes plus the few texels next to the receiver.
//!
//! # What a visit means
//! A visit `(s, R)` stands for the raw weights of every texel `j` of node `s`:
//! `S_ij^raw = ∫_{P_j} R_d(|x_i − y|) dA(y) ≈ R A_j`, `R` (m⁻², per channel) the profile's mean
//! over the node's footprints seen from `x_i`, to second order about the node's centroid `c_s`
//! ([`RdTable::cluster_mean`]: `R_d(d)` plus the Hessian's term from the node's second-moment
//! tensor, [`second_moments`]; the linear term vanishes about the area-weighted centroid). A
//! single texel carries its exact weight (`R = S_ij^raw / A_j`, the self pair included: the
//! profile integrated over the texel's footprint, as [`Kernels::subsurface_raw`]).
//!
//! # Error control
//! A node of radius `r_s` (centroid to the farthest member's footprint) at distance `d` from the
//! receiver is taken whole when it lies apart (`d > r_s`), holds one material (the receiver's),
//! and the third-order remainder of its mean times its area is within the tolerance `ε` in
//! every channel ([`RdTable::cluster_mean`]: `⅙ D₃(d − r_s) r_s tr M_s`, `D₃` bounding the
//! profile's third derivative by the rate at which the dipole's tail falls). `ε` is the
//! walk's tolerance ([`super::Settings::subsurface_tolerance`], else the operator's
//! [`super::Settings::tolerance`]; `ortm bake --tolerance` walks at
//! [`super::DEFAULT_SUBSURFACE_TOLERANCE`] unless told otherwise): a fraction of a sender's
//! power per unit area at the receiver, like a form factor. Against the centroid's value `R_d(d)` with
//! the first-order test `(|R_d(d − r_s) − R_d(d)| + |R_d(d) − R_d(d + r_s)|)·A_s ≤ ε` (what a
//! walk saved without moments still uses, [`RdTable::cluster_value`]), the head at 512² visits
//! 487 nodes per receiver instead of 757 at ε = 10⁻⁴, and its subsurface term under its lamps
//! is closer to the walk's exact sum (0.18 % of the term's RMS instead of 0.34 %; the ignored
//! test `apps/ortm/tests/subsurface_walk.rs`).
//!
//! # Uses
//! - Normalisation ([`SubsurfaceWalk::normalise`]): `Q_j = Σ_i S_ij^raw A_i / A_j`; the midpoint
//!   rule depends only on distance, so for a node `Q_j` takes `R_d(|x_j − c_s|) A_s`: the walk
//!   from `j` with each visit's area. A visited texel with a footprint adds its own
//!   `S_ij^raw A_i / A_j` (`j`'s footprint seen from `i`: the footprint rule is not
//!   symmetric; only that weight is integrated). Then the same per-channel scale as
//!   [`Kernels::normalise_subsurface`] ([`Kernels::scale_subsurface`]). The texel pairs it
//!   integrated in polar form (the costly near ones, [`NearWeights`]) are kept, and later
//!   walks read a single texel's weight from them instead of integrating it again. With
//!   [`Kernels::balance_rounds`] > 0 the weights are balanced in rows and columns from every
//!   pair instead ([`Kernels::normalise_subsurface_keeping_near`]; `n × support²` pairs, ~390
//!   MB on the head at 256²), and each walk's row carries its receiver's factor `α_i`
//!   ([`crate::bake::transport::Patch::subsurface_gather`]) besides the senders' `k_j`.
//! - The bake's cell integration ([`crate::bake::cells`]): a visit adds
//!   `R·W_s` to the receiver's transfer, `W_s = Σ_{j ∈ s} A_j k_j / ρ_j` per channel
//!   ([`SubsurfaceWalk::weight`]; `k_j` the sender scale, `ρ_j` its albedo), and the self visit
//!   also the point mass `−1` of `R(i, i)`.

use rayon::prelude::*;

use super::super::dipole::RdTable;
use super::super::{Cancelled, Kernels, NearWeights, Patch, SetupProgress, footprint};
use super::tree::Tree;
use glam::Vec3;

/// A node whose members are of more than one material.
pub const MIXED: u32 = u32::MAX;

/// The Barnes–Hut walk of the profile over a cluster tree, shared by the texels' subsurface
/// walk ([`SubsurfaceWalk::walk`]) and the continuous surface's re-emission
/// ([`crate::bake::transport::surface::SurfaceReemission::at`]): from a point of material `m`,
/// the nodes of that material within the profile's support, each taken whole where
/// [`RdTable::cluster_value`] accepts it at `tolerance`, refined down to leaves otherwise.
pub(crate) struct ProfileWalk<'a> {
    /// The cluster tree walked.
    pub tree: &'a Tree,
    /// Per node: the material of all its members, or [`MIXED`].
    pub material: &'a [u32],
    /// The material's profile.
    pub table: &'a RdTable,
    /// Error allowed per node taken whole ([`RdTable::cluster_value`]).
    pub tolerance: f64,
    /// Per node: its second-moment tensor about its centroid ([`second_moments`]); when
    /// given, a node is taken whole at its second-order mean ([`RdTable::cluster_mean`])
    /// instead of its centroid's value.
    pub moment: Option<&'a [Moment]>,
}

/// A node's second-moment tensor about its centroid, `∫ (y − c)(y − c)ᵀ dA` over its members'
/// footprints, m⁴: `[xx, yy, zz, xy, xz, yz]`.
pub type Moment = [f32; 6];

/// `uᵀ M u` of the tensor `m` along the unit vector `u`.
#[inline]
fn along(m: &Moment, u: Vec3) -> f64 {
    let [xx, yy, zz, xy, xz, yz] = m.map(|v| v as f64);
    let (x, y, z) = (u.x as f64, u.y as f64, u.z as f64);
    let uu = xx * x * x + yy * y * y + zz * z * z + 2.0 * (xy * x * y + xz * x * z + yz * y * z);
    uu.max(0.0)
}

/// `a·(v vᵀ)` as a [`Moment`]'s components, in f64.
#[inline]
pub(crate) fn outer(v: glam::DVec3, a: f64) -> [f64; 6] {
    [
        a * v.x * v.x,
        a * v.y * v.y,
        a * v.z * v.z,
        a * v.x * v.y,
        a * v.x * v.z,
        a * v.y * v.z,
    ]
}

/// Per node of `tree` (built over `patches`): the second-moment tensor of its members'
/// footprints about its centroid ([`Moment`]); a member without a footprint counts as a
/// square of its area in its plane.
pub fn second_moments(tree: &Tree, patches: &[Patch]) -> Vec<Moment> {
    second_moments_with(tree, |j| {
        let p = &patches[j as usize];
        let a = p.area_m2 as f64;
        // A parallelogram s·f₀ + t·f₁, s, t uniform in [−½, ½]: (f₀f₀ᵀ + f₁f₁ᵀ)·A/12.
        let [f0, f1] = p.footprint_m.unwrap_or_else(|| {
            let t = p.normal.any_orthonormal_pair();
            let side = p.area_m2.max(0.0).sqrt();
            [t.0 * side, t.1 * side]
        });
        let (x, y) = (
            outer(f0.as_dvec3(), a / 12.0),
            outer(f1.as_dvec3(), a / 12.0),
        );
        std::array::from_fn(|k| x[k] + y[k])
    })
}

/// Per node of `tree`: its second-moment tensor about its centroid, from each member's own
/// tensor about its position, `leaf(member)` (`[xx, yy, zz, xy, xz, yz]`, m⁴). Children
/// before parents, by the parallel-axis rule.
pub(crate) fn second_moments_with(tree: &Tree, leaf: impl Fn(u32) -> [f64; 6]) -> Vec<Moment> {
    let nodes = &tree.nodes;
    let mut m = vec![[0.0f64; 6]; nodes.len()];
    for id in (0..nodes.len()).rev() {
        let n = &nodes[id];
        m[id] = if n.is_leaf() {
            leaf(tree.order[n.first as usize])
        } else {
            let mut sum = [0.0f64; 6];
            for &c in &n.children {
                let k = &nodes[c as usize];
                let shift = outer((k.centroid - n.centroid).as_dvec3(), k.area_m2 as f64);
                for (i, v) in sum.iter_mut().enumerate() {
                    *v += m[c as usize][i] + shift[i];
                }
            }
            sum
        };
    }
    m.into_iter().map(|v| v.map(|x| x as f32)).collect()
}

impl ProfileWalk<'_> {
    /// Calls `visit(node, Some(R))` for every node taken whole, `R` the profile at its
    /// centroid (m⁻², per channel), and `visit(leaf, None)` for every leaf reached, from the
    /// point `x` (metres) of material `m`; `radius(node)` is the radius around the node's
    /// centroid that holds its members (metres). Nodes of another material, and those wholly
    /// beyond `support` (metres), are skipped.
    pub fn walk(
        &self,
        m: u32,
        x: Vec3,
        support: f64,
        radius: impl Fn(u32) -> f64,
        mut visit: impl FnMut(u32, Option<[f64; 3]>),
    ) {
        let mut stack = vec![0u32];
        while let Some(s) = stack.pop() {
            let mat = self.material[s as usize];
            if mat != m && mat != MIXED {
                continue;
            }
            let n = &self.tree.nodes[s as usize];
            let d = (n.centroid - x).length() as f64;
            let r = radius(s);
            if d - r > support {
                continue;
            }
            if n.is_leaf() {
                visit(s, None);
                continue;
            }
            let area = n.area_m2 as f64;
            let whole = match self.moment {
                _ if mat != m => None,
                Some(moment) if d > r => {
                    let m = &moment[s as usize];
                    let m_tr = (m[0] + m[1] + m[2]) as f64;
                    let m_uu = || along(m, (x - n.centroid) / d as f32);
                    self.table
                        .cluster_mean(d, r, area, m_tr, m_uu, self.tolerance)
                }
                Some(_) => None,
                None => self.table.cluster_value(d, r, area, self.tolerance),
            };
            if let Some(mid) = whole {
                visit(s, Some(mid));
                continue;
            }
            stack.extend(n.children);
        }
    }
}

/// The tree's per-node data for the subsurface walk.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct SubsurfaceWalk {
    tolerance: f64,
    /// Per node: the material of all its members, or [`MIXED`].
    material: Vec<u32>,
    /// Per node: `W_s = Σ A_j k_j / ρ_j` per channel, m² (0 where `ρ_j = 0`).
    weight: Vec<[f32; 3]>,
    /// Per node: its second-moment tensor ([`second_moments`]); empty in a walk saved
    /// without it, which takes nodes whole at their centroid's value.
    #[serde(default)]
    moment: Vec<Moment>,
    /// The raw weights of the texel pairs integrated in polar form, kept by
    /// [`SubsurfaceWalk::normalise`] for [`SubsurfaceWalk::walk`]'s single texels (empty
    /// before).
    near: NearWeights,
}

impl SubsurfaceWalk {
    /// The walk over `tree` (built over `patches`) at tolerance `tolerance`, with the sender
    /// weights of `patches` as they are (see [`SubsurfaceWalk::set_weights`]).
    pub fn new(tree: &Tree, patches: &[Patch], tolerance: f32) -> Self {
        let nodes = &tree.nodes;
        let mut material = vec![MIXED; nodes.len()];
        for id in (0..nodes.len()).rev() {
            let n = &nodes[id];
            material[id] = if n.is_leaf() {
                patches[tree.order[n.first as usize] as usize].material
            } else {
                let [a, b] = n.children.map(|c| material[c as usize]);
                if a == b { a } else { MIXED }
            };
        }
        let moment = second_moments(tree, patches);
        let mut walk = Self {
            tolerance: tolerance as f64,
            material,
            moment,
            weight: Vec::new(),
            near: NearWeights::default(),
        };
        walk.set_weights(tree, patches);
        walk
    }

    /// The same walk taking nodes whole at their centroid's value under the first-order test
    /// ([`RdTable::cluster_value`]) instead of their second-order mean: the rule before the
    /// moments, kept to measure against (`apps/ortm/tests/subsurface_walk.rs`).
    pub fn with_centroid_values(mut self) -> Self {
        self.moment = Vec::new();
        self
    }

    /// Recomputes every node's sender weight `W_s` from `patches` (after their scales change).
    pub fn set_weights(&mut self, tree: &Tree, patches: &[Patch]) {
        let nodes = &tree.nodes;
        let mut weight = vec![[0.0f32; 3]; nodes.len()];
        for id in (0..nodes.len()).rev() {
            let n = &nodes[id];
            weight[id] = if n.is_leaf() {
                let p = &patches[tree.order[n.first as usize] as usize];
                [0, 1, 2].map(|c| {
                    if p.rho[c] > 0.0 {
                        p.area_m2 * p.subsurface_scale[c] / p.rho[c]
                    } else {
                        0.0
                    }
                })
            } else {
                let [a, b] = n.children.map(|c| weight[c as usize]);
                [0, 1, 2].map(|c| a[c] + b[c])
            };
        }
        self.weight = weight;
    }

    /// The walk's tolerance: the error a node's profile mean may carry, as a fraction of a
    /// sender's power per unit area at the receiver (module docs, "Error control").
    pub fn tolerance(&self) -> f64 {
        self.tolerance
    }

    /// `W_s` of node `node` per channel, m² (module docs).
    #[inline]
    pub fn weight(&self, node: u32) -> [f32; 3] {
        self.weight[node as usize]
    }

    /// Calls `visit(node, R, self_pair)` for the senders of translucent texel `i` (module docs):
    /// every texel of the receiver's material within the profile's support lies in exactly one
    /// visited node. Nothing for an opaque texel.
    pub fn walk(
        &self,
        tree: &Tree,
        patches: &[Patch],
        kernels: &Kernels,
        i: usize,
        visit: impl FnMut(u32, [f64; 3], bool),
    ) {
        let leaf = |j: usize, a: &Patch, b: &Patch| {
            (self.near.get(i as u32, j as u32)).or_else(|| kernels.subsurface_raw(a, b, i == j))
        };
        // The receiver's factor on its row ([`Patch::subsurface_gather`]; 1 as the walk
        // normalises, an exact product then).
        let g = patches[i].subsurface_gather.to_array().map(f64::from);
        let mut visit = visit;
        let scaled = |s: u32, rd: [f64; 3], me: bool| {
            visit(s, [rd[0] * g[0], rd[1] * g[1], rd[2] * g[2]], me)
        };
        self.walk_with(tree, patches, kernels, i, leaf, scaled);
    }

    /// [`SubsurfaceWalk::walk`] with the raw weight of a single texel `j` (patch `b`) seen
    /// from `i` (patch `a`) given by `leaf(j, a, b)`; `None` or 0 visits nothing.
    fn walk_with(
        &self,
        tree: &Tree,
        patches: &[Patch],
        kernels: &Kernels,
        i: usize,
        mut leaf: impl FnMut(usize, &Patch, &Patch) -> Option<[f64; 3]>,
        mut visit: impl FnMut(u32, [f64; 3], bool),
    ) {
        let a = &patches[i];
        let m = a.material;
        let (Some(Some(table)), Some(&support)) = (
            kernels.tables.get(m as usize),
            kernels.support_m.get(m as usize),
        ) else {
            return;
        };
        let walk = ProfileWalk {
            tree,
            material: &self.material,
            table,
            tolerance: self.tolerance,
            moment: (!self.moment.is_empty()).then_some(&self.moment[..]),
        };
        let radius = |s: u32| tree.nodes[s as usize].radius_m as f64;
        walk.walk(m, a.position_m, support, radius, |s, whole| match whole {
            Some(mid) => visit(s, mid, false),
            None => {
                let j = tree.order[tree.nodes[s as usize].first as usize] as usize;
                let b = &patches[j];
                if let Some(w) = leaf(j, a, b)
                    && w != [0.0; 3]
                {
                    let inv = 1.0 / b.area_m2.max(f32::MIN_POSITIVE) as f64;
                    visit(s, w.map(|x| x * inv), i == j);
                }
            }
        });
    }

    /// Sets every translucent patch's [`Patch::subsurface_scale`] from its re-emission
    /// `Q_j` summed by the walk (module docs), as [`Kernels::normalise_subsurface`] does from
    /// every pair, and the node weights after it. Reports "transport: subsurface weights", then
    /// "transport: subsurface cap" ([`Kernels::scale_subsurface_with`]).
    /// Returns the number of patches scaled in some channel.
    pub fn normalise(
        &mut self,
        tree: &Tree,
        patches: &mut [Patch],
        kernels: &Kernels,
        progress: &SetupProgress,
    ) -> Result<usize, Cancelled> {
        if kernels.balance_rounds > 0 {
            let (scaled, near) = kernels.normalise_subsurface_keeping_near(patches, progress)?;
            self.set_weights(tree, patches);
            self.near = near;
            return Ok(scaled);
        }
        progress.phase("transport: subsurface weights", patches.len() as u64);
        type Near = Vec<(u32, [f32; 3])>;
        let per_sender: Vec<([f64; 3], Near)> = {
            let patches: &[Patch] = patches;
            (0..patches.len())
                .into_par_iter()
                .map(|j| {
                    if j % 4096 == 0 {
                        progress.advance(4096.min(patches.len() - j) as u64);
                    }
                    let (mut q, mut q_texels) = ([0.0f64; 3], [0.0f64; 3]);
                    let mut near: Near = Vec::new();
                    if progress.check().is_err() {
                        return (q, near);
                    }
                    let b = &patches[j];
                    let inv_area = 1.0 / b.area_m2.max(f32::MIN_POSITIVE) as f64;
                    // A texel `i` beside a sender with a footprint: its weight as the receiver
                    // of `j` (the footprint rule is not symmetric in the pair), summed here;
                    // the walk's own weight (`j` seen from `i`) is not needed.
                    let leaf = |i: usize, walker: &Patch, a: &Patch| {
                        let Some(f) = walker.footprint_m else {
                            return kernels.subsurface_raw(walker, a, i == j);
                        };
                        if let Some(w) = kernels.subsurface_raw(a, walker, i == j) {
                            if footprint::is_near(a.position_m, walker.position_m, f) {
                                near.push((i as u32, w.map(|x| x as f32)));
                            }
                            for c in 0..3 {
                                q_texels[c] += w[c] * a.area_m2 as f64 * inv_area;
                            }
                        }
                        None
                    };
                    self.walk_with(tree, patches, kernels, j, leaf, |s, rd, _| {
                        let area = tree.nodes[s as usize].area_m2 as f64;
                        for c in 0..3 {
                            q[c] += rd[c] * area;
                        }
                    });
                    for c in 0..3 {
                        q[c] += q_texels[c];
                    }
                    (q, near)
                })
                .collect()
        };
        progress.check()?;
        let near = NearWeights::by_receiver(patches.len(), per_sender.iter().map(|(_, n)| n));
        let q: Vec<[f64; 3]> = per_sender.into_iter().map(|(q, _)| q).collect();
        let scaled = kernels.scale_subsurface_with(patches, &q, progress)?;
        self.set_weights(tree, patches);
        self.near = near;
        Ok(scaled)
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::Vec3;

    use super::*;
    use crate::bake::raycast::Visibility;
    use crate::bake::transport::Effects;
    use crate::scene::SubsurfaceModel;
    use crate::scene::subsurface::skin1;

    /// A bumpy `n × n` sheet of `pitch`-metre texels (heights of a few texels, so distances
    /// are 3D), materials 0 and 1 in two halves (both skin).
    /// With `footprints`, each texel carries its square footprint (side `√area`, in the sheet's
    /// xy plane).
    fn sheet(n: usize, pitch: f32, footprints: bool) -> Vec<Patch> {
        let mut v = Vec::new();
        for y in 0..n {
            for x in 0..n {
                let (fx, fy) = (x as f32 / n as f32, y as f32 / n as f32);
                let z = 4.0 * pitch * ((7.0 * fx).sin() + (5.0 * fy).cos());
                v.push(Patch {
                    position_m: Vec3::new(x as f32 * pitch, y as f32 * pitch, z),
                    normal: Vec3::Z,
                    lift_normal: Vec3::Z,
                    area_m2: pitch * pitch * (1.0 + 0.3 * fx),
                    rho: Vec3::new(0.8, 0.5, 0.4),
                    material: u32::from(x >= 3 * n / 4),
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: footprints.then(|| {
                        let side = pitch * (1.0 + 0.3 * fx).sqrt();
                        [Vec3::X * side, Vec3::Y * side]
                    }),
                });
            }
        }
        v
    }

    fn kernels() -> Kernels {
        let skin = skin1(SubsurfaceModel::Dipole);
        Kernels::from_parts(
            Effects {
                radiosity: false,
                subsurface: true,
            },
            vec![Some(skin), Some(skin)],
            Arc::new(Visibility::from_triangles(Vec::new())),
        )
    }

    /// Per receiver: every texel of its material within the support lies in exactly one
    /// visited node, no other material's texel in any; at ε = 0 only single texels are visited
    /// and `Q` equals the sum over every pair; at ε > 0 each visited node errs by at most ε
    /// (module docs), so `|Q − Q_exact| ≤ ε · (block visits)`, and blocks are taken.
    #[test]
    fn walk_covers_the_support_once_and_bounds_its_error() {
        let (n, pitch) = (64usize, 0.6e-3f32);
        let patches = sheet(n, pitch, false);
        let k = kernels();
        let exact = k.subsurface_reemission(&patches);
        let tree = Tree::build(&patches);
        let support = k.support_m[0];
        for eps in [0.0f32, 1e-4, 1e-3] {
            let walk = SubsurfaceWalk::new(&tree, &patches, eps);
            let (mut visits, mut leaves) = (0usize, 0usize);
            for i in (0..patches.len()).step_by(37) {
                let mut seen = vec![0u32; patches.len()];
                let mut q = [0.0f64; 3];
                let mut blocks = 0usize;
                walk.walk(&tree, &patches, &k, i, |s, rd, me| {
                    let node = &tree.nodes[s as usize];
                    assert_eq!(me, node.is_leaf() && tree.members(s)[0] as usize == i);
                    blocks += usize::from(!node.is_leaf());
                    leaves += usize::from(node.is_leaf());
                    for &j in tree.members(s) {
                        seen[j as usize] += 1;
                    }
                    for c in 0..3 {
                        q[c] += rd[c] * node.area_m2 as f64;
                    }
                });
                visits += blocks;
                let pi = patches[i].position_m;
                for (j, p) in patches.iter().enumerate() {
                    let within = (p.position_m - pi).length() as f64 <= support;
                    if p.material != patches[i].material {
                        assert_eq!(seen[j], 0, "ε {eps}: {i} sees {j} of another material");
                    } else if within {
                        assert_eq!(seen[j], 1, "ε {eps}: {i} sees {j} {} times", seen[j]);
                    } else {
                        assert!(seen[j] <= 1);
                    }
                }
                let bound = eps as f64 * blocks as f64 + 1e-9 * exact[i][0].max(1.0);
                for c in 0..3 {
                    assert!(
                        (q[c] - exact[i][c]).abs() <= bound,
                        "ε {eps}: texel {i} channel {c}: walk {} exact {} bound {bound}",
                        q[c],
                        exact[i][c]
                    );
                }
            }
            println!("ε {eps}: {visits} block visits, {leaves} texel visits");
            if eps == 0.0 {
                assert_eq!(visits, 0, "ε = 0 takes no block");
            } else {
                assert!(visits > 0, "ε {eps}: some blocks are taken");
            }
        }
    }

    /// A node's second-order mean ([`RdTable::cluster_mean`], with [`second_moments`]) against
    /// the sum of its members' footprint integrals: within the tolerance whenever it is given,
    /// and far closer than the centroid's value `R_d(d)·A` (the first-order rule's) — the
    /// Hessian term is what it adds.
    #[test]
    fn second_order_mean_is_within_its_tolerance_and_beats_the_centroid() {
        let (n, pitch) = (48usize, 0.5e-3f32);
        let patches = sheet(n, pitch, true);
        let k = kernels();
        let table = k.tables[0].as_ref().unwrap();
        let tree = Tree::build(&patches);
        let moment = second_moments(&tree, &patches);
        let (mut taken, mut err_mean, mut err_centroid) = (0usize, 0.0f64, 0.0f64);
        for i in (0..patches.len()).step_by(97) {
            let x = patches[i].position_m;
            for (s, node) in tree.nodes.iter().enumerate() {
                let members = tree.members(s as u32);
                if members.len() < 4 || members.iter().any(|&j| patches[j as usize].material != 0) {
                    continue;
                }
                let d = (node.centroid - x).length() as f64;
                let (r, area) = (node.radius_m as f64, node.area_m2 as f64);
                let u = (x - node.centroid) / d as f32;
                let m = &moment[s];
                let m_tr = (m[0] + m[1] + m[2]) as f64;
                for tol in [1e-5, 1e-4, 1e-3] {
                    let Some(mean) = table.cluster_mean(d, r, area, m_tr, || along(m, u), tol)
                    else {
                        continue;
                    };
                    let mut exact = [0.0f64; 3];
                    for &j in members {
                        let w = k.subsurface_raw(&patches[i], &patches[j as usize], false);
                        for (e, v) in exact.iter_mut().zip(w.unwrap()) {
                            *e += v;
                        }
                    }
                    let centroid = table.rd_within(d);
                    for c in 0..3 {
                        let e = (mean[c] * area - exact[c]).abs();
                        assert!(
                            e <= tol + 1e-3 * exact[c],
                            "receiver {i} node {s} ε {tol}: mean {} exact {} ({} members)",
                            mean[c] * area,
                            exact[c],
                            members.len()
                        );
                        err_mean += e;
                        err_centroid += (centroid[c] * area - exact[c]).abs();
                    }
                    taken += 1;
                }
            }
        }
        println!("{taken} nodes: error {err_mean:.3e} (mean) vs {err_centroid:.3e} (centroid)");
        assert!(taken > 1000, "{taken} nodes taken");
        assert!(
            err_mean < 0.2 * err_centroid,
            "second order {err_mean:e} vs centroid {err_centroid:e}"
        );
    }

    /// [`second_moments`] against the tensor summed over each node's members directly.
    #[test]
    fn second_moments_follow_the_parallel_axis_rule() {
        let patches = sheet(24, 1e-3, true);
        let tree = Tree::build(&patches);
        let moment = second_moments(&tree, &patches);
        for (s, node) in tree.nodes.iter().enumerate().step_by(7) {
            let mut direct = [0.0f64; 6];
            for &j in tree.members(s as u32) {
                let p = &patches[j as usize];
                let [f0, f1] = p.footprint_m.unwrap();
                let a = p.area_m2 as f64;
                let parts = [
                    outer(f0.as_dvec3(), a / 12.0),
                    outer(f1.as_dvec3(), a / 12.0),
                    outer((p.position_m - node.centroid).as_dvec3(), a),
                ];
                for (k, v) in direct.iter_mut().enumerate() {
                    *v += parts[0][k] + parts[1][k] + parts[2][k];
                }
            }
            let scale = direct[0] + direct[1] + direct[2];
            for k in 0..6 {
                assert!(
                    (moment[s][k] as f64 - direct[k]).abs() <= 1e-4 * scale,
                    "node {s} component {k}: {} vs {}",
                    moment[s][k],
                    direct[k]
                );
            }
        }
    }

    /// The walk's normalisation scales as the pairwise one does, to its tolerance, with the
    /// midpoint rule and with footprints.
    #[test]
    fn walk_normalisation_matches_the_pairwise_one() {
        for footprints in [false, true] {
            normalisation_matches(footprints);
        }
    }

    fn normalisation_matches(footprints: bool) {
        let patches = sheet(48, 2e-3, footprints);
        let k = kernels();
        let mut exact = patches.clone();
        let scaled = k.normalise_subsurface(&mut exact);
        let tree = Tree::build(&patches);
        let mut walked = patches.clone();
        let mut walk = SubsurfaceWalk::new(&tree, &walked, 0.0);
        let n = walk
            .normalise(&tree, &mut walked, &k, &SetupProgress::none())
            .unwrap();
        assert!(scaled > 0, "2 mm texels: some senders are scaled");
        assert_eq!(n, scaled, "footprints {footprints}");
        for (a, b) in exact.iter().zip(&walked) {
            let d = (a.subsurface_scale - b.subsurface_scale)
                .abs()
                .max_element();
            assert!(d < 1e-5, "footprints {footprints}: scales differ by {d}");
        }
        // The node weights follow the scales.
        let root = walk.weight(0);
        let sum: f64 = walked
            .iter()
            .map(|p| (p.area_m2 * p.subsurface_scale.x / p.rho.x) as f64)
            .sum();
        assert!((root[0] as f64 - sum).abs() < 1e-4 * sum);
    }

    /// Balanced weights ([`Kernels::balance_rounds`]) through the walk: on skin texels of
    /// unequal size (columns 1.5 and 3 mm wide in turn, a square 54 mm wide) the walk's
    /// normalisation gives every texel the pairwise balance's factors exactly, and what the
    /// walk makes a texel gather under a uniform irradiance (`Σ_visits R·W_s·ρ`, exact at
    /// ε = 0) is ρ̄ within 10⁻³ everywhere, borders included — where the capped walk's rows are
    /// more than 5 % off somewhere.
    #[test]
    fn balanced_walk_holds_the_rows() {
        let mut k = kernels();
        let rho = Vec3::new(0.8, 0.5, 0.4);
        let rho_bar: [f64; 3] =
            std::array::from_fn(|c| k.profiles[0].unwrap().channels[c].total_reflectance());
        let (n, pitch) = (24usize, 2.25e-3f32);
        let mut patches = Vec::new();
        for y in 0..n {
            let mut x0 = 0.0f32;
            for x in 0..n {
                let w = if x % 2 == 0 { 1.5e-3 } else { 3e-3 };
                patches.push(Patch {
                    position_m: Vec3::new(x0 + 0.5 * w, y as f32 * pitch, 0.0),
                    normal: Vec3::Z,
                    lift_normal: Vec3::Z,
                    area_m2: w * pitch,
                    rho,
                    material: 0,
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: Some([Vec3::X * w, Vec3::Y * pitch]),
                });
                x0 += w;
            }
        }
        let tree = Tree::build(&patches);
        let worst_row = |k: &Kernels| {
            let mut walked = patches.clone();
            let mut walk = SubsurfaceWalk::new(&tree, &walked, 0.0);
            walk.normalise(&tree, &mut walked, k, &SetupProgress::none())
                .unwrap();
            let mut worst = 0.0f64;
            for i in 0..walked.len() {
                let mut row = [0.0f64; 3];
                walk.walk(&tree, &walked, k, i, |s, rd, _| {
                    let w = walk.weight(s);
                    for c in 0..3 {
                        row[c] += rd[c] * w[c] as f64 * rho[c] as f64;
                    }
                });
                for c in 0..3 {
                    worst = worst.max((row[c] / rho_bar[c] - 1.0).abs());
                }
            }
            (walked, worst)
        };
        let (_, capped) = worst_row(&k);
        k.balance_rounds = 60;
        let (walked, balanced) = worst_row(&k);
        println!("rows off ρ̄ at worst: capped {capped:.4}, balanced {balanced:.2e}");
        assert!(capped > 0.05, "the capped rows are off ρ̄: {capped}");
        assert!(balanced < 1e-3, "balanced rows: {balanced}");
        let mut pairwise = patches.clone();
        k.normalise_subsurface(&mut pairwise);
        for (a, b) in walked.iter().zip(&pairwise) {
            assert_eq!(
                (a.subsurface_scale, a.subsurface_gather),
                (b.subsurface_scale, b.subsurface_gather)
            );
        }
    }
}
