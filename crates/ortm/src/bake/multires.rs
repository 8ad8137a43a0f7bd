//! Multi-resolution offset maps ([`crate::maps::levels`]) from the transfer `R(t, t')`.
//!
//! # What is computed
//! For every receiver `t`, its row `R(t, ·)` is partitioned into blocks of the lightmap's
//! quadtree, top-down: a block `b` of level `ℓ` is kept whole when the first-order light taken as
//! the block's area-weighted mean changes the result by little whatever that light is, and is
//! split into its four children otherwise; single texels (level 0) are exact. Kept blocks become
//! entries `(ℓ, Δ = b − ⌊t/2^ℓ⌋, Σ_{j∈b} R(t, j))` of the level-`ℓ` map of offset `Δ`.
//!
//! # Error control
//! Taking `B_o` as its block mean `P_ℓ(b) = Σ A_j B_o(j) / Σ A_j` errs by
//! `Σ_j (R(t,j) − S_b A_j / A_b) B_o(j)`, with `S_b = Σ_j R(t,j)` and `A_b = Σ_j A_j`. Its terms
//! sum to zero, so for any first order with `0 ≤ B_o ≤ B_max` the error is at most
//! `δ_b B_max / 2`, `δ_b = Σ_j |R(t,j) − S_b A_j / A_b|` (per channel, the largest taken). A
//! block is kept when `δ_b ≤ ε` (the tolerance): every receiver's error is bounded by `ε B_max / 2`
//! per block it uses, for every lighting. `ε = 0` keeps only exact blocks: with a generic
//! transfer, every single texel — the full-budget form, equal to Eq. 9 with every offset.
//!
//! # Receiver blocks
//! Neighbouring receivers mostly keep the same far sender blocks with nearly the same values.
//! [`coarsen_receivers`] shares such an entry between the covered receivers of a `2^r × 2^r`
//! receiver block (`r ≤ ℓ`) as their area-weighted mean, when no receiver's own value is more
//! than `ε/2` from it (the error a kept sender block may add, `ε·B_max/2`, for any first order;
//! the mean keeps the transferred power exactly). The result is a sum per receiver level,
//! `G_r(c) = Σ V·P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)`, read back by every covered texel of the block
//! ([`apply_blocks`], the CPU form). [`to_block_maps`] groups them into maps with a receiver
//! level ([`TransferMap::receiver_level`]), one per `(r, ℓ, Δ)`, which the bake writes
//! (`ortm bake --levels ε --receiver-blocks on`; off by default: on a multi-chart mesh the
//! maps' crops keep most zeros between shared blocks while the maps multiply, README), the
//! atlases pack and the renderer applies. `ortm bench accuracy --levels` measures both forms.
//!
//! # Cost
//! Rows come from a caller's closure (the dense transfer matrix, or the pair evaluator
//! [`Transport::r`]): `n` evaluations per receiver. The partition costs `O(n log n)` per
//! receiver in the worst case; blocks whose `Σ |R|` is within `ε / 2` are kept without a scan.

use std::collections::BTreeMap;

use glam::IVec2;
use rayon::prelude::*;

use crate::Lightmap;
use crate::bake::near_field::NearRows;
use crate::bake::texels::TexelGrid;
use crate::bake::transport::{Cancelled, SetupProgress, Transport};
use crate::maps::levels::{add3, halve, level_count};
use crate::maps::{MapsError, TransferMap};

/// How the receivers' rows are partitioned.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MultiresSettings {
    /// `ε`: the largest `δ_b` of a kept block (module docs). 0: every block down to texels.
    pub tolerance: f64,
    /// Coarsest pyramid level used (blocks of `2^max_level` texels).
    pub max_level: u32,
}

impl Default for MultiresSettings {
    fn default() -> Self {
        Self {
            tolerance: 1e-3,
            max_level: 16,
        }
    }
}

/// One kept block of one receiver's row.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct Entry {
    /// Pyramid level.
    pub level: u8,
    /// Offset in level-`level` blocks.
    pub offset: IVec2,
    /// `Σ_{j ∈ block} R(t, j)`, per channel.
    pub value: [f32; 3],
}

/// Per-level sums of one row: `Σ R` and `Σ |R|` per block and channel, levels `≥ 1` (level 0
/// is the row itself, read in place).
struct RowSums {
    sum: Vec<Vec<[f64; 3]>>,
    abs: Vec<Vec<[f64; 3]>>,
}

impl RowSums {
    /// `(Σ R, Σ |R|)` of block `i` of level `l` of `row`.
    fn at(&self, row: &[[f64; 3]], l: usize, i: usize) -> ([f64; 3], [f64; 3]) {
        if l == 0 {
            (row[i], row[i].map(f64::abs))
        } else {
            (self.sum[l][i], self.abs[l][i])
        }
    }
}

