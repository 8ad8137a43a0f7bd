//! The subsurface near field at sub-texel resolution: a correction `δ` (W/m², per texel and
//! channel) to the first scattering of the direct light, so that each translucent texel's
//! nearby senders scatter the direct light *across* their footprint, not the light at their
//! centre. A solve takes `δ` as a radiosity source beside that first scattering,
//! `B = X (E_d + F B) + δ` ([`crate::bake::transport::dense::FactoredTransport::solve_with_source`],
//! [`crate::bake::transport::hier::Operator::solve_with_source`]), so its later bounces are
//! solved too. The bake's maps hold the part of it a renderer without sub-texel light can:
//! [`near_rows`] gives each skin receiver's window the sub-texels' weights, which its rows take
//! in place of the transport's first scattering (`ortm bake --near-field N`), as [`correction`]
//! with [`SubTexelLight::Input`] adds it to a solve.
//!
//! # Why
//! The transport ([`crate::bake::transport`]) holds the direct irradiance constant over each
//! sender texel: `B_i = Σ_j S_ij E_j`. Skin's profile falls by `e` within 0.7 mm (blue) to
//! 3.7 mm (red), while a texel of the head is 1.8 mm at 256² and 7 mm at 64², so wherever a
//! shadow edge or a terminator crosses the texels around a receiver, what reaches the receiver
//! depends on where within those texels the light falls. On the head at 64² such texels carry
//! 95 % of the squared error of the subsurface-only exact solve against the path-traced
//! reference (README, "The subsurface near field"). The flat footprints of a coarse texel also
//! fold over one another in creases (eyelids, lips), where [`Kernels::normalise_subsurface`]
//! must cap them; sub-texels follow the surface more closely.
//!
//! # Method
//! The scene is rasterised at `n ×` the lightmap's size (`n` odd, so a texel's centre is its
//! middle sub-texel's) and lit there ([`lighting::irradiance`]: point-sampled, ray-cast
//! shadows). For every translucent receiver `i` and every texel `j` of its material within
//! `reach` texels of it in the lightmap (a square window: the senders that matter most share
//! `i`'s chart),
//!
//! ```text
//! δ_i += Σ_{s ∈ j} S(x_i, P_s) · E_s − S_ij · E_in,j
//! ```
//!
//! with `s` running over the sub-texels of `j`'s square on `j`'s chart (a sub-texel of another
//! chart in the square, at a chart's border, stands for other surface and is left out),
//! `S(x_i, P_s)` the profile integrated over sub-texel `s`'s footprint
//! ([`Kernels::subsurface_raw`], polar for near pairs), `E_s` the sub-texel's direct
//! irradiance, `S_ij` the pair's weight in the transport and `E_in,j = input_j / ρ̄_j` the
//! irradiance the transport was given (the centre's, or the mean over the texel:
//! [`lighting::first_order_and_input`]). So `δ`
//! replaces, pair by pair, the transport's first scattering of the direct light by the finer
//! one; where the light is uniform over `j` the two agree up to the quadrature (on a plane
//! `|δ|` is 4·10⁻⁶ of the value, tested), and `δ = 0` for opaque receivers. Across a hard
//! shadow edge on a plane of skin with 2.5 mm texels, the first scattering at texel
//! resolution is 6.1 % (relative RMSE) off the profile integrated over the lit surface by
//! brute force, 2.1 % with `n = 3` and 0.47 % with `n = 7` (tested).
//!
//! The sub-texels' weights are not capped: the coarse texels' caps ([`Patch::subsurface_scale`],
//! which `S_ij` carries) stand for their flat footprints folding over one another in a crease,
//! which the sub-texels' smaller footprints mostly do not (on the head at 64² a trial build
//! with the coarse caps on the sub-texels was further from the reference than the texels
//! alone were at 3 × 3 reach, and one with caps normalised at `n ×` the size was no nearer than
//! none).
//!
//! The window's reach (`ortm solve --near-field-reach R`), on the head against the path-traced
//! reference (subsurface only, `n = 3`, centres' input; README, "The subsurface near field"):
//! at 64² the texel alone (`R = 0`) 4.86 % (total), its 3 × 3 neighbourhood 2.77 %, 5 × 5 (the
//! default) 2.64 %; at 256² 2.38 %, 1.81 % and 1.76 %.
//!
//! Much of what `δ` changes on the head is the weights rather than where the light falls: on
//! lit skin away from shadow edges the indirect light is a percent or two of the first order,
//! so a weight 0.1 % off moves it by a tenth or more, and the sub-texels' unnormalised weights are nearer the path-traced
//! reference than the capped or balanced texel weights. With the senders' own input on their
//! sub-texels ([`SubTexelLight::Input`]) the head's 256² solve goes from 18.2 % to 13.7 %
//! (indirect, against an 8,192-path reference), with the sub-texels' own light to 12.4 %
//! (README, "The subsurface near field").
//!
//! What `δ` leaves out: senders beyond the window or across a UV seam (still at texel
//! resolution in the transport); shadow edges within a sub-texel (the error falls as the
//! sub-texels shrink). Its later bounces, which the source carries, change little on the head
//! (against the path-traced reference at 256², `n = 3`, 15.71 % → 15.67 % indirect; at 64²
//! 28.6 % → 29.1 %: README, "The subsurface near field").
//! Distances in metres, irradiance and `δ` in W/m².

