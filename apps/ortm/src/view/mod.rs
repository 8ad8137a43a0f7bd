//! `ortm view`: the interactive viewer. A winit window with egui; the bake is relit every
//! frame by the `passes` crate on the window's device while the user moves lights, changes
//! the view (first order | final | indirect | side by side), the number of transfer maps,
//! exposure, debug views, the true reference for the lights on screen (exact solve or path
//! traced, in the background), an error view against it, and a CPU mirror of the bake. See
//! `docs/viewer.md` for the controls.
//!
//! # Files
//! - [`camera`]: orbit camera, projection for light handles and dragging.
//! - [`app`]: UI state, egui panels, shortcuts, mouse handling (no GPU calls).
//! - [`frame`]: the GPU frame (passes + indirect subtraction + display into an image).
//! - [`debug`]: CPU lightmaps for the debug views, the CPU mirror and the error view.
//! - [`reference`]: the true reference, computed on a worker thread and cached per lighting.
//! - [`window`]: winit/wgpu/egui plumbing, the frame loop, `--frames/--screenshot`.
//!
//! # Data flow
//! `ViewerInput` (the bake opened by [`ortm::render::open_bake`] in `src/cli/view.rs`:
//! scene, texel grid, atlases, lights) →
//! [`window::run`] → per frame: [`app::AppState::ui`] → [`frame::ViewRenderer::render`] →
//! egui paints the image and the panels into the window.

pub mod app;
pub mod camera;
pub mod debug;
pub mod frame;
pub mod reference;
pub mod window;

use std::path::PathBuf;

use glam::Vec3;
use ortm::atlas::AtlasSet;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::Effects;
use ortm::scene::{Light, Scene};
use passes::{AtlasData, TransferPiece};

pub use window::run;

/// Shadow-map layers of the viewer's first-order pass: the lights on screen together may
/// need at most this many ([`ortm::render::shadow_layers_for`]: 6 per point light, 1 per
/// spot or directional light), so 4 point lights, or more spot and directional ones.
pub const SHADOW_LAYERS: u32 = 24;

/// What the viewer shows: a loaded, checked bake.
pub struct ViewerInput {
    /// Window title (scene and bake folder).
    pub title: String,
    /// The scene the bake was made from.
    pub scene: Scene,
    /// Its covered texels at the bake's lightmap size.
    pub grid: TexelGrid,
    /// The atlases and pieces (CPU copy, for the CPU views).
    pub set: AtlasSet,
    /// The atlases as passes input.
    pub atlases: Vec<AtlasData>,
    /// Map indices that have pieces, by decreasing importance (`index.json`; map-index order
    /// when the bake has no index).
    pub map_order: Vec<u32>,
    /// Initial lights.
    pub lights: Vec<Light>,
    /// Side of each shadow-map layer, texels.
    pub shadow_size: u32,
    /// Sub-texels per texel side of the transfer's input (`--first-order-samples`; the GPU's
    /// first-order pass and the CPU mirror).
    pub first_order_samples: u32,
    /// First status line (e.g. a warning).
    pub note: String,
    /// The bake's effects (from its settings), which the reference includes.
    pub effects: Effects,
    /// Display: direct light per pixel or from the lightmaps (`--direct`), lightmap
    /// filter (`--filter`).
    pub display: crate::cli::render::DisplayArgs,
}

/// Options of a viewer run.
#[derive(Clone, Debug)]
pub struct RunOptions {
    /// Draw this many frames, then exit.
    pub frames: Option<u32>,
    /// With `frames`: write the last frame's 3D image here (PNG).
    pub screenshot: Option<PathBuf>,
    /// Window size in physical pixels.
    pub window_size: (u32, u32),
    /// With `frames`: resize the window to this size after half the frames.
    pub resize: Option<(u32, u32)>,
    /// Fixed exposure; `None`: automatic.
    pub exposure: Option<f32>,
    /// Light set-up file shown in the save/load field.
    pub lights_file: Option<PathBuf>,
    /// Initial view.
    pub mode: app::ViewMode,
    /// Initial debug view.
    pub debug: app::DebugView,
    /// Initial map of the one-map debug view (rank in importance order).
    pub debug_map: usize,
    /// Initial source of the shown lightmap (bake, reference, error view, CPU mirror).
    pub source: app::Source,
    /// Paths per texel of the path-traced reference.
    pub reference_spp: u32,
    /// Which reference (exact solve, path tracer, or the exact one where it fits).
    pub reference_method: reference::Method,
    /// Relative error shown red in the error view.
    pub error_scale: f64,
    /// Initial number of transfer maps (`None`: all).
    pub maps: Option<usize>,
    /// With `screenshot`: also write the whole window (UI included) here, when the surface
    /// can be copied from.
    pub window_screenshot: Option<PathBuf>,
}

impl ViewerInput {
    /// Which map indices are among the first `k` by importance (indexed by map index).
    pub fn first_maps(&self, k: usize) -> Vec<bool> {
        let n = self
            .set
            .pieces
            .iter()
            .map(|p| p.map_index as usize + 1)
            .max()
            .unwrap_or(0);
        let mut keep = vec![false; n];
        for &m in self.map_order.iter().take(k) {
            if let Some(x) = keep.get_mut(m as usize) {
                *x = true;
            }
        }
        keep
    }

    /// The pieces of the first `k` maps by importance, as passes input.
    pub fn pieces_of_first(&self, k: usize) -> Vec<TransferPiece> {
        let keep = self.first_maps(k);
        self.set
            .pieces
            .iter()
            .filter(|p| keep.get(p.map_index as usize).copied().unwrap_or(false))
            .map(ortm::render::transfer_piece)
            .collect()
    }

    /// The offset `Δt` of map `m` (texels), `(0, 0)` if it has no pieces.
    pub fn offset_of(&self, m: u32) -> (i32, i32) {
        self.set
            .pieces
            .iter()
            .find(|p| p.map_index == m)
            .map_or((0, 0), |p| (p.offset[0], p.offset[1]))
    }

    /// Bounding sphere of the mesh (centre, radius in metres).
    pub fn bounds(&self) -> (Vec3, f32) {
        match self.scene.mesh.bounding_sphere() {
            Some((c, r)) => (c, r.max(1e-6)),
            None => (Vec3::ZERO, 1.0),
        }
    }
}

/// Map indices with pieces, by decreasing importance (ties and maps missing from `index`
/// by map index).
pub fn importance_order(set: &AtlasSet, index: Option<&ortm::bake_dir::BakeIndex>) -> Vec<u32> {
    let mut maps: Vec<u32> = set.pieces.iter().map(|p| p.map_index).collect();
    maps.sort_unstable();
    maps.dedup();
    let importance = |m: u32| -> f64 {
        index
            .and_then(|ix| ix.maps.iter().find(|e| e.index == m))
            .map_or(0.0, |e| e.importance)
    };
    maps.sort_by(|a, b| importance(*b).total_cmp(&importance(*a)).then(a.cmp(b)));
    maps
}