/// Level geometry and the texel weights shared by every row.
struct Layout {
    dims: Vec<(u32, u32)>,
    /// Per level, per block: summed texel area (m²); level 0 is each texel's area (0 where
    /// uncovered), row-major.
    weight: Vec<Vec<f64>>,
}

impl Layout {
    fn new(grid: &TexelGrid, levels: u32) -> Self {
        let (w, h) = (grid.width, grid.height);
        let area: Vec<f64> = grid.area_map().iter().map(|&a| a as f64).collect();
        let mut dims = vec![(w, h)];
        let mut weight = vec![area];
        for l in 1..levels as usize {
            let d = dims[l - 1];
            weight.push(halve(d, &weight[l - 1], 0.0, |a, b| *a += b));
            dims.push((d.0.div_ceil(2), d.1.div_ceil(2)));
        }
        Self { dims, weight }
    }

    /// The block sums of `row` (a full `W × H` row) into `out`, levels `1..`: each level's sum
    /// and absolute sum from one pass over the level below (level 0 read in place), every
    /// block's children added in row-major order from zero, as [`halve`] adds them.
    fn sums_into(&self, row: &[[f64; 3]], out: &mut RowSums) {
        let levels = self.dims.len();
        out.sum.resize_with(levels, Vec::new);
        out.abs.resize_with(levels, Vec::new);
        for l in 1..levels {
            let (w, h) = self.dims[l - 1];
            let (nw, nh) = self.dims[l];
            let (below, above) = out.sum.split_at_mut(l);
            let (below_abs, above_abs) = out.abs.split_at_mut(l);
            let (sum, abs) = (&mut above[0], &mut above_abs[0]);
            sum.clear();
            sum.resize((nw * nh) as usize, [0.0; 3]);
            abs.clear();
            abs.resize((nw * nh) as usize, [0.0; 3]);
            for y in 0..h {
                for x in 0..w {
                    let j = (y * w + x) as usize;
                    let o = ((y / 2) * nw + x / 2) as usize;
                    let (v, a) = if l == 1 {
                        (row[j], row[j].map(f64::abs))
                    } else {
                        (below[l - 1][j], below_abs[l - 1][j])
                    };
                    add3(&mut sum[o], &v);
                    add3(&mut abs[o], &a);
                }
            }
        }
    }
}

/// The kept blocks of receiver texel `(tx, ty)` for its full-resolution row `row` and the row's
/// block sums (module docs).
fn partition(
    layout: &Layout,
    sums: &RowSums,
    row: &[[f64; 3]],
    (tx, ty): (u32, u32),
    settings: &MultiresSettings,
) -> Vec<Entry> {
    let eps = settings.tolerance;
    let top = (layout.dims.len() as u32 - 1).min(settings.max_level);
    let (w0, h0) = layout.dims[0];
    let mut stack: Vec<(u32, u32, u32)> = Vec::new();
    let (tw, th) = layout.dims[top as usize];
    for by in (0..th).rev() {
        for bx in (0..tw).rev() {
            stack.push((top, bx, by));
        }
    }
    let mut out = Vec::new();
    while let Some((l, bx, by)) = stack.pop() {
        let (lw, _) = layout.dims[l as usize];
        let i = (by * lw + bx) as usize;
        let (s, a) = sums.at(row, l as usize, i);
        if a == [0.0; 3] {
            continue;
        }
        let emit = |out: &mut Vec<Entry>| {
            out.push(Entry {
                level: l as u8,
                offset: IVec2::new(bx as i32 - (tx >> l) as i32, by as i32 - (ty >> l) as i32),
                value: s.map(|c| c as f32),
            })
        };
        if l == 0 || a.iter().all(|&c| 2.0 * c <= eps) {
            emit(&mut out);
            continue;
        }
        let wb = layout.weight[l as usize][i];
        let mut keep = wb > 0.0;
        if keep {
            let mut delta = [0.0f64; 3];
            let (x0, y0) = (bx << l, by << l);
            let (x1, y1) = ((x0 + (1 << l)).min(w0), (y0 + (1 << l)).min(h0));
            'scan: for y in y0..y1 {
                for x in x0..x1 {
                    let j = (y * w0 + x) as usize;
                    let f = layout.weight[0][j] / wb;
                    for c in 0..3 {
                        delta[c] += (row[j][c] - s[c] * f).abs();
                    }
                    if delta.iter().any(|&d| d > eps) {
                        keep = false;
                        break 'scan;
                    }
                }
            }
        }
        if keep {
            emit(&mut out);
        } else {
            for (cx, cy) in [(1, 1), (0, 1), (1, 0), (0, 0)] {
                let (nx, ny) = (2 * bx + cx, 2 * by + cy);
                let (nw, nh) = layout.dims[l as usize - 1];
                if nx < nw && ny < nh {
                    stack.push((l - 1, nx, ny));
                }
            }
        }
    }
    out
}

