//! Transfer pass: the final lightmap from the first-order one (paper Eq. 9),
//! `final[t] = first_order[t] + Σ_pieces atlas[src + (t − dst)] · P_ℓ(⌊t / 2^ℓ⌋ + Δ)`, where a
//! piece of level `ℓ` ([`TransferPiece::level`]) reads block `⌊t/2^ℓ⌋ + Δ` of level `ℓ` of the
//! first-order pyramid ([`crate::pyramid`]); level 0 is the first-order map itself
//! (`first_order[t + Δt]`, the paper's form).
//!
//! # Data flow
//! Once: [`TransferPass::new`] builds pipelines for the chosen [`TransferPath`];
//! [`TransferPass::prepare`] uploads the atlases and turns the pieces into plain per-atlas
//! work with [`crate::schedule::build_schedule`] (blend) and
//! [`crate::schedule::build_tiles`] (compute). Per frame: [`TransferPass::encode`] records
//! the work reading the first-order texture (and, when some piece has level > 0, the packed
//! pyramid the pyramid pass wrote this frame, [`TransferInputs::pyramid`]) and writing
//! [`TransferOutput::final_lightmap_tex`]. Every path branches per piece (a flat value) between
//! the first-order read (level 0, unchanged) and the pyramid read at
//! `origin_ℓ + ⌊t/2^ℓ⌋ + Δ`; pieces are cropped so that read stays inside level `ℓ`
//! ([`crate::schedule`]).
//!
//! **Receiver blocks** ([`TransferPiece::receiver_level`] `r > 0`): such a piece writes one
//! value per `2^r × 2^r` block into the grid `G_r`, which lives below the lightmap in a taller
//! accumulation target ([`crate::schedule`], "Receiver blocks"). Both paths then *resolve*:
//! `final[t] = acc[t] + Σ_r G_r(⌊t/2^r⌋)` at covered texels (first-order alpha > 0) —
//! `shaders/transfer_resolve.wgsl` (one full-screen draw) in the blend path, `cs_resolve` in
//! the compute path. Without receiver blocks the target is the lightmap and nothing changes.
//!
//! - **Blend path** (`shaders/transfer.wgsl`, the paper's method): a full-screen draw copies
//!   first-order RGBA (alpha = coverage) into the accumulation target; then per atlas one
//!   instanced draw of all its pieces — a quad per piece rasterised at `dst`, reading the
//!   atlas and first-order texels with `textureLoad`, blended additively (One + One).
//! - **Paired pieces** (blend path with [`TransferOptions::pair_pieces`], the default of
//!   [`TransferOptions::best_for`]; `shaders/transfer_pair.wgsl`, [`crate::pairing`]):
//!   overlapping pieces drawn two per quad from binary16 pair pages (one pair fetch, two
//!   first-order fetches, one blend per fragment); unpaired pieces as above.
//! - **Compute path** (`shaders/transfer_gather.wgsl`, [`crate::transfer_gather`]): per atlas
//!   one dispatch, one workgroup per non-empty 8×8 tile gathering the pieces covering it into
//!   an RGBA32F storage buffer; no blending, no atomics. Same result up to float summation
//!   order.
//! - **Rows path** (`shaders/transfer_rows.wgsl`, [`crate::rows`], [`crate::transfer_rows`]):
//!   the pieces turned around once per scene into every texel's row of `(weight, source)`
//!   entries (the source: the first-order map and the packed pyramid, copied into one texture
//!   each frame); one invocation per texel sums its row. Receiver blocks need no resolve:
//!   their entries sit in the rows of the blocks' texels. Same result up to float summation
//!   order and the rows' pruning ([`TransferOptions::rows_prune`]: none by default, a bound
//!   `τ` of each row's weight in `best_for`); the default on CPU adapters
//!   ([`TransferOptions::best_for`]).
//!
//! # Accumulation format
//! [`AccumFormat::Rgba32Float`] needs the `FLOAT32_BLENDABLE` feature in the blend path
//! (lavapipe and most desktop GPUs have it; [`TransferOptions::best_for`] checks).
//! [`AccumFormat::Rgba16Float`] is always blendable but rounds after every blend: with unit
//! roundoff `u = 2⁻¹¹` and `n` blends into a texel, the error is at most
//! `≈ (n + 1)·u·Σ|terms|` (each partial sum rounded once, plus the rounding of each term),
//! i.e. ~1e-3 relative after one or two blends and ~1e-2 after ~20 — plus half-float's
//! range (max 65504 W/m²). See `docs/render.md` for measured error and speed.
//!
//! # Conventions and units
//! Texel `(x, y)`, `y` down, row 0 = `v = 1`; `Δt` in texels. Lightmaps in W/m² (radiosity),
//! atlas values dimensionless. The output keeps the first-order alpha (coverage).
//!
//! # Limits
//! Atlases are uploaded as RGBA32F (16 bytes per texel). Each atlas must fit the device's
//! 2D texture limit.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::pairing::{PairInstance, PairedSchedule, pair_schedule};
use crate::pyramid::PyramidScene;
use crate::rows::build_rows_pruned;
use crate::schedule::{FrameSchedule, build_schedule};
use crate::transfer_gather::{GatherPass, GatherScene};
use crate::transfer_rows::{RowsPass, RowsScene};
use crate::types::{AtlasData, TransferPiece};
use crate::util;

