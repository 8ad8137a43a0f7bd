//! The coarse level of the transport: texels grouped into clusters (one per `block × block`
//! tile of the lightmap, chart and material), the dense solve over the clusters, and the smooth
//! higher-order remainder `R_rem = R − R_fine` spread back to texel pairs by area.
//!
//! A cluster's centroid and normal are the area-weighted means of its texels; its area is their
//! sum; its albedo the area-weighted mean. `R_rem(i, j) ≈ R_rem(I, J)·A_j / A_J` for texels `i ∈ I`,
//! `j ∈ J` (piecewise constant per cluster pair, proportional to the sender's area share).
//!
//! # Slits
//! The remainder is smooth only where the surface does not face itself at close range. Between
//! the two sides of a slit (lips, eyelids, the folds of an ear, a room's corners) the higher
//! bounces are as local as the first, and a tile that folds has its centroid off the surface
//! and a mean normal facing neither side, so the centroids' form factor loses the light the
//! sides trade. With `slits` ([`Remainder::build`]; the hierarchical operator's rows, `ortm bake
//! --levels ε --tolerance τ`) the texels most coupled to the surface beside them are clusters of
//! their own ([`slit_texels`], at most [`MAX_SLIT_TEXELS`]) and near cluster pairs take their
//! members' mean form factor ([`near_form_factors`]); the coarse solve's transfer is then
//! kept in single precision ([`DenseTransport::transfer_f32_with`]). Measured against each scene's own
//! hierarchical solve (maps at `ε` = 3·10⁻³, `τ` = 10⁻³; README, *Slits in the remainder*),
//! indirect: head 256² 28.6 % → 9.5 %, maze 128² 14.9 % → 3.8 %, Cornell 128² 7.8 % → 4.4 %.

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use super::dense::DenseTransport;
use super::form_factor::{self, FfPatch};
use super::{Cancelled, Kernels, Patch, SetupProgress};
use crate::bake::point_grid::PointGrid;
use crate::bake::texels::{Texel, TexelGrid};

/// The higher-order remainder at the coarse level.
#[derive(serde::Serialize, serde::Deserialize)]
pub struct Remainder {
    /// Cluster of every texel (grid texel order).
    pub cluster_of: Vec<u32>,
    /// Cluster patches.
    pub clusters: Vec<Patch>,
    /// `R_rem(I, J)` per channel, row-major `n_c × n_c`.
    pub rem: [Vec<f32>; 3],
    /// The whole cluster transfer `R(I, J)` (fine + remainder) per channel, row-major
    /// `n_c × n_c`: the far field of the cell integration ([`crate::bake::cells`]).
    pub full: [Vec<f32>; 3],
    /// The cluster system's form factors `F(I, J)`, row-major `n_c × n_c`, kept where the
    /// slit texels are (the multi-resolution rows of the hierarchical transport, whose receiver
    /// gather compares them with a texel's own: [`crate::bake::multires::RECEIVER_GATHER`]);
    /// empty otherwise.
    pub form_factors: Vec<f32>,
    /// Where [`Self::form_factors`] is kept: per cluster `C`, its subsurface weights `S(C, M)`
    /// (the cluster solve's own, [`Kernels::r_subsurface`], with its point mass `−1` at
    /// `M = C`) from every cluster `M` that has one, in cluster order; empty rows for opaque
    /// clusters, and no rows otherwise.
    pub subsurface: Vec<SubsurfaceRow>,
    /// Block size in texels.
    pub block: u32,
    /// Texels that are clusters of their own besides the tiles ([`slit_texels`]).
    pub alone: u32,
}

/// One cluster's non-zero subsurface weights: `(sender cluster, weight per channel)`, in
/// cluster order ([`Remainder::subsurface`]).
pub type SubsurfaceRow = Vec<(u32, [f32; 3])>;

/// The cluster a texel belongs to: its `block × block` tile, chart and material.
fn cluster_key(t: &Texel, block: u32) -> (u32, u32, u32, u32) {
    (t.x / block, t.y / block, t.chart, t.material)
}

/// The cluster key of a texel that stays a cluster of its own ([`slit_texels`]).
fn single_key(t: &Texel) -> (u32, u32, u32, u32) {
    (t.x, t.y, t.chart, u32::MAX - t.material)
}

/// The number of clusters [`cluster_texels`] makes of `grid` (the bake's memory check sizes the
/// coarse solve with it before building anything).
pub fn cluster_count(grid: &TexelGrid, block: u32) -> usize {
    let block = block.max(1);
    (grid.texels.iter())
        .map(|t| cluster_key(t, block))
        .collect::<std::collections::HashSet<_>>()
        .len()
}