/// Every covered receiver's kept blocks for each of `settings`: `[setting][receiver]`, receivers
/// in the grid's texel order. `row(i, out)` fills `out` (one value per covered texel, grid order)
/// with `R(i, ·)`; each row is computed once for all settings.
///
/// Reports the phase "multi-resolution rows" (one step per receiver) to `progress`.
///
/// # Errors
/// [`Cancelled`] when `progress` is cancelled.
pub fn partition_rows(
    grid: &TexelGrid,
    row: impl Fn(u32, &mut [[f32; 3]]) + Sync,
    settings: &[MultiresSettings],
    progress: &SetupProgress,
) -> Result<Vec<Vec<Vec<Entry>>>, Cancelled> {
    partition_rows_in(grid, row, settings, 0..grid.texels.len() as u32, progress)
}

/// [`partition_rows`] of the receivers `receivers` only (texel indices; `out[s][i]` is
/// receiver `receivers.start + i`'s): what a shard of a sharded bake computes
/// ([`crate::bake::shard`]). A receiver's entries do not depend on which others are computed.
///
/// # Errors
/// [`Cancelled`] when `progress` is cancelled.
pub fn partition_rows_in(
    grid: &TexelGrid,
    row: impl Fn(u32, &mut [[f32; 3]]) + Sync,
    settings: &[MultiresSettings],
    receivers: std::ops::Range<u32>,
    progress: &SetupProgress,
) -> Result<Vec<Vec<Vec<Entry>>>, Cancelled> {
    let layout = Layout::new(grid, level_count(grid.width, grid.height));
    let n = grid.texels.len();
    let w = grid.width;
    // Each covered texel's index in the `W × H` grid, read once per row (not the texels
    // themselves: ~100 bytes each, `n` of them per row).
    let at: Vec<u32> = grid.texels.iter().map(|t| t.y * w + t.x).collect();
    progress.phase("multi-resolution rows", receivers.len() as u64);
    let per_receiver: Vec<Vec<Vec<Entry>>> = receivers
        .into_par_iter()
        .map_init(
            || {
                (
                    vec![[0.0f32; 3]; n],
                    vec![[0.0f64; 3]; layout.weight[0].len()],
                    RowSums {
                        sum: Vec::new(),
                        abs: Vec::new(),
                    },
                )
            },
            |(r, full, sums), i| {
                progress.check()?;
                row(i, r);
                for (&k, v) in at.iter().zip(r.iter()) {
                    full[k as usize] = v.map(|c| c as f64);
                }
                let t = &grid.texels[i as usize];
                layout.sums_into(full, sums);
                let out = settings
                    .iter()
                    .map(|s| partition(&layout, sums, full, (t.x, t.y), s))
                    .collect();
                progress.advance(1);
                Ok(out)
            },
        )
        .collect::<Result<_, Cancelled>>()?;
    let mut out: Vec<Vec<Vec<Entry>>> = (settings.iter())
        .map(|_| Vec::with_capacity(per_receiver.len()))
        .collect();
    for per_setting in per_receiver {
        for (o, e) in out.iter_mut().zip(per_setting) {
            o.push(e);
        }
    }
    Ok(out)
}

/// Rows of the pair evaluator: `R(i, j)` = [`Transport::r`].
pub fn transport_row(tr: &Transport) -> impl Fn(u32, &mut [[f32; 3]]) + Sync + '_ {
    move |i, out| {
        for (j, o) in out.iter_mut().enumerate() {
            *o = tr.r(i, j as u32);
        }
    }
}

/// Rows of the hierarchical transport ([`Transport::build_hierarchical`], `ortm bake
/// --tolerance`), `None` without its operator: the first bounce of the operator's links (every
/// link into the receiver's leaf or an ancestor spread over its sender node by area, as
/// [`crate::bake::cells`] bins it), the subsurface term of its walk (each visited node's
/// profile value times its texels' weights, and the point mass `−1` at the receiver) and the
/// coarse higher-order remainder by area, gathered at the receiver ([`RECEIVER_GATHER`]). No
/// visibility ray per pair: `O(n)` per row.
pub fn hierarchical_row(tr: &Transport) -> Option<impl Fn(u32, &mut [[f32; 3]]) + Sync + '_> {
    hierarchical_row_with(tr, None)
}

