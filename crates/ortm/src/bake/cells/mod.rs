//! Transfer-map values by integrating the transfer over each offset's Voronoi cell
//! ([`crate::bake::CellRule::Integrated`], the default).
//!
//! # What is computed
//! Eq. 9 of the paper splits the indirect light at `t` by offset cells,
//! `B(t) − B_o(t) = Σ_k Σ_{v ∈ V_k} R(t, t+v)·B_o(t+v)`, and takes `B_o` at each cell's site:
//! `≈ Σ_k M_k(t)·B_o(t+Δt_k)`. Here `M_k(t) = Σ_{v ∈ V_k} R(t, t+v)` — the transfer integrated
//! over the cell (dimensionless, RGB), where Eq. 10 takes one sample,
//! `TR(t, t+Δt_k)·TVA(t, Δt_k)` ([`crate::bake::CellRule::Sampled`]). The transfer is far from
//! smooth in offset space (a cell of a few hundred offsets spans several UV charts, and one
//! sample can land on the near-singular peak of the form factor or the subsurface profile), so
//! the integral is the better estimate; `ortm bench cells` compares both. The render-time
//! format and Eq. 9 are the same for both rules; when every integer offset is selected both
//! are exact.
//!
//! # Data flow (receiver-major)
//! [`integrate`] takes the [`Transport`], the [`TexelGrid`], the offsets and their discrete
//! cells ([`DiscreteCells`]) and returns [`CellValues`] (every map's values, their peaks and
//! [`CellStats`]). For each receiving texel `t` the sum runs over every sender `j`, binned into
//! the cell of the offset `j − t` (a lookup table over all offsets). Senders are grouped by the
//! clusters of the coarse level ([`crate::bake::transport::coarse`]):
//! - **far clusters**: the cluster transfer `R(I, J)` of the dense coarse solve, shared by area.
//!   When the cluster's tile, seen from `t`, lies inside one cell (a precomputed table of
//!   cell-uniform windows) it adds to that cell in O(1); otherwise each quadrant of the tile
//!   goes whole to the cell of its texel nearest the quadrant's centre. So for far pairs the
//!   partition of offset space is the Voronoi one up to ±`P/4` texels (±2 with 8×8
//!   clusters; exact for 1×1 and 2×2 clusters) — still a partition, so every sender's transfer
//!   is counted once, only the site whose first-order light it multiplies can be a neighbouring
//!   one.
//! - **near clusters** (centroids closer than [`NEAR_FACTOR`]·(r_I + r_J), or within reach of
//!   the subsurface profile's support): the coarse remainder by area, plus texel by texel the
//!   exact subsurface term (within the profile's support) and the exact first bounce (shadow
//!   ray) — for every texel of form-factor-near clusters, and for the near-singular neighbours
//!   closer than [`FF_EXACT_PITCHES`] texel pitches of the others (whose remaining bounce is the
//!   cluster's, by area).
//!
//! # With the hierarchical operator
//! When the transport holds the hierarchical first-bounce operator
//! ([`crate::bake::transport::Transport::links`], `ortm bake --tolerance ε`), the first bounce
//! comes from its links instead ([`links`]): every receiver walks up the cluster tree and bins
//! each link's sender node into the cell its texture-space bounding box falls in (descending
//! where the box straddles cells, down to single texels). The coarse clusters then carry only
//! the higher-order remainder (`R_rem` for every cluster pair), and the exact zone only the
//! subsurface term. Cost and error follow the operator's tolerance instead of the cluster
//! size: no texel-by-texel first bounce over whole near clusters.
//!
//! With translucent texels the operator also holds a subsurface walk
//! ([`crate::bake::transport::hier::subsurface`]): each receiver's senders within the profile's
//! support come as tree nodes, refined to the same tolerance, and are binned like the links'
//! sender nodes — no texel-by-texel exact zone, whose `n × support²` pairs grow as `N⁴` in the
//! lightmap's side.
//!
//! # Seams
//! Texture-space Voronoi assumes the first-order light is smooth across a cell. Where a cell
//! straddles a UV seam or several charts, its site can land on an unrelated surface. So every
//! sender (texel-exact or far cluster) is counted with whichever of its cell's site, the sites
//! of the cell's Voronoi neighbours and the receiver itself lies physically nearest to it. The
//! total transfer of `t` is unchanged; only which first-order sample it multiplies.
//!
//! A receiver whose site `t + Δt_k` is uncovered cannot be reached by map `k` (its first-order
//! light is 0 there). Its transfer in that cell is counted with the receiver's own cell (the
//! one holding `Δt = 0`; if that cell's site is uncovered too, the covered site nearest to
//! `Δt = 0`): like a seam crossing, `B_o` near the receiver is a far better sample than the
//! unrelated chart a neighbouring site would land on, and dropping it (as Eq. 10 must) would
//! lose whole cells of transfer wherever a site falls off the charts.
//!
//! The error of each rule against the exact solve (head and Cornell box) is printed by
//! `cargo test -p ortm-cli --test bake_exact -- --nocapture`.

mod links;

use glam::{IVec2, Vec3, Vec4};
use rayon::prelude::*;

