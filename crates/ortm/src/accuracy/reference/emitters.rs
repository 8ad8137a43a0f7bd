//! The first-order radiosity as a light: a density over the scene's surface that sends the
//! reference's indirect paths towards brightly lit surfaces (a lamp just under a ceiling makes a
//! small spot that cosine-sampled bounces rarely find and that then carries most of the light).
//!
//! Every triangle is cut into `k²` equal sub-triangles ("cells", `k` from its share of the
//! area, about [`TARGET_CELLS`] in all); each cell's probability is
//! `(1 − α)·B̄_o(centroid)·A_cell / Σ + α·A_cell / A_total` with `B̄_o` the mean over channels
//! of the first order `ρ·E_direct` (`ρ̄`, the profile's total diffuse reflectance, on
//! translucent surfaces; see [`super::path`] for their split) evaluated exactly at the cell's
//! centroid (same lights and shadow rays as the paths) and `α =` [`UNIFORM_SHARE`] (no density
//! when no centroid is lit). The density only shapes where points are drawn: the paths
//! evaluate `B_o` exactly at the point they reach, so the cells' size enters no result. The
//! uniform share keeps the density `> 0` on every surface, so shadowed-centroid cells that are
//! partly lit are still reached (and the cosine-sampled bounce covers them too under multiple
//! importance sampling).
//!
//! A point is drawn by the cell CDF (its inverse found from a guide table, Chen and Asau's:
//! the same cell as a binary search of the cumulative sums, in a step or two instead of ~17
//! reads of a 1 MB array), then uniformly inside the cell; its area
//! density (m⁻²) is `P(cell) / A_cell`, found again from any hit's barycentrics by
//! [`FirstOrderLight::pdf_area`].

use glam::Vec3;
use rayon::prelude::*;

use super::path::{SceneView, Scratch};
use super::sampler::PathSampler;
use crate::bake::raycast::RayHit;

/// About this many cells over the whole surface (more on large triangles, at least one per
/// triangle).
pub const TARGET_CELLS: f64 = 65_536.0;

/// Largest subdivision of one triangle (cells per edge).
const MAX_SUBDIVISION: u32 = 256;

/// Share of the density spread uniformly by area over the surface.
pub const UNIFORM_SHARE: f64 = 0.2;

/// Cell layout of one triangle.
#[derive(Clone, Copy, Debug, Default)]
struct TriangleCells {
    /// Index of the triangle's first cell slot (`2k²` slots: `(i, j, upper)`, `i, j < k`;
    /// slots outside the triangle have probability 0).
    first: u32,
    /// Cells per edge; 0 when the triangle does not emit.
    k: u32,
    /// Area of one cell, m².
    cell_area_m2: f32,
}

/// The first-order radiosity's sampling density over the surface.
pub struct FirstOrderLight {
    triangles: Vec<TriangleCells>,
    /// `(first slot, triangle)` of the emitting triangles, in slot order.
    owners: Vec<(u32, u32)>,
    /// Probability of each cell slot.
    probability: Vec<f32>,
    /// Running sum of `probability`, ending at 1 (up to rounding; draws and densities use the
    /// last entry as the total).
    cdf: Vec<f64>,
    /// `guide[k]`: the first slot whose `cdf` passes `k / G` of the total (`G` = the number of
    /// slots): where the search for a number in `[k/G, (k+1)/G)` starts.
    guide: Vec<u32>,
}

/// A drawn point: its triangle and barycentrics.
#[derive(Clone, Copy, Debug)]
pub struct LightSample {
    /// Triangle index.
    pub triangle: u32,
    /// Barycentric weights of the triangle's vertices 0, 1, 2.
    pub barycentrics: [f32; 3],
}

impl FirstOrderLight {
    /// The density of `view`'s first order; `None` when the scene has no surface or no cell
    /// centroid is lit (the paths then keep cosine-sampled bounces alone).
    pub fn build(view: &SceneView<'_>) -> Option<Self> {
        let (triangles, slots, total_area) = cell_layout(view)?;
        let owners: Vec<(u32, u32)> = triangles
            .iter()
            .enumerate()
            .filter(|(_, c)| c.k > 0)
            .map(|(t, c)| (c.first, t as u32))
            .collect();
        let lit = lit_per_slot(view, &triangles, &owners, slots);
        let lit_sum: f64 = lit.iter().sum();
        if lit_sum <= 0.0 {
            return None;
        }
        let mut probability = vec![0.0f32; slots as usize];
        for c in triangles.iter().filter(|c| c.k > 0) {
            let uniform = c.cell_area_m2 as f64 / total_area;
            for local in (0..2 * c.k * c.k).filter(|&l| slot_centroid(c.k, l).is_some()) {
                let slot = (c.first + local) as usize;
                probability[slot] =
                    ((1.0 - UNIFORM_SHARE) * lit[slot] / lit_sum + UNIFORM_SHARE * uniform) as f32;
            }
        }
        let cdf = probability
            .iter()
            .scan(0.0f64, |run, p| {
                *run += *p as f64;
                Some(*run)
            })
            .collect::<Vec<f64>>();
        let guide = guide_table(&cdf);
        Some(Self {
            triangles,
            owners,
            probability,
            cdf,
            guide,
        })
    }

