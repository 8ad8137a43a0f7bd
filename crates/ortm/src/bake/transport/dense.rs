//! Dense, exact solution of the transport system over a set of patches: the ground truth for
//! small lightmaps (every covered texel a patch, up to a few thousand) and the coarse-level
//! solver of the higher-order remainder ([`super::coarse`]).
//!
//! Per channel it forms `M = I − X F` and solves with an LU factorisation (faer, partial
//! pivoting): `B = M⁻¹ X ρ̄⁻¹ B_o` for one lighting, or the full transfer
//! `R = M⁻¹ X ρ̄⁻¹ − I` (see the [module docs](super) for the notation). Memory is `O(n²)`
//! doubles per matrix (n = 4,000 → 128 MB each); time `O(n³)`.

use faer::Mat;
use faer::linalg::solvers::{DenseSolveCore, PartialPivLu, Solve};
use glam::Vec3;
use rayon::prelude::*;

use super::{Cancelled, Kernels, Patch, SetupProgress};

/// Largest number of patches the exact dense solve is run on by the tools (`ortm solve`, the
/// viewer's and the accuracy bench's reference): memory grows as n² (three 6,000² matrices of
/// doubles are 864 MB) and time as n³.
pub const MAX_TEXELS: usize = 6000;

/// `solve(ch)` for the three channels, reporting one step each to `progress` ("transport: solve
/// (R, G, B)") and stopping between channels when it is cancelled (each channel runs whole).
fn per_channel<T>(
    progress: &SetupProgress,
    solve: impl Fn(usize) -> T,
) -> Result<[T; 3], Cancelled> {
    progress.phase("transport: solve (R, G, B)", 3);
    let mut out: [Option<T>; 3] = [None, None, None];
    for (ch, o) in out.iter_mut().enumerate() {
        progress.check()?;
        *o = Some(solve(ch));
        progress.advance(1);
    }
    Ok(out.map(|m| m.expect("every channel solved")))
}

/// The assembled transport system over `n` patches.
pub struct DenseTransport {
    /// Number of patches.
    pub n: usize,
    /// Form factors `F_ij` (with visibility), `n × n`.
    pub form_factors: Mat<f64>,
    /// The exitance operator `X`, row by row: the non-zero entries `(j, X_ij)` per channel —
    /// `(i, ρ̄_i)` alone on an opaque row, the subsurface weights `S_ij` of the patches within
    /// the profile's support on a translucent row (no `n²` matrix per channel is kept).
    pub exitance: Vec<Vec<(u32, [f64; 3])>>,
    /// Effective albedo ρ̄ per patch.
    pub rho: Vec<Vec3>,
    /// Whether each patch is translucent.
    pub translucent: Vec<bool>,
}