/// A cluster whose texel-level coupling to a receiver differs from the receiver's cluster's by
/// more than this (a form factor times the albedo, or a subsurface weight, per channel) takes
/// part in the receiver's gather of the coarse remainder ([`hierarchical_row_with`]).
///
/// # The receiver gather
/// The coarse remainder holds the higher bounces between clusters (tiles of the lightmap and
/// slit texels, [`crate::bake::transport::coarse`]); a texel used to take its tile's row,
/// `rem(C, ·)`, as if every texel of the tile saw and touched the same clusters. Beside a slit
/// the tile's mean undercounts the light the texel gathers from the slit texels next to it —
/// by bounces and, on skin, through the profile — and the maps of the head at 256² were up to
/// 30 % below their solve at the corners of the lips. The remainder at cluster level is
/// `rem(C, ·) ≈ ρ_C Σ_K F(C, K) R(K, ·) + Σ_M S(C, M) (rem(M, ·) + ρ_M F(M, ·))` (a bounce
/// off every cluster `K` whose light `R(K, ·)` is the cluster solve's, and on skin the profile
/// from every cluster `M` whose bounced light is its remainder and first bounce); the texel's
/// own couplings — `F(i, K)`, the links' form factors summed per cluster, and `S(i, M)`, the
/// walk's and the near field's weights summed per cluster, both collected while the row is
/// painted — replace the tile's where they differ by more than this:
///
/// ```text
/// rem(i, ·) = rem(C, ·) + Σ_K (ρ_i F(i, K) − ρ_C F(C, K)) R(K, ·)
///                       + Σ_M (S(i, M) − S(C, M)) (rem(M, ·) + ρ_M F(M, ·))     (skin)
/// ```
///
/// On the head at 256² (`ortm bake head --size 256 --levels 3e-3`, rendered on the CPU
/// mirrors) the maps went from 7.12 % to 5.97 % (indirect) off their solve (`ortm solve head
/// --size 256 --near-field 3 --near-field-light input`) and from 16.69 % to 15.32 % off the
/// 8,192-path reference, the rows from 27 to 30 s. The threshold was chosen from 10⁻⁴, 3·10⁻⁴,
/// 10⁻³, 3·10⁻³ and 10⁻²: 6.08 / 6.03 / 5.97 / 5.92 / 5.83 % off the solve, 15.32 / 15.31 /
/// 15.32 / 15.38 / 15.52 % off the reference, rows 35 / 34 / 30 / 31 / 30 s; at 10⁻³ the rooms
/// gain as much as at 10⁻⁴ (README, *Slits in the remainder*, "The receiver gather").
pub const RECEIVER_GATHER: f32 = 1e-3;