use glam::Vec3;
use rayon::prelude::*;
use thiserror::Error;

use crate::bake::lighting;
use crate::bake::raycast::Visibility;
use crate::bake::texels::{TexelError, TexelGrid};
use crate::bake::transport::{Cancelled, Kernels, Patch, SetupProgress, texel_patches};
use crate::scene::{Light, Scene};

/// The largest reach (senders within this many texels in x and in y).
pub const MAX_REACH: u32 = 8;

/// Sub-texels per texel side at most (the sub-texel grid holds `n²` times the texels).
pub const MAX_SUBDIVISION: u32 = 7;

/// Bytes each covered sub-texel takes while the correction runs: its texel (96 bytes), its
/// patch (~70) and its irradiance (12), rounded up (measured on the head at 256², `n = 3`:
/// 0.58 → 0.66 GiB resident for 540 k sub-texels).
pub const BYTES_PER_SUB_TEXEL: u64 = 200;

/// Memory the correction needs for `grid` at `n` sub-texels per side, bytes: its covered
/// sub-texels ([`BYTES_PER_SUB_TEXEL`] each; about `n²` times the covered texels) and the
/// sub-texel grid's slot map (4 bytes per sub-texel of the `n·W × n·H` grid).
pub fn memory_bytes(grid: &TexelGrid, n: u32) -> u64 {
    let n2 = (n as u64).pow(2);
    n2 * (grid.texels.len() as u64 * BYTES_PER_SUB_TEXEL
        + grid.width as u64 * grid.height as u64 * 4)
}

/// Why the near field could not be computed.
#[derive(Debug, Error)]
pub enum NearFieldError {
    /// The sub-texel grid could not be rasterised.
    #[error(transparent)]
    Texels(#[from] TexelError),
    /// The progress' cancel flag was raised.
    #[error("cancelled")]
    Cancelled,
}

impl From<Cancelled> for NearFieldError {
    fn from(_: Cancelled) -> Self {
        Self::Cancelled
    }
}

/// How finely the near field is resolved.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct NearField {
    /// Sub-texels per texel side (odd, 3 to [`MAX_SUBDIVISION`]).
    pub subdivision: u32,
    /// Senders within this many texels of the receiver in x and in y.
    pub reach: u32,
    /// The light a sender's sub-texels scatter ([`correction`]).
    pub light: SubTexelLight,
}

/// The direct light on a sender's sub-texels in [`correction`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SubTexelLight {
    /// Each sub-texel's own (the scene lit at `n ×` the lightmap's size).
    #[default]
    SubTexels,
    /// The sender's light as the transport's input holds it (`input_j / ρ̄_j`: its mean over
    /// the texel with an averaged input, its centre's otherwise) on all its sub-texels: only
    /// the weights are resolved. What the bake's maps hold with `ortm bake --near-field`
    /// ([`near_rows`]), whose renderer has no sub-texel light.
    Input,
}