impl DenseTransport {
    /// Assembles the system: `n(n−1)/2` visibility rays (in parallel), plus the subsurface
    /// weights of translucent pairs, normalised over `patches` here
    /// ([`Kernels::normalise_subsurface`], whatever the patches' `subsurface_scale`), so the
    /// exact solve uses the weights of the pair evaluator ([`super::Transport`]).
    pub fn new(patches: &[Patch], kernels: &Kernels) -> Self {
        Self::build(patches, kernels, &SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`DenseTransport::new`] reporting the form factors' rows to `progress` ("transport:
    /// form factors", one step per pair) and stopping between rows when it is cancelled.
    pub fn build(
        patches: &[Patch],
        kernels: &Kernels,
        progress: &SetupProgress,
    ) -> Result<Self, Cancelled> {
        let mut patches = patches.to_vec();
        kernels.normalise_subsurface_with(&mut patches, progress)?;
        let patches = &patches[..];
        let n = patches.len();
        progress.phase(
            "transport: form factors",
            (n as u64) * (n as u64).saturating_sub(1) / 2,
        );
        // c_ij = F_ij / A_j and c_ji for every pair i < j (one visibility ray each), in rows
        // of the upper triangle computed in parallel.
        let rows: Vec<Vec<(f32, f32)>> = (0..n)
            .into_par_iter()
            .map(|i| {
                if progress.check().is_err() {
                    return Vec::new();
                }
                let row = (i + 1..n)
                    .map(|j| kernels.form_factor_pair(&patches[i], &patches[j]))
                    .collect();
                progress.advance((n - i - 1) as u64);
                row
            })
            .collect();
        progress.check()?;
        let c = |i: usize, j: usize| -> f64 {
            match i.cmp(&j) {
                std::cmp::Ordering::Less => rows[i][j - i - 1].0 as f64,
                std::cmp::Ordering::Greater => rows[j][i - j - 1].1 as f64,
                std::cmp::Ordering::Equal => 0.0,
            }
        };
        let form_factors = Mat::from_fn(n, n, |i, j| c(i, j) * patches[j].area_m2 as f64);
        let translucent: Vec<bool> = patches
            .iter()
            .map(|p| kernels.is_translucent(p.material))
            .collect();
        let exitance: Vec<Vec<(u32, [f64; 3])>> = (0..n)
            .into_par_iter()
            .map(|i| {
                if !translucent[i] {
                    return vec![(i as u32, patches[i].rho.to_array().map(f64::from))];
                }
                (0..n)
                    .filter_map(|j| {
                        let s = kernels.subsurface(&patches[i], &patches[j], i == j)?;
                        (s != [0.0; 3]).then_some((j as u32, s))
                    })
                    .collect()
            })
            .collect();
        Ok(Self {
            n,
            form_factors,
            exitance,
            rho: patches.iter().map(|p| p.rho).collect(),
            translucent,
        })
    }

    fn inv_rho(&self, j: usize, ch: usize) -> f64 {
        let r = self.rho[j][ch] as f64;
        if r > 0.0 { 1.0 / r } else { 0.0 }
    }

    /// `M = I − X F` for channel `ch`: rows scaled by `ρ̄` where `X` is diagonal (no translucent
    /// patch), else the sparse rows of `X` times `F` ([`sparse_times_dense`]).
    fn system(&self, ch: usize) -> Mat<f64> {
        let n = self.n;
        let mut m = if self.translucent.iter().any(|&t| t) {
            sparse_times_dense(&self.exitance, ch, &self.form_factors)
        } else {
            Mat::from_fn(n, n, |i, j| {
                exitance_times(&self.exitance[i], ch, |k| self.form_factors[(k, j)])
            })
        };
        // `X F` into `I − X F` in place.
        for j in 0..n {
            let col = m.col_as_slice_mut(j);
            for v in col.iter_mut() {
                *v = 0.0 - *v;
            }
            col[j] += 1.0;
        }
        m
    }

    /// `X` for channel `ch` as a dense matrix, column `j` scaled by `scale(j)`.
    fn exitance_dense(&self, ch: usize, scale: impl Fn(usize) -> f64) -> Mat<f64> {
        let mut x = Mat::<f64>::zeros(self.n, self.n);
        for (i, row) in self.exitance.iter().enumerate() {
            for &(j, v) in row {
                x[(i, j as usize)] = v[ch] * scale(j as usize);
            }
        }
        x
    }

    /// Exact final radiosity `B` (W/m²) for the first-order radiosity `b_o` (W/m², one per patch).
    /// Factorises the system on every call; for many lightings one after another (the viewer)
    /// keep a [`DenseTransport::factor`].
    pub fn solve(&self, b_o: &[Vec3]) -> Vec<Vec3> {
        self.factor().solve(b_o)
    }

    /// The LU factorisation of the system per channel, `O(n³)` once; each
    /// [`FactoredTransport::solve`] after it is `O(n²)`.
    pub fn factor(&self) -> FactoredTransport {
        FactoredTransport {
            n: self.n,
            inv_rho: (0..self.n)
                .map(|j| std::array::from_fn(|ch| self.inv_rho(j, ch)))
                .collect(),
            exitance: self.exitance.clone(),
            channels: std::array::from_fn(|ch| self.system(ch).partial_piv_lu()),
        }
    }

    /// Exact final radiosity for several first-order lightings at once (one LU per channel).
    pub fn solve_many(&self, b_os: &[Vec<Vec3>]) -> Vec<Vec<Vec3>> {
        let k = b_os.len();
        let mut out = vec![vec![Vec3::ZERO; self.n]; k];
        for ch in 0..3 {
            let rhs = Mat::from_fn(self.n, k, |i, c| {
                exitance_times(&self.exitance[i], ch, |j| {
                    b_os[c][j][ch] as f64 * self.inv_rho(j, ch)
                })
            });
            let b = self.system(ch).partial_piv_lu().solve(&rhs);
            for (c, o) in out.iter_mut().enumerate() {
                for i in 0..self.n {
                    o[i][ch] = b[(i, c)] as f32;
                }
            }
        }
        out
    }

    /// The full transfer `R = M⁻¹ X ρ̄⁻¹ − I` per channel (`R[(i, j)]` = fraction of `B_o(j)`
    /// added to `B(i)`); columns of black patches (ρ̄ = 0, never lit) are zero.
    pub fn transfer(&self) -> [Mat<f64>; 3] {
        self.transfer_with(&SetupProgress::none())
            .unwrap_or_else(|_| unreachable!("never cancelled"))
    }

    /// [`DenseTransport::transfer`] reporting one step per channel to `progress` ("transport:
    /// solve") and stopping between channels when it is cancelled (each channel's
    /// factorisation and solve, `O(n³)`, runs whole).
    pub fn transfer_with(&self, progress: &SetupProgress) -> Result<[Mat<f64>; 3], Cancelled> {
        per_channel(progress, |ch| self.transfer_channel(ch))
    }

    /// [`DenseTransport::transfer_with`] stored in single precision: each channel solved in f64
    /// and rounded, so the three matrices take half the memory. For the coarse remainder of
    /// many clusters ([`super::coarse`]), an approximation by area already.
    pub fn transfer_f32_with(&self, progress: &SetupProgress) -> Result<[Mat<f32>; 3], Cancelled> {
        per_channel(progress, |ch| self.transfer_channel_f32(ch))
    }

    /// The full transfer of channel `ch` in f32 ([`DenseTransport::transfer_f32_with`]),
    /// solved in f64 and rounded: solved in f32, the triangular solves' products of small
    /// couplings fall into subnormal numbers, whose arithmetic made the head's 256² remainder
    /// (5,084 clusters) 4× slower than in f64 (README, "Slits in the remainder").
    fn transfer_channel_f32(&self, ch: usize) -> Mat<f32> {
        let r = self.transfer_channel(ch);
        Mat::from_fn(self.n, self.n, |i, j| r[(i, j)] as f32)
    }

    /// The full transfer of channel `ch` ([`DenseTransport::transfer`]).
    fn transfer_channel(&self, ch: usize) -> Mat<f64> {
        let lu = self.system(ch).partial_piv_lu();
        let mut r = if self.translucent.iter().any(|&t| t) {
            lu.solve(self.exitance_dense(ch, |j| self.inv_rho(j, ch)))
        } else {
            // `X ρ̄⁻¹` is diagonal: `M⁻¹` (faster than the solve against it) times each
            // column's `ρ̄_j / ρ̄_j` (1, or 0 for black patches).
            let mut r = lu.inverse();
            for (j, row) in self.exitance.iter().enumerate() {
                let d = row
                    .first()
                    .map_or(0.0, |&(_, x)| x[ch] * self.inv_rho(j, ch));
                for v in r.col_as_slice_mut(j) {
                    *v *= d;
                }
            }
            r
        };
        self.less_identity(ch, &mut r);
        r
    }

    /// `R = (M⁻¹ X ρ̄⁻¹) − I` from the solve `r`, in place; the columns of black patches
    /// (ρ̄ = 0, never lit) are set to zero.
    fn less_identity(&self, ch: usize, r: &mut Mat<f64>) {
        for j in 0..self.n {
            if self.inv_rho(j, ch) == 0.0 {
                r.col_as_slice_mut(j).fill(0.0);
            } else {
                r[(j, j)] -= 1.0;
            }
        }
    }

    /// Row sums `Σ_j F_ij` (1 inside a closed environment; less where light escapes).
    pub fn form_factor_row_sums(&self) -> Vec<f64> {
        (0..self.n)
            .map(|i| (0..self.n).map(|j| self.form_factors[(i, j)]).sum())
            .collect()
    }

    /// Column sums `Σ_j A_j F_ji / A_i` over `patches` (those this transport was built from):
    /// the fraction of patch `i`'s radiosity power that the other patches receive — 1 inside a
    /// closed environment, less where light escapes. Equal to the row sums only for a
    /// reciprocal kernel, which collocated texels are not ([`super::form_factor`]).
    pub fn form_factor_column_sums(&self, patches: &[Patch]) -> Vec<f64> {
        (0..self.n)
            .map(|i| {
                (0..self.n)
                    .map(|j| patches[j].area_m2 as f64 * self.form_factors[(j, i)])
                    .sum::<f64>()
                    / patches[i].area_m2 as f64
            })
            .collect()
    }
}

/// Columns of `F` per block of [`sparse_times_dense`]: a row's sums are four AVX-512 registers
/// of `f64`, and the block's copy of `F` (`n × 32` doubles, 1.3 MB at n = 5,084) stays in a
/// 2 MB L2 cache. (8 columns: the same within the timing noise.)
const PRODUCT_BLOCK: usize = 32;

/// `X F` for channel `ch` of the sparse rows `x` (row `i`: its non-zero entries `(k, X_ik)`) and
/// the dense `f` (`n × n`): `nnz(X) · n` multiply-adds instead of the dense product's `n³`. On
/// the head's 256² remainder (5,084 clusters, 203 non-zero weights per row) the coarse solve's
/// three channels take 14.7–15.2 s instead of 18.9 s. Blocks of [`PRODUCT_BLOCK`] columns in
/// parallel; each block's columns of `F` are copied row-major first, so a row's entries read
/// `PRODUCT_BLOCK` adjacent values per entry. The sums run in the order of each row's entries
/// (not faer's blocked order: results equal the dense product's to rounding; the head's 256²
/// bake is byte-identical).
fn sparse_times_dense(x: &[Vec<(u32, [f64; 3])>], ch: usize, f: &Mat<f64>) -> Mat<f64> {
    let n = f.nrows();
    let cols = f.ncols();
    if n == 0 {
        return Mat::zeros(0, cols);
    }
    let mut out = vec![0.0f64; n * cols];
    out.par_chunks_mut(n * PRODUCT_BLOCK)
        .enumerate()
        .for_each(|(b, chunk)| {
            let c0 = b * PRODUCT_BLOCK;
            let width = chunk.len() / n;
            let mut block = vec![[0.0f64; PRODUCT_BLOCK]; n];
            for (l, col) in (c0..c0 + width).enumerate() {
                for (k, v) in f.col_as_slice(col).iter().enumerate() {
                    block[k][l] = *v;
                }
            }
            for (i, row) in x.iter().enumerate() {
                let mut acc = [0.0f64; PRODUCT_BLOCK];
                for &(k, w) in row {
                    let w = w[ch];
                    for (a, v) in acc.iter_mut().zip(&block[k as usize]) {
                        *a += w * v;
                    }
                }
                for (l, a) in acc[..width].iter().enumerate() {
                    chunk[l * n + i] = *a;
                }
            }
        });
    Mat::from_fn(n, cols, |i, j| out[j * n + i])
}

/// `(X v)_i` for channel `ch` from row `i` of `X` (its non-zero entries `(j, X_ij)`).
fn exitance_times(row: &[(u32, [f64; 3])], ch: usize, v: impl Fn(usize) -> f64) -> f64 {
    row.iter().map(|&(j, x)| x[ch] * v(j as usize)).sum()
}

/// The transport system of a [`DenseTransport`] factorised once ([`DenseTransport::factor`]):
/// solves for any first-order lighting in `O(n²)`.
pub struct FactoredTransport {
    n: usize,
    inv_rho: Vec<[f64; 3]>,
    /// The sparse rows of `X` ([`DenseTransport::exitance`]).
    exitance: Vec<Vec<(u32, [f64; 3])>>,
    channels: [PartialPivLu<f64>; 3],
}

impl FactoredTransport {
    /// Exact final radiosity `B` (W/m²) for the first-order radiosity `b_o` (W/m², one per
    /// patch), as [`DenseTransport::solve`].
    pub fn solve(&self, b_o: &[Vec3]) -> Vec<Vec3> {
        self.solve_with_source(b_o, None)
    }

