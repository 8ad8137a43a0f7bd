//! The bake orchestrator: selection, Voronoi cells, map values, resumable writing, report.
//! See the [module docs](super) for the data flow.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use glam::{IVec2, Vec3};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::Lightmap;
use crate::bake::near_field::{NearField, NearRows, SubTexelLight};
use crate::bake::near_gather::NearGather;
use crate::bake::offsets::{self, ImportanceMetric, OffsetError, SelectionSettings};
use crate::bake::texels::{TexelError, TexelGrid};
use crate::bake::transport::{Effects, SetupProgress, Transport, hier};
use crate::bake_dir::{self, BakeIndex, BakeKey, LightmapSize};
use crate::maps::{MapsError, TransferMap};
use crate::scene::{Scene, scene_hash};

/// How offsets are chosen.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum Selector {
    /// Importance sampling of the Delaunay C0 density (the paper's method).
    #[default]
    Importance,
    /// One jittered sample per cell of a regular grid (the paper's rejected baseline).
    JitteredGrid,
}

/// How a map's value over its Voronoi cell is computed.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize, Default)]
#[serde(rename_all = "kebab-case")]
pub enum CellRule {
    /// The transfer integrated over the cell, `Σ_{v ∈ V} R(t, t+v)`
    /// ([`crate::bake::cells`]); the default.
    #[default]
    Integrated,
    /// The paper's Eq. 10, `TR(t, t+Δt)·TVA(t, Δt)`: one sample of the transfer times the cell's
    /// area (cells of at most [`EXACT_CELL_MAX`] offsets, and the origin's, are summed exactly).
    Sampled,
}

/// Every setting that influences the bake's output (stored in the index).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeSettings {
    /// Lightmap width and height, texels.
    pub size: (u32, u32),
    /// Number of offsets (transfer maps), `(0, 0)` included.
    pub offsets: usize,
    /// Effects included in the transfer.
    pub effects: Effects,
    /// Random seed (selection).
    pub seed: u64,
    /// Offset selector.
    pub selector: Selector,
    /// Transference metric.
    pub metric: ImportanceMetric,
    /// Seed grid per axis (≈ `seed_grid²` seed offsets).
    pub seed_grid: u32,
    /// Refinement iterations of the importance density.
    pub refinement_iterations: usize,
    /// Draws between rebuilds of the density.
    pub rebuild_every: usize,
    /// Cluster size (texels per side) of the coarse higher-order solve; 0 = automatic
    /// ([`crate::bake::transport::coarse::auto_block`]: single texels up to 4,096 covered
    /// texels, else the finest block with at most 1,024 clusters). The default stays 8: with
    /// exact clusters the evaluator is exact, but today's offset maps get worse (README,
    /// "Transport model").
    pub coarse_block: u32,
    /// Tolerance `ε` of the hierarchical first bounce ([`crate::bake::transport::hier`]): when
    /// set, the cell integration takes the first bounce from the operator's links
    /// ([`crate::bake::cells`], "With the hierarchical operator") and the coarse clusters carry
    /// only the higher-order remainder; `None`: first bounce from the coarse clusters and texel
    /// pairs.
    #[serde(default)]
    pub tolerance: Option<f32>,
    /// With [`Self::tolerance`]: the subsurface walk's own tolerance
    /// ([`crate::bake::transport::hier::Settings::subsurface_tolerance`]); `None`: the same
    /// as `tolerance`. Recorded (and so in the bake's key) only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub subsurface_tolerance: Option<f32>,
    /// Receivers sampled per offset when estimating its transference.
    pub selection_receivers: usize,
    /// How map values cover their Voronoi cells.
    #[serde(default)]
    pub cell_rule: CellRule,
    /// Multi-resolution maps ([`crate::bake::multires`], [`crate::maps::levels`]) at this
    /// tolerance `ε` instead of importance-sampled offsets: every receiver's transfer row is
    /// partitioned into pyramid blocks with error at most `ε·B_max/2` each; `offsets`,
    /// `selector`, `metric` and `cell_rule` are then unused. `None`: the paper's offsets.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub levels: Option<f64>,
    /// With [`Self::levels`]: share kept blocks between neighbouring receivers
    /// ([`crate::bake::multires::coarsen_receivers`], each shared value within `ε/2` of every
    /// receiver's own) and write maps with receiver levels
    /// ([`crate::bake::multires::to_block_maps`]); `false`: one value per receiver
    /// ([`crate::bake::multires::to_maps`]). Recorded in the bake's settings (and so its key)
    /// only when `levels` is set ([`Self::to_json`]).
    #[serde(default)]
    pub receiver_blocks: bool,
    /// With [`Self::levels`] and [`Self::tolerance`]: the interreflection's near field gathered
    /// by `G × G` rays per texel ([`crate::bake::near_gather`]), its form factors `ΔF` added to
    /// every receiver's first bounce ([`crate::bake::multires::with_gathered_rows`]); `None`:
    /// off. Recorded (and so in the bake's key) only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_gather: Option<u32>,
    /// With [`Self::near_gather`]: the near set's radius in texel sizes; `None`:
    /// [`crate::bake::near_gather::DEFAULT_REACH`]. Recorded only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_gather_reach: Option<f32>,
    /// With [`Self::tolerance`]: rounds of balancing of the subsurface weights' rows and
    /// columns ([`crate::bake::transport::Kernels::balance_rounds`]; README, "The subsurface
    /// weights' rows"); `None`: the columns capped alone. Recorded (and so in the bake's key)
    /// only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub balance_subsurface: Option<u32>,
    /// With [`Self::levels`] and [`Self::tolerance`]: skin's near field, `N × N` sub-texels per
    /// sender ([`crate::bake::near_field::near_rows`]): every translucent receiver's first
    /// scattering from the senders within [`Self::near_field_reach`] texels takes the profile
    /// integrated over their sub-texels (not normalised) instead of the transport's texel
    /// weights ([`crate::bake::multires::hierarchical_row_with`]); `None`: off. Recorded (and so
    /// in the bake's key) only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_field: Option<u32>,
    /// With [`Self::near_field`]: the window's reach in texels; `None`: the near field's
    /// default ([`crate::bake::near_field::NearField::new`], 2). Recorded only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub near_field_reach: Option<u32>,
    /// With [`Self::levels`] and [`Self::tolerance`]: the most texels that stay clusters of
    /// their own in the coarse remainder ([`crate::bake::transport::coarse::slit_texels`]);
    /// `None`: [`crate::bake::transport::coarse::MAX_SLIT_TEXELS`]. Recorded (and so in the
    /// bake's key) only when set.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub slit_texels: Option<u32>,
    /// How the scene was named when baking (a built-in name or a scene-file path, as given), so
    /// that `ortm render DIR` can find it again; informational (the scene hash identifies it).
    pub scene: Option<String>,
}