use crate::Lightmap;
use crate::bake::offsets::DiscreteCells;
use crate::bake::texels::TexelGrid;
use crate::bake::transport::{Patch, Transport};

/// Cluster pairs whose centroids are closer than this many times the sum of their radii get
/// texel-exact first-bounce form factors; farther pairs use the cluster transfer.
pub const NEAR_FACTOR: f32 = 1.0;

const NO_CELL: u32 = u32::MAX;

/// Cell values of every map, receiver-major over the covered texels only: `values[i · K + k]`
/// is map `k`'s value at covered texel `i` of the [`TexelGrid`] (0 where its site `t + Δt_k` is
/// uncovered); uncovered texels hold 0 in every map.
pub struct CellValues {
    /// Lightmap width, texels.
    pub width: u32,
    /// Lightmap height, texels.
    pub height: u32,
    /// Number of maps `K`.
    pub maps: usize,
    /// Lightmap slot `y · width + x` of every covered texel, in grid order.
    slots: Vec<u32>,
    values: Vec<[f32; 3]>,
    /// Per map, the largest channel of `|value|` over the map.
    pub peak: Vec<f64>,
    /// Diagnostics of the integration.
    pub stats: CellStats,
}

/// What the integration did (for reports and benchmarks).
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct CellStats {
    /// Cluster pairs evaluated texel by texel (near field).
    pub near_cluster_pairs: u64,
    /// Texel pairs evaluated exactly (near field).
    pub near_texel_pairs: u64,
    /// Far cluster windows that fell inside one cell (O(1) each).
    pub uniform_windows: u64,
    /// Far cluster windows split texel by texel.
    pub split_windows: u64,
    /// Texel-exact pairs counted at a nearer site than their own cell's (module docs, "Seams").
    pub rehomed: u64,
    /// Far cluster windows counted at a nearer site than their own cell's (module docs, "Seams").
    pub rehomed_far: u64,
    /// Receiver cells whose site was uncovered, moved to the nearest cell with a covered site.
    pub moved_uncovered: u64,
    /// Hierarchical links applied to a receiver ([`links`]).
    pub links: u64,
    /// Sender nodes of those links binned whole into one cell.
    pub link_nodes: u64,
    /// Sender nodes of the subsurface walk ([`links`]) binned whole into one cell.
    pub subsurface_nodes: u64,
}

impl CellValues {
    /// Map `k` as a full lightmap.
    pub fn map(&self, k: usize) -> Lightmap {
        let mut m = Lightmap::new(self.width, self.height);
        for (i, &slot) in self.slots.iter().enumerate() {
            m.data[slot as usize] = self.values[i * self.maps + k];
        }
        m
    }
}