/// [`hierarchical_row`] with skin's near field when `near` is given (`ortm bake --near-field`,
/// [`crate::bake::near_field::near_rows`]): the walk's first scattering from the senders in a
/// receiver's window is left out and the near rows' sub-texel weights (`W_ij / ρ̄_j`, not
/// normalised) are added in its place; the point mass `−1`, the links and the remainder stay.
/// Receivers without near rows (opaque, or not asked for) keep the walk's.
pub fn hierarchical_row_with<'a>(
    tr: &'a Transport,
    near: Option<&'a NearRows>,
) -> Option<impl Fn(u32, &mut [[f32; 3]]) + Sync + 'a> {
    use crate::bake::transport::hier::tree::NO_PARENT;
    let op = tr.links.as_ref()?;
    let tree = op.tree();
    let parent = tree.parents();
    let rem = &tr.remainder;
    let nc = rem.clusters.len();
    // Each texel's share of its cluster's area, by which the cluster rows are spread.
    let share: Vec<f32> = (tr.patches.iter().zip(&rem.cluster_of))
        .map(|(p, &c)| p.area_m2 / rem.clusters[c as usize].area_m2)
        .collect();
    // The senders' areas, read `n` times per row (not the patches themselves).
    let area: Vec<f32> = tr.patches.iter().map(|p| p.area_m2).collect();
    // The receiver gather reads the cluster system's form factors and subsurface weights, which
    // the remainder keeps with its slit texels.
    let gather = !rem.form_factors.is_empty();
    Some(move |i: u32, out: &mut [[f32; 3]]| {
        let ci = rem.cluster_of[i as usize] as usize;
        let p = &tr.patches[i as usize];
        out.fill([0.0; 3]);
        // The texel's form factors summed per cluster, F(i, K), for the gather.
        let mut f_k = vec![0.0f32; if gather { nc } else { 0 }];
        let mut node = tree.leaf_of[i as usize];
        while node != NO_PARENT {
            for l in op.links_of(node) {
                let k = l.irradiance_per_radiosity(op.link_direction(node, l.send), p.normal);
                if k <= 0.0 {
                    continue;
                }
                let inv_area = 1.0 / tree.nodes[l.send as usize].area_m2;
                for &j in tree.members(l.send) {
                    let f = k * area[j as usize] * inv_area;
                    let o = &mut out[j as usize];
                    for (c, v) in o.iter_mut().enumerate() {
                        *v += p.rho[c] * f;
                    }
                    if gather {
                        f_k[rem.cluster_of[j as usize] as usize] += f;
                    }
                }
            }
            node = parent[node as usize];
        }
        // The texel's subsurface weights summed per cluster, S(i, M) (skin receivers).
        let skin = gather && tr.kernels.is_translucent(p.material);
        let mut s_m: [Vec<f32>; 3] =
            std::array::from_fn(|_| vec![0.0f32; if skin { nc } else { 0 }]);
        let near_row = near
            .map(|n| (n, &n.rows[i as usize]))
            .filter(|(_, r)| !r.is_empty());
        if let Some(walk) = op.subsurface_walk() {
            walk.walk(tree, &tr.patches, &tr.kernels, i as usize, |s, rd, me| {
                for &j in tree.members(s) {
                    if near_row.is_some_and(|(n, _)| n.in_window(i as usize, j as usize)) {
                        continue;
                    }
                    let w = walk.weight(tree.leaf_of[j as usize]);
                    for c in 0..3 {
                        let v = (rd[c] * w[c] as f64) as f32;
                        out[j as usize][c] += v;
                        if skin {
                            s_m[c][rem.cluster_of[j as usize] as usize] += v;
                        }
                    }
                }
                if me {
                    for v in out[i as usize].iter_mut() {
                        *v -= 1.0;
                    }
                    if skin {
                        for s in s_m.iter_mut() {
                            s[ci] -= 1.0;
                        }
                    }
                }
            });
        }
        if let Some((_, row)) = near_row {
            for &(j, w) in row {
                for (c, (v, w)) in out[j as usize].iter_mut().zip(w).enumerate() {
                    *v += w;
                    if skin {
                        s_m[c][rem.cluster_of[j as usize] as usize] += w;
                    }
                }
            }
        }
        // The receiver's cluster row, gathered at the texel (RECEIVER_GATHER).
        let mut row: [Vec<f32>; 3] = rem
            .rem
            .each_ref()
            .map(|r| r[ci * nc..(ci + 1) * nc].to_vec());
        if gather {
            let rho_c = rem.clusters[ci].rho;
            let f_c = &rem.form_factors[ci * nc..(ci + 1) * nc];
            for k in 0..nc {
                for (c, row) in row.iter_mut().enumerate() {
                    let d = p.rho[c] * f_k[k] - rho_c[c] * f_c[k];
                    if d.abs() > RECEIVER_GATHER {
                        axpy(row, d, &rem.full[c][k * nc..(k + 1) * nc]);
                    }
                }
            }
        }
        if skin {
            for &(m, s) in &rem.subsurface[ci] {
                for (c, v) in s.iter().enumerate() {
                    s_m[c][m as usize] -= v;
                }
            }
            for (c, (row, s_m)) in row.iter_mut().zip(&s_m).enumerate() {
                for (m, &d) in s_m.iter().enumerate() {
                    if d.abs() > RECEIVER_GATHER {
                        let rho_m = rem.clusters[m].rho[c];
                        let rem_m = &rem.rem[c][m * nc..(m + 1) * nc];
                        let f_m = &rem.form_factors[m * nc..(m + 1) * nc];
                        for ((v, r), f) in row.iter_mut().zip(rem_m).zip(f_m) {
                            *v += d * (r + rho_m * f);
                        }
                    }
                }
            }
        }
        for ((o, &cj), &f) in out.iter_mut().zip(&rem.cluster_of).zip(&share) {
            let cj = cj as usize;
            for (c, v) in o.iter_mut().enumerate() {
                *v += row[c][cj] * f;
            }
        }
    })
}

/// `y += a·x`.
fn axpy(y: &mut [f32], a: f32, x: &[f32]) {
    for (y, x) in y.iter_mut().zip(x) {
        *y += a * x;
    }
}

/// `row` with the gathered near field's first bounce added ([`crate::bake::near_gather`],
/// `ortm bake --near-gather G`): `ρ_i ΔF_ij` at every sender `j` of receiver `i`'s row of
/// `gathered` (`ΔF`, one row per covered texel), the form factors the rays found on the mesh
/// less the transport's to the same texels. The higher bounces stay the transport's.
pub fn with_gathered_rows<'a>(
    tr: &'a Transport,
    row: impl Fn(u32, &mut [[f32; 3]]) + Sync + 'a,
    gathered: &'a [Vec<(u32, f32)>],
) -> impl Fn(u32, &mut [[f32; 3]]) + Sync + 'a {
    move |i, out| {
        row(i, out);
        let rho = tr.patches[i as usize].rho;
        for &(j, d) in &gathered[i as usize] {
            for (c, v) in out[j as usize].iter_mut().enumerate() {
                *v += rho[c] * d;
            }
        }
    }
}