/// Which implementation accumulates the pieces.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum TransferPath {
    /// Instanced quads with additive blending (the paper's method).
    #[default]
    Blend,
    /// Compute shader gathering per tile (no blending).
    Compute,
    /// Compute shader summing each texel's row of (weight, source) entries, the maps turned
    /// around once per scene ([`crate::rows`], [`crate::transfer_rows`]).
    Rows,
}

/// Format of the blend path's accumulation target (and so of its final lightmap).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum AccumFormat {
    /// 32-bit float; needs `FLOAT32_BLENDABLE`.
    #[default]
    Rgba32Float,
    /// 16-bit float; always blendable, ~3 decimal digits.
    Rgba16Float,
}

impl AccumFormat {
    /// The wgpu texture format.
    pub fn texture_format(self) -> wgpu::TextureFormat {
        match self {
            AccumFormat::Rgba32Float => wgpu::TextureFormat::Rgba32Float,
            AccumFormat::Rgba16Float => wgpu::TextureFormat::Rgba16Float,
        }
    }
}

/// Settings fixed at creation.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TransferOptions {
    /// Blend or compute accumulation.
    pub path: TransferPath,
    /// Accumulation format of the blend path (the compute path always uses RGBA32F).
    pub accum_format: AccumFormat,
    /// Blend path only: draw overlapping pieces two per quad ([`crate::pairing`]): one
    /// binary16 pair-texel fetch, two first-order fetches and one blend per fragment. Values
    /// rounded to binary16 with a per-piece power-of-two scale (relative error ≤ 2⁻¹¹, see
    /// the module docs of `pairing`). On in [`TransferOptions::best_for`], off in `default()`
    /// (exact f32 atlases); see `docs/render.md` for its speed.
    pub pair_pieces: bool,
    /// Blend path only: how the fragment shaders read the first-order map, the atlases and
    /// the pair pages. [`util::TexelReads::Storage`] needs
    /// [`Gpu::supports_storage_reads`]; same values, and on lavapipe much cheaper
    /// (`docs/render.md`). `best_for` takes [`Gpu::best_texel_reads`].
    pub texel_reads: util::TexelReads,
    /// Rows path only: each texel's row pruned at this `τ` ([`crate::rows`], "Pruning": its
    /// transfer changes by at most `τ · Σ|w| · max source`). [`crate::rows::ROWS_PRUNE`] in
    /// [`TransferOptions::best_for`], 0 (every entry) in `default()`.
    pub rows_prune: f32,
}

impl TransferOptions {
    /// The fastest measured settings for `gpu` (`docs/render.md`, `ortm bench render`):
    /// - path: [`TransferPath::Rows`] on a CPU adapter (lavapipe, `ortm bench render --paths
    ///   all`: 15.1 ms against 17.9 ms for the paired blend path and 67.2 ms for the compute
    ///   path with 100 offsets at 256², 22.3 ms against 166.9 ms and 371.2 ms for the head's
    ///   multi-resolution maps at 256²), [`TransferPath::Compute`] on hardware GPUs (H100:
    ///   0.12 ms vs 1.27 ms for the paired blend path; its few raster back-ends blend slowly;
    ///   the rows path not measured there yet);
    /// - blend accumulation in RGBA32F when the device can blend it, else RGBA16F;
    /// - paired pieces (~28 % less transfer CPU on lavapipe at 256²/100);
    /// - read-only storage textures where the device has them ([`Gpu::best_texel_reads`]);
    /// - rows pruned at [`crate::rows::ROWS_PRUNE`] (on lavapipe the rows pass ~6 % faster, 8 %
    ///   less CPU, for the head's maps at 256², whose indirect light moves 0.08 % RMS;
    ///   `docs/render.md`, "Rows pruning").
    pub fn best_for(gpu: &Gpu) -> Self {
        Self {
            path: if gpu.adapter_info.device_type == wgpu::DeviceType::Cpu {
                TransferPath::Rows
            } else {
                TransferPath::Compute
            },
            accum_format: if gpu.supports_float32_blend() {
                AccumFormat::Rgba32Float
            } else {
                AccumFormat::Rgba16Float
            },
            pair_pieces: true,
            texel_reads: gpu.best_texel_reads(),
            rows_prune: crate::rows::ROWS_PRUNE,
        }
    }
}