impl Default for BakeSettings {
    fn default() -> Self {
        Self {
            size: (256, 256),
            offsets: 100,
            effects: Effects::default(),
            seed: 1,
            selector: Selector::Importance,
            metric: ImportanceMetric::Max,
            seed_grid: 10,
            refinement_iterations: 1000,
            rebuild_every: 20,
            coarse_block: 8,
            tolerance: None,
            subsurface_tolerance: None,
            selection_receivers: 4096,
            cell_rule: CellRule::Integrated,
            levels: None,
            receiver_blocks: false,
            near_gather: None,
            near_gather_reach: None,
            balance_subsurface: None,
            near_field: None,
            near_field_reach: None,
            slit_texels: None,
            scene: None,
        }
    }
}

impl BakeSettings {
    /// The near gather these settings ask for (`None`: off), checked: it needs multi-resolution
    /// maps on the hierarchical transport (their rows take `ΔF` per texel pair; the offsets'
    /// cells do not), and `G` and the reach in range ([`NearGather::check`]). The rows may hold
    /// a quarter of the memory limit.
    pub fn near_gather(&self) -> Result<Option<NearGather>, BakeError> {
        let Some(g) = self.near_gather else {
            if let Some(r) = self.near_gather_reach {
                return Err(BakeError::Settings(format!(
                    "--near-gather-reach {r}: applies to --near-gather G (2–64 rays per side), \
                     which is off"
                )));
            }
            return Ok(None);
        };
        if self.levels.is_none() || self.tolerance.is_none() {
            return Err(BakeError::Settings(format!(
                "--near-gather {g} needs --levels ε and --tolerance: the gathered form factors go \
                 into the multi-resolution maps' rows of the hierarchical transport (the \
                 offsets' cells do not take them)"
            )));
        }
        let max_bytes = crate::io::limits::memory_limit_bytes()
            .map_err(|e| BakeError::Settings(e.to_string()))?
            .map(|l| l / 4);
        let gather = NearGather {
            reach: self
                .near_gather_reach
                .unwrap_or(crate::bake::near_gather::DEFAULT_REACH),
            max_bytes,
            ..NearGather::new(g)
        };
        gather.check().map_err(|e| {
            BakeError::Settings(match self.near_gather_reach {
                Some(r) if NearGather::new(g).check().is_ok() => {
                    format!("--near-gather-reach {r}: {e}")
                }
                _ => format!("--near-gather {g}: {e}; 0 turns it off"),
            })
        })?;
        Ok(Some(gather))
    }

    /// Skin's near field these settings ask for (`None`: off), checked: it needs
    /// multi-resolution maps on the hierarchical transport (their rows take it, as the
    /// transport's subsurface walk's first scattering; the offsets' cells do not), the
    /// subsurface effect, an odd `N` from 3 to 7 and a reach of at most 8 ([`NearField::check`]).
    pub fn near_field(&self) -> Result<Option<NearField>, BakeError> {
        let Some(n) = self.near_field else {
            if let Some(r) = self.near_field_reach {
                return Err(BakeError::Settings(format!(
                    "--near-field-reach {r}: applies to --near-field N (odd, 3–7), which is off"
                )));
            }
            return Ok(None);
        };
        if self.levels.is_none() || self.tolerance.is_none() {
            return Err(BakeError::Settings(format!(
                "--near-field {n} needs --levels ε on the hierarchical transport (--tolerance, \
                 or --levels without --coarse-block): the near field goes into the \
                 multi-resolution maps' rows from the transport's subsurface walk (the \
                 offsets' cells do not take it)"
            )));
        }
        if !self.effects.subsurface {
            return Err(BakeError::Settings(format!(
                "--near-field {n} is skin's near field, and --effects leaves out the subsurface \
                 term (sss): add sss to --effects, or leave --near-field out"
            )));
        }
        let near = NearField::from_flags(n, self.near_field_reach, SubTexelLight::Input)
            .map_err(BakeError::Settings)?;
        Ok(Some(near))
    }

    /// The cap on the coarse remainder's slit texels these settings ask for, checked: a cap
    /// other than the default needs multi-resolution maps on the hierarchical transport (the
    /// only bakes that keep slit texels) and at most [`MAX_SLIT_TEXELS_FLAG`] (the coarse
    /// solve is dense: 32,768 clusters take 8 GiB per matrix of doubles and hours of LU; the
    /// bake's memory check sizes it first).
    pub fn slit_texels(&self) -> Result<usize, BakeError> {
        let Some(n) = self.slit_texels else {
            return Ok(crate::bake::transport::coarse::MAX_SLIT_TEXELS);
        };
        if self.levels.is_none() || self.tolerance.is_none() {
            return Err(BakeError::Settings(format!(
                "--slit-texels {n} needs --levels ε on the hierarchical transport (--tolerance, \
                 or --levels without --coarse-block): only its multi-resolution maps' rows keep \
                 slit texels in the coarse remainder"
            )));
        }
        if n > MAX_SLIT_TEXELS_FLAG {
            return Err(BakeError::Settings(format!(
                "--slit-texels {n}: at most {MAX_SLIT_TEXELS_FLAG} (the coarse solve is dense, \
                 its time grows as the cube of the clusters); the default is {}",
                crate::bake::transport::coarse::MAX_SLIT_TEXELS
            )));
        }
        Ok(n as usize)
    }

    /// The settings as the bake records them in `index.json` (and hashes into its
    /// [`BakeKey`]): every field, except `receiver_blocks` when `levels` is unset (it changes
    /// nothing there, so the paper's bakes keep their keys); with `levels` it is always written,
    /// so a resumed bake never mixes maps with and without receiver blocks.
    pub fn to_json(&self) -> serde_json::Value {
        let mut v = serde_json::to_value(self).expect("settings serialise");
        if self.levels.is_none()
            && let Some(o) = v.as_object_mut()
        {
            o.remove("receiver_blocks");
        }
        v
    }
}