/// Up to this many covered texels the automatic block size ([`auto_block`]) makes every texel a
/// cluster: the coarse solve is then the exact dense solve (a few `n × n` matrices, 134 MB of
/// doubles each at 4,096, and seconds of LU on 2 cores).
pub const AUTO_EXACT_TEXELS: usize = 4096;

/// Beyond [`AUTO_EXACT_TEXELS`], the most clusters the automatic block size allows: the bake's
/// speed budget (the head at 256² with 100 offsets within 10 s on 2 cores, README "Bake speed";
/// 3,910 clusters took 22 s and 1.6 GB there).
pub const AUTO_MAX_CLUSTERS: usize = 1024;

/// The automatic block (texels per side): 1 up to [`AUTO_EXACT_TEXELS`] covered texels, else
/// the smallest block whose clusters number at most [`AUTO_MAX_CLUSTERS`].
pub fn auto_block(grid: &TexelGrid) -> u32 {
    let n = grid.texels.len();
    if n <= AUTO_EXACT_TEXELS {
        return 1;
    }
    // Full tiles of b² texels give n / b² clusters; partial tiles at chart borders add more.
    let mut block = ((n as f64 / AUTO_MAX_CLUSTERS as f64).sqrt().floor() as u32).max(1);
    while cluster_count(grid, block) > AUTO_MAX_CLUSTERS {
        block += 1;
    }
    block
}

/// At most this many texels are clusters of their own by default ([`slit_texels`]; `ortm bake
/// --slit-texels N` sets another cap): with the
/// [`AUTO_MAX_CLUSTERS`] tiles at most 5,120 clusters, whose single-precision solve took 9.2 s
/// on the head at 256² (5,084 clusters; the double-precision one of 4,072 clusters 11.0 s).
pub const MAX_SLIT_TEXELS: usize = 4096;

/// A texel whose unoccluded form factor to the surface within its cluster's reach is above
/// this is a slit texel ([`slit_texels`]). On the head at 128² (4×4 tiles; `ortm bake head
/// --size 128 --levels 3e-3 --tolerance 1e-4`, rendered on the CPU mirrors against `ortm solve
/// head --size 128`, indirect) 0.05 kept 1,274 texels and the maps were 6.4 % off, 0.02 kept
/// 1,631 (4.7 %), 0.005 keeps 2,706 (2.7 %; bake 9.5 → 15 s), and every texel up to 8,192
/// gave 2.7 % again; where [`MAX_SLIT_TEXELS`] binds (head 256², maze 128²) the choice is the
/// same.
pub const SLIT_COUPLING: f32 = 0.005;

/// The texels that stay clusters of their own in the coarse solve: those that see the surface
/// beside them — the two sides of a slit (lips, eyelids), the folds of an ear, a room's
/// corners — where the higher bounces are as local as the first. A tile's centroid and mean
/// normal would average them away (where a tile folds, its centroid lies off the surface and
/// its normal faces neither side), and the remainder would then spread what is left over the
/// whole tile. A texel's coupling is its unoccluded form factor to the surface within `block`
/// texel sizes of it, sampled at every `s`-th texel in x and y (`s = ⌈block / 4⌉`, each sample
/// standing for `s²` texels); the `max` most coupled above [`SLIT_COUPLING`] are kept (ties by
/// index; [`MAX_SLIT_TEXELS`] by default). Nothing at `block` ≤ 1 (every texel is its own
/// cluster already).
pub fn slit_texels(grid: &TexelGrid, patches: &[Patch], block: u32, max: usize) -> Vec<bool> {
    let n = patches.len();
    let mut slit = vec![false; n];
    if block <= 1 || n == 0 || n != grid.texels.len() {
        return slit;
    }
    let stride = block.div_ceil(4);
    let reach = |p: &Patch| block as f32 * p.area_m2.max(0.0).sqrt();
    let cell = (patches.iter()).map(reach).fold(0.0f32, f32::max).max(1e-6);
    // The samples: every `stride`-th texel in x and y, as a patch of `stride²` its area.
    let samples = PointGrid::new(
        f64::from(cell),
        (grid.texels.iter().zip(patches).enumerate())
            .filter(|(_, (t, _))| t.x % stride == 0 && t.y % stride == 0)
            .map(|(i, (_, p))| (i as u32, p.position_m)),
    );
    let weight = (stride * stride) as f32;
    let coupling: Vec<f32> = (0..n)
        .into_par_iter()
        .map(|i| {
            let p = &patches[i];
            let r = reach(p);
            let fp = FfPatch {
                texel: false,
                ..p.ff()
            };
            let mut k = 0.0f32;
            samples.for_each_within(p.position_m, r, |j| {
                let q = &patches[j as usize];
                if j as usize != i && (q.position_m - p.position_m).length() < r {
                    let fq = FfPatch {
                        area_m2: q.area_m2 * weight,
                        texel: false,
                        ..q.ff()
                    };
                    k += form_factor::unoccluded_form_factor(&fp, &fq).max(0.0) * fq.area_m2;
                }
            });
            k
        })
        .collect();
    let mut order: Vec<u32> = (0..n as u32)
        .filter(|&i| coupling[i as usize] > SLIT_COUPLING)
        .collect();
    order.sort_unstable_by(|&a, &b| {
        (coupling[b as usize].total_cmp(&coupling[a as usize])).then(a.cmp(&b))
    });
    for &i in order.iter().take(max) {
        slit[i as usize] = true;
    }
    slit
}

