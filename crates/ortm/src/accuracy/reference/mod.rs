//! The independent reference: texture-space Monte Carlo path tracing of the transport's
//! continuous model, sharing none of the bake's approximations (no clusters, offsets, cells,
//! form factors or texel quadrature of the profile).
//!
//! # Data flow
//! For every covered texel of a [`TexelGrid`] (its centre, shading normal for cosines, face
//! normal to lift rays):
//! - the first order `B_o = ρ̄·E_direct`, exactly as [`crate::bake::lighting::first_order`]
//!   computes it (same lights, same lifted shadow rays; no noise);
//! - `samples_per_texel` paths ([`path`]), each an unbiased sample of the final radiosity
//!   `B`: for an opaque texel `B_o + ρ·∫ L_in cosθ dω` (cosine-sampled bounces through the BVH,
//!   next-event estimation to every light at every vertex, Russian roulette); for a translucent
//!   one (subsurface on) `∫ R_d(|x − y|) E(y) dA(y)` with `y` sampled by the profile and
//!   probe rays ([`subsurface`]), by Euclidean distance, so light crosses seams and ears;
//! - by default ([`Estimator::FirstOrderLight`]) the first-order radiosity of every surface
//!   (`ρ̄·E_direct` on translucent ones, the rest of their light from the bounce) is also
//!   sampled as a light at every path vertex (module `emitters`: points drawn ∝ `B_o·A`, `B_o`
//!   evaluated exactly at the drawn point by the same lights and shadow rays), combined with the
//!   cosine-sampled bounce by the balance heuristic: unbiased, and far less noisy where a lamp
//!   nearly touches a surface (Cornell: ~6× lower standard error at equal paths per texel);
//! - the paths' numbers: randomised quasi-Monte Carlo ([`sampler`]) — the paths are split into
//!   independent replicates, each an Owen-scrambled Sobol point set over the first vertices'
//!   numbers, so the paths of a replicate stratify the profile's disc, the bounce's hemisphere
//!   and the first order's light;
//! - the mean and its standard error (the spread of the replicates' means) per channel.
//!
//! With subsurface off translucent materials are opaque with the profile's total diffuse
//! reflectance ρ̄ (the texels' albedo), as in the transport. Units: W/m², linear RGB, metres.
//!
//! # Determinism
//! Texel `i`'s numbers come from its own ChaCha8 stream (seed `settings.seed`, stream `i`: the
//! replicates' scramble seeds, the numbers beyond the Sobol dimensions), and
//! each texel is summed by one thread in sample order, so the result depends on the seed only,
//! not on the thread count. Texels are traced in parallel (rayon); `progress` is called as they
//! finish and `cancel` is checked between batches of samples.

mod emitters;
mod path;
pub mod sampler;
pub mod subsurface;

use std::sync::atomic::{AtomicBool, AtomicUsize, Ordering};
use std::time::Instant;

use glam::Vec3;
use rand::SeedableRng;
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;
use thiserror::Error;

use crate::bake::lighting;
use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
use crate::bake::transport::Effects;
use crate::scene::{Light, Scene};
pub use path::{ROULETTE_AFTER, SceneView, Scratch, SurfacePoint};
use sampler::PathSampler;

/// Samples traced between two checks of the cancel flag.
const CANCEL_CHECK_SAMPLES: u32 = 64;

/// Path vertices (irradiance steps, from the texel's) at which [`Estimator::FirstOrderLight`]
/// samples the first order as a light.
pub const FIRST_ORDER_LIGHT_VERTICES: u32 = u32::MAX;

/// How the paths sample the indirect light. Both are unbiased estimates of the same `B`.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Estimator {
    /// Cosine-sampled bounces, next-event estimation to the lights.
    Cosine,
    /// As [`Estimator::Cosine`], plus the first-order radiosity `B_o = ρ·E_direct` of the
    /// surfaces sampled as a light (module `emitters`: points drawn ∝ `B_o·A`, one shadow ray,
    /// `B_o` evaluated exactly at the point) at the first [`FIRST_ORDER_LIGHT_VERTICES`]
    /// vertices, combined with the bounce by the balance heuristic.
    #[default]
    FirstOrderLight,
}

/// Independent replicates per texel by default ([`sampler`]): enough for a standard error whose
/// own spread is small (a texel's error exceeds 3 of its standard errors with probability
/// 0.53 % — a Student t with 31 degrees of freedom — against 0.27 % for a known σ), few enough
/// that each replicate's stratified points cancel much of the variance (head 64², 256 paths:
/// noise 3.96 % of the final with 32, 3.82 % with 16, 5.05 % with independent paths).
pub const DEFAULT_REPLICATES: u32 = 32;

/// Settings of a reference run.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Paths per covered texel (rounded up to a multiple of the replicates).
    pub samples_per_texel: u32,
    /// Independent replicates the paths are split into ([`sampler`]; their means' spread is
    /// the standard error); `samples_per_texel` replicates make every path independent
    /// (plain Monte Carlo).
    pub replicates: u32,
    /// Seed of the random streams (the result is deterministic for a seed, whatever the thread
    /// count).
    pub seed: u64,
    /// Which effects to trace (radiosity: diffuse bounces; subsurface: the profile).
    pub effects: Effects,
}