/// Errors of the bake.
#[derive(Debug, thiserror::Error)]
pub enum BakeError {
    /// The UV layout could not be rasterized.
    #[error(transparent)]
    Texels(#[from] TexelError),
    /// Offset selection failed (the cause is the error's source).
    #[error("offset selection")]
    Offsets(#[from] OffsetError),
    /// Writing or reading maps failed.
    #[error(transparent)]
    Maps(#[from] MapsError),
    /// A file could not be written.
    #[error("cannot write '{path}': {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
    /// Stopped by the user; finished maps are kept.
    #[error(
        "interrupted after {done} of {total} maps; finished maps are kept — rerun the same command \
         to resume"
    )]
    Interrupted {
        /// Maps finished.
        done: usize,
        /// Maps planned.
        total: usize,
    },
    /// Another process is writing the bake directory.
    #[error(transparent)]
    Lock(#[from] crate::io::LockError),
    /// Settings that cannot work.
    #[error("invalid bake setting: {0}")]
    Settings(String),
}

/// Progress events of a bake, for a progress display.
#[derive(Clone, Debug)]
pub enum BakeEvent {
    /// A phase starts with `total` steps.
    Phase {
        /// Phase name.
        name: &'static str,
        /// Steps.
        total: u64,
    },
    /// `n` more steps of the current phase are done.
    Advance(u64),
    /// A line of information.
    Message(String),
}

/// Result of a bake.
#[derive(Clone, Debug)]
pub struct BakeSummary {
    /// Maps in the index.
    pub maps: usize,
    /// Maps reused from an interrupted run.
    pub reused: usize,
    /// Seconds per phase: transport set-up, selection, maps.
    pub seconds: [f64; 3],
    /// Covered texels.
    pub texels: usize,
    /// Stored (cropped) texels over all maps.
    pub stored_texels: u64,
}

/// Receivers (texel indices) used to estimate transference: every covered texel, or an evenly
/// strided subset of at most `max` of them.
pub fn selection_receivers(grid: &TexelGrid, max: usize) -> Vec<u32> {
    let n = grid.texels.len();
    let stride = n.div_ceil(max.max(1)).max(1);
    (0..n as u32).step_by(stride).collect()
}

/// Transference of `offset`: max (or mean) over `receivers` of the largest channel of
/// `|R(t, t + Δt)|` (0 where the sender is uncovered).
pub fn transference(
    transport: &Transport,
    grid: &TexelGrid,
    receivers: &[u32],
    offset: IVec2,
    metric: ImportanceMetric,
) -> f64 {
    let values = receivers.iter().filter_map(|&i| {
        let t = &grid.texels[i as usize];
        let j = grid.at(t.x as i32 + offset.x, t.y as i32 + offset.y)?;
        let r = transport.r(i, j);
        Some(r[0].abs().max(r[1].abs()).max(r[2].abs()) as f64)
    });
    match metric {
        ImportanceMetric::Max => values.fold(0.0, f64::max),
        ImportanceMetric::Average => values.sum::<f64>() / receivers.len().max(1) as f64,
    }
}

/// The values of one transfer map over the full lightmap (see the module docs) and its
/// importance (largest channel of `|R|` over the map).
pub fn compute_map_values(
    transport: &Transport,
    grid: &TexelGrid,
    offset: IVec2,
    tva: &[f32],
    contains_origin: bool,
) -> (Lightmap, f64) {
    let w = grid.width;
    map_over_receivers(grid, offset, |x, y, i, j| {
        let mut r = Vec3::from_array(transport.r(i, j));
        let imp = r.abs().max_element() as f64;
        let delta = if i == j && transport.is_translucent(i) {
            1.0
        } else {
            0.0
        };
        r += Vec3::splat(delta);
        let a_j = transport.patches[j as usize].area_m2;
        let mut v = r / a_j * tva[(y * w + x) as usize];
        if contains_origin {
            v -= Vec3::splat(delta);
        }
        (v.to_array(), imp)
    })
}

/// One transfer map of `offset` from `texel(x, y, i, j)` = (value, importance) for every
/// covered receiver `i` at `(x, y)` whose sender `j` at `(x, y) + offset` is covered (0
/// elsewhere); rows in parallel. Returns the map and the largest importance. Serves
/// [`compute_map_values`] and [`compute_map_values_exact`].
fn map_over_receivers(
    grid: &TexelGrid,
    offset: IVec2,
    texel: impl Fn(u32, u32, u32, u32) -> ([f32; 3], f64) + Sync,
) -> (Lightmap, f64) {
    let (w, h) = (grid.width, grid.height);
    let rows: Vec<(Vec<[f32; 3]>, f64)> = (0..h)
        .into_par_iter()
        .map(|y| {
            let mut row = vec![[0.0f32; 3]; w as usize];
            let mut imp = 0.0f64;
            for x in 0..w {
                let Some(i) = grid.at(x as i32, y as i32) else {
                    continue;
                };
                let Some(j) = grid.at(x as i32 + offset.x, y as i32 + offset.y) else {
                    continue;
                };
                let (v, texel_imp) = texel(x, y, i, j);
                imp = imp.max(texel_imp);
                row[x as usize] = v;
            }
            (row, imp)
        })
        .collect();
    let mut map = Lightmap::new(w, h);
    let mut importance = 0.0f64;
    for (y, (row, imp)) in rows.into_iter().enumerate() {
        let start = y * w as usize;
        map.data[start..start + w as usize].copy_from_slice(&row);
        importance = importance.max(imp);
    }
    (map, importance)
}

/// Cells with at most this many integer offsets are integrated exactly (see [`MapPlan::map`]).
pub const EXACT_CELL_MAX: usize = 48;

/// The values of one transfer map integrated exactly over its Voronoi cell:
/// `Σ_{v ∈ V(Δt)} R(t, t + v)` for every receiver `t` whose sender `t + Δt` is covered. Exact
/// for any cell (it includes the subsurface point mass and the near-singular self term), at a
/// cost of one `R` evaluation per cell member and receiver.
pub fn compute_map_values_exact(
    transport: &Transport,
    grid: &TexelGrid,
    offset: IVec2,
    runs: &[offsets::RowRun],
) -> (Lightmap, f64) {
    map_over_receivers(grid, offset, |x, y, i, _| {
        let (x, y) = (x as i32, y as i32);
        let mut imp = 0.0f64;
        let mut sum = [0.0f64; 3];
        for run in runs {
            for dx in run.dx_start..=run.dx_end_inclusive {
                let Some(j) = grid.at(x + dx, y + run.dy) else {
                    continue;
                };
                let r = transport.r(i, j);
                if dx == offset.x && run.dy == offset.y {
                    imp = imp.max(r[0].abs().max(r[1].abs()).max(r[2].abs()) as f64);
                }
                for c in 0..3 {
                    sum[c] += r[c] as f64;
                }
            }
        }
        ([sum[0] as f32, sum[1] as f32, sum[2] as f32], imp)
    })
}

pub use crate::bake_dir::SelectionRecord;

/// Chooses the offsets (importance-sampled or jittered grid).
pub fn select_offsets(
    transport: &Transport,
    grid: &TexelGrid,
    settings: &BakeSettings,
    events: &(dyn Fn(BakeEvent) + Sync),
) -> Result<(Vec<IVec2>, Vec<[f64; 3]>), BakeError> {
    let (w, h) = (grid.width, grid.height);
    match settings.selector {
        Selector::JitteredGrid => Ok((
            offsets::select_jittered_grid(w, h, settings.offsets, settings.seed)?,
            Vec::new(),
        )),
        Selector::Importance => {
            let receivers = selection_receivers(grid, settings.selection_receivers);
            let sel = SelectionSettings {
                seed_grid: settings.seed_grid,
                refinement_iterations: settings.refinement_iterations,
                rebuild_every: settings.rebuild_every,
                final_count: settings.offsets,
                metric: settings.metric,
                seed: settings.seed,
            };
            let total =
                (settings.seed_grid as u64).pow(2) + 1 + settings.refinement_iterations as u64;
            events(BakeEvent::Phase {
                name: "selecting offsets",
                total,
            });
            let selection = offsets::select_importance(
                &sel,
                w,
                h,
                |batch| {
                    let v: Vec<f64> = batch
                        .par_iter()
                        .map(|&o| transference(transport, grid, &receivers, o, settings.metric))
                        .collect();
                    events(BakeEvent::Advance(batch.len() as u64));
                    v
                },
                |_, _, _| {},
            );
            let selection = match selection {
                Err(offsets::OffsetError::ZeroTransference { seeds }) => {
                    // Nothing to importance-sample: a convex object, or surfaces that do not
                    // see each other, without subsurface scattering. The maps then hold
                    // whatever transfer the seeds missed (usually none); the bake stays valid.
                    events(BakeEvent::Message(format!(
                        "warning: no light transport at any of the {seeds} seed offsets (a \
                         convex mesh, or surfaces that do not see each other, without \
                         subsurface scattering?): the offsets are chosen on a jittered grid \
                         instead, and the final lightmap will be about the first order"
                    )));
                    return Ok((
                        offsets::select_jittered_grid(w, h, settings.offsets, settings.seed)?,
                        Vec::new(),
                    ));
                }
                other => other?,
            };
            let points = selection
                .data_points
                .iter()
                .map(|(p, v)| [p.x, p.y, *v])
                .collect();
            Ok((selection.offsets, points))
        }
    }
}

/// Computes the transfer maps of `offsets` in memory (no files) with the cell rule `rule`: the
/// core of the bake, used directly by tests. `events` receives the integration phase's progress
/// and one `Advance` per map.
pub fn bake_maps(
    transport: &Transport,
    grid: &TexelGrid,
    offset_list: &[IVec2],
    rule: CellRule,
    events: &(dyn Fn(BakeEvent) + Sync),
) -> Result<Vec<TransferMap>, BakeError> {
    let mut plan = MapPlan::new(grid, offset_list, rule)?;
    plan.prepare(transport, grid, events);
    (0..offset_list.len())
        .map(|k| {
            let m = plan.map(transport, grid, k)?;
            events(BakeEvent::Advance(1));
            Ok(m)
        })
        .collect()
}

/// Voronoi cells and areas of a set of offsets, ready to generate maps one by one.
pub struct MapPlan {
    offsets: Vec<IVec2>,
    cells: offsets::DiscreteCells,
    areas: Vec<f64>,
    area_map: Vec<f32>,
    rule: CellRule,
    integrated: Option<crate::bake::cells::CellValues>,
}

impl MapPlan {
    /// Computes the clipped Voronoi cells (areas) and the discrete cells (for TVA).
    pub fn new(grid: &TexelGrid, offset_list: &[IVec2], rule: CellRule) -> Result<Self, BakeError> {
        let (w, h) = (grid.width, grid.height);
        let polys = offsets::clipped_cell_polygons(offset_list, w, h)?;
        Ok(Self {
            offsets: offset_list.to_vec(),
            cells: offsets::discrete_cells(offset_list, w, h)?,
            areas: polys.real_areas(),
            area_map: grid.area_map(),
            rule,
            integrated: None,
        })
    }

    /// For [`CellRule::Integrated`], integrates every cell at once (receiver-major, see
    /// [`crate::bake::cells`]); a phase of `height` steps. Nothing to do for
    /// [`CellRule::Sampled`], whose maps are computed one by one.
    pub fn prepare(
        &mut self,
        transport: &Transport,
        grid: &TexelGrid,
        events: &(dyn Fn(BakeEvent) + Sync),
    ) {
        if self.rule != CellRule::Integrated || self.integrated.is_some() {
            return;
        }
        events(BakeEvent::Phase {
            name: "integrating cells",
            total: grid.texels.len() as u64,
        });
        let t0 = std::time::Instant::now();
        let iv = crate::bake::cells::integrate(transport, grid, &self.offsets, &self.cells, &|n| {
            events(BakeEvent::Advance(n))
        });
        let st = &iv.stats;
        events(BakeEvent::Message(format!(
            "cells integrated in {:.2} s: {} near cluster pairs ({} texel pairs, {} of them \
             counted at a nearer site), {} far windows in one cell, {} split, {} counted at a \
             nearer site, {} receiver cells with an uncovered site moved to the receiver's cell; \
             {} links binned as {} sender nodes; {} subsurface sender nodes",
            t0.elapsed().as_secs_f64(),
            st.near_cluster_pairs,
            st.near_texel_pairs,
            st.rehomed,
            st.uniform_windows,
            st.split_windows,
            st.rehomed_far,
            st.moved_uncovered,
            st.links,
            st.link_nodes,
            st.subsurface_nodes
        )));
        self.integrated = Some(iv);
    }

    /// The `k`-th map.
    ///
    /// [`CellRule::Integrated`]: from [`MapPlan::prepare`]'s integration (run here, without
    /// progress events, if it has not been).
    /// [`CellRule::Sampled`]: small cells (at most [`EXACT_CELL_MAX`] integer offsets) and the
    /// cell holding the zero offset are summed exactly ([`compute_map_values_exact`]) — near
    /// `Δt = 0` the transfer is far from coherent in `Δt` (the subsurface profile and the form
    /// factors of neighbouring texels peak there and the texel's own term is a point mass) — and
    /// larger cells use Eq. 10 as in the paper.
    pub fn map(
        &mut self,
        transport: &Transport,
        grid: &TexelGrid,
        k: usize,
    ) -> Result<TransferMap, BakeError> {
        self.prepare(transport, grid, &|_| {});
        self.map_prepared(transport, grid, k)
    }

    /// A plan whose integrated cell values are already computed (a sharded bake's merge,
    /// [`crate::bake::shard`]): maps come from `values` without the transport.
    pub fn with_values(
        grid: &TexelGrid,
        offset_list: &[IVec2],
        values: crate::bake::cells::CellValues,
    ) -> Result<Self, BakeError> {
        let mut plan = Self::new(grid, offset_list, CellRule::Integrated)?;
        plan.integrated = Some(values);
        Ok(plan)
    }

    /// The `k`-th map from the integrated values ([`MapPlan::prepare`] or
    /// [`MapPlan::with_values`]).
    ///
    /// # Errors
    /// [`BakeError::Settings`] when there are none.
    pub fn integrated_map(&self, k: usize) -> Result<TransferMap, BakeError> {
        let Some(iv) = &self.integrated else {
            return Err(BakeError::Settings(
                "internal: MapPlan::integrated_map without integrated values".into(),
            ));
        };
        Ok(TransferMap::from_full(
            self.offsets[k],
            self.areas[k],
            iv.peak[k],
            &iv.map(k),
        )?)
    }

    /// The `k`-th map, without preparing: for [`CellRule::Integrated`], [`MapPlan::prepare`] must
    /// have run (else the map is computed by the sampled rule's code path, which is an error).
    ///
    /// # Errors
    /// [`BakeError::Settings`] when the integrated rule was not prepared.
    pub fn map_prepared(
        &self,
        transport: &Transport,
        grid: &TexelGrid,
        k: usize,
    ) -> Result<TransferMap, BakeError> {
        if self.rule == CellRule::Integrated && self.integrated.is_none() {
            return Err(BakeError::Settings(
                "internal: MapPlan::map_prepared before MapPlan::prepare".into(),
            ));
        }
        let (values, importance) = match &self.integrated {
            Some(iv) => (iv.map(k), iv.peak[k]),
            None => {
                let runs = &self.cells.real[k];
                let contains_origin = runs
                    .iter()
                    .any(|r| r.dy == 0 && r.dx_start <= 0 && 0 <= r.dx_end_inclusive);
                let members: usize = runs.iter().map(|r| r.len()).sum();
                if contains_origin || members <= EXACT_CELL_MAX {
                    compute_map_values_exact(transport, grid, self.offsets[k], runs)
                } else {
                    let tva = offsets::tva_map(&self.area_map, grid.width, grid.height, runs)?;
                    compute_map_values(transport, grid, self.offsets[k], &tva, false)
                }
            }
        };
        Ok(TransferMap::from_full(
            self.offsets[k],
            self.areas[k],
            importance,
            &values,
        )?)
    }
}

/// Writes `value` as pretty JSON with [`crate::io::write_atomic`] (temporary file, fsync, rename).
fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), BakeError> {
    let text = serde_json::to_vec_pretty(value).map_err(|e| BakeError::Io {
        path: path.to_owned(),
        source: std::io::Error::other(e),
    })?;
    crate::io::write_atomic(path, &text).map_err(|e| {
        MapsError::from(crate::io::FileError::io(
            "cannot write",
            path,
            crate::io::DirKind::Bake,
        )(e))
        .into()
    })
}

/// What every way of baking needs before the transport: the checked settings, the covered
/// texels and the bake's key.
pub(crate) struct Setup {
    /// Covered texels.
    pub grid: TexelGrid,
    /// Cluster size of the coarse solve (automatic resolved).
    pub block: u32,
    /// Clusters of the coarse solve: its lightmap tiles and at most `clusters − tiles` slit
    /// texels alone.
    pub clusters: usize,
    /// The lightmap tiles among [`Self::clusters`].
    pub tiles: usize,
    /// The cap on the slit texels the multi-resolution rows' coarse solve keeps alone
    /// ([`BakeSettings::slit_texels`], checked).
    pub max_slits: usize,
    /// Integrated cell values the bake will hold (memory estimate).
    pub cell_values: u64,
    /// The scene's hash.
    pub hash: String,
    /// The settings as recorded ([`BakeSettings::to_json`]).
    pub settings_json: serde_json::Value,
    /// The bake key (scene hash + settings).
    pub key: BakeKey,
}

impl Setup {
    /// Checks `settings` against the limits and rasterizes the texels.
    pub(crate) fn new(scene: &Scene, settings: &BakeSettings) -> Result<Self, BakeError> {
        if settings.offsets == 0 {
            return Err(BakeError::Settings("--offsets must be at least 1".into()));
        }
        settings.near_gather()?;
        let near = settings.near_field()?;
        let (w, h) = settings.size;
        crate::io::limits::check_bake_request(w, h, settings.offsets)
            .map_err(|e| BakeError::Settings(e.to_string()))?;
        crate::io::limits::check_lightmap_memory(w, h)
            .map_err(|e| BakeError::Settings(e.to_string()))?;
        let grid = TexelGrid::build_with_size(scene, w, h)?;
        if let Some(near) = near {
            let limit = crate::io::limits::memory_limit_bytes()
                .map_err(|e| BakeError::Settings(e.to_string()))?;
            near.check_memory(&grid, limit, (4, "a quarter of"))
                .map_err(|e| {
                    BakeError::Settings(format!(
                        "{e}, or turn the near field off (--near-field 1; `ortm bake` turns it \
                         on for skin's levels bakes)"
                    ))
                })?;
        }
        if let Some(rounds) = settings.balance_subsurface {
            if settings.tolerance.is_none() {
                return Err(BakeError::Settings(format!(
                    "--balance-subsurface {rounds} needs the hierarchical transport, whose \
                     subsurface walk takes the balanced weights: give --tolerance, or --levels \
                     without --coarse-block"
                )));
            }
            let limit = crate::io::limits::memory_limit_bytes()
                .map_err(|e| BakeError::Settings(e.to_string()))?;
            crate::bake::transport::check_balance(scene, &grid, settings.effects, rounds, limit)
                .map_err(|e| BakeError::Settings(format!("--balance-subsurface {rounds}: {e}")))?;
        }
        let block = match settings.coarse_block {
            0 => crate::bake::transport::coarse::auto_block(&grid),
            b => b,
        };
        // With the hierarchical operator the multi-resolution rows' coarse solve also keeps
        // slit texels alone (`Transport::build_hierarchical_with_slits`).
        let max_slits = settings.slit_texels()?;
        let slits = if settings.tolerance.is_some()
            && settings.levels.is_some()
            && settings.effects.radiosity
            && block > 1
        {
            max_slits.min(grid.texels.len())
        } else {
            0
        };
        let tiles = crate::bake::transport::coarse::cluster_count(&grid, block);
        let clusters = tiles + slits;
        let cell_values = match settings.cell_rule {
            CellRule::Integrated => grid.texels.len() as u64 * settings.offsets as u64,
            CellRule::Sampled => 0,
        };
        crate::io::limits::check_bake_memory(
            clusters as u64,
            grid.texels.len() as u64,
            block,
            cell_values,
        )
        .map_err(|e| BakeError::Settings(e.to_string()))?;
        let hash = scene_hash(scene);
        let settings_json = settings.to_json();
        let key = BakeKey::new(&hash, &settings_json);
        Ok(Self {
            grid,
            block,
            clusters,
            tiles,
            max_slits,
            cell_values,
            hash,
            settings_json,
            key,
        })
    }

