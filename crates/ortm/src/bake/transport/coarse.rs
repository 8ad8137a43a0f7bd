//! The coarse level of the transport: texels grouped into clusters (one per `block × block`
//! tile of the lightmap, chart and material), the dense solve over the clusters, and the smooth
//! higher-order remainder `R_rem = R − R_fine` spread back to texel pairs by area.
//!
//! A cluster's centroid and normal are the area-weighted means of its texels; its area is their
//! sum; its albedo the area-weighted mean. `R_rem(i, j) ≈ R_rem(I, J)·A_j / A_J` for texels `i ∈ I`,
//! `j ∈ J` (piecewise constant per cluster pair, proportional to the sender's area share).

use std::collections::HashMap;

use glam::Vec3;
use rayon::prelude::*;

use super::dense::DenseTransport;
use super::{Cancelled, Kernels, Patch, SetupProgress};
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
    /// Block size in texels.
    pub block: u32,
}

/// The cluster a texel belongs to: its `block × block` tile, chart and material.
fn cluster_key(t: &Texel, block: u32) -> (u32, u32, u32, u32) {
    (t.x / block, t.y / block, t.chart, t.material)
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

/// Groups texels into clusters: one per (tile of `block × block` texels, chart, material).
pub fn cluster_texels(grid: &TexelGrid, patches: &[Patch], block: u32) -> (Vec<u32>, Vec<Patch>) {
    let block = block.max(1);
    let mut ids: HashMap<(u32, u32, u32, u32), u32> = HashMap::new();
    let mut cluster_of = Vec::with_capacity(grid.texels.len());
    let mut acc: Vec<(f64, Vec3, Vec3, Vec3, Vec3, u32)> = Vec::new();
    // Per cluster: its members' count and the first member's footprint (a cluster of one
    // texel keeps it, so that at `block` = 1 the clusters' weights are the texels').
    let mut single: Vec<(u32, Option<[Vec3; 2]>)> = Vec::new();
    for (t, p) in grid.texels.iter().zip(patches) {
        let key = cluster_key(t, block);
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
                    footprint_m: if members == 1 { footprint } else { None },
                }
            },
        )
        .collect();
    (cluster_of, clusters)
}

impl Remainder {
    /// Clusters the texels, solves the cluster system densely and keeps `R − R_fine`. The
    /// clusters' subsurface weights are normalised over the clusters
    /// ([`Kernels::normalise_subsurface`]) for both, as the dense solve does.
    pub fn new(grid: &TexelGrid, patches: &[Patch], kernels: &Kernels, block: u32) -> Self {
        Self::build(grid, patches, kernels, block, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`Remainder::new`] with progress and cancellation: the clusters' form factors
    /// ([`DenseTransport::build`]) and the solve ([`DenseTransport::transfer_with`]).
    pub fn build(
        grid: &TexelGrid,
        patches: &[Patch],
        kernels: &Kernels,
        block: u32,
        progress: &SetupProgress,
    ) -> Result<Self, Cancelled> {
        let (cluster_of, mut clusters) = cluster_texels(grid, patches, block);
        kernels.normalise_subsurface_with(&mut clusters, progress)?;
        let n = clusters.len();
        let dense = DenseTransport::build(&clusters, kernels, progress)?;
        let full = dense.transfer_with(progress)?;
        // R_fine per cluster pair (one visibility ray each), rows in parallel.
        let fine: Vec<Vec<[f64; 3]>> = (0..n)
            .into_par_iter()
            .map(|i| {
                (0..n)
                    .map(|j| kernels.r_fine(&clusters[i], &clusters[j], i == j))
                    .collect()
            })
            .collect();
        let rem = std::array::from_fn(|ch| {
            let mut v = vec![0.0f32; n * n];
            for i in 0..n {
                for j in 0..n {
                    let f = if dense.rho[j][ch] > 0.0 {
                        fine[i][j][ch]
                    } else {
                        0.0
                    };
                    v[i * n + j] = (full[ch][(i, j)] - f) as f32;
                }
            }
            v
        });
        drop(fine);
        let full = std::array::from_fn(|ch| {
            let m = &full[ch];
            let mut v = vec![0.0f32; n * n];
            for i in 0..n {
                for j in 0..n {
                    v[i * n + j] = m[(i, j)] as f32;
                }
            }
            v
        });
        Ok(Self {
            cluster_of,
            clusters,
            rem,
            full,
            block,
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