impl NearField {
    /// `subdivision` sub-texels per side and a reach of 2 texels (5 × 5 senders): at 256² on
    /// the head that covers red's profile to 4 mm on each side, where it has fallen by `e`
    /// (blue and green are negligible well within it).
    pub fn new(subdivision: u32) -> Self {
        Self {
            subdivision,
            reach: 2,
            light: SubTexelLight::SubTexels,
        }
    }

    /// The near field `--near-field n [--near-field-reach reach]` asks for, scattering `light`,
    /// checked ([`NearField::check`]); the error names the flag at fault and how to turn the
    /// near field off (`--near-field 1`).
    pub fn from_flags(n: u32, reach: Option<u32>, light: SubTexelLight) -> Result<Self, String> {
        let defaults = Self::new(n);
        let near = Self {
            reach: reach.unwrap_or(defaults.reach),
            light,
            ..defaults
        };
        near.check().map(|_| near).map_err(|e| {
            if (Self { reach: 0, ..near }).check().is_ok() {
                format!("--near-field-reach {}: {e}", near.reach)
            } else {
                format!("--near-field {n}: {e}; 1 turns it off")
            }
        })
    }

    /// `Err` naming the need and the fix when this near field's sub-texels for `grid`
    /// ([`memory_bytes`]) take more than `limit / divisor` bytes (`share` says that fraction in
    /// words, e.g. "half"); `Ok` without a limit.
    pub fn check_memory(
        &self,
        grid: &TexelGrid,
        limit: Option<u64>,
        (divisor, share): (u64, &str),
    ) -> Result<(), String> {
        let need = memory_bytes(grid, self.subdivision);
        match limit.filter(|&l| need > l / divisor) {
            None => Ok(()),
            Some(limit) => {
                let mb = |b: u64| b as f64 / 1e6;
                Err(format!(
                    "--near-field {n}: its {n}×{n} sub-texels of {} covered texels need about \
                     {:.1} MB, more than {share} the memory limit ({:.1} MB: physical memory or \
                     ORTM_MEMORY_LIMIT_BYTES); give a smaller N or a smaller --size",
                    grid.texels.len(),
                    mb(need),
                    mb(limit),
                    n = self.subdivision,
                ))
            }
        }
    }

    /// `Err` with the rule when `subdivision` is even, below 3 or above [`MAX_SUBDIVISION`], or
    /// `reach` above [`MAX_REACH`].
    pub fn check(&self) -> Result<(), String> {
        let n = self.subdivision;
        if n < 3 || n.is_multiple_of(2) || n > MAX_SUBDIVISION {
            return Err(format!(
                "{n} sub-texels per side: give an odd number from 3 to {MAX_SUBDIVISION} (the \
                 texel's centre is then its middle sub-texel's)"
            ));
        }
        if self.reach > MAX_REACH {
            return Err(format!(
                "a reach of {} texels: give 0 to {MAX_REACH} (the cost grows as (2R + 1)²)",
                self.reach
            ));
        }
        Ok(())
    }
}