/// Groups texels into clusters: one per (tile of `block × block` texels, chart, material), and
/// one per texel where `alone` says so (empty: none; else one flag per texel, [`slit_texels`]).
pub fn cluster_texels(
    grid: &TexelGrid,
    patches: &[Patch],
    block: u32,
    alone: &[bool],
) -> (Vec<u32>, Vec<Patch>) {
    let block = block.max(1);
    let mut ids: HashMap<(u32, u32, u32, u32), u32> = HashMap::new();
    let mut cluster_of = Vec::with_capacity(grid.texels.len());
    let mut acc: Vec<(f64, Vec3, Vec3, Vec3, Vec3, u32)> = Vec::new();
    // Per cluster: its members' count and the first member's footprint (a cluster of one
    // texel keeps it, so that at `block` = 1 the clusters' weights are the texels').
    let mut single: Vec<(u32, Option<[Vec3; 2]>)> = Vec::new();
    for (i, (t, p)) in grid.texels.iter().zip(patches).enumerate() {
        let key = if alone.get(i) == Some(&true) {
            single_key(t)
        } else {
            cluster_key(t, block)
        };
        let n = ids.len() as u32;
        let id = *ids.entry(key).or_insert_with(|| {
            acc.push((
                0.0,
                Vec3::ZERO,
                Vec3::ZERO,
                Vec3::ZERO,
                Vec3::ZERO,
                t.material,
            ));
            single.push((0, p.footprint_m));
            n
        });
        cluster_of.push(id);
        single[id as usize].0 += 1;
        let a = &mut acc[id as usize];
        let w = p.area_m2;
        a.0 += w as f64;
        a.1 += p.position_m * w;
        a.2 += p.normal * w;
        a.3 += p.lift_normal * w;
        a.4 += p.rho * w;
    }
    let clusters = acc
        .into_iter()
        .zip(single)
        .map(
            |((area, pos, nrm, lift, rho, material), (members, footprint))| {
                let a = area as f32;
                Patch {
                    position_m: pos / a,
                    normal: nrm.try_normalize().unwrap_or(Vec3::Z),
                    lift_normal: lift.try_normalize().unwrap_or(Vec3::Z),
                    area_m2: a,
                    rho: rho / a,
                    material,
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: if members == 1 { footprint } else { None },
                }
            },
        )
        .collect();
    (cluster_of, clusters)
}

/// Cluster pairs whose centroids are closer than this many times the sum of their radii (and
/// every cluster with itself) take their form factor from their members' ([`near_form_factors`]).
pub const NEAR_CLUSTER_FACTOR: f32 = 1.5;

/// At most this many members per side of a near cluster pair are sampled (evenly strided in
/// texel order) for its form factor: at most `NEAR_SAMPLES²` rays per pair.
pub const NEAR_SAMPLES: usize = 16;

