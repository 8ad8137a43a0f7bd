//! Shading normals for meshes that do not bring their own: hard edges are kept.
//!
//! # Rule
//! Two triangles that share an edge (both end positions, after welding) are smoothed together
//! across it when
//! - the file has smoothing groups (OBJ `s N`): both are in the same non-zero group
//!   (`s off` / `s 0` faces are flat), or
//! - otherwise: the angle between their face normals is at most the crease angle
//!   ([`DEFAULT_CREASE_DEG`], scene file key `crease_angle_deg`).
//!
//! Around every position, the triangles joined this way (transitively, through shared
//! edges) form one *smoothing fan*; each fan gets the area-weighted sum of its triangles'
//! normals `(b−a)×(c−a)`. A position with one fan keeps the normal slot of its own index,
//! with the value [`super::obj::smooth_normals`] gives (so a mesh without any hard edge gets
//! exactly the normals of smoothing every shared position); a position with several fans
//! gets one new slot per fan, appended after the positions' slots.
//!
//! [`NormalRule::SmoothAll`] is the plain rule (every shared position smoothed), kept for
//! meshes whose stored bakes depend on it (the scanned head: 766 of its corners lie on edges
//! sharper than 60°); a crease angle of 180° without smoothing groups is the same rule.

use std::collections::HashMap;

use glam::{DVec3, Vec3};

use super::MeshTriangle;

/// Default crease angle, degrees.
pub const DEFAULT_CREASE_DEG: f32 = 60.0;

/// How normals are computed for a mesh without normals.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum NormalRule {
    /// Smoothing groups if the file has them, else split at edges sharper than this angle
    /// (degrees).
    Crease(f32),
    /// Smooth every shared position, whatever the angle.
    SmoothAll,
}

impl Default for NormalRule {
    fn default() -> Self {
        NormalRule::Crease(DEFAULT_CREASE_DEG)
    }
}

/// One triangle's use of an edge: (triangle, corner at the edge's lower position index,
/// corner at its higher one); corners are numbered `3·t + k`.
type EdgeUse = (u32, u32, u32);

/// Union-find over triangle corners (`3·t + k`).
struct Corners(Vec<u32>);

impl Corners {
    fn find(&mut self, mut i: u32) -> u32 {
        while self.0[i as usize] != i {
            let up = self.0[self.0[i as usize] as usize];
            self.0[i as usize] = up;
            i = up;
        }
        i
    }

    fn union(&mut self, a: u32, b: u32) {
        let (ra, rb) = (self.find(a), self.find(b));
        if ra != rb {
            self.0[ra.max(rb) as usize] = ra.min(rb);
        }
    }
}

/// Joins the corners of triangles smoothed together across a shared edge (the rule of the
/// module docs): `face` are the triangles' unnormalised normals, `groups` the smoothing
/// groups, `cos_limit` the cosine of the crease angle.
fn join_corners(
    triangles: &[MeshTriangle],
    face: &[DVec3],
    groups: Option<&[u32]>,
    cos_limit: f64,
) -> Corners {
    // Edges → the (triangle, corner of the edge's first end, corner of its second end).
    let mut edges: HashMap<(u32, u32), Vec<EdgeUse>> = HashMap::new();
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri.position[k], tri.position[(k + 1) % 3]);
            let (key, ca, cb) = if a < b {
                ((a, b), k, (k + 1) % 3)
            } else {
                ((b, a), (k + 1) % 3, k)
            };
            let c = |k: usize| (3 * t + k) as u32;
            edges.entry(key).or_default().push((t as u32, c(ca), c(cb)));
        }
    }
    let joined = |s: u32, t: u32| -> bool {
        if let Some(g) = groups {
            return g[s as usize] != 0 && g[s as usize] == g[t as usize];
        }
        let (ns, nt) = (face[s as usize], face[t as usize]);
        match (ns.try_normalize(), nt.try_normalize()) {
            (Some(a), Some(b)) => a.dot(b) >= cos_limit - 1e-12,
            _ => true, // a zero-area triangle does not make a crease
        }
    };
    let mut uf = Corners((0..3 * triangles.len() as u32).collect());
    for list in edges.values() {
        for i in 0..list.len() {
            for j in i + 1..list.len() {
                let (s, sa, sb) = list[i];
                let (t, ta, tb) = list[j];
                if s != t && joined(s, t) {
                    uf.union(sa, ta);
                    uf.union(sb, tb);
                }
            }
        }
    }
    uf
}