/// The uniform and the target layout shared by every transfer shader, prepended to each.
pub(crate) const PARAMS_WGSL: &str = include_str!("../shaders/transfer_params.wgsl");

/// The quad vertex code shared by `transfer.wgsl` and `transfer_pair.wgsl`, prepended to
/// each (after [`PARAMS_WGSL`]).
const QUAD_WGSL: &str = include_str!("../shaders/transfer_quad.wgsl");

/// Uniform of every transfer shader. 32 bytes.
/// Must match `Params` in `shaders/transfer_params.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct TransferParams {
    /// Accumulation target `[width, height]` ([`crate::schedule::target_size`]).
    pub target_size: [u32; 2],
    /// Lightmap `[width, height]`.
    pub lightmap_size: [u32; 2],
    /// `R`, the highest receiver level (0: no receiver blocks).
    pub receiver_levels: u32,
    /// Padding to 32 bytes.
    pub _pad: [u32; 3],
}

impl TransferParams {
    /// The uniform of `schedule`.
    pub fn of(schedule: &FrameSchedule) -> Self {
        Self {
            target_size: schedule.target_size(),
            lightmap_size: schedule.lightmap_size,
            receiver_levels: schedule.receiver_levels,
            _pad: [0; 3],
        }
    }
}

/// Blend-path pipelines.
#[derive(Debug)]
struct BlendPipelines {
    /// group 0: params + first-order texture.
    frame_layout: wgpu::BindGroupLayout,
    /// group 1: atlas.
    atlas_layout: wgpu::BindGroupLayout,
    copy: wgpu::RenderPipeline,
    piece: wgpu::RenderPipeline,
    /// Receiver blocks: group 0 layout (params + accumulation target) and the resolve
    /// pipeline (`shaders/transfer_resolve.wgsl`).
    resolve: (wgpu::BindGroupLayout, wgpu::RenderPipeline),
    /// Paired pieces (with `TransferOptions::pair_pieces`): group 1 layout and pipeline.
    pair: Option<(wgpu::BindGroupLayout, wgpu::RenderPipeline)>,
}

/// The transfer pass (either path).
#[derive(Debug)]
pub struct TransferPass {
    options: TransferOptions,
    blend: Option<BlendPipelines>,
    gather: Option<GatherPass>,
    rows: Option<RowsPass>,
}

/// Per-scene GPU data: atlases, the schedule and its buffers, the output texture.
#[derive(Debug)]
pub struct TransferScene {
    /// The frame's work as plain data.
    pub schedule: FrameSchedule,
    params: wgpu::Buffer,
    atlas_views: Vec<wgpu::TextureView>,
    /// Instance buffer per batch (blend path).
    instance_buffers: Vec<wgpu::Buffer>,
    /// Compute-path data.
    gather: Option<GatherScene>,
    /// Rows-path data.
    pub rows: Option<RowsScene>,
    /// Paired pieces (blend path with `TransferOptions::pair_pieces`); `None` otherwise.
    /// The pages' `texels` are emptied once uploaded (they live on the GPU);
    /// [`pair_schedule`] on `schedule` rebuilds them (deterministic) for a CPU mirror.
    pub paired: Option<PairedSchedule>,
    /// Paired path: views of the pair pages, instance buffers per page, instance buffers of
    /// the unpaired pieces per batch of `paired.singles`.
    pair_gpu: Option<PairGpu>,
    /// A 1×1 texture bound as the pyramid when no piece has level > 0 (never read).
    dummy_pyramid: wgpu::TextureView,
    /// Blend path with receiver blocks: a view of the accumulation target (lightmap + `G_r`
    /// grids) the pieces draw into, and the resolve's bind group reading it (both fixed per
    /// scene); `None` otherwise (the pieces draw into `final_tex`).
    accum: Option<(wgpu::TextureView, wgpu::BindGroup)>,
    final_tex: wgpu::Texture,
}

impl TransferScene {
    /// The final lightmap the last `encode` wrote (accumulation format).
    pub fn output(&self) -> &wgpu::Texture {
        &self.final_tex
    }

    /// The highest piece level (0: no pyramid needed).
    pub fn max_level(&self) -> u32 {
        self.schedule.max_level()
    }
}

/// GPU objects of the paired path.
#[derive(Debug)]
struct PairGpu {
    page_views: Vec<wgpu::TextureView>,
    page_buffers: Vec<wgpu::Buffer>,
    single_buffers: Vec<wgpu::Buffer>,
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct TransferInputs<'a> {
    /// Prepared scene.
    pub scene: &'a TransferScene,
    /// First-order lightmap (RGBA, alpha = coverage), the size given to `prepare`: what the
    /// pieces multiply.
    pub first_order: &'a wgpu::TextureView,
    /// The first-order term the final starts from, when it is not `first_order` (same size
    /// and coverage): the centres' first order when `first_order` is averaged over the
    /// texels' squares ([`crate::first_order::FirstOrderScene::transfer_input`]).
    pub base: Option<&'a wgpu::TextureView>,
    /// The first-order pyramid (written this frame by [`crate::pyramid::PyramidPass`] from
    /// `first_order`), holding at least the highest piece level; required when some piece has
    /// level > 0, ignored otherwise.
    pub pyramid: Option<&'a PyramidScene>,
}

