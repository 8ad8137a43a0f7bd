//! Transfer-map values by integrating the transfer over each offset's Voronoi cell.
//!
//! # Why
//! Eq. 9 of the paper splits the indirect light at `t` by offset cells,
//! `B(t) − B_o(t) = Σ_k Σ_{v ∈ V_k} R(t, t+v)·B_o(t+v)`, and approximates every cell by its site:
//! `≈ Σ_k M_k(t)·B_o(t+Δt_k)`. Eq. 10 takes `M_k(t) = TR(t, t+Δt_k)·TVA(t, Δt_k)` — one sample of
//! the transfer times the cell's area. The transfer is far from smooth in offset space: a cell
//! of a few hundred offsets spans several UV charts, and across a seam the sample can land on the
//! near-singular peak of the form factor or the subsurface profile (then the whole cell is
//! weighted by it) or on an unrelated chart. Measured on the head at 64² (`ortm bench
//! cells`), that one-sample estimate is what makes importance-sampled offsets lose to a jittered
//! grid. Here `M_k(t) = Σ_{v ∈ V_k} R(t, t+v)` — the transfer integrated over the cell, only
//! `B_o` is taken at the site. The render-time format and Eq. 9 are unchanged; when every integer
//! offset is selected both rules agree and are exact.
//!
//! # How (receiver-major)
//! For each receiving texel `t` the sum runs over every sender `j`, binned into the cell of the
//! offset `j − t` (a lookup table over all offsets). Senders are grouped by the clusters of the
//! coarse level ([`crate::transport::coarse`]):
//! - **far clusters**: the cluster transfer `R(I, J)` of the dense coarse solve, shared by area.
//!   When the cluster's tile, seen from `t`, lies inside one cell (a precomputed table of
//!   cell-uniform windows) it adds in O(1); otherwise texel by texel.
//! - **near clusters** (centroids closer than [`NEAR_FACTOR`]·(r_I + r_J), or within reach of
//!   the subsurface profile's support): the coarse remainder by area, plus texel by texel the
//!   exact subsurface term (within the profile's support) and the exact first bounce (shadow
//!   ray) — for every texel of form-factor-near clusters, and for the near-singular neighbours
//!   closer than [`FF_EXACT_PITCHES`] texel pitches of the others (whose remaining bounce is the
//!   cluster's, by area).
//!
//! # Seams
//! A texel-exact sender that is physically nearer the receiver than its cell's site (it lies
//! across a UV seam, or in a chart the site's offset does not reach) is moved to the origin's
//! cell: `B_o(t)` is a far better sample of its first-order light than `B_o(t + Δt_k)`. The
//! total transfer of `t` is unchanged; only which first-order sample it multiplies.
//!
//! A receiver whose site `t + Δt_k` is uncovered cannot be reached by map `k` (its first-order
//! light is 0 there); such values are dropped, as with Eq. 10.
//!
//! The error of each choice against the exact solve (head, 64²) is printed by the
//! `bake_exact` tests.

use glam::{IVec2, Vec3};
use rayon::prelude::*;

use crate::Lightmap;
use crate::offsets::DiscreteCells;
use crate::texels::TexelGrid;
use crate::transport::{Patch, Transport};

/// Cluster pairs whose centroids are closer than this many times the sum of their radii get
/// texel-exact first-bounce form factors; farther pairs use the cluster transfer.
pub const NEAR_FACTOR: f32 = 1.0;

const NO_CELL: u32 = u32::MAX;

/// Cell values of every map, receiver-major: `values[slot · K + k]` is map `k`'s value at lightmap
/// slot `slot` (0 where the receiver is uncovered or its site `t + Δt_k` is).
pub struct CellValues {
    /// Lightmap width, texels.
    pub width: u32,
    /// Lightmap height, texels.
    pub height: u32,
    /// Number of maps `K`.
    pub maps: usize,
    values: Vec<[f32; 3]>,
    /// Per map, the largest channel of `|value|` over the map.
    pub peak: Vec<f64>,
    /// Diagnostics of the integration.
    pub stats: CellStats,
}