/// Offset → cell lookup with a table of cell-uniform `P × P` windows (`P` = the cluster block
/// rounded up to a power of two).
struct CellTable {
    w: i32,
    h: i32,
    /// Row length of the tables (`2W − 1 + P`).
    stride: usize,
    cell: Vec<u32>,
    /// For each window origin, the cell when the `P × P` window starting there lies in one
    /// cell, else [`NO_CELL`] (empty when `P` = 1).
    uniform: Vec<u32>,
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
    fn new(cells: &DiscreteCells, w: u32, h: u32, p: usize) -> Self {
        let (wi, hi) = (w as i32, h as i32);
        let stride = (2 * w as usize - 1) + p;
        let rows = (2 * h as usize - 1) + p;
        let mut cell = vec![NO_CELL; stride * rows];
        for (k, runs) in cells.real.iter().enumerate() {
            for r in runs {
                let row = (r.dy + hi - 1) as usize * stride;
                for dx in r.dx_start..=r.dx_end_inclusive {
                    cell[row + (dx + wi - 1) as usize] = k as u32;
                }
            }
        }
        let uniform = if p >= 2 {
            uniform_windows(&cell, stride, rows, p)
        } else {
            Vec::new()
        };
        Self {
            w: wi,
            h: hi,
            stride,
            cell,
            uniform,
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
}

/// A far sender cluster as the offset-space window of its tile.
struct Tile {
    /// Tile origin, texels.
    origin: IVec2,
    /// Per quadrant of the `P × P` tile (index `qx + 2·qy`): the quadrant's texel nearest its
    /// centre (it picks the quadrant's cell when the window straddles cells) and the quadrant's
    /// area share (0 for an empty quadrant).
    quads: [(IVec2, f64); 4],
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
    /// Each cluster's texels as a quadtree over its tile.
    tiles: Vec<Tile>,
    /// Near clusters of each cluster, sorted by index.
    near: Vec<Vec<Near>>,
}

/// The coarse level's clusters as receivers and senders: their texels, tiles and near
/// clusters.
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
    let near = near_clusters(transport, &texels);
    let p = b.next_power_of_two() as i32;
    let tiles = texels
        .iter()
        .enumerate()
        .map(|(c, list)| tile_quadrants(transport, grid, tile[c], p, c, list))
        .collect();
    Clusters {
        texels,
        tiles,
        near,
    }
}

/// For every cluster, its near clusters (sorted by index; see [`Near`]): within
/// [`NEAR_FACTOR`]·(r_I + r_J) for the first bounce, or with texel pairs possibly within the
/// subsurface support or [`FF_EXACT_PITCHES`] texel pitches. `texels` lists each cluster's
/// texels.
fn near_clusters(transport: &Transport, texels: &[Vec<u32>]) -> Vec<Vec<Near>> {
    let rem = &transport.remainder;
    let nc = rem.clusters.len();
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
    // With links the first bounce is theirs: near clusters only for the subsurface term.
    let bounce_here = k.effects.radiosity && transport.links.is_none();
    (0..nc)
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
                    let ff_zone = if bounce_here {
                        FF_EXACT_PITCHES * max_pitch
                    } else {
                        0.0
                    };
                    let exact_zone = ci == cj || d - reach < support.max(ff_zone);
                    let near_bounce = bounce_here && d < NEAR_FACTOR * reach;
                    if !(exact_zone || near_bounce || support > 0.0 && d - reach < support) {
                        return None;
                    }
                    let exact_bounce = near_bounce;
                    let bounce = if exact_bounce || ci == cj || !bounce_here {
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
        .collect()
}

/// Cluster `c`'s `p × p` tile at `origin` with its texels `list` split into quadrants: each
/// quadrant's texel nearest its centre and its share of the cluster's area.
fn tile_quadrants(
    transport: &Transport,
    grid: &TexelGrid,
    origin: IVec2,
    p: i32,
    c: usize,
    list: &[u32],
) -> Tile {
    let inv_area = 1.0 / transport.remainder.clusters[c].area_m2 as f64;
    let half = (p / 2).max(1);
    let ideal =
        [0, 1, 2, 3].map(|q| origin + IVec2::new((q % 2) * half + p / 4, (q / 2) * half + p / 4));
    // (representative texel, its squared distance to the ideal centre, share)
    let mut best = [(IVec2::ZERO, i32::MAX, 0.0f64); 4];
    for &i in list {
        let t = &grid.texels[i as usize];
        let at = IVec2::new(t.x as i32, t.y as i32);
        let rel = at - origin;
        let q = ((rel.x / half).min(1) + 2 * (rel.y / half).min(1)) as usize;
        let d2 = (at - ideal[q]).length_squared();
        let e = &mut best[q];
        if d2 < e.1 {
            e.0 = at;
            e.1 = d2;
        }
        e.2 += transport.patches[i as usize].area_m2 as f64 * inv_area;
    }
    let quads = best.map(|(at, _, share)| (at, share));
    Tile { origin, quads }
}

/// The candidate sites of every cell for the seam rule ([`place`]), as one flat list: cell `k`'s
/// are `cells[start[k]..start[k + 1]]` — `k` itself, then its Voronoi neighbours (sorted), then
/// the origin cell (the receiver itself) when there is one. Each receiver holds the positions of
/// these sites in the same order ([`Receivers::cand`]), with each cell's own site carrying the
/// squared radius around it within which no other candidate can be nearer ([`Candidates::reach`]).
struct Candidates {
    start: Vec<u32>,
    cells: Vec<u32>,
}

impl Candidates {
    fn new(neighbours: &[Vec<u32>], origin: Option<u32>) -> Self {
        let mut start = Vec::with_capacity(neighbours.len() + 1);
        let mut cells = Vec::new();
        for (k, n) in neighbours.iter().enumerate() {
            start.push(cells.len() as u32);
            cells.push(k as u32);
            cells.extend_from_slice(n);
            cells.extend(origin);
        }
        start.push(cells.len() as u32);
        Self { start, cells }
    }

    /// Where an uncovered site stands in a receiver's candidate positions: at infinite distance
    /// from every (finite) sender, so it is never the nearest.
    const UNCOVERED: Vec3 = Vec3::new(f32::INFINITY, 0.0, 0.0);

    /// Receiver `r`'s candidate positions in `pos` (all receivers', [`Receivers::cand`]).
    #[inline]
    fn of<'p>(&self, pos: &'p [Vec4], r: usize) -> &'p [Vec4] {
        let n = self.cells.len();
        &pos[r * n..(r + 1) * n]
    }

    /// One receiver's candidate positions (`site[k]` the site of cell `k`, `None` where
    /// uncovered), appended to `out` in candidate order as `(x, y, z, w)`: `w` is 0 except at
    /// each cell's own site, where it is the squared radius [`Candidates::reach`].
    fn push_positions(&self, site: &[Option<Vec3>], out: &mut Vec<Vec4>) {
        for (k, w) in self.start.windows(2).enumerate() {
            let cells = &self.cells[w[0] as usize..w[1] as usize];
            let own = site[k];
            let others = cells[1..].iter().map(|&n| site[n as usize]);
            let reach = own.map_or(-1.0, |s| Self::reach(s, others.clone()));
            out.push(own.unwrap_or(Self::UNCOVERED).extend(reach));
            out.extend(others.map(|n| n.unwrap_or(Self::UNCOVERED).extend(0.0)));
        }
    }