/// The reference lightmaps, per covered texel of the grid (grid order), W/m², RGB.
#[derive(Clone, Debug)]
pub struct ReferenceMaps {
    /// First order `B_o = ρ̄·E_direct`, exactly as the transport defines it (no noise).
    pub first_order: Vec<Vec3>,
    /// Final radiosity `B` (Monte Carlo estimate).
    pub final_b: Vec<Vec3>,
    /// Standard error of `final_b` per texel and channel (of the mean over the samples).
    pub std_error: Vec<Vec3>,
    /// Paths traced per texel.
    pub samples_per_texel: u32,
    /// Independent replicates per texel (the standard error has one degree of freedom fewer).
    pub replicates: u32,
}

/// Figures of a reference run.
#[derive(Clone, Copy, Debug, Default)]
pub struct TraceStats {
    /// Rays cast by the paths (bounces, shadow rays, probe rays; not the first order's).
    pub rays: u64,
    /// Wall time of the run, seconds.
    pub seconds: f64,
}

impl TraceStats {
    /// Rays per second.
    pub fn rays_per_second(&self) -> f64 {
        self.rays as f64 / self.seconds.max(1e-9)
    }
}

impl ReferenceMaps {
    /// Mean over covered texels and channels of `std_error / |value|`, for the texels and
    /// channels where `|value|` exceeds `1e-3` of the mean of `values` (e.g.
    /// `maps.mean_relative_std_error(&maps.final_b)` or of [`ReferenceMaps::indirect`]).
    pub fn mean_relative_std_error(&self, values: &[Vec3]) -> f64 {
        let n = values.len().max(1) as f64;
        let mean: f64 = values
            .iter()
            .map(|v| v.abs().element_sum() as f64 / 3.0)
            .sum::<f64>()
            / n;
        let floor = 1e-3 * mean;
        let (mut sum, mut count) = (0.0f64, 0usize);
        for (v, e) in values.iter().zip(&self.std_error) {
            for c in 0..3 {
                let x = v[c].abs() as f64;
                if x > floor {
                    sum += e[c] as f64 / x;
                    count += 1;
                }
            }
        }
        if count == 0 { 0.0 } else { sum / count as f64 }
    }

    /// The noise's share of a relative RMSE: `sqrt(Σ σ²) / sqrt(Σ |value|²)` over covered texels
    /// and channels, the relative RMSE that the reference's own noise adds to a comparison with
    /// `values` ([`crate::accuracy::compare::relative_rmse`]'s form; e.g. of `final_b`). 0 when
    /// `values` are all 0.
    pub fn rms_relative_std_error(&self, values: &[Vec3]) -> f64 {
        let (mut num, mut den) = (0.0f64, 0.0f64);
        for (v, e) in values.iter().zip(&self.std_error) {
            num += e.as_dvec3().length_squared();
            den += v.as_dvec3().length_squared();
        }
        if den > 0.0 { (num / den).sqrt() } else { 0.0 }
    }

    /// `final − first order` per texel.
    pub fn indirect(&self) -> Vec<Vec3> {
        self.final_b
            .iter()
            .zip(&self.first_order)
            .map(|(b, o)| *b - *o)
            .collect()
    }
}

/// Why a reference run stopped without a result.
#[derive(Debug, Error)]
pub enum ReferenceError {
    /// The cancel flag was raised.
    #[error("the reference was cancelled")]
    Cancelled,
}

/// Traces the reference of `scene` under `lights` at the covered texels of `grid`.
/// `progress(done, total)` is called from worker threads as texels finish; raising `cancel`
/// stops the run within a moment.
pub fn trace(
    scene: &Scene,
    grid: &TexelGrid,
    lights: &[Light],
    settings: &Settings,
    progress: &(dyn Fn(usize, usize) + Sync),
    cancel: &AtomicBool,
) -> Result<ReferenceMaps, ReferenceError> {
    trace_with_stats(scene, grid, lights, settings, progress, cancel).map(|(m, _)| m)
}

/// [`trace`], with the run's figures.
pub fn trace_with_stats(
    scene: &Scene,
    grid: &TexelGrid,
    lights: &[Light],
    settings: &Settings,
    progress: &(dyn Fn(usize, usize) + Sync),
    cancel: &AtomicBool,
) -> Result<(ReferenceMaps, TraceStats), ReferenceError> {
    trace_with_estimator(
        scene,
        grid,
        lights,
        settings,
        Estimator::default(),
        progress,
        cancel,
    )
}