/// What the integration did (for reports and benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct CellStats {
    /// Cluster pairs evaluated texel by texel (near field).
    pub near_cluster_pairs: u64,
    /// Texel pairs evaluated exactly (near field).
    pub near_texel_pairs: u64,
    /// Far cluster windows that fell inside one cell (O(1) each).
    pub uniform_windows: u64,
    /// Far cluster windows split texel by texel.
    pub split_windows: u64,
    /// Texel-exact pairs moved to the origin's cell (sender nearer the receiver than its site).
    pub rehomed: u64,
}

impl CellValues {
    /// Map `k` as a full lightmap.
    pub fn map(&self, k: usize) -> Lightmap {
        let mut m = Lightmap::new(self.width, self.height);
        for (slot, v) in m.data.iter_mut().enumerate() {
            *v = self.values[slot * self.maps + k];
        }
        m
    }
}

/// Offset → cell lookup with a table of cell-uniform `block × block` windows.
struct CellTable {
    w: i32,
    h: i32,
    /// Row length of the tables (`2W − 1 + block`).
    stride: usize,
    cell: Vec<u32>,
    uniform: Vec<u32>,
    /// Half the block size (0 when the block is 1).
    half: i32,
    /// Cell-uniform `half × half` windows.
    uniform_half: Vec<u32>,
}

/// For every start `(c, r)` of the table, the cell when the `b × b` window starting there lies in
/// one cell, else [`NO_CELL`].
fn uniform_windows(cell: &[u32], stride: usize, rows: usize, b: usize) -> Vec<u32> {
    // Horizontal: the window of `b` entries starting at c is one cell.
    let mut horiz = vec![NO_CELL; stride * rows];
    for (crow, hrow) in cell
        .chunks_exact(stride)
        .zip(horiz.chunks_exact_mut(stride))
    {
        let mut run = 0usize;
        for c in (0..stride).rev() {
            run = if c + 1 < stride && crow[c] == crow[c + 1] {
                run + 1
            } else {
                1
            };
            if crow[c] != NO_CELL && run >= b {
                hrow[c] = crow[c];
            }
        }
    }
    // Vertical: `b` rows of equal horizontal windows.
    let mut uniform = vec![NO_CELL; stride * rows];
    for c in 0..stride {
        let mut run = 0usize;
        for r in (0..rows).rev() {
            let v = horiz[r * stride + c];
            run = if v == NO_CELL {
                0
            } else if r + 1 < rows && horiz[(r + 1) * stride + c] == v {
                run + 1
            } else {
                1
            };
            if run >= b {
                uniform[r * stride + c] = v;
            }
        }
    }
    uniform
}

impl CellTable {
    fn new(cells: &DiscreteCells, w: u32, h: u32, block: u32) -> Self {
        let (wi, hi) = (w as i32, h as i32);
        let b = block.max(1) as usize;
        let stride = (2 * w as usize - 1) + b;
        let rows = (2 * h as usize - 1) + b;
        let mut cell = vec![NO_CELL; stride * rows];
        for (k, runs) in cells.real.iter().enumerate() {
            for r in runs {
                let row = (r.dy + hi - 1) as usize * stride;
                for dx in r.dx_start..=r.dx_end_inclusive {
                    cell[row + (dx + wi - 1) as usize] = k as u32;
                }
            }
        }
        let uniform = uniform_windows(&cell, stride, rows, b);
        // Quadrants tile the block exactly only for even blocks.
        let uniform_half = if b >= 2 && b.is_multiple_of(2) {
            uniform_windows(&cell, stride, rows, b / 2)
        } else {
            Vec::new()
        };
        Self {
            w: wi,
            h: hi,
            stride,
            cell,
            uniform,
            half: if b >= 2 && b.is_multiple_of(2) {
                (b / 2) as i32
            } else {
                0
            },
            uniform_half,
        }
    }

    #[inline]
    fn index(&self, dx: i32, dy: i32) -> usize {
        (dy + self.h - 1) as usize * self.stride + (dx + self.w - 1) as usize
    }

    #[inline]
    fn cell(&self, dx: i32, dy: i32) -> u32 {
        self.cell[self.index(dx, dy)]
    }

    #[inline]
    fn uniform(&self, dx: i32, dy: i32) -> u32 {
        self.uniform[self.index(dx, dy)]
    }

    #[inline]
    fn uniform_half(&self, dx: i32, dy: i32) -> u32 {
        self.uniform_half[self.index(dx, dy)]
    }
}