    /// The squared radius around a covered site `own` within which it is nearer than every
    /// other candidate: a sender at distance `d` from `own` is at least `D − d` from a candidate
    /// `D` away, so every sender within `D/2` of `own` takes `own` (and as the first candidate
    /// it wins ties). Taken as `0.49·D` of the nearest other covered candidate, so that f32
    /// rounding of the distances cannot turn a tie near `D/2` the other way; infinite when no
    /// other candidate is covered.
    fn reach(own: Vec3, others: impl Iterator<Item = Option<Vec3>>) -> f32 {
        let nearest = others
            .flatten()
            .map(|s| (s - own).length_squared())
            .fold(f32::INFINITY, f32::min);
        0.49 * 0.49 * nearest
    }
}

/// The cell whose site represents a sender at `p_m` whose offset lies in `cell`, for a receiver
/// whose candidate sites ([`Candidates`]) stand at `pos`: of the cell's own site, its Voronoi
/// neighbours' sites and the origin's (the receiver itself), the one physically nearest the
/// sender (the first of equals in candidate order; uncovered sites never). Texture-space Voronoi
/// assumes the first-order light is smooth across a cell; where the cell straddles a UV seam or
/// several charts, its own site can land on an unrelated surface while a neighbouring site (or
/// the receiver, for a sender across a seam) lies next to the sender.
///
/// A sender within the cell's [`Candidates::reach`] of its own site takes it without the
/// other candidates being looked at (the same answer, found sooner: most senders).
#[inline]
fn place(cell: u32, p_m: Vec3, pos: &[Vec4], cand: &Candidates, moved: &mut u64) -> u32 {
    let (a, b) = (
        cand.start[cell as usize] as usize,
        cand.start[cell as usize + 1] as usize,
    );
    let (cells, pos) = (&cand.cells[a..b], &pos[a..b]);
    let p = p_m.extend(0.0);
    // The distance to a candidate, its `w` (the reach or 0) left out.
    let dist2 = |s: Vec4| (p - s).truncate().length_squared();
    let mut best = cell;
    let mut d_best = dist2(pos[0]);
    if d_best <= pos[0].w {
        return cell;
    }
    for (&k, &s) in cells[1..].iter().zip(&pos[1..]) {
        let d = dist2(s);
        if d < d_best {
            best = k;
            d_best = d;
        }
    }
    if best != cell {
        *moved += 1;
    }
    best
}

/// Voronoi neighbours of every cell: cells whose offsets touch in the lookup table.
fn cell_neighbours(table: &CellTable, cells: usize) -> Vec<Vec<u32>> {
    let mut n: Vec<Vec<u32>> = vec![Vec::new(); cells];
    let rows = table.cell.len() / table.stride;
    for r in 0..rows {
        for c in 0..table.stride {
            let a = table.cell[r * table.stride + c];
            if a == NO_CELL {
                continue;
            }
            let right = (c + 1 < table.stride).then(|| table.cell[r * table.stride + c + 1]);
            let down = (r + 1 < rows).then(|| table.cell[(r + 1) * table.stride + c]);
            for b in [right, down].into_iter().flatten() {
                if b != NO_CELL && b != a {
                    n[a as usize].push(b);
                    n[b as usize].push(a);
                }
            }
        }
    }
    for v in &mut n {
        v.sort_unstable();
        v.dedup();
    }
    n
}

/// The offset nearest to `Δt = 0` for which `valid` holds (ties by index).
fn nearest_valid_to_zero(offsets: &[IVec2], valid: &dyn Fn(usize) -> bool) -> Option<usize> {
    (0..offsets.len())
        .filter(|&j| valid(j))
        .min_by_key(|&j| (offsets[j].length_squared(), j))
}

/// Integrates the transfer over every cell of `cells` (the discrete Voronoi cells of `offsets`)
/// for every receiver; see the module docs. Receivers are processed cluster by cluster (a far
/// cluster pair's transfer is read once for all receivers of the cluster, and the receivers'
/// table lookups stay within a few cache lines). `progress` is called with the number of
/// receivers (covered texels) finished.
pub fn integrate(
    transport: &Transport,
    grid: &TexelGrid,
    offsets: &[IVec2],
    cells: &DiscreteCells,
    progress: &(dyn Fn(u64) + Sync),
) -> CellValues {
    let run = Integrator::new(transport, grid, offsets, cells);
    let kmaps = offsets.len();
    let receivers = &run.0.clusters.texels;
    // Each cluster's values go into the maps as soon as they are computed (a bounded channel
    // to one writer thread), so the integration holds the maps and a few clusters' values,
    // not every cluster's values besides the maps (0.9 GiB more at 1024² with 100 maps).
    let (send, recv) = std::sync::mpsc::sync_channel::<(usize, ClusterValues)>(IN_FLIGHT);
    let (values, stats) = std::thread::scope(|scope| {
        let writer = scope.spawn(move || {
            let mut out = Assembly::new(grid, kmaps);
            for (ci, cv) in recv {
                out.add(&receivers[ci], cv);
            }
            (out.values, out.stats)
        });
        // One job per cluster: rayon otherwise splits the clusters into about two ranges per
        // thread and runs each range whole once split, so the last one can hold one core busy
        // alone (the head's 512² cells ran their last ~6 s on one of two cores).
        (0..run.cluster_count())
            .into_par_iter()
            .with_max_len(1)
            .for_each_with(send, |send, ci| {
                let (values, stats) = run.0.receiving_cluster(ci);
                progress(receivers[ci].len() as u64);
                // The writer only stops once every sender is dropped.
                send.send((ci, ClusterValues { values, stats }))
                    .expect("the cell writer outlives the integration");
            });
        writer.join().expect("the cell writer does not panic")
    });
    Assembly {
        grid,
        kmaps,
        values,
        stats,
    }
    .finish()
}