/// Output of the pass.
#[derive(Clone, Debug)]
pub struct TransferOutput {
    /// `first_order + Σ transfer` (RGB W/m², alpha = coverage), owned by the scene and
    /// overwritten every frame.
    pub final_lightmap_tex: wgpu::Texture,
}

impl TransferPass {
    /// Builds the pipelines of `options.path`.
    ///
    /// Errors: [`PassError::MissingFeature`] for RGBA32F blending without
    /// `FLOAT32_BLENDABLE` or storage-texture reads the device lacks; [`PassError::Gpu`] when
    /// pipeline creation fails.
    pub fn new(gpu: &Gpu, options: &TransferOptions) -> Result<Self, PassError> {
        if options.path == TransferPath::Blend
            && options.accum_format == AccumFormat::Rgba32Float
            && !gpu.supports_float32_blend()
        {
            return Err(PassError::MissingFeature {
                option: "TransferOptions.accum_format = Rgba32Float".into(),
                feature: "FLOAT32_BLENDABLE".into(),
                adapter: gpu.adapter_info.name.clone(),
                fallback: "AccumFormat::Rgba16Float or TransferPath::Compute".into(),
            });
        }
        if options.path == TransferPath::Blend
            && options.texel_reads == util::TexelReads::Storage
            && !gpu.supports_storage_reads()
        {
            return Err(PassError::MissingFeature {
                option: "TransferOptions.texel_reads = Storage".into(),
                feature: "read-only storage textures in fragment shaders".into(),
                adapter: gpu.adapter_info.name.clone(),
                fallback: "TexelReads::Sampled".into(),
            });
        }
        match options.path {
            TransferPath::Blend => {
                let blend = gpu.scoped("ortm.transfer.new", || {
                    Self::blend_pipelines(
                        &gpu.device,
                        options.accum_format.texture_format(),
                        options.pair_pieces,
                        options.texel_reads,
                    )
                })?;
                Ok(Self {
                    options: *options,
                    blend: Some(blend),
                    gather: None,
                    rows: None,
                })
            }
            TransferPath::Compute => Ok(Self {
                options: *options,
                blend: None,
                gather: Some(GatherPass::new(gpu)?),
                rows: None,
            }),
            TransferPath::Rows => Ok(Self {
                options: *options,
                blend: None,
                gather: None,
                rows: Some(RowsPass::new(gpu)?),
            }),
        }
    }

    /// The options the pass was created with.
    pub fn options(&self) -> &TransferOptions {
        &self.options
    }

