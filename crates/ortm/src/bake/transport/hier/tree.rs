//! The cluster tree of the hierarchical transport: a binary tree over patches (texels) in 3D,
//! split at the median of the longest axis of the member centroids' bounding box, down to one
//! patch per leaf.
//!
//! A node whose members face different ways (`|Σ A n| / A <` [`SPLIT_FLATNESS`]) is split by
//! orientation instead (at the middle of the range of the normal component that varies most),
//! so a room's corner separates into its walls at once.
//!
//! Why 3D rather than texture-space blocks: the operator links clusters by their geometry
//! (distance, size, orientation), and a 3D split keeps clusters compact whatever the UV layout
//! — the head's thousands of small charts, or a chart that wraps around a corner. Clusters
//! that mix orientations (a room's corner) are never linked as a whole: the admissibility test
//! ([`super::Operator`]) asks for flat clusters, so those are refined.
//!
//! Each node stores what the block-level kernel needs: area (m²), area-weighted centroid (m),
//! the area-weighted normal sum `Σ A_j n_j` (m²; its length over the area is 1 for a flat
//! cluster), and a bounding radius (m) around the centroid that covers the members' footprints.

use glam::Vec3;

use super::super::Patch;

/// Below this `|Σ A n| / A` a node is split by orientation rather than by position.
pub const SPLIT_FLATNESS: f32 = 0.95;

/// Node index sentinel: no children (a leaf).
pub const NO_CHILD: u32 = u32::MAX;

/// A cluster of patches.
#[derive(Clone, Copy, Debug, serde::Serialize, serde::Deserialize)]
pub struct Node {
    /// First member in [`Tree::order`].
    pub first: u32,
    /// Number of members.
    pub count: u32,
    /// Children (both [`NO_CHILD`] for a leaf).
    pub children: [u32; 2],
    /// Total area, m².
    pub area_m2: f32,
    /// Area-weighted centroid, metres.
    pub centroid: Vec3,
    /// `Σ A_j n_j`, m².
    pub normal_sum: Vec3,
    /// Radius around the centroid that contains every member's footprint, metres.
    pub radius_m: f32,
}

impl Node {
    /// True for a single patch.
    #[inline]
    pub fn is_leaf(&self) -> bool {
        self.children[0] == NO_CHILD
    }

    /// `|Σ A n| / A` in `[0, 1]`: 1 when every member faces the same way.
    #[inline]
    pub fn flatness(&self) -> f32 {
        if self.area_m2 > 0.0 {
            self.normal_sum.length() / self.area_m2
        } else {
            0.0
        }
    }
}

/// The tree: nodes in depth-first order (a parent before its children; node 0 the root) and
/// the members of every node as a contiguous range of `order`.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Tree {
    /// Nodes; node 0 is the root.
    pub nodes: Vec<Node>,
    /// Patch indices, each node's members contiguous.
    pub order: Vec<u32>,
    /// The leaf node of every patch (patch order).
    pub leaf_of: Vec<u32>,
}

/// No parent: the root's entry in [`Tree::parents`].
pub const NO_PARENT: u32 = u32::MAX;

impl Tree {
    /// Unit direction from node `r`'s centroid to node `s`'s: the direction of a link from
    /// sender `s` into block receiver `r` ([`super::Link`]), computed as the refinement
    /// computed it (bit for bit).
    #[inline]
    pub fn direction(&self, r: u32, s: u32) -> Vec3 {
        let d = self.nodes[s as usize].centroid - self.nodes[r as usize].centroid;
        d / d.length()
    }

    /// The parent of every node ([`NO_PARENT`] for the root), in node order.
    pub fn parents(&self) -> Vec<u32> {
        let mut parent = vec![NO_PARENT; self.nodes.len()];
        for (id, n) in self.nodes.iter().enumerate() {
            if n.children[0] != NO_CHILD {
                for c in n.children {
                    parent[c as usize] = id as u32;
                }
            }
        }
        parent
    }