/// The correction `δ` (W/m², in `grid`'s texel order) of the module docs for `scene` (whose
/// rasterisation `grid` is) lit by `lights`, given the transport's `kernels` and the input
/// `input` (first-order radiosity per texel, W/m²) the solve was given. Reports the phase
/// "near field" to `progress` and stops when it is cancelled.
///
/// # Panics
/// When `near` fails [`NearField::check`] or `input` is not one value per texel.
#[allow(
    clippy::too_many_arguments,
    reason = "the scene, its grid, kernels, lights and visibility, the solve's input, the settings and the progress are each needed"
)]
pub fn correction(
    scene: &Scene,
    grid: &TexelGrid,
    kernels: &Kernels,
    lights: &[Light],
    vis: &Visibility,
    input: &[Vec3],
    near: NearField,
    progress: &SetupProgress,
) -> Result<Vec<Vec3>, NearFieldError> {
    if let Err(e) = near.check() {
        panic!("near_field::correction: {e}");
    }
    assert_eq!(input.len(), grid.texels.len(), "one input per texel");
    let mut patches = texel_patches(grid);
    if !patches.iter().any(|p| kernels.is_translucent(p.material)) {
        return Ok(vec![Vec3::ZERO; patches.len()]);
    }
    kernels.normalise_subsurface_with(&mut patches, progress)?;
    let n = near.subdivision;
    let fine = TexelGrid::build_with_size(scene, grid.width * n, grid.height * n)?;
    let fine_patches: Vec<Patch> = texel_patches(&fine);
    let e_fine = lighting::irradiance(&fine, lights, vis);
    let children = sub_texels(grid, &fine, n);
    let total = grid.texels.len();
    progress.phase("near field", total as u64);
    let reach = near.reach as i32;
    let middle = (n / 2) as i32;
    let delta = (0..total)
        .into_par_iter()
        .map(|i| {
            if i % 1024 == 0 {
                progress.advance(1024.min(total - i) as u64);
            }
            let a = &patches[i];
            if !kernels.is_translucent(a.material) || progress.check().is_err() {
                return Vec3::ZERO;
            }
            let ti = &grid.texels[i];
            let centre = fine.at(
                ti.x as i32 * n as i32 + middle,
                ti.y as i32 * n as i32 + middle,
            );
            let mut d = [0.0f64; 3];
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let Some(j) = grid.at(ti.x as i32 + dx, ti.y as i32 + dy) else {
                        continue;
                    };
                    let b = &patches[j as usize];
                    let Some(s_ij) = kernels.subsurface(a, b, i == j as usize) else {
                        continue;
                    };
                    let e_in: [f64; 3] = std::array::from_fn(|c| {
                        let rho = b.rho[c] as f64;
                        if rho > 0.0 {
                            input[j as usize][c] as f64 / rho
                        } else {
                            0.0
                        }
                    });
                    let mut fine_sum = [0.0f64; 3];
                    for &s in &children[j as usize] {
                        let self_pair = Some(s) == centre;
                        let Some(w) =
                            kernels.subsurface_raw(a, &fine_patches[s as usize], self_pair)
                        else {
                            continue;
                        };
                        let e = match near.light {
                            SubTexelLight::SubTexels => e_fine[s as usize].as_dvec3().to_array(),
                            SubTexelLight::Input => e_in,
                        };
                        for c in 0..3 {
                            fine_sum[c] += w[c] * e[c];
                        }
                    }
                    for c in 0..3 {
                        d[c] += fine_sum[c] - s_ij[c] * e_in[c];
                    }
                }
            }
            Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32)
        })
        .collect();
    progress.check()?;
    Ok(delta)
}

/// The near field's weights as rows of the bake's maps ([`near_rows`]): per receiving texel,
/// the senders of its window and, per channel, what multiplies each sender's transfer input
/// (first-order radiosity, W/m²) in the receiver's row.
#[derive(Clone, Debug, Default)]
pub struct NearRows {
    /// Senders within this many texels of the receiver in x and in y (the window).
    pub reach: u32,
    /// Column and row of every texel of the grid (to tell the window's senders).
    pub texel_xy: Vec<[u32; 2]>,
    /// Per receiver (grid texel order; empty for opaque receivers and those not asked for):
    /// `(j, W_ij / ρ̄_j)` for every sender `j` of its material in its window, `W_ij` the
    /// profile integrated over `j`'s sub-texels, not normalised (dimensionless).
    pub rows: Vec<Vec<(u32, [f32; 3])>>,
}

impl NearRows {
    /// True when texel `j` lies in receiver `i`'s window (the senders whose first scattering
    /// the rows replace).
    #[inline]
    pub fn in_window(&self, i: usize, j: usize) -> bool {
        let ([xi, yi], [xj, yj]) = (self.texel_xy[i], self.texel_xy[j]);
        xi.abs_diff(xj) <= self.reach && yi.abs_diff(yj) <= self.reach
    }
}