/// Groups the receivers' entries into maps, one per `(level, offset)`, ordered by level then
/// offset (row-major).
///
/// # Errors
/// [`MapsError`] from cropping (a non-finite value).
pub fn to_maps(grid: &TexelGrid, entries: &[Vec<Entry>]) -> Result<Vec<TransferMap>, MapsError> {
    // (level, dy, dx) → (receiver, value) pairs.
    type Receivers = Vec<(u32, [f32; 3])>;
    let mut keyed: BTreeMap<(u8, i32, i32), Receivers> = BTreeMap::new();
    for (i, es) in entries.iter().enumerate() {
        for e in es {
            keyed
                .entry((e.level, e.offset.y, e.offset.x))
                .or_default()
                .push((i as u32, e.value));
        }
    }
    keyed
        .into_par_iter()
        .map(|((level, dy, dx), list)| {
            let mut full = Lightmap::new(grid.width, grid.height);
            for (i, v) in list {
                let t = &grid.texels[i as usize];
                full.set(t.x, t.y, v);
            }
            TransferMap::from_full(IVec2::new(dx, dy), 0.0, 0.0, &full)?.with_level(level as u32)
        })
        .collect()
}

/// Entries per level (for reports).
pub fn entries_per_level(entries: &[Vec<Entry>]) -> Vec<u64> {
    let mut out = Vec::new();
    for e in entries.iter().flatten() {
        if out.len() <= e.level as usize {
            out.resize(e.level as usize + 1, 0);
        }
        out[e.level as usize] += 1;
    }
    out
}

/// One kept block of the transfer shared by every covered receiver of a receiver block: the
/// value `V` multiplies `P_ℓ(⌊c / 2^(ℓ − r)⌋ + Δ)` and adds into every covered texel `t` with
/// `⌊t / 2^r⌋ = c` ([`coarsen_receivers`], [`apply_blocks`]).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct BlockEntry {
    /// Receiver level `r` (0: a single texel), at most [`Self::level`].
    pub receiver_level: u8,
    /// Receiver block `c` in level-`r` blocks.
    pub receiver: [u32; 2],
    /// Sender pyramid level `ℓ`.
    pub level: u8,
    /// Offset `Δ` in level-`ℓ` blocks (the same for every receiver of the block).
    pub offset: IVec2,
    /// `V`: the receivers' area-weighted mean of `Σ_{j ∈ block} R(t, j)`, per channel.
    pub value: [f32; 3],
}

/// A sender block and a receiver block of its level: `(ℓ, Δy, Δx, cy, cx)`.
type GroupKey = (u8, i32, i32, u32, u32);

/// Receivers (grid texel index) with their own values.
type Members = Vec<(u32, [f32; 3])>;