    /// Builds the transport the settings ask for (with progress and cancellation).
    pub(crate) fn transport(
        &self,
        scene: &Scene,
        settings: &BakeSettings,
        events: &(dyn Fn(BakeEvent) + Sync),
        cancel: &AtomicBool,
    ) -> Result<Transport, BakeError> {
        let (grid, block, clusters, tiles) = (&self.grid, self.block, self.clusters, self.tiles);
        let (w, h) = settings.size;
        let links = match settings.tolerance {
            Some(t) => format!("; hierarchical first bounce at tolerance {t:e}"),
            None => String::new(),
        };
        let alone = match clusters - tiles {
            0 => String::new(),
            n => format!(" and up to {n} slit texels alone"),
        };
        events(BakeEvent::Message(format!(
            "{} covered texels at {w}x{h}; building the transport (BVH, coarse solve, {tiles} \
             clusters of {block}² texels{alone}{links})",
            grid.texels.len(),
        )));
        let interrupted = || BakeError::Interrupted {
            done: 0,
            total: settings.offsets,
        };
        let progress = SetupProgress::new(events, cancel);
        Ok(match settings.tolerance {
            None => Transport::build(scene, grid, settings.effects, block, &progress)
                .map_err(|_| interrupted())?,
            Some(tolerance) => {
                // The links may take what the memory limit leaves after the rest of the bake.
                let rest = crate::io::limits::bake_memory_bytes(
                    clusters as u64,
                    grid.texels.len() as u64,
                    self.cell_values,
                );
                let max_bytes = crate::io::limits::memory_limit_bytes()
                    .map_err(|e| BakeError::Settings(e.to_string()))?
                    .map(|l| l.saturating_sub(rest));
                let hs = hier::Settings {
                    tolerance,
                    subsurface_tolerance: settings.subsurface_tolerance,
                    max_bytes,
                    subsurface_balance_rounds: settings.balance_subsurface.unwrap_or(0),
                    ..hier::Settings::default()
                };
                // The slit texels for the multi-resolution rows; the offsets' cells take the
                // tiles alone (`Transport::build_hierarchical_with_slits`).
                let t = Transport::build_hierarchical_with_slits(
                    scene,
                    grid,
                    settings.effects,
                    block,
                    settings.levels.map(|_| self.max_slits),
                    &hs,
                    &progress,
                )
                .map_err(|e| match e {
                    hier::BuildError::Cancelled => interrupted(),
                    e @ hier::BuildError::TooLarge { .. } => BakeError::Settings(format!(
                        "{e} (--tolerance {tolerance:e}; the links may use the memory limit \
                             less the rest of the bake: physical memory or ORTM_MEMORY_LIMIT_BYTES)"
                    )),
                })?;
                let rem = &t.remainder;
                if rem.alone > 0 {
                    events(BakeEvent::Message(format!(
                        "coarse solve: {} clusters, {} of them slit texels alone",
                        rem.clusters.len(),
                        rem.alone
                    )));
                }
                t
            }
        })
    }
}

/// Bakes `scene` into `dir` (resumable; see the module docs). `cancel` is polled between maps.
pub fn bake(
    scene: &Scene,
    settings: &BakeSettings,
    dir: &Path,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<BakeSummary, BakeError> {
    let t0 = std::time::Instant::now();
    // Settings checked before the directory is made: a refused bake leaves nothing behind.
    let setup = Setup::new(scene, settings)?;
    // Held to the end: one writer per directory, and the stale-temp sweep only under it.
    let _lock = crate::io::DirLock::acquire(dir)?;
    let transport = setup.transport(scene, settings, events, cancel)?;
    let t_transport = t0.elapsed().as_secs_f64();
    let Setup {
        grid,
        hash,
        settings_json,
        key,
        ..
    } = setup;
    let (w, h) = settings.size;

    if let Some(tolerance) = settings.levels {
        let t = std::time::Instant::now();
        let all = 0..grid.texels.len() as u32;
        let near = NearFieldRows::build(
            scene,
            &transport,
            &grid,
            settings,
            all.clone(),
            events,
            cancel,
        )?;
        let entries = level_rows_in(
            &transport,
            &grid,
            tolerance,
            Some(&near),
            all,
            events,
            cancel,
        )?;
        drop(near);
        drop(transport);
        let written = write_level_entries(
            dir,
            &key,
            &grid,
            entries,
            (tolerance, settings.receiver_blocks),
            events,
            cancel,
        )?;
        let t_rows = t.elapsed().as_secs_f64() - written.write_seconds;
        let maps = written.entries.len();
        let (reused, stored_texels) = (written.reused, written.stored_texels);
        bake_index((w, h), hash, settings_json, written.entries).write(dir)?;
        return Ok(BakeSummary {
            maps,
            reused,
            seconds: [
                t_transport,
                t_rows,
                t0.elapsed().as_secs_f64() - t_transport - t_rows,
            ],
            texels: grid.texels.len(),
            stored_texels,
        });
    }

    let (offset_list, points) =
        saved_or_new_selection(dir, &key, &transport, &grid, settings, events)?;
    let t_select = t0.elapsed().as_secs_f64() - t_transport;

    let plan = MapPlan::new(&grid, &offset_list, settings.cell_rule)?;
    let written = write_maps(dir, &key, Some(transport), &grid, plan, events, cancel)?;
    let (reused, stored_texels) = (written.reused, written.stored_texels);
    finish_offset_bake(
        dir,
        (&grid, hash, settings_json),
        (&offset_list, &points),
        written,
    )?;
    Ok(BakeSummary {
        maps: offset_list.len(),
        reused,
        seconds: [
            t_transport,
            t_select,
            t0.elapsed().as_secs_f64() - t_transport - t_select,
        ],
        texels: grid.texels.len(),
        stored_texels,
    })
}

/// The end of an offset bake whose maps are written: the report pictures, then `index.json`
/// (last, so a directory with an index is a complete bake).
pub(crate) fn finish_offset_bake(
    dir: &Path,
    (grid, hash, settings_json): (&TexelGrid, String, serde_json::Value),
    (offset_list, points): (&[IVec2], &[[f64; 3]]),
    written: WrittenMaps,
) -> Result<(), BakeError> {
    let importance: Vec<f64> = written.entries.iter().map(|e| e.importance).collect();
    let index = bake_index(
        (grid.width, grid.height),
        hash,
        settings_json,
        written.entries,
    );
    crate::bake::report::write_bake_report(dir, grid, offset_list, &importance, points).map_err(
        |e| BakeError::Io {
            path: dir.join("report"),
            source: std::io::Error::other(e.to_string()),
        },
    )?;
    index.write(dir)?;
    Ok(())
}

/// The index of a finished bake of a `width × height` lightmap.
pub(crate) fn bake_index(
    (width, height): (u32, u32),
    scene_hash: String,
    settings: serde_json::Value,
    maps: Vec<bake_dir::MapEntry>,
) -> BakeIndex {
    BakeIndex::new(LightmapSize { width, height }, scene_hash, settings, maps)
}

/// The offsets and importance data points of the bake `key`: those saved in `dir`'s
/// `selection.json` when it belongs to the same bake and is plausible, else a new selection
/// ([`select_offsets`]), saved atomically.
pub(crate) fn saved_or_new_selection(
    dir: &Path,
    key: &BakeKey,
    transport: &Transport,
    grid: &TexelGrid,
    settings: &BakeSettings,
    events: &(dyn Fn(BakeEvent) + Sync),
) -> Result<(Vec<IVec2>, Vec<[f64; 3]>), BakeError> {
    let (w, h) = settings.size;
    let sel_path = dir.join(bake_dir::SELECTION_FILE_NAME);
    match bake_dir::read_selection(dir, key.as_str(), settings.offsets, (w, h))
        .map_err(MapsError::from)?
    {
        bake_dir::SavedSelection::Reuse(s) => {
            events(BakeEvent::Message(
                "reusing the saved offset selection".into(),
            ));
            return Ok((
                s.offsets.iter().map(|o| IVec2::from_array(*o)).collect(),
                s.data_points,
            ));
        }
        bake_dir::SavedSelection::Discard(why) => {
            events(BakeEvent::Message(format!(
                "{why}: not reused; selecting the offsets again"
            )));
        }
        bake_dir::SavedSelection::None => {}
    }
    let (o, p) = select_offsets(transport, grid, settings, events)?;
    write_json_atomic(
        &sel_path,
        &SelectionRecord::new(
            key.as_str(),
            o.iter().map(|v| v.to_array()).collect(),
            p.clone(),
        ),
    )?;
    Ok((o, p))
}

/// The maps of a bake directory after [`write_maps`].
pub(crate) struct WrittenMaps {
    /// Index entries, in offset order.
    pub(crate) entries: Vec<bake_dir::MapEntry>,
    /// Maps kept from an earlier run.
    pub(crate) reused: usize,
    /// Stored (cropped) texels over all maps.
    pub(crate) stored_texels: u64,
}

/// Writes every map of `plan` that `dir` does not already hold for the bake `key`
/// (stale temporary files are removed first). Maps are independent: they are computed,
/// cropped, encoded and written in parallel, each atomically, so an interruption (`cancel`)
/// leaves only whole maps behind, whatever the order. `transport` (none for a sharded bake's
/// merge, whose plan holds the values) is dropped once the integrated cell rule's values are
/// computed, before any map is written.
pub(crate) fn write_maps(
    dir: &Path,
    key: &BakeKey,
    mut transport: Option<Transport>,
    grid: &TexelGrid,
    mut plan: MapPlan,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<WrittenMaps, BakeError> {
    let offset_list = plan.offsets.clone();
    let scan = bake_dir::scan_finished_maps(dir, key, grid.width, grid.height)?;
    for p in &scan.stale_temp {
        let _ = std::fs::remove_file(p);
    }
    let total = offset_list.len();
    let is_finished = |k: usize, offset: IVec2| {
        scan.finished
            .get(&(k as u32))
            .is_some_and(|e| e.offset == offset.to_array())
    };
    if offset_list
        .iter()
        .enumerate()
        .any(|(k, &o)| !is_finished(k, o))
    {
        if cancel.load(Ordering::Relaxed) {
            return Err(BakeError::Interrupted { done: 0, total });
        }
        if let Some(transport) = &transport {
            plan.prepare(transport, grid, events);
        }
    }
    if plan.rule == CellRule::Integrated {
        // The maps come from the integrated values: the transport (links, patches, tree —
        // most of a large bake's memory) goes before the writers' buffers arrive.
        transport = None;
    }
    write_each(
        total,
        |k| {
            scan.finished
                .get(&(k as u32))
                .filter(|e| e.offset == offset_list[k].to_array())
        },
        |k| {
            let map = match &transport {
                Some(transport) => plan.map_prepared(transport, grid, k)?,
                None => plan.integrated_map(k)?,
            };
            let entry = bake_dir::write_map_file(dir, k as u32, &map, key)?;
            Ok((entry, map.stored_texels()))
        },
        events,
        cancel,
    )
}

/// Writes maps `0..total` in parallel, each atomically by `write(k)` (its index entry and stored
/// texels), except those `finished(k)` keeps from an earlier run; reports one step per map and
/// stops at `cancel`. An interruption leaves only whole maps behind, whatever the order.
fn write_each<'a>(
    total: usize,
    finished: impl Fn(usize) -> Option<&'a bake_dir::MapEntry> + Sync,
    write: impl Fn(usize) -> Result<(bake_dir::MapEntry, u64), BakeError> + Sync,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<WrittenMaps, BakeError> {
    events(BakeEvent::Phase {
        name: "writing transfer maps",
        total: total as u64,
    });
    let written = std::sync::atomic::AtomicUsize::new(0);
    // Many writers at once: each map's `fsync` would otherwise leave a core idle.
    let results: Vec<Result<(bake_dir::MapEntry, bool, u64), BakeError>> =
        crate::io::with_write_pool(|| {
            (0..total)
                .into_par_iter()
                .map(|k| {
                    if let Some(e) = finished(k) {
                        let stored = e.rects.iter().map(|r| r.area()).sum::<u64>();
                        events(BakeEvent::Advance(1));
                        return Ok((e.clone(), true, stored));
                    }
                    if cancel.load(Ordering::Relaxed) {
                        return Err(BakeError::Interrupted {
                            done: written.load(Ordering::Relaxed),
                            total,
                        });
                    }
                    let (entry, stored) = write(k)?;
                    written.fetch_add(1, Ordering::Relaxed);
                    events(BakeEvent::Advance(1));
                    Ok((entry, false, stored))
                })
                .collect()
        });
    gather_written(results, written.load(Ordering::Relaxed), total)
}

/// The near fields the settings ask for, of the receivers `receivers` (texel indices; the
/// other rows empty): the interreflection's gathered form factors and skin's near-field
/// weights, each `None` when off.
pub(crate) struct NearFieldRows {
    /// `ΔF` per receiver.
    pub gathered: Option<crate::bake::near_gather::FormFactorRows>,
    /// Skin's near-field weights.
    pub skin: Option<NearRows>,
}

impl NearFieldRows {
    /// Both near fields for `receivers`: the gathered form factors the settings ask for
    /// ([`BakeSettings::near_gather`], [`crate::bake::near_gather::form_factor_rows`]) and
    /// skin's near-field weights ([`BakeSettings::near_field`],
    /// [`crate::bake::near_field::near_rows`]).
    pub(crate) fn build(
        scene: &Scene,
        transport: &Transport,
        grid: &TexelGrid,
        settings: &BakeSettings,
        receivers: std::ops::Range<u32>,
        events: &(dyn Fn(BakeEvent) + Sync),
        cancel: &AtomicBool,
    ) -> Result<Self, BakeError> {
        let progress = SetupProgress::new(events, cancel);
        let gathered = match settings.near_gather()? {
            None => None,
            Some(gather) => Some({
                use crate::bake::near_gather::{self, GatherError};
                let t = std::time::Instant::now();
                let rows = near_gather::form_factor_rows(
                    scene,
                    grid,
                    &transport.patches,
                    &transport.kernels,
                    &transport.kernels.visibility,
                    gather,
                    receivers.clone(),
                    &progress,
                )
                .map_err(|e| match e {
                    GatherError::Cancelled => BakeError::Interrupted { done: 0, total: 0 },
                    e @ GatherError::TooLarge { .. } => BakeError::Settings(format!(
                        "--near-gather {}: {e} (a quarter of the memory limit: physical memory \
                         or ORTM_MEMORY_LIMIT_BYTES); give a smaller --near-gather-reach",
                        gather.rays_per_side
                    )),
                })?;
                events(BakeEvent::Message(format!(
                    "near gather: {}×{} rays per texel, near set within {} texel sizes, {} \
                     form-factor corrections, in {:.2} s",
                    gather.rays_per_side,
                    gather.rays_per_side,
                    gather.reach,
                    rows.iter().map(Vec::len).sum::<usize>(),
                    t.elapsed().as_secs_f64()
                )));
                rows
            }),
        };
        let skin = match settings.near_field()? {
            None => None,
            Some(near) => Some({
                use crate::bake::near_field::{self, NearFieldError};
                let t = std::time::Instant::now();
                let rows = near_field::near_rows(
                    scene,
                    grid,
                    &transport.kernels,
                    near,
                    receivers,
                    &progress,
                )
                .map_err(|e| match e {
                    NearFieldError::Cancelled => BakeError::Interrupted { done: 0, total: 0 },
                    NearFieldError::Texels(e) => BakeError::Texels(e),
                })?;
                events(BakeEvent::Message(format!(
                    "near field: {n}×{n} sub-texels per sender, senders within {} texels, {} skin \
                     pairs, in {:.2} s",
                    near.reach,
                    rows.rows.iter().map(Vec::len).sum::<usize>(),
                    t.elapsed().as_secs_f64(),
                    n = near.subdivision,
                )));
                rows
            }),
        };
        Ok(Self { gathered, skin })
    }
}

/// Every receiver's kept blocks at `tolerance` ([`crate::bake::multires`]): its row from the
/// hierarchical transport when the bake has one ([`crate::bake::multires::hierarchical_row`],
/// `--tolerance`), with the gathered near field's first bounce and skin's near field when
/// `near` holds them, else from the pair evaluator ([`Transport::r`], `n²`
/// evaluations with a visibility ray each), partitioned; `receivers` (texel indices), all of
/// them for a single-process bake, a shard's share for a sharded one ([`crate::bake::shard`]).
pub(crate) fn level_rows_in(
    transport: &Transport,
    grid: &TexelGrid,
    tolerance: f64,
    near: Option<&NearFieldRows>,
    receivers: std::ops::Range<u32>,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<Vec<Vec<crate::bake::multires::Entry>>, BakeError> {
    use crate::bake::multires::{self, MultiresSettings};
    check_level_tolerance(tolerance)?;
    let progress = SetupProgress::new(events, cancel);
    let settings = MultiresSettings {
        tolerance,
        ..MultiresSettings::default()
    };
    let gathered = near.and_then(|n| n.gathered.as_deref());
    let skin = near.and_then(|n| n.skin.as_ref());
    Ok(
        match (multires::hierarchical_row_with(transport, skin), gathered) {
            (Some(row), Some(g)) => {
                let row = multires::with_gathered_rows(transport, row, g);
                multires::partition_rows_in(grid, row, &[settings], receivers, &progress)
            }
            (Some(row), None) => {
                multires::partition_rows_in(grid, row, &[settings], receivers, &progress)
            }
            (None, _) => multires::partition_rows_in(
                grid,
                multires::transport_row(transport),
                &[settings],
                receivers,
                &progress,
            ),
        }
        .map_err(|_| BakeError::Interrupted { done: 0, total: 0 })?
        .remove(0),
    )
}

/// The largest `--slit-texels` a bake takes ([`BakeSettings::slit_texels`]).
pub const MAX_SLIT_TEXELS_FLAG: u32 = 32_768;

/// Refuses a `--levels` tolerance that is not a number ≥ 0.
pub(crate) fn check_level_tolerance(tolerance: f64) -> Result<(), BakeError> {
    if !(tolerance.is_finite() && tolerance >= 0.0) {
        return Err(BakeError::Settings(format!(
            "--levels {tolerance}: give a tolerance ≥ 0, e.g. 3e-3"
        )));
    }
    Ok(())
}

/// The multi-resolution maps of every receiver's kept blocks `entries` (grid texel order):
/// grouped into one map per level and offset — or with `receiver_blocks`, shared between
/// neighbouring receivers ([`crate::bake::multires::coarsen_receivers`] at the same tolerance)
/// and grouped into one map per receiver level, level and offset
/// ([`crate::bake::multires::to_block_maps`]) — and written like [`write_maps`] (in parallel,
/// each atomically; a finished map of the same bake key, index, offset, level, receiver level
/// and rectangles is kept: the rows are deterministic).
pub(crate) fn write_level_entries(
    dir: &Path,
    key: &BakeKey,
    grid: &TexelGrid,
    entries: Vec<Vec<crate::bake::multires::Entry>>,
    (tolerance, receiver_blocks): (f64, bool),
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<LevelMapsWritten, BakeError> {
    use crate::bake::multires;
    let maps = if receiver_blocks {
        let blocks = multires::coarsen_receivers(grid, &entries, tolerance);
        drop(entries);
        let (all, shared) = multires::shared_entries(grid, &blocks);
        let block_entries = blocks.iter().filter(|b| b.receiver_level > 0).count();
        events(BakeEvent::Message(format!(
            "receiver blocks: {shared} of {all} receiver entries ({:.1} % shared) in \
             {block_entries} block entries; {} entries in all",
            100.0 * shared as f64 / all.max(1) as f64,
            blocks.len()
        )));
        multires::to_block_maps(grid, &blocks)?
    } else {
        let maps = multires::to_maps(grid, &entries)?;
        drop(entries);
        maps
    };
    if maps.len() > crate::io::limits::MAX_OFFSETS {
        return Err(BakeError::Settings(format!(
            "--levels {tolerance:e} makes {} maps, more than the {} a bake may hold \
             (MAX_OFFSETS); give a larger tolerance",
            maps.len(),
            crate::io::limits::MAX_OFFSETS
        )));
    }
    let t = std::time::Instant::now();
    let scan = bake_dir::scan_finished_maps(dir, key, grid.width, grid.height)?;
    for p in &scan.stale_temp {
        let _ = std::fs::remove_file(p);
    }
    let w = write_each(
        maps.len(),
        |k| {
            scan.finished.get(&(k as u32)).filter(|e| {
                let m = &maps[k];
                e.offset == m.offset.to_array()
                    && e.level == m.level()
                    && e.receiver_level == m.receiver_level()
                    && e.rects == m.rects()
            })
        },
        |k| {
            let entry = bake_dir::write_map_file(dir, k as u32, &maps[k], key)?;
            Ok((entry, maps[k].stored_texels()))
        },
        events,
        cancel,
    )?;
    Ok(LevelMapsWritten {
        entries: w.entries,
        reused: w.reused,
        stored_texels: w.stored_texels,
        write_seconds: t.elapsed().as_secs_f64(),
    })
}

/// What [`write_level_entries`] wrote, and the seconds its writing took.
pub(crate) struct LevelMapsWritten {
    pub entries: Vec<bake_dir::MapEntry>,
    pub reused: usize,
    pub stored_texels: u64,
    pub write_seconds: f64,
}

/// Joins the per-map results of [`write_maps`] (in offset order). A failed map's error comes
/// first; else an interruption anywhere is reported with the `written` count.
fn gather_written(
    results: Vec<Result<(bake_dir::MapEntry, bool, u64), BakeError>>,
    written: usize,
    total: usize,
) -> Result<WrittenMaps, BakeError> {
    let mut out = WrittenMaps {
        entries: Vec::with_capacity(total),
        reused: 0,
        stored_texels: 0,
    };
    let mut interrupted = None;
    for r in results {
        match r {
            Ok((e, was_reused, texels)) => {
                out.reused += usize::from(was_reused);
                out.stored_texels += texels;
                out.entries.push(e);
            }
            Err(BakeError::Interrupted { .. }) => {
                interrupted = Some(BakeError::Interrupted {
                    done: written,
                    total,
                });
            }
            Err(e) => return Err(e),
        }
    }
    match interrupted {
        Some(e) => Err(e),
        None => Ok(out),
    }
}