    /// A point drawn by the density, from three numbers of `u` (the cell, the point in it).
    pub fn sample(&self, rng: &mut PathSampler) -> LightSample {
        let total = *self.cdf.last().expect("at least one cell");
        let slot =
            inverse_cdf(&self.cdf, &self.guide, rng.uniform(), total).min(self.cdf.len() - 1);
        // Skip zero-probability slots a rounding edge could land on.
        let slot = (slot..self.cdf.len())
            .find(|&s| self.probability[s] > 0.0)
            .or_else(|| (0..slot).rev().find(|&s| self.probability[s] > 0.0))
            .expect("a cell with probability > 0") as u32;
        let t = self.owners[self.owners.partition_point(|o| o.0 <= slot) - 1].1 as usize;
        let c = self.triangles[t];
        let local = slot - c.first;
        let (r1, r2): (f32, f32) = (rng.uniform_f32(), rng.uniform_f32());
        let (r1, r2) = if r1 + r2 > 1.0 {
            (1.0 - r1, 1.0 - r2)
        } else {
            (r1, r2)
        };
        let (i, j, upper) = slot_cell(c.k, local);
        let (u, v) = if upper {
            ((i + 1) as f32 - r1, (j + 1) as f32 - r2)
        } else {
            (i as f32 + r1, j as f32 + r2)
        };
        let k = c.k as f32;
        let (b1, b2) = (u / k, v / k);
        LightSample {
            triangle: t as u32,
            barycentrics: [(1.0 - b1 - b2).max(0.0), b1, b2],
        }
    }

    /// Area density (m⁻²) of the point at `hit`'s triangle and barycentrics.
    pub fn pdf_area(&self, hit: &RayHit) -> f32 {
        let Some(c) = self.triangles.get(hit.triangle as usize) else {
            return 0.0;
        };
        if c.k == 0 || c.cell_area_m2 <= 0.0 {
            return 0.0;
        }
        let k = c.k as f32;
        let (u, v) = (hit.barycentrics[1] * k, hit.barycentrics[2] * k);
        let i = (u.max(0.0) as u32).min(c.k - 1);
        let j = (v.max(0.0) as u32).min(c.k - 1);
        let upper = (u - i as f32) + (v - j as f32) > 1.0 && i + j + 2 <= c.k;
        let local = 2 * (i * c.k + j) + upper as u32;
        let total = *self.cdf.last().expect("at least one cell") as f32;
        self.probability[(c.first + local) as usize] / (total * c.cell_area_m2)
    }
}

/// The guide table of the running sums `cdf` (Chen and Asau's): entry `k` of `G + 1` (`G` the
/// number of sums) is the first index whose sum passes `k / G` of the last.
fn guide_table(cdf: &[f64]) -> Vec<u32> {
    let (g, total) = (cdf.len(), cdf.last().copied().unwrap_or(0.0));
    (0..=g)
        .map(|k| cdf.partition_point(|&c| c <= k as f64 / g as f64 * total) as u32)
        .collect()
}

/// The first index whose running sum passes `x · total` (`x ∈ [0, 1)`), as
/// `cdf.partition_point(|&c| c <= x · total)` finds it (`cdf.len()` past the end): from the
/// guide's entry for `x`, stepped back where rounding put it past the answer, then forward.
fn inverse_cdf(cdf: &[f64], guide: &[u32], x: f64, total: f64) -> usize {
    let (g, u) = (cdf.len(), x * total);
    let mut i = (guide[((x * g as f64) as usize).min(g)] as usize).min(g);
    while i > 0 && cdf[i - 1] > u {
        i -= 1;
    }
    while i < g && cdf[i] <= u {
        i += 1;
    }
    i
}