/// Receiving clusters whose values may wait for [`integrate`]'s writer at once.
const IN_FLIGHT: usize = 64;

/// Every map's values, filled cluster by cluster.
struct Assembly<'a> {
    grid: &'a TexelGrid,
    kmaps: usize,
    /// Covered-texel-major, `kmaps` per covered texel.
    values: Vec<[f32; 3]>,
    stats: CellStats,
}

impl<'a> Assembly<'a> {
    fn new(grid: &'a TexelGrid, kmaps: usize) -> Self {
        Self {
            grid,
            kmaps,
            values: vec![[0.0f32; 3]; grid.texels.len() * kmaps],
            stats: CellStats::default(),
        }
    }

    /// Writes the values of the cluster whose receivers are `recv`.
    fn add(&mut self, recv: &[u32], out: ClusterValues) {
        let kmaps = self.kmaps;
        for (r, &i) in recv.iter().enumerate() {
            let i = i as usize;
            self.values[i * kmaps..(i + 1) * kmaps]
                .copy_from_slice(&out.values[r * kmaps..(r + 1) * kmaps]);
        }
        self.stats = self.stats.plus(&out.stats);
    }

    /// The maps, with their peaks.
    fn finish(self) -> CellValues {
        let mut peak = vec![0.0f64; self.kmaps];
        for px in self.values.chunks_exact(self.kmaps) {
            for (p, v) in peak.iter_mut().zip(px) {
                *p = p.max(v[0].abs().max(v[1].abs()).max(v[2].abs()) as f64);
            }
        }
        let w = self.grid.width;
        CellValues {
            width: w,
            height: self.grid.height,
            maps: self.kmaps,
            slots: (self.grid.texels.iter()).map(|t| t.y * w + t.x).collect(),
            values: self.values,
            peak,
            stats: self.stats,
        }
    }
}

/// The cell values of one receiving cluster: `K` values per receiver in the cluster's receiver
/// order ([`Integrator::receivers_by_cluster`]), and what it took. What a sharded bake's
/// shards compute ([`crate::bake::shard`]).
#[derive(Clone, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct ClusterValues {
    /// Receiver-major values, `K` per receiver.
    pub values: Vec<[f32; 3]>,
    /// What the integration did.
    pub stats: CellStats,
}

/// The prepared integration of [`integrate`] (cell table, clusters, candidate sites, link
/// index), from which receiving clusters are computed one by one — all of them by
/// [`integrate`], a share of them by a shard of a sharded bake. A cluster's values do not
/// depend on which other clusters are computed.
pub struct Integrator<'a>(Integration<'a>);

impl<'a> Integrator<'a> {
    /// Prepares the integration of `offsets` and their discrete `cells`.
    pub fn new(
        transport: &'a Transport,
        grid: &'a TexelGrid,
        offsets: &'a [IVec2],
        cells: &DiscreteCells,
    ) -> Self {
        let (w, h) = (grid.width, grid.height);
        let kmaps = offsets.len();
        let p = transport.remainder.block.max(1).next_power_of_two() as usize;
        let table = CellTable::new(cells, w, h, p);
        let origin = match table.cell(0, 0) {
            NO_CELL => None,
            c => Some(c),
        };
        let cand = Candidates::new(&cell_neighbours(&table, kmaps), origin);
        let links = (transport.links.as_ref())
            .map(|op| links::LinkIndex::new(op, grid, &transport.patches, &table));
        Self(Integration {
            transport,
            grid,
            offsets,
            clusters: clusters(transport, grid),
            table,
            origin,
            cand,
            links,
        })
    }

    /// Receiving clusters (the coarse level's clusters).
    pub fn cluster_count(&self) -> usize {
        self.0.clusters.texels.len()
    }

    /// The receivers (texel indices) of every cluster, in the order of their values.
    pub fn receivers_by_cluster(&self) -> Vec<Vec<u32>> {
        self.0.clusters.texels.clone()
    }

    /// An estimate of each receiving cluster's cost, for balancing shards: its receivers times
    /// the sender clusters each visits plus the texels of its exact zone.
    pub fn cluster_costs(&self) -> Vec<u64> {
        let cl = &self.0.clusters;
        let nc = cl.texels.len() as u64;
        (0..cl.texels.len())
            .map(|ci| {
                let zone: u64 = (cl.near[ci].iter())
                    .filter(|n| n.exact_zone)
                    .map(|n| cl.texels[n.cluster as usize].len() as u64)
                    .sum();
                cl.texels[ci].len() as u64 * (nc + zone + 1)
            })
            .collect()
    }

