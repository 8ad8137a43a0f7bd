//! `ortm view DIR`: the interactive viewer (see `src/view/` and `docs/viewer.md`). This file
//! only parses the arguments and loads the bake (the same checks as `ortm render`: scene hash,
//! atlas sizes), so a missing or corrupt bake directory is reported on stderr before any
//! window opens.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ortm::bake::texels::TexelGrid;
use ortm::render::{self, BakeAndScene, DEFAULT_ATLAS_SIDE};
use ortm::scene::Light;

use super::render::BakeArgs;
use crate::view::app::{DebugView, Source, ViewMode};
use crate::view::reference::{DEFAULT_SPP, Method};
use crate::view::{RunOptions, SHADOW_LAYERS, ViewerInput, importance_order};

/// Initial view (`--view`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum ViewArg {
    /// First-order lightmap.
    FirstOrder,
    /// Final lightmap.
    Final,
    /// Final − first order.
    Indirect,
    /// First order | final.
    SideBySide,
}

/// Initial debug view (`--debug`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum DebugArg {
    /// None.
    Off,
    /// Covered texels and chart borders.
    Coverage,
    /// Texels per m².
    Density,
    /// One offset map's contribution (`--debug-map`).
    Map,
}

/// Which reference (`--reference-method`).
#[derive(clap::ValueEnum, Clone, Copy, Debug)]
pub enum MethodArg {
    /// The exact dense solve where the covered texels fit, else path tracing.
    Auto,
    /// The exact dense solve (refused above its texel limit).
    Exact,
    /// The path-traced reference.
    PathTraced,
}

/// Arguments of `ortm view`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    bake: BakeArgs,
    /// Light set-up file (`[[light]]` tables, as saved by the viewer) replacing the scene's
    /// lights; also the file the viewer's save/load buttons use.
    #[arg(long = "lights", value_name = "FILE")]
    lights_file: Option<PathBuf>,
    #[command(flatten)]
    display: super::render::DisplayArgs,
    /// Window size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x800")]
    size: String,
    /// Exposure: `auto`, or a number multiplying the radiance B/π before tonemapping.
    #[arg(long, default_value = "auto")]
    exposure: String,
    /// Side of each shadow-map layer, texels ([`SHADOW_LAYERS`] layers: 4 point lights, or
    /// more spot and directional ones).
    #[arg(long, default_value_t = super::render::DEFAULT_SHADOW_SIZE, help = format!("Side of each shadow-map layer, texels ({SHADOW_LAYERS} layers: 4 point lights, or more spot and directional ones)"))]
    shadow_size: u32,
    /// Sub-texels per texel side (odd, 1–7) over which the transfer's input is averaged, as
    /// `ortm render --first-order-samples` (whose default is 3); the viewer takes the centres
    /// by default, since on a CPU adapter (lavapipe) the averaged first order costs about ten
    /// times the pass (README, "The transfer's input").
    #[arg(long, default_value_t = 1, value_name = "N")]
    first_order_samples: u32,
    /// Atlas side when the bake has no atlases.json (power of two).
    #[arg(long, default_value_t = DEFAULT_ATLAS_SIDE)]
    atlas_size: u32,
    /// Initial view.
    #[arg(long, value_enum, default_value_t = ViewArg::Final)]
    view: ViewArg,
    /// Initial debug view.
    #[arg(long, value_enum, default_value_t = DebugArg::Off)]
    debug: DebugArg,
    /// Map shown by `--debug map`: its rank in importance order (0 = most important).
    #[arg(long, default_value_t = 0)]
    debug_map: usize,
    /// Start showing the true reference for the lights (exact solve, or path-traced where
    /// the exact solve does not fit), computed in the background.
    #[arg(long, conflicts_with_all = ["error", "cpu_mirror"])]
    reference: bool,
    /// Start in the error view: |GPU lightmap − reference| / RMS(reference), false colour.
    #[arg(long, conflicts_with = "cpu_mirror")]
    error: bool,
    /// Start showing the CPU mirror of the bake (ray-cast first order + CPU transfer of the
    /// same maps; a check of the GPU passes, not the truth).
    #[arg(long)]
    cpu_mirror: bool,
    /// Which reference to compute.
    #[arg(long, value_enum, default_value_t = MethodArg::Auto)]
    reference_method: MethodArg,
    /// Paths per texel of the path-traced reference.
    #[arg(
        long,
        value_name = "SPP",
        default_value_t = DEFAULT_SPP,
        value_parser = clap::value_parser!(u32).range(1..=i64::from(ortm::io::limits::MAX_SAMPLES_PER_TEXEL)),
        help = format!("Paths per texel of the path-traced reference, 1..={}", ortm::io::limits::MAX_SAMPLES_PER_TEXEL)
    )]
    reference_spp: u32,
    /// Relative error shown red in the error view (× the reference's RMS).
    #[arg(long, value_name = "X", default_value_t = crate::view::app::DEFAULT_ERROR_SCALE)]
    error_scale: f64,
    /// Number of transfer maps used at start (first K by importance; default all).
    #[arg(long, value_name = "K")]
    maps: Option<usize>,
    /// Draw N frames, then exit (for tests and documentation).
    #[arg(long, value_name = "N")]
    frames: Option<u32>,
    /// With --frames: write the last frame's 3D view (read back from the GPU) as PNG.
    #[arg(long, value_name = "PNG", requires = "frames")]
    screenshot: Option<PathBuf>,
    /// With --frames: resize the window to WIDTHxHEIGHT after half the frames (checks that
    /// resizing keeps drawing).
    #[arg(long, value_name = "WxH", requires = "frames")]
    resize: Option<String>,
    /// With --frames: also write the whole window, panels included, as PNG (when the
    /// window surface allows copies).
    #[arg(long, value_name = "PNG", requires = "frames")]
    window_screenshot: Option<PathBuf>,
}