/// Replaces the form factors of near cluster pairs in `dense` (built over `clusters`) by their
/// members' area-weighted mean, `F_IJ = Σ_{i∈I} (A_i/A_I) Σ_{j∈J} F_ij`: the Galerkin projection
/// of the texels' operator onto the clusters. A cluster's centroid and mean normal stand for it
/// only far away: where a tile of the lightmap folds (a lip, an eyelid, the rim of an ear) the
/// centroid lies off the surface and the mean normal faces neither side, so the centroids'
/// form factor between the two sides of a slit — and a cluster's light onto itself — were
/// lost, and with them the higher bounces there. Members are subsampled to at most
/// [`NEAR_SAMPLES`] per side.
pub fn near_form_factors(
    dense: &mut DenseTransport,
    cluster_of: &[u32],
    clusters: &[Patch],
    patches: &[Patch],
    kernels: &Kernels,
    progress: &SetupProgress,
) -> Result<(), Cancelled> {
    if !kernels.effects.radiosity {
        return Ok(());
    }
    let n = clusters.len();
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); n];
    for (i, &c) in cluster_of.iter().enumerate() {
        members[c as usize].push(i as u32);
    }
    let radius: Vec<f32> = (0..n)
        .map(|c| {
            (members[c].iter())
                .map(|&i| {
                    let p = &patches[i as usize];
                    (p.position_m - clusters[c].position_m).length() + 0.5 * p.area_m2.sqrt()
                })
                .fold(0.0, f32::max)
        })
        .collect();
    let sampled: Vec<Vec<u32>> = members
        .iter()
        .map(|m| {
            let step = m.len().div_ceil(NEAR_SAMPLES).max(1);
            m.iter().step_by(step).copied().collect()
        })
        .collect();
    // Near pairs I ≤ J, found through a grid of the centroids.
    let reach = radius.iter().copied().fold(0.0, f32::max) * 2.0 * NEAR_CLUSTER_FACTOR;
    let grid = PointGrid::new(
        f64::from(reach.max(1e-6)),
        (clusters.iter().enumerate()).map(|(c, p)| (c as u32, p.position_m)),
    );
    let pairs: Vec<(u32, u32)> = (0..n)
        .into_par_iter()
        .flat_map_iter(|a| {
            let mut out = Vec::new();
            grid.for_each_within(clusters[a].position_m, reach, |b| {
                let b = b as usize;
                let d = (clusters[a].position_m - clusters[b].position_m).length();
                if b >= a && d < NEAR_CLUSTER_FACTOR * (radius[a] + radius[b]) {
                    out.push((a as u32, b as u32));
                }
            });
            out
        })
        .collect();
    progress.phase("transport: near cluster form factors", pairs.len() as u64);
    let values: Vec<(f64, f64)> = pairs
        .par_iter()
        .map(|&(a, b)| {
            if progress.check().is_err() {
                return (0.0, 0.0);
            }
            progress.advance(1);
            let (a, b) = (a as usize, b as usize);
            let area =
                |s: &[u32]| -> f64 { s.iter().map(|&i| patches[i as usize].area_m2 as f64).sum() };
            let (sa, sb) = (&sampled[a], &sampled[b]);
            let (wa, wb) = (area(sa), area(sb));
            // Σ_i A_i Σ_j c_ij A_j and the reverse, over the sampled members.
            let (mut ab, mut ba) = (0.0f64, 0.0f64);
            for &i in sa {
                for &j in sb {
                    if i == j {
                        continue;
                    }
                    let (p, q) = (&patches[i as usize], &patches[j as usize]);
                    let (c_pq, c_qp) = kernels.form_factor_pair(p, q);
                    let (ap, aq) = (p.area_m2 as f64, q.area_m2 as f64);
                    ab += ap * c_pq as f64 * aq;
                    ba += aq * c_qp as f64 * ap;
                }
            }
            if wa <= 0.0 || wb <= 0.0 {
                return (0.0, 0.0);
            }
            // Scaled from the samples' areas to the clusters' (the sender's total area).
            let (area_a, area_b) = (clusters[a].area_m2 as f64, clusters[b].area_m2 as f64);
            (ab / wa * area_b / wb, ba / wb * area_a / wa)
        })
        .collect();
    progress.check()?;
    for (&(a, b), &(ab, ba)) in pairs.iter().zip(&values) {
        let (a, b) = (a as usize, b as usize);
        dense.form_factors[(a, b)] = ab;
        if a != b {
            dense.form_factors[(b, a)] = ba;
        }
    }
    Ok(())
}