/// The near field's weights for the bake's rows, for the receivers `receivers` (texel indices):
/// every translucent receiver's senders of its material within `near.reach` texels, each with
/// the profile integrated over its `near.subdivision²` sub-texels from the receiver's centre
/// (as [`correction`] integrates them), divided by the sender's albedo. A row built with them
/// ([`crate::bake::multires::hierarchical_row_with`]) takes these in place of its transport's
/// first scattering from those senders, so that the maps scatter the renderer's input as
/// [`correction`] with [`SubTexelLight::Input`] does (less the later bounces of that change,
/// which the solve carries and the maps do not). Reports the phase "near field" and stops when
/// cancelled.
///
/// # Panics
/// When `near` fails [`NearField::check`].
pub fn near_rows(
    scene: &Scene,
    grid: &TexelGrid,
    kernels: &Kernels,
    near: NearField,
    receivers: std::ops::Range<u32>,
    progress: &SetupProgress,
) -> Result<NearRows, NearFieldError> {
    if let Err(e) = near.check() {
        panic!("near_field::near_rows: {e}");
    }
    let patches = texel_patches(grid);
    let texel_xy = grid.texels.iter().map(|t| [t.x, t.y]).collect();
    let mut rows = vec![Vec::new(); grid.texels.len()];
    let translucent = |i: usize| kernels.is_translucent(patches[i].material);
    if !(receivers.start as usize..receivers.end as usize).any(translucent) {
        return Ok(NearRows {
            reach: near.reach,
            texel_xy,
            rows,
        });
    }
    let n = near.subdivision;
    let fine = TexelGrid::build_with_size(scene, grid.width * n, grid.height * n)?;
    let fine_patches: Vec<Patch> = texel_patches(&fine);
    let children = sub_texels(grid, &fine, n);
    let total = receivers.len();
    progress.phase("near field", total as u64);
    let reach = near.reach as i32;
    let middle = (n / 2) as i32;
    let first = receivers.start as usize;
    let computed: Vec<Vec<(u32, [f32; 3])>> = receivers
        .into_par_iter()
        .map(|i| {
            let i = i as usize;
            if (i - first).is_multiple_of(1024) {
                progress.advance(1024.min(total - (i - first)) as u64);
            }
            let a = &patches[i];
            if !kernels.is_translucent(a.material) || progress.check().is_err() {
                return Vec::new();
            }
            let ti = &grid.texels[i];
            let centre = fine.at(
                ti.x as i32 * n as i32 + middle,
                ti.y as i32 * n as i32 + middle,
            );
            let mut row = Vec::new();
            for dy in -reach..=reach {
                for dx in -reach..=reach {
                    let Some(j) = grid.at(ti.x as i32 + dx, ti.y as i32 + dy) else {
                        continue;
                    };
                    let b = &patches[j as usize];
                    if b.material != a.material {
                        continue;
                    }
                    let mut w = [0.0f64; 3];
                    for &s in &children[j as usize] {
                        let self_pair = Some(s) == centre;
                        if let Some(ws) =
                            kernels.subsurface_raw(a, &fine_patches[s as usize], self_pair)
                        {
                            for c in 0..3 {
                                w[c] += ws[c];
                            }
                        }
                    }
                    let per_input = std::array::from_fn(|c| {
                        let rho = b.rho[c] as f64;
                        if rho > 0.0 { (w[c] / rho) as f32 } else { 0.0 }
                    });
                    row.push((j, per_input));
                }
            }
            row.sort_unstable_by_key(|e| e.0);
            row
        })
        .collect();
    progress.check()?;
    for (row, i) in computed.into_iter().zip(first..) {
        rows[i] = row;
    }
    Ok(NearRows {
        reach: near.reach,
        texel_xy,
        rows,
    })
}