/// Runs `ortm view`.
pub fn run(a: Args) -> Result<()> {
    if a.frames == Some(0) {
        bail!("--frames 0: give at least one frame");
    }
    let window_size = render::parse_size(&a.size)?;
    let exposure = render::parse_exposure(&a.exposure)?;
    if a.reference_spp == 0 {
        bail!("--reference-spp 0: give at least one path per texel");
    }
    if !(a.error_scale.is_finite() && a.error_scale > 0.0) {
        bail!(
            "--error-scale {}: give a positive number (e.g. 0.5: errors of half the reference's \
             RMS show red)",
            a.error_scale
        );
    }
    let input = load_input(&a)?;
    crate::view::run(
        input,
        RunOptions {
            frames: a.frames,
            screenshot: a.screenshot,
            window_size,
            resize: a.resize.as_deref().map(render::parse_size).transpose()?,
            exposure,
            lights_file: a.lights_file,
            mode: match a.view {
                ViewArg::FirstOrder => ViewMode::FirstOrder,
                ViewArg::Final => ViewMode::Final,
                ViewArg::Indirect => ViewMode::Indirect,
                ViewArg::SideBySide => ViewMode::SideBySide,
            },
            debug: match a.debug {
                DebugArg::Off => DebugView::Off,
                DebugArg::Coverage => DebugView::Coverage,
                DebugArg::Density => DebugView::Density,
                DebugArg::Map => DebugView::MapContribution,
            },
            debug_map: a.debug_map,
            source: if a.reference {
                Source::Reference
            } else if a.error {
                Source::Error
            } else if a.cpu_mirror {
                Source::CpuMirror
            } else {
                Source::Bake
            },
            reference_spp: a.reference_spp,
            reference_method: match a.reference_method {
                MethodArg::Auto => Method::Auto,
                MethodArg::Exact => Method::Exact,
                MethodArg::PathTraced => Method::PathTraced,
            },
            error_scale: a.error_scale,
            maps: a.maps,
            window_screenshot: a.window_screenshot,
        },
    )?;
    Ok(())
}

/// The opened, checked bake and the initial lights, as the viewer's input.
fn load_input(a: &Args) -> Result<ViewerInput> {
    if !a.bake.dir.is_dir() {
        bail!(
            "bake directory '{}' does not exist or is not a folder (make one with `ortm bake \
             SCENE -o DIR`)",
            a.bake.dir.display()
        );
    }
    let BakeAndScene {
        index, set, scene, ..
    } = a.bake.open(a.atlas_size)?;
    let (w, h) = set.lightmap_size;
    let grid = TexelGrid::build_with_size(&scene, w, h)?;
    let lights = initial_lights(a, &scene.lights)?;
    let note = if lights.is_empty() {
        "no lights: add one in the Lights panel (P, L or I)".to_string()
    } else {
        String::new()
    };
    let (atlases, _pieces) = render::transfer_inputs(&set, (w, h))?;
    let map_order = importance_order(&set, index.as_ref());
    // The bake's effects, which the reference includes (all of them for a bake without index).
    let effects = render::effects_of(index.as_ref());
    Ok(ViewerInput {
        title: format!("{} — {}", scene.name, a.bake.dir.display()),
        scene,
        grid,
        set,
        atlases,
        map_order,
        lights,
        shadow_size: a.shadow_size,
        first_order_samples: a.first_order_samples,
        note,
        effects,
        display: a.display,
    })
}

/// `--light`, `--lights FILE` or the scene's lights, within the viewer's shadow-map layers.
fn initial_lights(a: &Args, scene_lights: &[Light]) -> Result<Vec<Light>> {
    let lights = match (&a.lights_file, a.bake.lights.is_empty()) {
        (Some(_), false) => bail!("give either --light or --lights FILE, not both"),
        (Some(p), true) => ortm::scene::file::load_lights_fragment(p)
            .with_context(|| format!("loading the light set-up '{}'", p.display()))?,
        (None, false) => a.bake.lights()?,
        (None, true) => scene_lights.to_vec(),
    };
    if render::shadow_layers_for(&lights) > SHADOW_LAYERS {
        bail!(
            "{} lights need {} shadow-map layers; the viewer has {SHADOW_LAYERS} (6 per point \
             light, 1 per spot or directional light)",
            lights.len(),
            render::shadow_layers_for(&lights)
        );
    }
    Ok(lights)
}