    /// Builds the tree over `patches` (at least one).
    pub fn build(patches: &[Patch]) -> Self {
        assert!(
            !patches.is_empty(),
            "a cluster tree needs at least one patch"
        );
        let mut order: Vec<u32> = (0..patches.len() as u32).collect();
        let mut nodes = Vec::with_capacity(2 * patches.len());
        // Explicit stack of (node index, range); children are pushed after their parent is
        // written, so parents precede children.
        nodes.push(node_of(patches, &order, 0, patches.len()));
        let mut stack = vec![0usize];
        while let Some(id) = stack.pop() {
            let (first, count) = (nodes[id].first as usize, nodes[id].count as usize);
            if count <= 1 {
                continue;
            }
            let members = &mut order[first..first + count];
            let mid = if nodes[id].flatness() < SPLIT_FLATNESS {
                split_by_orientation(patches, members)
            } else {
                None
            }
            .unwrap_or_else(|| split_at_median(patches, members));
            let left = nodes.len();
            nodes.push(node_of(patches, &order, first, mid));
            nodes.push(node_of(patches, &order, first + mid, count - mid));
            nodes[id].children = [left as u32, left as u32 + 1];
            stack.push(left);
            stack.push(left + 1);
        }
        let mut leaf_of = vec![0u32; patches.len()];
        for (id, n) in nodes.iter().enumerate() {
            if n.is_leaf() {
                leaf_of[order[n.first as usize] as usize] = id as u32;
            }
        }
        Self {
            nodes,
            order,
            leaf_of,
        }
    }

    /// The patches of node `id`.
    #[inline]
    pub fn members(&self, id: u32) -> &[u32] {
        let n = &self.nodes[id as usize];
        &self.order[n.first as usize..(n.first + n.count) as usize]
    }
}

/// Splits `members` at the median of the longest axis of their centroids; returns the size
/// of the first part.
fn split_at_median(patches: &[Patch], members: &mut [u32]) -> usize {
    let axis = longest_axis(patches, members);
    let mid = members.len() / 2;
    members.select_nth_unstable_by(mid, |&a, &b| {
        let (pa, pb) = (
            patches[a as usize].position_m,
            patches[b as usize].position_m,
        );
        pa[axis].total_cmp(&pb[axis]).then(a.cmp(&b))
    });
    mid
}

/// Splits `members` by orientation: at the middle of the range of the normal component that
/// varies most (a room's corner: the two walls). Returns the size of the first part, or
/// `None` when the normals do not vary.
fn split_by_orientation(patches: &[Patch], members: &mut [u32]) -> Option<usize> {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &m in members.iter() {
        let n = patches[m as usize].normal;
        lo = lo.min(n);
        hi = hi.max(n);
    }
    let e = hi - lo;
    let axis = if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    };
    if e[axis] <= 1e-6 {
        return None;
    }
    let cut = 0.5 * (lo[axis] + hi[axis]);
    members.sort_unstable_by(|&a, &b| {
        let (na, nb) = (patches[a as usize].normal, patches[b as usize].normal);
        (na[axis] > cut).cmp(&(nb[axis] > cut)).then(a.cmp(&b))
    });
    let k = members
        .iter()
        .take_while(|&&m| patches[m as usize].normal[axis] <= cut)
        .count();
    (k > 0 && k < members.len()).then_some(k)
}

/// Axis (0, 1, 2) of the largest extent of the members' centroids.
fn longest_axis(patches: &[Patch], members: &[u32]) -> usize {
    let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
    for &m in members {
        let p = patches[m as usize].position_m;
        lo = lo.min(p);
        hi = hi.max(p);
    }
    let e = hi - lo;
    if e.x >= e.y && e.x >= e.z {
        0
    } else if e.y >= e.z {
        1
    } else {
        2
    }
}

/// The node over `order[first..first + count]` (no children yet).
fn node_of(patches: &[Patch], order: &[u32], first: usize, count: usize) -> Node {
    let members = &order[first..first + count];
    let (mut area, mut c, mut ns) = (0.0f64, glam::DVec3::ZERO, glam::DVec3::ZERO);
    for &m in members {
        let p = &patches[m as usize];
        let a = p.area_m2 as f64;
        area += a;
        c += p.position_m.as_dvec3() * a;
        ns += p.normal.as_dvec3() * a;
    }
    let centroid = if area > 0.0 {
        (c / area).as_vec3()
    } else {
        patches[members[0] as usize].position_m
    };
    // A member's footprint reaches about half its diagonal from its centre.
    let radius_m = members
        .iter()
        .map(|&m| {
            let p = &patches[m as usize];
            (p.position_m - centroid).length() + 0.7072 * p.area_m2.max(0.0).sqrt()
        })
        .fold(0.0f32, f32::max);
    Node {
        first: first as u32,
        count: count as u32,
        children: [NO_CHILD; 2],
        area_m2: area as f32,
        centroid,
        normal_sum: ns.as_vec3(),
        radius_m,
    }
}