    /// [`FactoredTransport::solve`] with radiosity `source` (W/m², one per patch) emitted by
    /// the patches beside their first scattering of `b_o`: `B = M⁻¹ (X ρ̄⁻¹ B_o + source)`, so
    /// the source is in `B` and so are all its bounces (`B = X (E_d + F B) + source`). The
    /// subsurface near field ([`crate::bake::near_field`]) is such a source.
    pub fn solve_with_source(&self, b_o: &[Vec3], source: Option<&[Vec3]>) -> Vec<Vec3> {
        assert_eq!(b_o.len(), self.n, "one first-order value per patch");
        if let Some(s) = source {
            assert_eq!(s.len(), self.n, "one source value per patch");
        }
        let mut out = vec![Vec3::ZERO; self.n];
        for (ch, lu) in self.channels.iter().enumerate() {
            let mut rhs = Mat::from_fn(self.n, 1, |i, _| {
                exitance_times(&self.exitance[i], ch, |j| {
                    b_o[j][ch] as f64 * self.inv_rho[j][ch]
                })
            });
            if let Some(s) = source {
                for (i, v) in s.iter().enumerate() {
                    rhs[(i, 0)] += v[ch] as f64;
                }
            }
            let b = lu.solve(&rhs);
            for (i, o) in out.iter_mut().enumerate() {
                o[ch] = b[(i, 0)] as f32;
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use super::*;
    use crate::bake::raycast::Visibility;
    use crate::bake::transport::Effects;

    /// The sparse product equals faer's dense one, for a size that is not a multiple of the
    /// column block and rows with no entry, one entry and many.
    #[test]
    fn sparse_times_dense_equals_the_dense_product() {
        let n = 21;
        let f = Mat::from_fn(n, n, |i, j| ((i * 7 + j * 13) % 17) as f64 / 17.0 - 0.4);
        let x: Vec<Vec<(u32, [f64; 3])>> = (0..n)
            .map(|i| {
                (0..n)
                    .filter(|j| i % 5 != 0 && (i * j + i) % (i % 4 + 2) == 0)
                    .map(|j| (j as u32, [0.1 * i as f64 - j as f64, 0.5, -(j as f64)]))
                    .collect()
            })
            .collect();
        assert!(x.iter().any(Vec::is_empty) && x.iter().any(|r| r.len() > 5));
        for ch in 0..3 {
            let dense = Mat::from_fn(n, n, |i, k| {
                x[i].iter()
                    .find(|e| e.0 as usize == k)
                    .map_or(0.0, |e| e.1[ch])
            });
            let want = &dense * &f;
            let got = sparse_times_dense(&x, ch, &f);
            for i in 0..n {
                for j in 0..n {
                    let (a, b) = (got[(i, j)], want[(i, j)]);
                    assert!(
                        (a - b).abs() <= 1e-12 * b.abs().max(1.0),
                        "({i}, {j}): {a} vs {b}"
                    );
                }
            }
        }
    }

    /// Two facing squares: the factorised solve equals the 2×2 closed form
    /// `B = (I − ρF)⁻¹ B_o` and the multi-lighting solve, for several lightings.
    #[test]
    fn factored_solve_matches_the_closed_form_of_two_facing_patches() {
        let patch = |z: f32, n: Vec3, rho: Vec3| Patch {
            position_m: Vec3::new(0.0, 0.0, z),
            normal: n,
            lift_normal: n,
            area_m2: 0.04,
            rho,
            material: 0,
            subsurface_scale: Vec3::ONE,
            subsurface_gather: Vec3::ONE,
            footprint_m: None,
        };
        let patches = [
            patch(0.0, Vec3::Z, Vec3::new(0.8, 0.5, 0.2)),
            patch(0.3, -Vec3::Z, Vec3::new(0.6, 0.7, 0.9)),
        ];
        let kernels = Kernels::from_parts(
            Effects::default(),
            vec![None],
            Arc::new(Visibility::from_triangles(Vec::new())),
        );
        let dense = DenseTransport::new(&patches, &kernels);
        let (f01, f10) = (dense.form_factors[(0, 1)], dense.form_factors[(1, 0)]);
        assert!(
            f01 > 0.05 && f10 > 0.05,
            "the squares see each other: {f01} {f10}"
        );
        let factored = dense.factor();
        let lightings = vec![
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::ZERO],
            vec![Vec3::ZERO, Vec3::new(0.5, 0.25, 4.0)],
            vec![Vec3::ONE, Vec3::ONE],
        ];
        let many = dense.solve_many(&lightings);
        for (b_o, b_many) in lightings.iter().zip(&many) {
            let b = factored.solve(b_o);
            for ch in 0..3 {
                let (r0, r1) = (patches[0].rho[ch] as f64, patches[1].rho[ch] as f64);
                let (a, c) = (r0 * f01, r1 * f10);
                let det = 1.0 - a * c;
                let (o0, o1) = (b_o[0][ch] as f64, b_o[1][ch] as f64);
                let want = [(o0 + a * o1) / det, (o1 + c * o0) / det];
                for i in 0..2 {
                    assert!((b[i][ch] as f64 - want[i]).abs() <= 1e-6 * want[i].max(1.0));
                    assert!((b[i][ch] - b_many[i][ch]).abs() <= 1e-6 * b_many[i][ch].max(1.0));
                }
            }
        }
    }
}