/// [`trace_with_stats`] with a chosen [`Estimator`] (both estimate the same `B`; they differ in
/// noise and cost).
pub fn trace_with_estimator(
    scene: &Scene,
    grid: &TexelGrid,
    lights: &[Light],
    settings: &Settings,
    estimator: Estimator,
    progress: &(dyn Fn(usize, usize) + Sync),
    cancel: &AtomicBool,
) -> Result<(ReferenceMaps, TraceStats), ReferenceError> {
    let start = Instant::now();
    let vis = Visibility::new(&scene.mesh);
    let first_order = lighting::first_order(grid, lights, &vis);
    let vertices = match estimator {
        Estimator::Cosine => 0,
        Estimator::FirstOrderLight => FIRST_ORDER_LIGHT_VERTICES,
    };
    let view =
        SceneView::new(scene, &vis, lights, settings.effects).with_first_order_light(vertices);
    let n = grid.texels.len();
    let done = AtomicUsize::new(0);
    let (replicates, per_replicate) = split_paths(settings.samples_per_texel, settings.replicates);
    let spp = replicates * per_replicate;
    let per_texel: Vec<Option<TexelEstimate>> = (0..n)
        .into_par_iter()
        .map_init(Scratch::default, |scratch, i| {
            if cancel.load(Ordering::Relaxed) {
                return None;
            }
            let est = if view.traces_anything() {
                let x = SurfacePoint::of_texel(&grid.texels[i]);
                estimate_texel(
                    &view,
                    &x,
                    first_order[i],
                    settings.seed,
                    i,
                    (replicates, per_replicate),
                    cancel,
                    scratch,
                )?
            } else {
                TexelEstimate {
                    mean: first_order[i],
                    std_error: Vec3::ZERO,
                    rays: 0,
                }
            };
            progress(done.fetch_add(1, Ordering::Relaxed) + 1, n);
            Some(est)
        })
        .collect();
    if cancel.load(Ordering::Relaxed) || per_texel.iter().any(Option::is_none) {
        return Err(ReferenceError::Cancelled);
    }
    let per_texel: Vec<TexelEstimate> = per_texel.into_iter().flatten().collect();
    let stats = TraceStats {
        rays: per_texel.iter().map(|e| e.rays).sum(),
        seconds: start.elapsed().as_secs_f64(),
    };
    Ok((
        ReferenceMaps {
            first_order,
            final_b: per_texel.iter().map(|e| e.mean).collect(),
            std_error: per_texel.iter().map(|e| e.std_error).collect(),
            samples_per_texel: spp,
            replicates,
        },
        stats,
    ))
}

/// One texel's result.
struct TexelEstimate {
    mean: Vec3,
    std_error: Vec3,
    rays: u64,
}

/// `(R, n)`: `R` replicates of `n` paths, `R·n ≥ spp` paths in all; `R` is `replicates` (at
/// least 1, at most `spp`), or more where a replicate would outgrow the Sobol sequence
/// (`n ≤` [`sampler::MAX_REPLICATE_PATHS`]).
pub fn split_paths(spp: u32, replicates: u32) -> (u32, u32) {
    let spp = spp.max(1);
    let r = replicates
        .clamp(1, spp)
        .max(spp.div_ceil(sampler::MAX_REPLICATE_PATHS));
    (r, spp.div_ceil(r))
}

/// `R × n` samples of texel `index`'s final radiosity from its own stream (`split.0 = R`
/// replicates of `split.1 = n` paths, [`sampler::replicated_mean`]); `None` when cancelled.
#[allow(
    clippy::too_many_arguments,
    reason = "the texel, its stream and the run's shared state"
)]
fn estimate_texel(
    view: &SceneView<'_>,
    x: &SurfacePoint,
    b_o: Vec3,
    seed: u64,
    index: usize,
    split: (u32, u32),
    cancel: &AtomicBool,
    scratch: &mut Scratch,
) -> Option<TexelEstimate> {
    let (replicates, per_replicate) = split;
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    rng.set_stream(index as u64);
    let mut sampler = PathSampler::new(rng);
    let rays_before = scratch.rays;
    let mut traced = 0u32;
    let (mean, std_error) =
        sampler::replicated_mean(&mut sampler, replicates, per_replicate, |u| {
            traced += 1;
            if traced.is_multiple_of(CANCEL_CHECK_SAMPLES) && cancel.load(Ordering::Relaxed) {
                return None;
            }
            Some(view.sample(x, b_o, u, scratch).as_dvec3())
        })?;
    Some(TexelEstimate {
        mean: mean.as_vec3(),
        std_error: std_error.as_vec3(),
        rays: scratch.rays - rays_before,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Paths are split into at most the asked replicates, every replicate the same length, at
    /// least the asked paths in all, and no replicate longer than the Sobol sequence.
    #[test]
    fn paths_split_into_equal_replicates() {
        assert_eq!(split_paths(256, 32), (32, 8));
        assert_eq!(split_paths(100, 32), (32, 4));
        assert_eq!(split_paths(10, 32), (10, 1));
        assert_eq!(split_paths(0, 32), (1, 1));
        assert_eq!(split_paths(64, 1), (1, 64));
        let big = 3 * sampler::MAX_REPLICATE_PATHS;
        let (r, n) = split_paths(big, 1);
        assert!(
            n <= sampler::MAX_REPLICATE_PATHS && r * n >= big && r == 3,
            "{r} × {n}"
        );
    }
}