/// Slot `local` of a triangle cut `k` times per edge: cell `(i, j)` and whether it is the
/// upper sub-triangle.
fn slot_cell(k: u32, local: u32) -> (u32, u32, bool) {
    let upper = local % 2 == 1;
    let ij = local / 2;
    (ij / k, ij % k, upper)
}

/// Barycentrics of slot `local`'s centroid; `None` when the slot lies outside the triangle.
fn slot_centroid(k: u32, local: u32) -> Option<[f32; 3]> {
    let (i, j, upper) = slot_cell(k, local);
    let inside = if upper { i + j + 2 <= k } else { i + j < k };
    if !inside {
        return None;
    }
    let third = if upper { 2.0 / 3.0 } else { 1.0 / 3.0 };
    let kf = k as f32;
    let (b1, b2) = ((i as f32 + third) / kf, (j as f32 + third) / kf);
    Some([1.0 - b1 - b2, b1, b2])
}

/// The cells of every triangle of `view`'s mesh, the number of slots and the total area (m²);
/// `None` when that area is 0.
fn cell_layout(view: &SceneView<'_>) -> Option<(Vec<TriangleCells>, u32, f64)> {
    let mesh = &view.scene().mesh;
    let areas: Vec<f64> = mesh
        .triangles
        .iter()
        .map(|tri| {
            let p: [Vec3; 3] = std::array::from_fn(|k| mesh.positions_m[tri.position[k] as usize]);
            0.5 * (p[1] - p[0]).cross(p[2] - p[0]).as_dvec3().length()
        })
        .collect();
    let total_area: f64 = areas.iter().filter(|&&a| a > 0.0).sum();
    if total_area <= 0.0 {
        return None;
    }
    let mut triangles = vec![TriangleCells::default(); areas.len()];
    let mut slots = 0u32;
    for (t, cells) in triangles.iter_mut().enumerate() {
        if areas[t] <= 0.0 {
            continue;
        }
        let k = (areas[t] * TARGET_CELLS / total_area)
            .sqrt()
            .ceil()
            .clamp(1.0, MAX_SUBDIVISION as f64) as u32;
        *cells = TriangleCells {
            first: slots,
            k,
            cell_area_m2: (areas[t] / (k * k) as f64) as f32,
        };
        slots += 2 * k * k;
    }
    Some((triangles, slots, total_area))
}

/// Mean over channels of the first order `ρ·E_direct` at each slot's centroid × the cell's
/// area (W); 0 for slots outside their triangle.
fn lit_per_slot(
    view: &SceneView<'_>,
    triangles: &[TriangleCells],
    owners: &[(u32, u32)],
    slots: u32,
) -> Vec<f64> {
    (0..slots)
        .into_par_iter()
        .map_init(Scratch::default, |s, slot| {
            let t = owners[owners.partition_point(|o| o.0 <= slot) - 1].1;
            let c = triangles[t as usize];
            let Some(barycentrics) = slot_centroid(c.k, slot - c.first) else {
                return 0.0;
            };
            let p = view.point_of_hit(&RayHit {
                triangle: t,
                t: 0.0,
                barycentrics,
            });
            let b_o = p.albedo * view.direct(&p, s);
            b_o.element_sum() as f64 / 3.0 * c.cell_area_m2 as f64
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::{guide_table, inverse_cdf};

    /// The guide table's search finds the index a binary search of the running sums finds, for
    /// numbers on and beside every step of the sums (zero-probability runs included) and for
    /// random ones.
    #[test]
    fn the_guide_finds_what_the_binary_search_finds() {
        use rand::{RngExt, SeedableRng};
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(3);
        let weights: Vec<f32> = (0..1000)
            .map(|i| match i % 7 {
                0 | 1 => 0.0,
                _ => rng.random::<f32>().powi(4),
            })
            .collect();
        let cdf: Vec<f64> = weights
            .iter()
            .scan(0.0f64, |run, &w| {
                *run += f64::from(w);
                Some(*run)
            })
            .collect();
        let total = *cdf.last().unwrap();
        let guide = guide_table(&cdf);
        let mut xs: Vec<f64> = (0..20_000).map(|_| rng.random::<f64>()).collect();
        for &c in &cdf {
            let x = c / total;
            xs.extend(
                [x, x.next_down(), x.next_up()]
                    .into_iter()
                    .filter(|x| (0.0..1.0).contains(x)),
            );
        }
        xs.extend([0.0, 1.0f64.next_down()]);
        for x in xs {
            let want = cdf.partition_point(|&c| c <= x * total);
            assert_eq!(inverse_cdf(&cdf, &guide, x, total), want, "x = {x}");
        }
    }
}