/// A near cluster of a receiving cluster.
#[derive(Clone, Copy)]
struct Near {
    cluster: u32,
    /// First bounce texel by texel for every texel of the cluster (centroids closer than
    /// [`NEAR_FACTOR`]·(r_I + r_J)); else the cluster-level bounce `bounce`, shared by area.
    exact_bounce: bool,
    /// Cluster-level first bounce `ρ̄_I F_IJ` with centroid visibility.
    bounce: [f32; 3],
    /// Whether some texel pair may lie in the exact zone (subsurface support or
    /// [`FF_EXACT_PITCHES`]).
    exact_zone: bool,
}

/// Texel pairs closer than this many texel pitches (`√A` of the receiver) get the exact texel
/// form factor (the near-singular neighbours); farther near pairs use the point-to-cluster one.
pub const FF_EXACT_PITCHES: f32 = 3.0;

struct Clusters {
    /// Texel indices of each cluster.
    texels: Vec<Vec<u32>>,
    /// Tile origin (texels) of each cluster.
    tile: Vec<IVec2>,
    /// Near clusters of each cluster, sorted by index.
    near: Vec<Vec<Near>>,
    /// Texels of each cluster by quadrant of its tile: `(x, y, area share)`.
    quads: Vec<[Vec<(i32, i32, f64)>; 4]>,
    /// Area share of each quadrant.
    quad_share: Vec<[f64; 4]>,
}

fn clusters(transport: &Transport, grid: &TexelGrid) -> Clusters {
    let rem = &transport.remainder;
    let nc = rem.clusters.len();
    let b = rem.block.max(1);
    let mut texels = vec![Vec::new(); nc];
    let mut tile = vec![IVec2::ZERO; nc];
    for (i, &c) in rem.cluster_of.iter().enumerate() {
        texels[c as usize].push(i as u32);
        let t = &grid.texels[i];
        tile[c as usize] = IVec2::new((t.x / b * b) as i32, (t.y / b * b) as i32);
    }
    let radius: Vec<f32> = (0..nc)
        .map(|c| {
            let p = rem.clusters[c].position_m;
            texels[c]
                .iter()
                .map(|&i| (transport.patches[i as usize].position_m - p).length())
                .fold(0.0f32, f32::max)
        })
        .collect();
    let max_pitch = transport
        .patches
        .iter()
        .map(|p| p.area_m2.sqrt())
        .fold(0.0f32, f32::max);
    let k = &transport.kernels;
    let near = (0..nc)
        .into_par_iter()
        .map(|ci| {
            let a: &Patch = &rem.clusters[ci];
            (0..nc)
                .filter_map(|cj| {
                    let bp: &Patch = &rem.clusters[cj];
                    let d = (a.position_m - bp.position_m).length();
                    let reach = radius[ci] + radius[cj];
                    let support = if k.is_translucent(a.material) && a.material == bp.material {
                        k.support_m[a.material as usize] as f32
                    } else {
                        0.0
                    };
                    let ff_zone = if k.effects.radiosity {
                        FF_EXACT_PITCHES * max_pitch
                    } else {
                        0.0
                    };
                    let exact_zone = ci == cj || d - reach < support.max(ff_zone);
                    let near_bounce = k.effects.radiosity && d < NEAR_FACTOR * reach;
                    if !(exact_zone || near_bounce || support > 0.0 && d - reach < support) {
                        return None;
                    }
                    let exact_bounce = near_bounce;
                    let bounce = if exact_bounce || ci == cj {
                        [0.0; 3]
                    } else {
                        k.r_bounce(a, bp, false).map(|v| v as f32)
                    };
                    Some(Near {
                        cluster: cj as u32,
                        exact_bounce,
                        bounce,
                        exact_zone: exact_zone || exact_bounce,
                    })
                })
                .collect()
        })
        .collect();
    let half = (b / 2).max(1);
    let mut quads: Vec<[Vec<(i32, i32, f64)>; 4]> = vec![Default::default(); nc];
    let mut quad_share = vec![[0.0f64; 4]; nc];
    for (c, list) in texels.iter().enumerate() {
        let inv_area = 1.0 / rem.clusters[c].area_m2 as f64;
        for &i in list {
            let t = &grid.texels[i as usize];
            let (qx, qy) = (
                (t.x - tile[c].x as u32) / half,
                (t.y - tile[c].y as u32) / half,
            );
            let q = (qx.min(1) + 2 * qy.min(1)) as usize;
            let share = transport.patches[i as usize].area_m2 as f64 * inv_area;
            quads[c][q].push((t.x as i32, t.y as i32, share));
            quad_share[c][q] += share;
        }
    }
    Clusters {
        texels,
        tile,
        near,
        quads,
        quad_share,
    }
}