    fn blend_pipelines(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        pair_pieces: bool,
        reads: util::TexelReads,
    ) -> BlendPipelines {
        let f32x4 = wgpu::TextureFormat::Rgba32Float;
        let module = util::shader(
            device,
            "ortm.transfer.shader",
            &format!(
                "{}{PARAMS_WGSL}{}{}{}{QUAD_WGSL}{}",
                util::FULLSCREEN_WGSL,
                reads.wgsl(0, 1, "first_order", f32x4),
                reads.wgsl(0, 2, "pyramid", f32x4),
                reads.wgsl(1, 0, "atlas", f32x4),
                include_str!("../shaders/transfer.wgsl")
            ),
        );
        let fs = wgpu::ShaderStages::FRAGMENT;
        // Order = @binding order in transfer.wgsl.
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ortm.transfer.frame_layout"),
            entries: &[
                util::uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT),
                reads.entry(1, fs, f32x4),
                reads.entry(2, fs, f32x4),
            ],
        });
        let atlas_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ortm.transfer.atlas_layout"),
            entries: &[reads.entry(0, fs, f32x4)],
        });
        let copy_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ortm.transfer.copy_pipeline_layout"),
            bind_group_layouts: &[Some(&frame_layout)],
            immediate_size: 0,
        });
        let piece_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ortm.transfer.piece_pipeline_layout"),
            bind_group_layouts: &[Some(&frame_layout), Some(&atlas_layout)],
            immediate_size: 0,
        });
        let copy = util::fullscreen_pipeline(
            device,
            "ortm.transfer.copy_pipeline",
            Some(&copy_layout),
            &module,
            "fs_copy",
            format,
            None,
        );
        let piece = util::colour_pipeline(
            device,
            "ortm.transfer.piece_pipeline",
            Some(&piece_layout),
            &module,
            (
                "vs_piece",
                // Must match `PieceInstance` (schedule.rs) and `PieceIn` (transfer.wgsl).
                &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<crate::schedule::PieceInstance>() as u64,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &wgpu::vertex_attr_array![
                        0 => Uint32x2, 1 => Uint32x2, 2 => Uint32x2, 3 => Sint32x2,
                        4 => Uint32x2, 5 => Uint32x2, 6 => Uint32x2
                    ],
                })],
            ),
            "fs_piece",
            format,
            Some(util::ADDITIVE),
        );
        let pair = pair_pieces.then(|| Self::pair_pipeline(device, format, &frame_layout, reads));
        BlendPipelines {
            frame_layout,
            atlas_layout,
            copy,
            piece,
            pair,
            resolve: Self::resolve_pipeline(device, format),
        }
    }

    /// The receiver-block resolve (`shaders/transfer_resolve.wgsl`): its group 0 layout and
    /// full-screen pipeline writing the final lightmap in `format`.
    fn resolve_pipeline(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
    ) -> (wgpu::BindGroupLayout, wgpu::RenderPipeline) {
        let module = util::shader(
            device,
            "ortm.transfer.resolve_shader",
            &format!(
                "{}{PARAMS_WGSL}{}",
                util::FULLSCREEN_WGSL,
                include_str!("../shaders/transfer_resolve.wgsl")
            ),
        );
        let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ortm.transfer.resolve_layout"),
            entries: &[
                util::uniform_entry(0, wgpu::ShaderStages::FRAGMENT),
                util::texture_entry(1, wgpu::ShaderStages::FRAGMENT),
            ],
        });
        let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ortm.transfer.resolve_pipeline_layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let pipeline = util::fullscreen_pipeline(
            device,
            "ortm.transfer.resolve_pipeline",
            Some(&pipeline_layout),
            &module,
            "fs_resolve",
            format,
            None,
        );
        (layout, pipeline)
    }

    fn pair_pipeline(
        device: &wgpu::Device,
        format: wgpu::TextureFormat,
        frame_layout: &wgpu::BindGroupLayout,
        reads: util::TexelReads,
    ) -> (wgpu::BindGroupLayout, wgpu::RenderPipeline) {
        let page_format = wgpu::TextureFormat::Rgba32Uint;
        let module = util::shader(
            device,
            "ortm.transfer.pair_shader",
            &format!(
                "{PARAMS_WGSL}{}{}{}{QUAD_WGSL}{}",
                reads.wgsl(0, 1, "first_order", wgpu::TextureFormat::Rgba32Float),
                reads.wgsl(0, 2, "pyramid", wgpu::TextureFormat::Rgba32Float),
                reads.wgsl(1, 0, "page", page_format),
                include_str!("../shaders/transfer_pair.wgsl")
            ),
        );
        let page_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ortm.transfer.page_layout"),
            entries: &[reads.entry(0, wgpu::ShaderStages::FRAGMENT, page_format)],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ortm.transfer.pair_pipeline_layout"),
            bind_group_layouts: &[Some(frame_layout), Some(&page_layout)],
            immediate_size: 0,
        });
        let pipeline = util::colour_pipeline(
            device,
            "ortm.transfer.pair_pipeline",
            Some(&layout),
            &module,
            (
                "vs_pair",
                // Must match `PairInstance` (pairing.rs) and `PairIn` (transfer_pair.wgsl).
                &[Some(wgpu::VertexBufferLayout {
                    array_stride: std::mem::size_of::<PairInstance>() as u64,
                    step_mode: wgpu::VertexStepMode::Instance,
                    attributes: &wgpu::vertex_attr_array![
                        0 => Uint32x2, 1 => Uint32x2, 2 => Uint32x2, 3 => Sint32x2,
                        4 => Sint32x2, 5 => Float32x2, 6 => Uint32x2, 7 => Uint32x2
                    ],
                })],
            ),
            "fs_pair",
            format,
            Some(util::ADDITIVE),
        );
        (page_layout, pipeline)
    }

    /// Uploads atlases, validates and schedules the pieces, allocates the output.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        lightmap_size: [u32; 2],
        atlases: &[AtlasData],
        pieces: &[TransferPiece],
    ) -> Result<TransferScene, PassError> {
        gpu.check_texture_size("lightmap", lightmap_size[0], lightmap_size[1])?;
        let sizes = atlas_sizes(atlases)?;
        let schedule = build_schedule(lightmap_size, &sizes, pieces)?;
        let device = &gpu.device;
        // The rows path holds the maps' values in its rows: no atlas on the GPU.
        let atlas_views = if self.options.path == TransferPath::Rows {
            Vec::new()
        } else {
            self.upload_atlases(gpu, atlases)?
        };
        let target = schedule.target_size();
        if schedule.receiver_levels > 0 {
            gpu.check_texture_size("transfer accumulation target", target[0], target[1])?;
        }
        let params = util::buffer_init(
            device,
            "ortm.transfer.params",
            bytemuck::bytes_of(&TransferParams::of(&schedule)),
            wgpu::BufferUsages::UNIFORM,
        );
        let (instance_buffers, gather, rows, final_tex, accum) = match self.options.path {
            TransferPath::Blend => {
                let bufs = instance_buffers(device, "instances", &schedule.batches);
                let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC;
                let format = self.options.accum_format.texture_format();
                let tex = util::texture_2d(
                    device,
                    "ortm.transfer.final_lightmap",
                    lightmap_size,
                    format,
                    usage,
                );
                let accum = (schedule.receiver_levels > 0)
                    .then(|| {
                        let t = util::texture_2d(
                            device,
                            "ortm.transfer.accumulation",
                            target,
                            format,
                            usage,
                        );
                        self.resolve_bind_group(device, &params, util::view(&t))
                    })
                    .transpose()?;
                (bufs, None, None, tex, accum)
            }
            TransferPath::Compute => {
                let g = self
                    .gather
                    .as_ref()
                    .ok_or_else(|| PassError::InvalidInput {
                        what: "TransferPass".into(),
                        problem: "compute path without its pipelines (internal bug)".into(),
                    })?;
                let (scene, tex) = g.prepare(gpu, &schedule, &params)?;
                (Vec::new(), Some(scene), None, tex, None)
            }
            TransferPath::Rows => {
                let r = self.rows.as_ref().ok_or_else(|| PassError::InvalidInput {
                    what: "TransferPass".into(),
                    problem: "rows path without its pipelines (internal bug)".into(),
                })?;
                let (scene, tex) = r.prepare(
                    gpu,
                    &build_rows_pruned(&schedule, atlases, self.options.rows_prune)?,
                )?;
                (Vec::new(), None, Some(scene), tex, None)
            }
        };
        let (paired, pair_gpu) = self.prepare_pairs(gpu, &schedule, atlases)?;
        let dummy_pyramid = util::view(&gpu.create_rgba32f_texture(
            "ortm.transfer.dummy_pyramid",
            1,
            1,
            &[[0.0; 4]],
            wgpu::TextureUsages::TEXTURE_BINDING | self.options.texel_reads.usage(),
        )?);
        gpu.check("ortm.transfer.prepare")?;
        Ok(TransferScene {
            schedule,
            params,
            atlas_views,
            instance_buffers,
            gather,
            rows,
            paired,
            pair_gpu,
            dummy_pyramid,
            accum,
            final_tex,
        })
    }

    /// The blend path's accumulation target `view` with the resolve's bind group reading it
    /// (`params` + the target, `shaders/transfer_resolve.wgsl`).
    fn resolve_bind_group(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        view: wgpu::TextureView,
    ) -> Result<(wgpu::TextureView, wgpu::BindGroup), PassError> {
        let bp = self.blend.as_ref().ok_or_else(|| PassError::InvalidInput {
            what: "TransferPass".into(),
            problem: "blend path without its pipelines (internal bug)".into(),
        })?;
        let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.transfer.resolve_bind_group"),
            layout: &bp.resolve.0,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&view),
                },
            ],
        });
        Ok((view, bg))
    }

    /// One RGBA32F texture per atlas (RGB, A = 0); returns their views.
    fn upload_atlases(
        &self,
        gpu: &Gpu,
        atlases: &[AtlasData],
    ) -> Result<Vec<wgpu::TextureView>, PassError> {
        let mut atlas_views = Vec::with_capacity(atlases.len());
        for (i, a) in atlases.iter().enumerate() {
            let rgba: Vec<[f32; 4]> = a.rgb.iter().map(|c| [c[0], c[1], c[2], 0.0]).collect();
            let tex = gpu.create_rgba32f_texture(
                &format!("ortm.transfer.atlas{i}"),
                a.width,
                a.height,
                &rgba,
                // The compute path reads atlases as sampled textures.
                wgpu::TextureUsages::TEXTURE_BINDING | self.options.texel_reads.usage(),
            )?;
            atlas_views.push(util::view(&tex));
        }
        Ok(atlas_views)
    }

    /// The paired schedule and its GPU objects (blend path with `pair_pieces`; `None`s
    /// otherwise). The pages' texels are dropped once uploaded.
    fn prepare_pairs(
        &self,
        gpu: &Gpu,
        schedule: &FrameSchedule,
        atlases: &[AtlasData],
    ) -> Result<(Option<PairedSchedule>, Option<PairGpu>), PassError> {
        if self.options.path != TransferPath::Blend || !self.options.pair_pieces {
            return Ok((None, None));
        }
        let limit = gpu.device.limits().max_texture_dimension_2d;
        let mut paired = pair_schedule(schedule, atlases, limit)?;
        let g = Self::upload_pairs(gpu, &paired, self.options.texel_reads)?;
        for page in &mut paired.pages {
            page.texels = Vec::new();
        }
        Ok((Some(paired), Some(g)))
    }

    fn upload_pairs(
        gpu: &Gpu,
        paired: &PairedSchedule,
        reads: util::TexelReads,
    ) -> Result<PairGpu, PassError> {
        let device = &gpu.device;
        let mut page_views = Vec::with_capacity(paired.pages.len());
        let mut page_buffers = Vec::with_capacity(paired.pages.len());
        for (i, p) in paired.pages.iter().enumerate() {
            let label = format!("ortm.transfer.pair_page{i}");
            gpu.check_texture_size(&label, p.width, p.height)?;
            let tex = util::texture_2d(
                device,
                &label,
                [p.width, p.height],
                wgpu::TextureFormat::Rgba32Uint,
                reads.usage() | wgpu::TextureUsages::COPY_DST,
            );
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &tex,
                    mip_level: 0,
                    origin: wgpu::Origin3d::ZERO,
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(&p.texels),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(p.width * 16),
                    rows_per_image: Some(p.height),
                },
                wgpu::Extent3d {
                    width: p.width,
                    height: p.height,
                    depth_or_array_layers: 1,
                },
            );
            page_views.push(util::view(&tex));
            page_buffers.push(util::buffer_init(
                device,
                &format!("ortm.transfer.pair_instances{i}"),
                bytemuck::cast_slice(&p.instances),
                wgpu::BufferUsages::VERTEX,
            ));
        }
        let single_buffers = instance_buffers(device, "single_instances", &paired.singles.batches);
        Ok(PairGpu {
            page_views,
            page_buffers,
            single_buffers,
        })
    }

    /// Records the frame's transfer work into `encoder`. `inputs.scene` must come from
    /// this pass's [`TransferPass::prepare`] (a scene of the other path records nothing).
    ///
    /// Errors: [`PassError::InvalidInput`] when some piece has level > 0 and
    /// `inputs.pyramid` is missing, of another lightmap size, or lacks that level.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &TransferInputs<'_>,
    ) -> Result<TransferOutput, PassError> {
        let device = &gpu.device;
        let scene = inputs.scene;
        let pyramid = Self::pyramid_view(inputs)?;
        if let (Some(g), Some(gs)) = (&self.gather, &scene.gather) {
            g.encode(
                device,
                encoder,
                gs,
                (inputs.first_order, inputs.base, pyramid),
                &scene.atlas_views,
            );
        } else if let (Some(r), Some(rs)) = (&self.rows, &scene.rows) {
            r.encode(
                device,
                encoder,
                rs,
                (inputs.first_order, inputs.base, pyramid),
            );
        } else if let Some(bp) = &self.blend {
            self.encode_blend(bp, device, encoder, inputs, pyramid);
        }
        Ok(TransferOutput {
            final_lightmap_tex: scene.final_tex.clone(),
        })
    }

    /// The pyramid view to bind: the scene's dummy when every piece has level 0, else
    /// `inputs.pyramid`'s after checking it holds the pieces' levels.
    fn pyramid_view<'a>(inputs: &TransferInputs<'a>) -> Result<&'a wgpu::TextureView, PassError> {
        let scene = inputs.scene;
        let need = scene.max_level();
        if need == 0 {
            return Ok(&scene.dummy_pyramid);
        }
        let size = scene.schedule.lightmap_size;
        match inputs.pyramid {
            Some(p) if p.max_level() >= need && p.lightmap_size() == size => Ok(p.view()),
            Some(p) => Err(PassError::InvalidInput {
                what: "TransferInputs.pyramid".into(),
                problem: format!(
                    "holds levels 1..={} of a {:?} lightmap but the pieces need level {need} of \
                     a {size:?} one; prepare the pyramid for these pieces",
                    p.max_level(),
                    p.lightmap_size()
                ),
            }),
            None => Err(PassError::InvalidInput {
                what: "TransferInputs.pyramid".into(),
                problem: format!(
                    "is missing but some pieces read pyramid level {need}; pieces of level > 0 \
                     need the first-order pyramid (give texel weights, e.g. \
                     `Renderer::prepare_with_weights`)"
                ),
            }),
        }
    }

    fn encode_blend(
        &self,
        bp: &BlendPipelines,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &TransferInputs<'_>,
        pyramid: &wgpu::TextureView,
    ) {
        let scene = inputs.scene;
        // Order = @binding order in transfer.wgsl.
        let frame_bind_group = |first_order| {
            device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("ortm.transfer.frame_bind_group"),
                layout: &bp.frame_layout,
                entries: &[
                    wgpu::BindGroupEntry {
                        binding: 0,
                        resource: scene.params.as_entire_binding(),
                    },
                    wgpu::BindGroupEntry {
                        binding: 1,
                        resource: wgpu::BindingResource::TextureView(first_order),
                    },
                    wgpu::BindGroupEntry {
                        binding: 2,
                        resource: wgpu::BindingResource::TextureView(pyramid),
                    },
                ],
            })
        };
        let frame_bg = frame_bind_group(inputs.first_order);
        // The copy starts the final from the base when one is given.
        let copy_bg = inputs.base.map(frame_bind_group);
        // Paired path: the unpaired pieces here, the pairs after them.
        let (batches, instance_buffers) = match (&scene.paired, &scene.pair_gpu) {
            (Some(p), Some(g)) => (&p.singles.batches, &g.single_buffers),
            _ => (&scene.schedule.batches, &scene.instance_buffers),
        };
        let atlas_bgs: Vec<wgpu::BindGroup> = batches
            .iter()
            .map(|b| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&format!("ortm.transfer.atlas{}_bind_group", b.atlas)),
                    layout: &bp.atlas_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(
                            &scene.atlas_views[b.atlas as usize],
                        ),
                    }],
                })
            })
            .collect();
        // With receiver blocks the pieces draw into the accumulation target (the lightmap and
        // the G_r grids below it), and the resolve writes the final lightmap from it.
        let final_view = util::view(&scene.final_tex);
        let target = scene.accum.as_ref().map_or(&final_view, |(view, _)| view);
        let mut pass = util::clear_pass(encoder, "ortm.transfer.blend_pass", target);
        pass.set_bind_group(0, copy_bg.as_ref().unwrap_or(&frame_bg), &[]);
        pass.set_pipeline(&bp.copy);
        let [lw, lh] = scene.schedule.lightmap_size;
        pass.set_scissor_rect(0, 0, lw, lh);
        pass.draw(0..3, 0..1);
        pass.set_bind_group(0, &frame_bg, &[]);
        let [tw, th] = scene.schedule.target_size();
        pass.set_scissor_rect(0, 0, tw, th);
        pass.set_pipeline(&bp.piece);
        for ((batch, bg), buf) in batches.iter().zip(&atlas_bgs).zip(instance_buffers) {
            pass.set_bind_group(1, bg, &[]);
            pass.set_vertex_buffer(0, buf.slice(..));
            pass.draw(0..6, 0..batch.instances.len() as u32);
        }
        if let (Some(p), Some(g), Some((page_layout, pipeline))) =
            (&scene.paired, &scene.pair_gpu, &bp.pair)
        {
            pass.set_pipeline(pipeline);
            for ((page, view), buf) in p.pages.iter().zip(&g.page_views).zip(&g.page_buffers) {
                let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("ortm.transfer.pair_page_bind_group"),
                    layout: page_layout,
                    entries: &[wgpu::BindGroupEntry {
                        binding: 0,
                        resource: wgpu::BindingResource::TextureView(view),
                    }],
                });
                pass.set_bind_group(1, &bg, &[]);
                pass.set_vertex_buffer(0, buf.slice(..));
                pass.draw(0..6, 0..page.instances.len() as u32);
            }
        }
        drop(pass);
        if let Some((_, bg)) = &scene.accum {
            let mut pass = util::clear_pass(encoder, "ortm.transfer.resolve_pass", &final_view);
            pass.set_bind_group(0, bg, &[]);
            pass.set_pipeline(&bp.resolve.1);
            pass.draw(0..3, 0..1);
        }
    }
}