/// Shares the receivers' kept blocks ([`partition_rows`]) between neighbouring receivers: every
/// covered receiver of a `2^r × 2^r` receiver block (`r ≤ ℓ`) that keeps the same sender block
/// `(ℓ, b)` gets one value, their area-weighted mean `V` (so the transferred power is unchanged
/// for any first order), when no receiver's own value differs from `V` by more than
/// `tolerance / 2` in any channel — the same error, `tolerance · B_max / 2` for any first order
/// `0 ≤ B_o ≤ B_max`, that [`partition`] allows a kept sender block. Tried from `r = ℓ` down;
/// what cannot be shared stays per receiver (`r = 0`). `entries` is per receiver in the grid's
/// texel order. Deterministic: level-0 entries first, per receiver, then the others by sender
/// level, offset and receiver block.
pub fn coarsen_receivers(
    grid: &TexelGrid,
    entries: &[Vec<Entry>],
    tolerance: f64,
) -> Vec<BlockEntry> {
    let (w, h) = (grid.width, grid.height);
    let levels = level_count(w, h) as usize;
    // Covered receivers per block of each level.
    let mut covered: Vec<Vec<u32>> = vec![vec![0; (w * h) as usize]];
    for t in &grid.texels {
        covered[0][(t.y * w + t.x) as usize] = 1;
    }
    let mut dims = vec![(w, h)];
    for l in 1..levels {
        let d = dims[l - 1];
        covered.push(halve(d, &covered[l - 1], 0, |a, b| *a += b));
        dims.push((d.0.div_ceil(2), d.1.div_ceil(2)));
    }
    let area: Vec<f64> = grid.texels.iter().map(|t| t.area_m2 as f64).collect();
    // (ℓ, Δy, Δx, cy, cx at level ℓ, receiver) for every entry.
    let mut keyed: Vec<(GroupKey, u32, [f32; 3])> = Vec::new();
    let mut out = Vec::new();
    for (i, es) in entries.iter().enumerate() {
        let t = &grid.texels[i];
        for e in es {
            if e.level == 0 {
                out.push(BlockEntry {
                    receiver_level: 0,
                    receiver: [t.x, t.y],
                    level: 0,
                    offset: e.offset,
                    value: e.value,
                });
            } else {
                let l = e.level;
                let key = (l, e.offset.y, e.offset.x, t.y >> l, t.x >> l);
                keyed.push((key, i as u32, e.value));
            }
        }
    }
    keyed.sort_unstable_by_key(|k| (k.0, k.1));
    let mut stack: Vec<(u8, Members)> = Vec::new();
    for group in keyed.chunk_by(|a, b| a.0 == b.0) {
        let (l, _, _, _, _) = group[0].0;
        let offset = IVec2::new(group[0].0.2, group[0].0.1);
        stack.push((l, group.iter().map(|g| (g.1, g.2)).collect()));
        while let Some((r, members)) = stack.pop() {
            let t0 = &grid.texels[members[0].0 as usize];
            let c = [t0.x >> r, t0.y >> r];
            let emit_each = |out: &mut Vec<BlockEntry>| {
                for &(i, v) in &members {
                    let t = &grid.texels[i as usize];
                    out.push(BlockEntry {
                        receiver_level: 0,
                        receiver: [t.x, t.y],
                        level: l,
                        offset,
                        value: v,
                    });
                }
            };
            if r == 0 {
                emit_each(&mut out);
                continue;
            }
            let full = members.len() as u32
                == covered[r as usize][(c[1] * dims[r as usize].0 + c[0]) as usize];
            if full {
                let mut sum = [0.0f64; 3];
                let mut wsum = 0.0;
                for &(i, v) in &members {
                    let a = area[i as usize];
                    wsum += a;
                    for ch in 0..3 {
                        sum[ch] += a * v[ch] as f64;
                    }
                }
                let mean = sum.map(|s| if wsum > 0.0 { s / wsum } else { 0.0 });
                let ok = members.iter().all(|&(_, v)| {
                    (0..3).all(|ch| (v[ch] as f64 - mean[ch]).abs() <= 0.5 * tolerance)
                });
                if ok {
                    out.push(BlockEntry {
                        receiver_level: r,
                        receiver: c,
                        level: l,
                        offset,
                        value: mean.map(|m| m as f32),
                    });
                    continue;
                }
            }
            // Split by the receiver block's children.
            let mut children: Vec<(u32, Members)> = Vec::new();
            for &(i, v) in &members {
                let t = &grid.texels[i as usize];
                let k = ((t.y >> (r - 1)) & 1) * 2 + ((t.x >> (r - 1)) & 1);
                match children.iter_mut().find(|ch| ch.0 == k) {
                    Some(ch) => ch.1.push((i, v)),
                    None => children.push((k, vec![(i, v)])),
                }
            }
            children.sort_unstable_by_key(|ch| std::cmp::Reverse(ch.0));
            for (_, m) in children {
                stack.push((r - 1, m));
            }
        }
    }
    out
}

/// The final lightmap of block entries ([`coarsen_receivers`]) on the CPU: each entry adds
/// `V · P_ℓ(⌊c / 2^(ℓ − r)⌋ + Δ)` into its receiver level's sum `G_r(c)`, and every covered texel
/// `t` gets `B_o(t) + Σ_r G_r(⌊t / 2^r⌋)`. `weight` are the texel areas (0 where uncovered).
///
/// # Errors
/// [`MapsError`] from the pyramid (a lightmap or weights of the wrong size).
pub fn apply_blocks(
    grid: &TexelGrid,
    blocks: &[BlockEntry],
    first_order: &Lightmap,
    weight: &[f32],
) -> Result<Lightmap, MapsError> {
    use crate::maps::levels::Pyramid;
    let (w, h) = (grid.width, grid.height);
    let levels = level_count(w, h);
    let pyramid = Pyramid::new(first_order, weight, levels)?;
    let mut g: Vec<Vec<[f64; 3]>> = pyramid
        .levels
        .iter()
        .map(|l| vec![[0.0; 3]; (l.width * l.height) as usize])
        .collect();
    for b in blocks {
        let (r, l) = (b.receiver_level as u32, b.level as u32);
        let s = l - r;
        let p = pyramid.levels[l as usize].get(
            i64::from(b.receiver[0] >> s) + i64::from(b.offset.x),
            i64::from(b.receiver[1] >> s) + i64::from(b.offset.y),
        );
        let lw = pyramid.levels[r as usize].width;
        let a = &mut g[r as usize][(b.receiver[1] * lw + b.receiver[0]) as usize];
        for c in 0..3 {
            a[c] += b.value[c] as f64 * p[c] as f64;
        }
    }
    let mut out = first_order.clone();
    for t in &grid.texels {
        let slot = (t.y * w + t.x) as usize;
        let mut sum = [0.0f64; 3];
        for (r, gr) in g.iter().enumerate() {
            let lw = pyramid.levels[r].width;
            let v = gr[((t.y >> r) * lw + (t.x >> r)) as usize];
            for c in 0..3 {
                sum[c] += v[c];
            }
        }
        let b = first_order.data[slot];
        out.data[slot] = std::array::from_fn(|c| (b[c] as f64 + sum[c]) as f32);
    }
    Ok(out)
}