/// Integrates the transfer over every cell of `cells` (the discrete Voronoi cells of `offsets`)
/// for every receiver; see the module docs. `progress` is called with the number of lightmap rows
/// finished.
pub fn integrate(
    transport: &Transport,
    grid: &TexelGrid,
    offsets: &[IVec2],
    cells: &DiscreteCells,
    progress: &(dyn Fn(u64) + Sync),
) -> CellValues {
    let (w, h) = (grid.width, grid.height);
    let kmaps = offsets.len();
    let rem = &transport.remainder;
    let nc = rem.clusters.len();
    let table = CellTable::new(cells, w, h, rem.block);
    let cl = clusters(transport, grid);
    let origin = match table.cell(0, 0) {
        NO_CELL => None,
        c => Some(c),
    };
    let kern = &transport.kernels;
    let mut values = vec![[0.0f32; 3]; (w * h) as usize * kmaps];
    let stats: Vec<CellStats> = values
        .par_chunks_mut(w as usize * kmaps)
        .enumerate()
        .map(|(y, row)| {
            let mut st = CellStats::default();
            let mut acc = vec![[0.0f64; 3]; kmaps];
            let mut sites: Vec<Option<Vec3>> = vec![None; kmaps];
            for x in 0..w as i32 {
                let Some(i) = grid.at(x, y as i32) else {
                    continue;
                };
                acc.fill([0.0; 3]);
                let (xi, yi) = (x, y as i32);
                let pi = &transport.patches[i as usize];
                for (k, o) in offsets.iter().enumerate() {
                    sites[k] = grid
                        .at(xi + o.x, yi + o.y)
                        .map(|j| transport.patches[j as usize].position_m);
                }
                // The cell that represents a sender at `p` whose offset lies in `cell`: the
                // cell's site, unless the receiver itself is nearer the sender (a seam crossing:
                // the receiver's own first-order light is the better sample).
                let place = |cell: u32, p: Vec3, st: &mut CellStats| -> u32 {
                    match (origin, sites[cell as usize]) {
                        (Some(o), Some(site))
                            if o != cell
                                && (p - pi.position_m).length_squared()
                                    < (p - site).length_squared() =>
                        {
                            st.rehomed += 1;
                            o
                        }
                        _ => cell,
                    }
                };
                let ci = rem.cluster_of[i as usize] as usize;
                let near = &cl.near[ci];
                // The share-able first bounce of a near cluster (0 when it is texel-exact).
                let near_bounce = |n: &Near| -> [f64; 3] {
                    if n.exact_bounce {
                        [0.0; 3]
                    } else {
                        n.bounce.map(f64::from)
                    }
                };
                // Every cluster by area share: the cluster transfer for far clusters; the
                // remainder plus the point-to-cluster bounce for near ones (their subsurface part
                // and near-singular bounce are added texel by texel below).
                let mut next_near = 0usize;
                for cj in 0..nc {
                    let k = ci * nc + cj;
                    let v: [f64; 3] =
                        if next_near < near.len() && near[next_near].cluster as usize == cj {
                            let b = near_bounce(&near[next_near]);
                            next_near += 1;
                            [0, 1, 2].map(|c| rem.rem[c][k] as f64 + b[c])
                        } else {
                            [0, 1, 2].map(|c| rem.full[c][k] as f64)
                        };
                    if v == [0.0; 3] {
                        continue;
                    }
                    let o = cl.tile[cj];
                    let u = table.uniform(o.x - xi, o.y - yi);
                    if u != NO_CELL {
                        st.uniform_windows += 1;
                        let cell = u;
                        let a = &mut acc[cell as usize];
                        for c in 0..3 {
                            a[c] += v[c];
                        }
                        continue;
                    }
                    st.split_windows += 1;
                    // Quadrant by quadrant: O(1) when the half-size window is one cell.
                    for q in 0..4 {
                        let list = &cl.quads[cj][q];
                        if list.is_empty() {
                            continue;
                        }
                        if table.half > 0 {
                            let qo = o + IVec2::new(
                                (q as i32 % 2) * table.half,
                                (q as i32 / 2) * table.half,
                            );
                            let u = table.uniform_half(qo.x - xi, qo.y - yi);
                            if u != NO_CELL {
                                let share = cl.quad_share[cj][q];
                                let a = &mut acc[u as usize];
                                for c in 0..3 {
                                    a[c] += v[c] * share;
                                }
                                continue;
                            }
                        }
                        for &(tx, ty, share) in list {
                            let cell = table.cell(tx - xi, ty - yi);
                            if cell == NO_CELL {
                                continue;
                            }
                            let a = &mut acc[cell as usize];
                            for c in 0..3 {
                                a[c] += v[c] * share;
                            }
                        }
                    }
                }
                // The exact zone, texel by texel: the subsurface term within the profile's
                // support and the texel form factor of near-singular neighbours (replacing their
                // point-to-cluster share).
                let translucent = kern.is_translucent(pi.material);
                let support2 = if translucent {
                    (kern.support_m[pi.material as usize] as f32).powi(2)
                } else {
                    0.0
                };
                let ff2 = if kern.effects.radiosity {
                    FF_EXACT_PITCHES * FF_EXACT_PITCHES * pi.area_m2
                } else {
                    0.0
                };
                for n in near.iter().filter(|n| n.exact_zone) {
                    st.near_cluster_pairs += 1;
                    let cj = n.cluster as usize;
                    let inv_area = 1.0 / rem.clusters[cj].area_m2 as f64;
                    let approx = near_bounce(n);
                    let one_texel = cl.texels[cj].len() == 1;
                    for &j in &cl.texels[cj] {
                        let pj = &transport.patches[j as usize];
                        let d2 = (pj.position_m - pi.position_m).length_squared();
                        let in_sss = translucent && pj.material == pi.material && d2 < support2;
                        let in_ff = n.exact_bounce || one_texel || d2 < ff2;
                        if !(in_sss || in_ff || i == j) {
                            continue;
                        }
                        let t = &grid.texels[j as usize];
                        let cell = table.cell(t.x as i32 - xi, t.y as i32 - yi);
                        if cell == NO_CELL {
                            continue;
                        }
                        st.near_texel_pairs += 1;
                        let cell = place(cell, pj.position_m, &mut st);
                        let mut e = kern.r_subsurface(pi, pj, i == j);
                        if in_ff {
                            let b = kern.r_bounce(pi, pj, i == j);
                            let share = pj.area_m2 as f64 * inv_area;
                            for c in 0..3 {
                                e[c] += b[c] - approx[c] * share;
                            }
                        }
                        let a = &mut acc[cell as usize];
                        for c in 0..3 {
                            a[c] += e[c];
                        }
                    }
                }
                let out = &mut row[x as usize * kmaps..(x as usize + 1) * kmaps];
                for (k, o) in out.iter_mut().enumerate() {
                    if sites[k].is_some() {
                        *o = acc[k].map(|v| v as f32);
                    }
                }
            }
            progress(1);
            st
        })
        .collect();
    let mut peak = vec![0.0f64; kmaps];
    for px in values.chunks_exact(kmaps) {
        for (p, v) in peak.iter_mut().zip(px) {
            *p = p.max(v[0].abs().max(v[1].abs()).max(v[2].abs()) as f64);
        }
    }
    let stats = stats
        .into_iter()
        .fold(CellStats::default(), |a, b| CellStats {
            near_cluster_pairs: a.near_cluster_pairs + b.near_cluster_pairs,
            near_texel_pairs: a.near_texel_pairs + b.near_texel_pairs,
            uniform_windows: a.uniform_windows + b.uniform_windows,
            split_windows: a.split_windows + b.split_windows,
            rehomed: a.rehomed + b.rehomed,
        });
    CellValues {
        width: w,
        height: h,
        maps: kmaps,
        values,
        peak,
        stats,
    }
}