    /// The values of receiving clusters `range`, in parallel; `progress` is called with the
    /// receivers finished.
    pub fn clusters_in(
        &self,
        range: std::ops::Range<usize>,
        progress: &(dyn Fn(u64) + Sync),
    ) -> Vec<ClusterValues> {
        range
            .into_par_iter()
            .with_max_len(1)
            .map(|ci| {
                let (values, st) = self.0.receiving_cluster(ci);
                progress(self.0.clusters.texels[ci].len() as u64);
                ClusterValues { values, stats: st }
            })
            .collect()
    }
}

/// Every map's values from the values of every receiving cluster (`per_cluster[ci]` holding
/// `receivers[ci]`'s, [`Integrator`]), `kmaps` maps.
pub fn assemble(
    grid: &TexelGrid,
    kmaps: usize,
    receivers: &[Vec<u32>],
    per_cluster: Vec<ClusterValues>,
) -> CellValues {
    let mut out = Assembly::new(grid, kmaps);
    for (cv, recv) in per_cluster.into_iter().zip(receivers) {
        out.add(recv, cv);
    }
    out.finish()
}

impl CellStats {
    /// The field-wise sum of two sets of counts.
    fn plus(&self, b: &CellStats) -> CellStats {
        CellStats {
            near_cluster_pairs: self.near_cluster_pairs + b.near_cluster_pairs,
            near_texel_pairs: self.near_texel_pairs + b.near_texel_pairs,
            uniform_windows: self.uniform_windows + b.uniform_windows,
            split_windows: self.split_windows + b.split_windows,
            rehomed: self.rehomed + b.rehomed,
            moved_uncovered: self.moved_uncovered + b.moved_uncovered,
            rehomed_far: self.rehomed_far + b.rehomed_far,
            links: self.links + b.links,
            link_nodes: self.link_nodes + b.link_nodes,
            subsurface_nodes: self.subsurface_nodes + b.subsurface_nodes,
        }
    }
}

/// Everything [`integrate`] shares between receiving clusters.
struct Integration<'a> {
    transport: &'a Transport,
    grid: &'a TexelGrid,
    offsets: &'a [IVec2],
    clusters: Clusters,
    table: CellTable,
    /// The cell holding `Δt = 0`, if any.
    origin: Option<u32>,
    /// Every cell's candidate sites for the seam rule.
    cand: Candidates,
    /// The link walk's tables when the transport has the hierarchical operator.
    links: Option<links::LinkIndex>,
}

/// The running sums of one receiving cluster: per receiver `r` (in cluster order) and map `k`,
/// at `r · K + k`.
struct Receivers {
    /// Texel coordinates of each receiver.
    xy: Vec<(i32, i32)>,
    /// Transfer summed per cell.
    acc: Vec<[f64; 3]>,
    /// Position of the site `t + Δt_k`, `None` when uncovered.
    sites: Vec<Option<Vec3>>,
    /// Per receiver, the positions of its candidate sites in [`Candidates`] order
    /// ([`Candidates::UNCOVERED`] where uncovered), at `r · C` for `C` candidates; `w` holds
    /// each cell's reach at its own site ([`Candidates::push_positions`]).
    cand: Vec<Vec4>,
    stats: CellStats,
}

/// The share-able first bounce of a near cluster (0 when it is texel-exact).
fn near_bounce(n: &Near) -> [f64; 3] {
    if n.exact_bounce {
        [0.0; 3]
    } else {
        n.bounce.map(f64::from)
    }
}