/// `[width, height]` per atlas, after checking each holds `width·height` values.
fn atlas_sizes(atlases: &[AtlasData]) -> Result<Vec<[u32; 2]>, PassError> {
    let mut sizes = Vec::with_capacity(atlases.len());
    for (i, a) in atlases.iter().enumerate() {
        let n = a.width as usize * a.height as usize;
        if a.rgb.len() != n {
            return Err(PassError::BadLength {
                what: format!("atlases[{i}].rgb"),
                expected: n,
                got: a.rgb.len(),
                hint: "width·height RGB texels".into(),
            });
        }
        sizes.push([a.width, a.height]);
    }
    Ok(sizes)
}

/// One vertex buffer of piece instances per atlas batch, labelled `ortm.transfer.WHAT.atlasN`.
fn instance_buffers(
    device: &wgpu::Device,
    what: &str,
    batches: &[crate::schedule::AtlasBatch],
) -> Vec<wgpu::Buffer> {
    batches
        .iter()
        .map(|b| {
            util::buffer_init(
                device,
                &format!("ortm.transfer.{what}.atlas{}", b.atlas),
                bytemuck::cast_slice(&b.instances),
                wgpu::BufferUsages::VERTEX,
            )
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::TransferParams;

    #[test]
    fn params_size_matches_wgsl() {
        assert_eq!(std::mem::size_of::<TransferParams>(), 32);
    }
}
