//! The independent reference: texture-space Monte Carlo path tracing (API; the tracer is being
//! written — see issue 15).

use std::sync::atomic::AtomicBool;

use glam::Vec3;
use thiserror::Error;

use crate::bake::texels::TexelGrid;
use crate::bake::transport::Effects;
use crate::scene::{Light, Scene};

/// Settings of a reference run.
#[derive(Clone, Copy, Debug)]
pub struct Settings {
    /// Paths per covered texel.
    pub samples_per_texel: u32,
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
}

impl ReferenceMaps {
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
    let _ = (scene, grid, lights, settings, progress, cancel);
    unimplemented!("the path tracer is being written")
}