impl Integration<'_> {
    /// The cell values of every receiver of cluster `ci` (receiver-major, `K` per receiver,
    /// 0 where a site is uncovered) and what it took.
    fn receiving_cluster(&self, ci: usize) -> (Vec<[f32; 3]>, CellStats) {
        let mut rx = self.receivers(ci);
        self.add_cluster_shares(ci, &mut rx);
        let walk = (self.transport.links.as_ref()).and_then(|op| op.subsurface_walk());
        match (&self.links, walk) {
            (Some(index), Some(walk)) => {
                self.add_links(index, ci, &mut rx);
                self.add_subsurface_walk(index, walk, ci, &mut rx);
            }
            (Some(index), None) => {
                self.add_exact_zone(ci, &mut rx);
                self.add_links(index, ci, &mut rx);
            }
            (None, _) => self.add_exact_zone(ci, &mut rx),
        }
        self.move_uncovered(&mut rx);
        let out: Vec<[f32; 3]> = rx
            .acc
            .iter()
            .zip(&rx.sites)
            .map(|(a, s)| {
                if s.is_some() {
                    a.map(|v| v as f32)
                } else {
                    [0.0; 3]
                }
            })
            .collect();
        (out, rx.stats)
    }

    /// Empty sums and the sites of every receiver of cluster `ci`.
    fn receivers(&self, ci: usize) -> Receivers {
        let kmaps = self.offsets.len();
        let recv = &self.clusters.texels[ci];
        let xy: Vec<(i32, i32)> = recv
            .iter()
            .map(|&i| {
                let t = &self.grid.texels[i as usize];
                (t.x as i32, t.y as i32)
            })
            .collect();
        let mut sites: Vec<Option<Vec3>> = vec![None; recv.len() * kmaps];
        for (r, &(xi, yi)) in xy.iter().enumerate() {
            for (k, o) in self.offsets.iter().enumerate() {
                sites[r * kmaps + k] = self
                    .grid
                    .at(xi + o.x, yi + o.y)
                    .map(|j| self.transport.patches[j as usize].position_m);
            }
        }
        let cl = self.cand.cells.len();
        let mut cand = Vec::with_capacity(recv.len() * cl);
        for r in 0..recv.len() {
            (self.cand).push_positions(&sites[r * kmaps..(r + 1) * kmaps], &mut cand);
        }
        Receivers {
            xy,
            acc: vec![[0.0f64; 3]; recv.len() * kmaps],
            cand,
            sites,
            stats: CellStats::default(),
        }
    }

    /// Every sender cluster by area share: the cluster transfer for far clusters; the
    /// remainder plus the point-to-cluster bounce for near ones (their subsurface part and
    /// near-singular bounce are added texel by texel by [`Integration::add_exact_zone`]).
    fn add_cluster_shares(&self, ci: usize, rx: &mut Receivers) {
        let kmaps = self.offsets.len();
        let rem = &self.transport.remainder;
        let nc = rem.clusters.len();
        let near = &self.clusters.near[ci];
        let table = &self.table;
        let mut next_near = 0usize;
        for cj in 0..nc {
            let k = ci * nc + cj;
            let v: [f64; 3] = if next_near < near.len() && near[next_near].cluster as usize == cj {
                let b = near_bounce(&near[next_near]);
                next_near += 1;
                [0, 1, 2].map(|c| rem.rem[c][k] as f64 + b[c])
            } else if self.links.is_some() {
                // The first bounce comes from the links.
                [0, 1, 2].map(|c| rem.rem[c][k] as f64)
            } else {
                [0, 1, 2].map(|c| rem.full[c][k] as f64)
            };
            if v == [0.0; 3] {
                continue;
            }
            let tile = &self.clusters.tiles[cj];
            let pj = rem.clusters[cj].position_m;
            for (r, &(xi, yi)) in rx.xy.iter().enumerate() {
                let acc = &mut rx.acc[r * kmaps..(r + 1) * kmaps];
                let sites = self.cand.of(&rx.cand, r);
                let st = &mut rx.stats;
                if !table.uniform.is_empty() {
                    let u = table.uniform[table.index(tile.origin.x - xi, tile.origin.y - yi)];
                    if u != NO_CELL {
                        st.uniform_windows += 1;
                        self.add_placed(acc, sites, u, pj, v, 1.0, &mut st.rehomed_far);
                        continue;
                    }
                }
                // The window straddles cells: each quadrant goes whole to the cell of its
                // centre texel (see the module docs).
                st.split_windows += 1;
                for &(centre, share) in &tile.quads {
                    if share == 0.0 {
                        continue;
                    }
                    let cell = table.cell(centre.x - xi, centre.y - yi);
                    if cell == NO_CELL {
                        continue;
                    }
                    self.add_placed(acc, sites, cell, pj, v, share, &mut st.rehomed_far);
                }
            }
        }
    }

    /// The exact zone, texel by texel: the subsurface term within the profile's support and
    /// the texel form factor of near-singular neighbours (replacing their point-to-cluster
    /// share).
    fn add_exact_zone(&self, ci: usize, rx: &mut Receivers) {
        let kmaps = self.offsets.len();
        let transport = self.transport;
        let kern = &transport.kernels;
        let rem = &transport.remainder;
        let cl = &self.clusters;
        let recv = &cl.texels[ci];
        // With links the first bounce is theirs: the exact zone is the subsurface term only.
        let bounce_here = kern.effects.radiosity && self.links.is_none();
        for (r, (&i, &(xi, yi))) in recv.iter().zip(&rx.xy).enumerate() {
            let pi = &transport.patches[i as usize];
            let sites = self.cand.of(&rx.cand, r);
            let acc = &mut rx.acc[r * kmaps..(r + 1) * kmaps];
            let st = &mut rx.stats;
            let translucent = kern.is_translucent(pi.material);
            let support2 = if translucent {
                (kern.support_m[pi.material as usize] as f32).powi(2)
            } else {
                0.0
            };
            let ff2 = if bounce_here {
                FF_EXACT_PITCHES * FF_EXACT_PITCHES * pi.area_m2
            } else {
                0.0
            };
            for n in cl.near[ci].iter().filter(|n| n.exact_zone) {
                st.near_cluster_pairs += 1;
                let cj = n.cluster as usize;
                let inv_area = 1.0 / rem.clusters[cj].area_m2 as f64;
                let approx = near_bounce(n);
                let one_texel = cl.texels[cj].len() == 1;
                for &j in &cl.texels[cj] {
                    let pj = &transport.patches[j as usize];
                    let d2 = (pj.position_m - pi.position_m).length_squared();
                    let in_sss = translucent && pj.material == pi.material && d2 < support2;
                    let in_ff = bounce_here && (n.exact_bounce || one_texel || d2 < ff2);
                    if !(in_sss || in_ff || i == j) {
                        continue;
                    }
                    let t = &self.grid.texels[j as usize];
                    let cell = self.table.cell(t.x as i32 - xi, t.y as i32 - yi);
                    if cell == NO_CELL {
                        continue;
                    }
                    st.near_texel_pairs += 1;
                    let cell = self.place(cell, pj.position_m, sites, &mut st.rehomed);
                    let mut e = transport.r_subsurface(i, j);
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
        }
    }

    /// Cells whose site is uncovered for a receiver: their transfer is counted with the
    /// receiver's own cell (the one holding Δt = 0), or, when that cell's site is uncovered
    /// too, the cell with a covered site nearest to Δt = 0.
    fn move_uncovered(&self, rx: &mut Receivers) {
        let kmaps = self.offsets.len();
        for r in 0..rx.xy.len() {
            let sites = &rx.sites;
            let valid = |k: usize| sites[r * kmaps + k].is_some();
            let Some(home) = self
                .origin
                .map(|o| o as usize)
                .filter(|&o| valid(o))
                .or_else(|| nearest_valid_to_zero(self.offsets, &valid))
            else {
                continue;
            };
            for k in 0..kmaps {
                if valid(k) || rx.acc[r * kmaps + k] == [0.0; 3] {
                    continue;
                }
                rx.stats.moved_uncovered += 1;
                let moved = std::mem::take(&mut rx.acc[r * kmaps + k]);
                let a = &mut rx.acc[r * kmaps + home];
                for c in 0..3 {
                    a[c] += moved[c];
                }
            }
        }
    }

    /// [`place`] with this integration's candidates; `sites` are one receiver's candidate
    /// positions ([`Receivers::cand`]).
    #[inline]
    fn place(&self, cell: u32, p_m: Vec3, sites: &[Vec4], moved: &mut u64) -> u32 {
        place(cell, p_m, sites, &self.cand, moved)
    }

    /// Adds `v · share` to the receiver's sum `acc` in the cell that [`place`] picks for a
    /// sender at `p_m` whose offset lies in `cell`.
    #[inline]
    #[expect(
        clippy::too_many_arguments,
        reason = "one receiver's slices and one sender's data"
    )]
    fn add_placed(
        &self,
        acc: &mut [[f64; 3]],
        sites: &[Vec4],
        cell: u32,
        p_m: Vec3,
        v: [f64; 3],
        share: f64,
        moved: &mut u64,
    ) {
        let a = &mut acc[self.place(cell, p_m, sites, moved) as usize];
        for c in 0..3 {
            a[c] += v[c] * share;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};

    /// The nearest covered candidate by brute force, the first of equals in candidate order.
    fn nearest(cell: u32, p: Vec3, site: &[Option<Vec3>], cand: &Candidates) -> u32 {
        let (a, b) = (
            cand.start[cell as usize] as usize,
            cand.start[cell as usize + 1] as usize,
        );
        let mut best = (cell, f32::INFINITY);
        for &k in &cand.cells[a..b] {
            let Some(s) = site[k as usize] else { continue };
            let d = (p - s).length_squared();
            if d < best.1 {
                best = (k, d);
            }
        }
        best.0
    }

    /// [`place`] with each cell's reach gives the brute-force nearest candidate: random cells
    /// with random neighbours, some sites uncovered, some shared by two cells, senders near and
    /// far from the sites.
    #[test]
    fn place_with_reach_is_the_nearest_candidate() {
        let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(7);
        let mut early = 0usize;
        for _ in 0..200 {
            let kmaps = rng.random_range(1..12usize);
            let neighbours: Vec<Vec<u32>> = (0..kmaps)
                .map(|k| {
                    let mut n: Vec<u32> = (0..kmaps as u32)
                        .filter(|&j| j != k as u32 && rng.random_bool(0.5))
                        .collect();
                    n.sort_unstable();
                    n
                })
                .collect();
            let origin = rng
                .random_bool(0.7)
                .then(|| rng.random_range(0..kmaps as u32));
            let cand = Candidates::new(&neighbours, origin);
            let mut site: Vec<Option<Vec3>> = (0..kmaps)
                .map(|_| {
                    rng.random_bool(0.85)
                        .then(|| Vec3::new(rng.random(), rng.random(), rng.random()) * 0.2)
                })
                .collect();
            if kmaps > 1 {
                site[1] = site[0];
            }
            let mut pos = Vec::new();
            cand.push_positions(&site, &mut pos);
            for _ in 0..200 {
                let cell = rng.random_range(0..kmaps as u32);
                let spread = [1e-4f32, 1e-2, 0.1, 0.3][rng.random_range(0..4)];
                let base = site[cell as usize].unwrap_or(Vec3::ZERO);
                let p = base
                    + Vec3::new(
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                        rng.random_range(-1.0..1.0),
                    ) * spread;
                let own = cand.start[cell as usize] as usize;
                if (p - pos[own].truncate()).length_squared() <= pos[own].w {
                    early += 1;
                }
                let mut moved = 0;
                let got = place(cell, p, &pos, &cand, &mut moved);
                let want = nearest(cell, p, &site, &cand);
                assert_eq!(got, want, "cell {cell}, sender {p}");
                assert_eq!(moved, u64::from(got != cell));
            }
        }
        // The reach must take a fair share of the senders, or the test checks little of it.
        assert!(
            early > 5_000,
            "{early} of 40000 senders took the early answer"
        );
    }
}