impl Remainder {
    /// Clusters the texels, solves the cluster system densely and keeps `R − R_fine`. The
    /// clusters' subsurface weights are normalised over the clusters
    /// ([`Kernels::normalise_subsurface`]) for both, as the dense solve does.
    pub fn new(grid: &TexelGrid, patches: &[Patch], kernels: &Kernels, block: u32) -> Self {
        Self::build(grid, patches, kernels, block, None, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Remainder::new`] with progress and cancellation: the clusters' form factors
    /// ([`DenseTransport::build`]) and the solve ([`DenseTransport::transfer_with`]). With
    /// `slits` = `Some(max)` (the hierarchical operator's bakes, whose first bounce is the
    /// links' texel by texel, never the clusters'), at most `max` slit texels are clusters of
    /// their own ([`slit_texels`]) and near cluster pairs take their members' form factor
    /// ([`near_form_factors`]).
    pub fn build(
        grid: &TexelGrid,
        patches: &[Patch],
        kernels: &Kernels,
        block: u32,
        slits: Option<usize>,
        progress: &SetupProgress,
    ) -> Result<Self, Cancelled> {
        let single = match slits {
            Some(max) if kernels.effects.radiosity => slit_texels(grid, patches, block, max),
            _ => Vec::new(),
        };
        let (cluster_of, mut clusters) = cluster_texels(grid, patches, block, &single);
        kernels.normalise_subsurface_with(&mut clusters, progress)?;
        let n = clusters.len();
        let mut dense = DenseTransport::build(&clusters, kernels, progress)?;
        // Slit texels beside tiles: the near tiles' member form factors, the single-precision
        // transfer, and the form factors and subsurface weights the rows' receiver gather reads.
        let tiled_slits = slits.is_some() && block > 1;
        if tiled_slits {
            near_form_factors(
                &mut dense,
                &cluster_of,
                &clusters,
                patches,
                kernels,
                progress,
            )?;
        }
        // With the slit texels the coarse solve's transfer is kept in single precision (its
        // remainder is an approximation by area already; half the memory for the larger system).
        let (full64, full32) = if tiled_slits {
            (None, Some(dense.transfer_f32_with(progress)?))
        } else {
            (Some(dense.transfer_with(progress)?), None)
        };
        let full_at = |ch: usize, i: usize, j: usize| -> f64 {
            match (&full64, &full32) {
                (Some(m), _) => m[ch][(i, j)],
                (_, Some(m)) => f64::from(m[ch][(i, j)]),
                _ => unreachable!("one of the two solves ran"),
            }
        };
        // R_fine per cluster pair (one visibility ray each; with `slits`, the system's own form
        // factors, so the remainder holds no first bounce), rows in parallel; with the tiled
        // slits also each row's non-zero subsurface weights.
        let ff = &dense.form_factors;
        let (fine, subsurface): (Vec<Vec<[f64; 3]>>, Vec<SubsurfaceRow>) = (0..n)
            .into_par_iter()
            .map(|i| {
                let mut weights = Vec::new();
                let row = (0..n)
                    .map(|j| {
                        let (a, b) = (&clusters[i], &clusters[j]);
                        if slits.is_none() {
                            return kernels.r_fine(a, b, i == j);
                        }
                        let s = kernels.r_subsurface(a, b, i == j);
                        if tiled_slits && s.iter().any(|&x| x != 0.0) {
                            weights.push((j as u32, s.map(|x| x as f32)));
                        }
                        [0, 1, 2].map(|c| s[c] + a.rho[c] as f64 * ff[(i, j)])
                    })
                    .collect();
                (row, weights)
            })
            .unzip();
        let subsurface = if tiled_slits { subsurface } else { Vec::new() };
        let rem = std::array::from_fn(|ch| {
            let mut v = vec![0.0f32; n * n];
            for i in 0..n {
                for j in 0..n {
                    let f = if dense.rho[j][ch] > 0.0 {
                        fine[i][j][ch]
                    } else {
                        0.0
                    };
                    v[i * n + j] = (full_at(ch, i, j) - f) as f32;
                }
            }
            v
        });
        drop(fine);
        let form_factors = if tiled_slits {
            (0..n * n).map(|k| ff[(k / n, k % n)] as f32).collect()
        } else {
            Vec::new()
        };
        let full = std::array::from_fn(|ch| {
            let mut v = vec![0.0f32; n * n];
            for i in 0..n {
                for j in 0..n {
                    v[i * n + j] = full_at(ch, i, j) as f32;
                }
            }
            v
        });
        Ok(Self {
            cluster_of,
            clusters,
            rem,
            full,
            form_factors,
            subsurface,
            block,
            alone: single.iter().filter(|&&a| a).count() as u32,
        })
    }

    /// `R_rem(i, j)` per channel for texels `i`, `j` with the sender's area `area_j_m2`.
    #[inline]
    pub fn r(&self, i: u32, j: u32, area_j_m2: f32) -> [f32; 3] {
        let n = self.clusters.len();
        let (ci, cj) = (
            self.cluster_of[i as usize] as usize,
            self.cluster_of[j as usize] as usize,
        );
        let share = area_j_m2 / self.clusters[cj].area_m2;
        let k = ci * n + cj;
        [
            self.rem[0][k] * share,
            self.rem[1][k] * share,
            self.rem[2][k] * share,
        ]
    }
}