/// Normals for `triangles` over `positions` (metres) by `rule`, with per-triangle smoothing
/// groups `groups` (OBJ `s`; `None` when the file has none). Returns the normals and, per
/// triangle, its three normal indices. See the module docs.
pub fn crease_normals(
    positions: &[Vec3],
    triangles: &[MeshTriangle],
    groups: Option<&[u32]>,
    rule: NormalRule,
) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let smooth = super::obj::smooth_normals(positions, triangles);
    let plain: Vec<[u32; 3]> = triangles.iter().map(|t| t.position).collect();
    let cos_limit = match rule {
        NormalRule::SmoothAll => return (smooth, plain),
        // 180° joins every pair of faces: exactly the plain rule (also at bow-tie positions,
        // whose fans share no edge).
        NormalRule::Crease(deg) if deg >= 180.0 && groups.is_none() => return (smooth, plain),
        NormalRule::Crease(deg) => (deg.clamp(0.0, 180.0) as f64).to_radians().cos(),
    };
    let face: Vec<DVec3> = triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.position.map(|i| positions[i as usize].as_dvec3());
            (b - a).cross(c - a)
        })
        .collect();
    let mut uf = join_corners(triangles, &face, groups, cos_limit);
    // Fans per position: root corner → fan slot.
    let mut fans_of: Vec<Vec<u32>> = vec![Vec::new(); positions.len()];
    for (t, tri) in triangles.iter().enumerate() {
        for k in 0..3 {
            let root = uf.find((3 * t + k) as u32);
            let fans = &mut fans_of[tri.position[k] as usize];
            if !fans.contains(&root) {
                fans.push(root);
            }
        }
    }
    if fans_of.iter().all(|f| f.len() <= 1) {
        return (smooth, plain);
    }
    let mut normals = smooth;
    let mut slot_of_root: HashMap<u32, u32> = HashMap::new();
    let mut sums: Vec<DVec3> = Vec::new();
    let mut indices = plain;
    for (t, (tri, idx)) in triangles.iter().zip(indices.iter_mut()).enumerate() {
        for (k, (&p, slot_out)) in tri.position.iter().zip(idx.iter_mut()).enumerate() {
            if fans_of[p as usize].len() <= 1 {
                continue;
            }
            let root = uf.find((3 * t + k) as u32);
            let slot = *slot_of_root.entry(root).or_insert_with(|| {
                sums.push(DVec3::ZERO);
                (sums.len() - 1) as u32
            });
            sums[slot as usize] += face[t];
            *slot_out = positions.len() as u32 + slot;
        }
    }
    // A fan whose sum cancels (or is of zero-area triangles) keeps the position's normal.
    let firsts: Vec<Vec3> = {
        let mut f = vec![Vec3::Z; sums.len()];
        for (t, idx) in indices.iter().enumerate() {
            for k in 0..3 {
                if let Some(s) = (idx[k] as usize).checked_sub(positions.len()) {
                    f[s] = normals[triangles[t].position[k] as usize];
                }
            }
        }
        f
    };
    normals.extend(
        sums.iter()
            .zip(&firsts)
            .map(|(s, f)| s.try_normalize().map_or(*f, |n| n.as_vec3())),
    );
    (normals, indices)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tri(position: [u32; 3]) -> MeshTriangle {
        MeshTriangle {
            position,
            uv: [0; 3],
            normal: position,
            material: 0,
        }
    }

    /// Two triangles folded along the edge 0–1 by `deg` degrees out of plane.
    fn hinge(deg: f32) -> (Vec<Vec3>, Vec<MeshTriangle>) {
        let a = deg.to_radians();
        let p = vec![
            Vec3::ZERO,
            Vec3::X,
            Vec3::new(0.5, 1.0, 0.0),
            Vec3::new(0.5, -a.cos(), a.sin()),
        ];
        (p, vec![tri([0, 1, 2]), tri([1, 0, 3])])
    }

    #[test]
    fn folds_below_the_crease_are_smooth_above_are_split() {
        // 30° fold: one fan per position, exactly the smooth normals.
        let (p, t) = hinge(30.0);
        let (n, idx) = crease_normals(&p, &t, None, NormalRule::default());
        assert_eq!(n, super::super::obj::smooth_normals(&p, &t));
        assert_eq!(idx, vec![[0, 1, 2], [1, 0, 3]]);
        // 90° fold: the shared corners get one normal per face, equal to the face normals.
        let (p, t) = hinge(90.0);
        let (n, idx) = crease_normals(&p, &t, None, NormalRule::default());
        assert_eq!(n.len(), 4 + 4);
        for (ti, tr) in t.iter().enumerate() {
            let [a, b, c] = tr.position.map(|i| p[i as usize]);
            let f = (b - a).cross(c - a).normalize();
            for k in 0..3 {
                assert!((n[idx[ti][k] as usize] - f).length() < 1e-6, "{ti} {k}");
            }
        }
        // Smoothing groups override the angle: same group → smooth even at 90°.
        let (n2, idx2) = crease_normals(&p, &t, Some(&[1, 1]), NormalRule::default());
        assert_eq!(idx2, vec![[0, 1, 2], [1, 0, 3]]);
        assert_eq!(n2, super::super::obj::smooth_normals(&p, &t));
        // Group 0 is flat.
        let (_, idx3) = crease_normals(&p, &t, Some(&[0, 0]), NormalRule::default());
        assert_ne!(idx3[0][0], idx3[1][1]);
        // SmoothAll never splits.
        let (_, idx4) = crease_normals(&p, &t, None, NormalRule::SmoothAll);
        assert_eq!(idx4, vec![[0, 1, 2], [1, 0, 3]]);
    }
}