/// Groups block entries ([`coarsen_receivers`]) into maps, one per receiver level, sender level
/// and offset, ordered by receiver level, then level, then offset (row-major): the map of
/// `(r, ℓ, Δ)` holds each entry's value at its receiver block in the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid
/// ([`TransferMap::with_receiver_level`]). [`crate::maps::levels::apply_levels`] of the result
/// equals [`apply_blocks`] of `blocks` (up to the order of the f64 sums).
///
/// # Errors
/// [`MapsError`] from cropping (a non-finite value), a receiver block outside its grid or a
/// receiver level above the sender level.
pub fn to_block_maps(
    grid: &TexelGrid,
    blocks: &[BlockEntry],
) -> Result<Vec<TransferMap>, MapsError> {
    use crate::maps::receiver_grid;
    // (r, ℓ, dy, dx) → (receiver block, value) pairs.
    type Receivers = Vec<([u32; 2], [f32; 3])>;
    let mut keyed: BTreeMap<(u8, u8, i32, i32), Receivers> = BTreeMap::new();
    for b in blocks {
        keyed
            .entry((b.receiver_level, b.level, b.offset.y, b.offset.x))
            .or_default()
            .push((b.receiver, b.value));
    }
    let size = (grid.width, grid.height);
    keyed
        .into_par_iter()
        .map(|((r, level, dy, dx), list)| {
            let offset = IVec2::new(dx, dy);
            let (gw, gh) = receiver_grid(size, u32::from(r));
            let mut full = Lightmap::new(gw, gh);
            for ([cx, cy], v) in list {
                if cx >= gw || cy >= gh {
                    return Err(MapsError::InvalidCrop {
                        what: format!("receiver blocks of level {r}, offset {:?}", [dx, dy]),
                        reason: format!("block ({cx}, {cy}) is outside the {gw}×{gh} grid"),
                    });
                }
                full.set(cx, cy, v);
            }
            let cropped = TransferMap::from_full(offset, 0.0, 0.0, &full)?;
            TransferMap::from_crops(
                "receiver-block map",
                offset,
                0.0,
                0.0,
                size.0,
                size.1,
                cropped.crops().to_vec(),
            )?
            .with_level(u32::from(level))?
            .with_receiver_level(u32::from(r))
        })
        .collect()
}

/// What [`coarsen_receivers`] shared, for reports: `(receiver entries, shared)`, the
/// per-receiver entries the blocks stand for (a block entry of level `r` counts its covered
/// receivers) and how many of them lie in blocks of `r > 0`.
pub fn shared_entries(grid: &TexelGrid, blocks: &[BlockEntry]) -> (u64, u64) {
    let top = blocks.iter().map(|b| b.receiver_level).max().unwrap_or(0) as u32;
    // Covered receivers per block, per receiver level.
    let covered: Vec<std::collections::HashMap<[u32; 2], u64>> = (0..=top)
        .map(|r| {
            let mut m = std::collections::HashMap::new();
            for t in &grid.texels {
                *m.entry([t.x >> r, t.y >> r]).or_insert(0) += 1;
            }
            m
        })
        .collect();
    let (mut all, mut shared) = (0u64, 0u64);
    for b in blocks {
        let n = covered[b.receiver_level as usize]
            .get(&b.receiver)
            .copied()
            .unwrap_or(0);
        all += n;
        if b.receiver_level > 0 {
            shared += n;
        }
    }
    (all, shared)
}

/// Maps the block entries make on the GPU: one per receiver level, sender level and offset.
pub fn block_maps(blocks: &[BlockEntry]) -> usize {
    let mut keys: Vec<(u8, u8, i32, i32)> = blocks
        .iter()
        .map(|b| (b.receiver_level, b.level, b.offset.x, b.offset.y))
        .collect();
    keys.sort_unstable();
    keys.dedup();
    keys.len()
}