/// The sub-texels of every covered texel of `grid` in `fine` (`n×` its size): those below it
/// in the same chart, indices into `fine`'s texels.
pub fn sub_texels(grid: &TexelGrid, fine: &TexelGrid, n: u32) -> Vec<Vec<u32>> {
    let mut children: Vec<Vec<u32>> = vec![Vec::new(); grid.texels.len()];
    for (s, t) in fine.texels.iter().enumerate() {
        if let Some(j) = grid.at((t.x / n) as i32, (t.y / n) as i32)
            && grid.texels[j as usize].chart == t.chart
        {
            children[j as usize].push(s as u32);
        }
    }
    children
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use glam::Vec2;

    use super::*;
    use crate::bake::transport::Effects;
    use crate::scene::{Albedo, Material, Mesh, MeshTriangle, Subsurface, SubsurfaceModel};

    /// Side of the test plane, metres: more than twice skin's dipole support (18.8 mm) beyond
    /// the receivers measured.
    const SIDE_M: f32 = 0.08;

    /// A square of skin (Jensen's skin1, dipole) `SIDE_M` wide in the z = 0 plane, its UVs
    /// the unit square, lit by `light`, at `size`² texels.
    fn skin_plane(light: Light, size: u32) -> Scene {
        let p = [
            Vec3::ZERO,
            Vec3::new(SIDE_M, 0.0, 0.0),
            Vec3::new(SIDE_M, SIDE_M, 0.0),
            Vec3::new(0.0, SIDE_M, 0.0),
        ];
        let uv = [Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let tri = |a: u32, b: u32, c: u32| MeshTriangle {
            position: [a, b, c],
            uv: [a, b, c],
            normal: [0, 0, 0],
            material: 0,
        };
        Scene {
            name: "skin plane".into(),
            mesh: Mesh {
                positions_m: p.to_vec(),
                uvs: uv.to_vec(),
                normals: vec![Vec3::Z],
                triangles: vec![tri(0, 1, 2), tri(0, 2, 3)],
            },
            materials: vec![Material {
                name: "skin".into(),
                albedo: Albedo::Constant(Vec3::splat(0.5)),
                subsurface: Some(Subsurface {
                    sigma_a_per_mm: Vec3::new(0.032, 0.17, 0.48),
                    sigma_s_prime_per_mm: Vec3::new(0.74, 0.88, 1.01),
                    eta: 1.3,
                    model: SubsurfaceModel::Dipole,
                }),
            }],
            lights: vec![light],
            lightmap_size: (size, size),
            allow_uv_overlap: false,
        }
    }

    /// A spot straight above the plane with a hard edge (inner = outer cone): a circle of
    /// radius 14.05 mm whose rim passes 0.2 mm from the plane's centre, crossing texels and
    /// sub-texels at every angle.
    fn hard_spot() -> Light {
        let c = 0.5 * SIDE_M;
        Light::Spot {
            position_m: Vec3::new(c + 0.0137, c + 0.0021, 0.1),
            direction: Vec3::NEG_Z,
            color: Vec3::ONE,
            intensity_w_sr: 1.0,
            inner_deg: 8.0,
            outer_deg: 8.0,
        }
    }

    struct Solved {
        grid: TexelGrid,
        /// `Σ_j S_ij E_j` per texel: the transport's first scattering, at texel resolution.
        coarse: Vec<Vec3>,
        delta: Vec<Vec3>,
    }

    fn solve(scene: &Scene, n: u32) -> (Solved, Kernels) {
        let grid = TexelGrid::build(scene).unwrap();
        let vis = Arc::new(Visibility::new(&scene.mesh));
        let effects = Effects {
            radiosity: false,
            subsurface: true,
        };
        let kernels = Kernels::new(scene, effects, vis.clone());
        let input = lighting::first_order(&grid, &scene.lights, &vis);
        let mut patches = texel_patches(&grid);
        kernels.normalise_subsurface(&mut patches);
        let coarse = (0..patches.len())
            .into_par_iter()
            .map(|i| {
                let mut b = Vec3::ZERO;
                for (j, p) in patches.iter().enumerate() {
                    if let Some(s) = kernels.subsurface(&patches[i], p, i == j) {
                        let e = input[j] / p.rho;
                        b += Vec3::new(s[0] as f32, s[1] as f32, s[2] as f32) * e;
                    }
                }
                b
            })
            .collect();
        let delta = correction(
            scene,
            &grid,
            &kernels,
            &scene.lights,
            &vis,
            &input,
            NearField::new(n),
            &SetupProgress::none(),
        )
        .unwrap();
        (
            Solved {
                grid,
                coarse,
                delta,
            },
            kernels,
        )
    }

    /// `∫ R_d(|x − y|) E(y) dA(y)` over the plane by brute force: polar about `x`, 800
    /// geometric radial panels to the support and 2,048 angles (the spot's rim is the only
    /// discontinuity; halving both moves the result by < 10⁻³ of it).
    fn brute_force(kernels: &Kernels, light: &Light, x: Vec3) -> [f64; 3] {
        let profile = kernels.profiles[0].unwrap();
        let support = kernels.support_m[0];
        let (radial, angular) = (800usize, 2048usize);
        let r0 = 1e-7f64;
        let ratio = (support / r0).powf(1.0 / radial as f64);
        let mut sum = [0.0f64; 3];
        let mut inner = 0.0f64;
        for k in 0..=radial {
            let outer = if k == 0 {
                r0
            } else {
                r0 * ratio.powi(k as i32)
            };
            let r = 0.5 * (inner + outer);
            let dr = outer - inner;
            inner = outer;
            let rd = profile.rd(r);
            for a in 0..angular {
                let phi = (a as f64 + 0.5) * std::f64::consts::TAU / angular as f64;
                let y = x + Vec3::new((r * phi.cos()) as f32, (r * phi.sin()) as f32, 0.0);
                let e = lighting::irradiance_unshadowed_at(y, Vec3::Z, light);
                let w = r * dr * std::f64::consts::TAU / angular as f64;
                for c in 0..3 {
                    sum[c] += rd[c] * w * e[c] as f64;
                }
            }
        }
        sum
    }

    /// Under uniform light the sub-texels' weights add up to the texels' (their footprints
    /// tile the same plane), so the correction is the quadrature's difference alone.
    #[test]
    fn uniform_light_needs_no_correction() {
        let light = Light::Directional {
            direction: Vec3::new(0.3, 0.2, -1.0).normalize(),
            color: Vec3::ONE,
            irradiance_w_m2: 1.0,
        };
        let scene = skin_plane(light, 24);
        let (s, _) = solve(&scene, 3);
        let centre = Vec3::new(0.5 * SIDE_M, 0.5 * SIDE_M, 0.0);
        let (mut worst, mut measured) = (0.0f32, 0);
        for (i, t) in s.grid.texels.iter().enumerate() {
            if (t.position_m - centre).length() < 0.015 {
                measured += 1;
                let rel = (s.delta[i] / s.coarse[i]).abs().max_element();
                worst = worst.max(rel);
            }
        }
        println!("uniform light: {measured} receivers, largest |δ| / B {worst:e}");
        assert!(measured >= 40, "{measured} receivers");
        assert!(worst < 1e-4, "|δ| / B = {worst:e}");
    }

    /// Across a hard shadow edge the corrected first scattering is far nearer the profile
    /// integrated over the lit surface than the texel-resolution one, and nearer still with
    /// finer sub-texels.
    #[test]
    fn a_shadow_edge_is_resolved_within_the_texels() {
        let light = hard_spot();
        let scene = skin_plane(light, 32);
        let mut errors = Vec::new();
        for n in [3, 7] {
            let (s, kernels) = solve(&scene, n);
            let centre = Vec3::new(0.5 * SIDE_M, 0.5 * SIDE_M, 0.0);
            let (mut e_coarse, mut e_fine, mut norm) = (0.0f64, 0.0f64, 0.0f64);
            let mut measured = 0;
            for (i, t) in s.grid.texels.iter().enumerate() {
                // Receivers within 4 texels of the spot's rim, 10 mm around the centre.
                let foot = Vec3::new(0.5 * SIDE_M + 0.0137, 0.5 * SIDE_M + 0.0021, 0.0);
                let rim = ((t.position_m - foot).length() - 0.1 * 8f32.to_radians().tan()).abs();
                if (t.position_m - centre).length() > 0.010 || rim > 4.0 * SIDE_M / 32.0 {
                    continue;
                }
                measured += 1;
                let truth = brute_force(&kernels, &light, t.position_m);
                for (c, truth) in truth.into_iter().enumerate() {
                    let coarse = s.coarse[i][c] as f64;
                    let fine = coarse + s.delta[i][c] as f64;
                    e_coarse += (coarse - truth).powi(2);
                    e_fine += (fine - truth).powi(2);
                    norm += truth.powi(2);
                }
            }
            let (rc, rf) = ((e_coarse / norm).sqrt(), (e_fine / norm).sqrt());
            println!("n = {n}: {measured} receivers, relative RMSE {rc:.4} → {rf:.4}");
            assert!(measured >= 20, "{measured} receivers");
            errors.push((rc, rf));
        }
        let (coarse, fine3) = errors[0];
        let fine7 = errors[1].1;
        // Measured: 0.0609 → 0.0214 (n = 3) → 0.0047 (n = 7).
        assert!(fine3 < 0.5 * coarse, "n = 3: {fine3} against {coarse}");
        assert!(fine7 < 0.4 * fine3, "n = 7: {fine7} against n = 3: {fine3}");
    }

    /// The bake's near rows ([`near_rows`]) scatter the transfer input as the solve's correction
    /// with [`SubTexelLight::Input`] does: per receiver, `Σ_j (W_ij/ρ̄_j) input_j` less the
    /// transport's first scattering from the same window is `δ`, to rounding; an interior
    /// receiver has the whole window, `(2R + 1)²` senders, each inside it; and the input light
    /// differs from the sub-texels' own across the spot's rim (the two modes part there).
    #[test]
    fn near_rows_scatter_the_input_as_the_correction_does() {
        let light = hard_spot();
        let scene = skin_plane(light, 32);
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = Arc::new(Visibility::new(&scene.mesh));
        let effects = Effects {
            radiosity: false,
            subsurface: true,
        };
        let kernels = Kernels::new(&scene, effects, vis.clone());
        let input = lighting::first_order(&grid, &scene.lights, &vis);
        let near = NearField {
            reach: 1,
            light: SubTexelLight::Input,
            ..NearField::new(3)
        };
        let none = SetupProgress::none();
        let delta = |near| {
            correction(
                &scene,
                &grid,
                &kernels,
                &scene.lights,
                &vis,
                &input,
                near,
                &none,
            )
        };
        let (d_input, d_sub) = (
            delta(near).unwrap(),
            delta(NearField {
                light: SubTexelLight::SubTexels,
                ..near
            })
            .unwrap(),
        );
        let rows = near_rows(
            &scene,
            &grid,
            &kernels,
            near,
            0..grid.texels.len() as u32,
            &none,
        )
        .unwrap();
        let mut patches = texel_patches(&grid);
        kernels.normalise_subsurface(&mut patches);
        let (mut worst, mut scale, mut parted, mut first) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
        for (i, row) in rows.rows.iter().enumerate() {
            let t = &grid.texels[i];
            if (2..30).contains(&t.x) && (2..30).contains(&t.y) {
                assert_eq!(row.len(), 9, "receiver {i}");
            }
            let (mut d, mut f) = ([0.0f64; 3], [0.0f64; 3]);
            for &(j, w) in row {
                assert!(rows.in_window(i, j as usize));
                let (a, b) = (&patches[i], &patches[j as usize]);
                let s_ij = kernels.subsurface(a, b, i == j as usize).unwrap();
                for c in 0..3 {
                    let x = input[j as usize][c] as f64;
                    d[c] += w[c] as f64 * x - s_ij[c] * x / b.rho[c] as f64;
                    f[c] += w[c] as f64 * x;
                }
            }
            for c in 0..3 {
                first = first.max(f[c]);
                worst = worst.max((d[c] - d_input[i][c] as f64).abs());
                scale = scale.max((d_input[i][c] as f64).abs());
                parted = parted.max((d_sub[i][c] - d_input[i][c]).abs() as f64);
            }
        }
        // On a plane the sub-texels' weights nearly equal the texels' (footprints tile it, no
        // cap binds), so `δ` with the input's light is small — measured 6.3·10⁻⁵ W/m² beside a
        // first scattering up to 34 W/m², the rows 1.1·10⁻⁶ from it (f32 rounding); the head's is
        // not (`near_field_cli.rs`). Rows holding the texels' weights instead would be 100 %
        // of `δ` off.
        println!(
            "rows against δ: {worst:e} of {scale:e} (first scattering up to {first:e}); the two \
             lights part by {parted:e}"
        );
        assert!(
            worst < 1e-6 * first && worst < 0.1 * scale,
            "{worst:e} of {scale:e}"
        );
        assert!(parted > 0.1 * first, "{parted:e} of {first:e}");
    }

    #[test]
    fn even_or_out_of_range_subdivisions_are_refused() {
        for n in [0, 1, 2, 4, 9] {
            assert!(NearField::new(n).check().is_err(), "{n}");
        }
        for n in [3, 5, 7] {
            assert!(NearField::new(n).check().is_ok(), "{n}");
        }
    }
}
