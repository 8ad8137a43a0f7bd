//! The whole real-time frame as one script: first order → transfer → (indirect) →
//! dilation → display. [`Renderer`] owns one instance of each pass; [`RenderScene`] the
//! per-scene GPU data (the mesh is uploaded once, in [`Renderer::prepare`], and shared by
//! the first-order and display passes). [`Renderer::encode_frame`] records a frame — the
//! CLI render, the viewer and the benchmarks all record through it; [`FrameOptions`]
//! selects the stages to record, the lightmap to show, whether the shadow maps are
//! re-rendered, and timestamps. [`Renderer::render_image`] / [`Renderer::render_lightmaps`]
//! also submit and read back (for the CLI and for a reference comparison against the CPU
//! mirrors in [`crate::cpu`]).
//!
//! # Data flow
//! ```text
//! lights ─▶ FirstOrderPass ─first_order─▶ TransferPass ─final─▶ [IndirectPass: final − fo]
//!                              │   │                      └─shown map─▶ DilatePass ─▶ DisplayPass ─▶ RGBA8
//!                              │   └─▶ [PyramidPass] ─levels ≥ 1─▶ TransferPass
//!                              └────────▶ DilatePass (left half in side-by-side) ───────┘
//! ```
//! The pyramid pass ([`crate::pyramid`]) runs only when some transfer piece has level > 0
//! (multi-resolution maps); it needs the scene's texel weights
//! ([`Renderer::prepare_with_weights`]) and is recorded with the transfer stage, before it.
//! The transfer pass reads the *undilated* first-order map (first order is 0 outside
//! coverage, as in the bake); only the display sees dilated maps. With
//! [`FirstOrderOptions::samples`] `> 1` the first-order pass also writes the transfer's input
//! (the first order averaged over each texel's square): the pyramid and the pieces read that,
//! and the final starts from the first order (`final = first order + T(input) − input`;
//! [`crate::transfer::TransferInputs::base`]). Every dilation uses one
//! [`DilatePlan`], built at [`Renderer::prepare`] from the coverage the first-order pass
//! rasterises (the maps share it).
//!
//! # Stages and timestamps
//! A stage left out of [`FrameOptions::stages`] records nothing; the later stages read what
//! it last wrote (every pass's output is a texture owned by the scene, overwritten each
//! frame). With [`FrameOptions::timestamps`] the frame writes [`FRAME_TIMESTAMPS`] stamps:
//! `i` before stage `i` of [`TIMED_STAGES`] and the last one after the display.

use std::sync::OnceLock;

use crate::dilate::{DilateInputs, DilateOptions, DilatePass, DilatePlan, DilateTargets};
use crate::display::{
    Camera, DirectInputs, DirectLight, DisplayInputs, DisplayOptions, DisplayPass, DisplayScene,
    LightmapFilter, Specular,
};
use crate::error::PassError;
use crate::first_order::{FirstOrderInputs, FirstOrderOptions, FirstOrderPass, FirstOrderScene};
use crate::gpu::Gpu;
use crate::indirect::{IndirectInputs, IndirectPass, IndirectTargets};
use crate::mesh::GpuMesh;
use crate::pyramid::{PyramidInputs, PyramidPass, PyramidScene};
use crate::timestamps::Timestamps;
use crate::transfer::{TransferInputs, TransferOptions, TransferPass, TransferScene};
use crate::types::{
    AlbedoMap, AtlasData, LightDesc, MeshData, TexelImage, TexelWeights, TransferPiece,
};
use crate::util;

/// Options of every pass.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct RendererOptions {
    /// First-order pass (shadow maps).
    pub first_order: FirstOrderOptions,
    /// Transfer pass (blend/compute, accumulation format).
    pub transfer: TransferOptions,
    /// Gutter dilation.
    pub dilate: DilateOptions,
    /// Display (image size, side-by-side).
    pub display: DisplayOptions,
}

/// One instance of every pass.
#[derive(Debug)]
pub struct Renderer {
    first_order: FirstOrderPass,
    transfer: TransferPass,
    dilate: DilatePass,
    display: DisplayPass,
    indirect: IndirectPass,
    pyramid: PyramidPass,
}

/// Per-scene data of every pass.
#[derive(Debug)]
pub struct RenderScene {
    /// Lightmap `[W, H]` (= albedo size).
    pub lightmap_size: [u32; 2],
    /// The mesh, uploaded once and shared by the first-order and display passes.
    mesh: GpuMesh,
    /// First-order data.
    pub first_order: FirstOrderScene,
    /// Transfer data (atlases, schedule).
    pub transfer: TransferScene,
    /// The texel weights of the first-order pyramid (texel areas, m²), if given.
    weights: Option<TexelWeights>,
    /// The first-order pyramid, when some piece has level > 0.
    pub pyramid: Option<PyramidScene>,
    /// The dilation plan, built from the first-order pass's coverage (shared by both maps;
    /// apply it with [`crate::cpu::dilate::dilate`] for a CPU reference).
    pub dilate_plan: DilatePlan,
    /// Dilation targets of the shown (by default the final) map.
    pub dilate_final: DilateTargets,
    /// Dilation targets of the first-order map.
    pub dilate_first_order: DilateTargets,
    /// Display data.
    pub display: DisplayScene,
    /// The per-pixel direct light's surface map (albedo, diffusion length; dilated).
    surface: wgpu::Texture,
    /// The albedo it was made from.
    albedo: AlbedoMap,
    /// Whether some texel has a diffusion length > 0 (the display then reads the dilated
    /// first-order map too).
    subsurface: bool,
    /// Per triangle, the smallest diffusion length its pixels can look up (`Some` with
    /// `subsurface`; [`crate::display_split::DisplaySplit::min_lengths`]).
    triangle_lengths: Option<Vec<f32>>,
    /// The indirect map, allocated by the first frame that shows it.
    indirect: OnceLock<IndirectTargets>,
}

/// Per-frame parameters.
#[derive(Clone, Copy, Debug)]
pub struct FrameParams<'a> {
    /// Lights (first order, and specular).
    pub lights: &'a [LightDesc],
    /// Camera.
    pub camera: Camera,
    /// Exposure (multiplies radiance before tonemapping).
    pub exposure: f32,
    /// Optional specular highlight.
    pub specular: Option<Specular>,
}

/// The stages of a frame ([`FrameOptions::stages`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stages {
    /// First order (shadow maps + lighting).
    pub first_order: bool,
    /// Transfer.
    pub transfer: bool,
    /// The shown map: the indirect difference when [`Shown::Indirect`], then gutter
    /// dilation of it (and of the first-order map in side-by-side mode).
    pub dilate: bool,
    /// Display.
    pub display: bool,
}

impl Stages {
    /// Every stage.
    pub const ALL: Self = Self {
        first_order: true,
        transfer: true,
        dilate: true,
        display: true,
    };
    /// No stage.
    pub const NONE: Self = Self {
        first_order: false,
        transfer: false,
        dilate: false,
        display: false,
    };
    /// The lightmaps: first order and transfer.
    pub const LIGHTMAPS: Self = Self {
        first_order: true,
        transfer: true,
        ..Self::NONE
    };
    /// First order only.
    pub const FIRST_ORDER: Self = Self {
        first_order: true,
        ..Self::NONE
    };
    /// Transfer only.
    pub const TRANSFER: Self = Self {
        transfer: true,
        ..Self::NONE
    };
    /// The shown map's dilation only.
    pub const DILATE: Self = Self {
        dilate: true,
        ..Self::NONE
    };
    /// Display only.
    pub const DISPLAY: Self = Self {
        display: true,
        ..Self::NONE
    };
}

/// Names of the stages between consecutive frame timestamps.
pub const TIMED_STAGES: [&str; 5] = ["first order", "transfer", "indirect", "dilate", "display"];

/// Timestamps a frame writes with [`FrameOptions::timestamps`].
pub const FRAME_TIMESTAMPS: u32 = TIMED_STAGES.len() as u32 + 1;

/// Which lightmap the display shows (right half in side-by-side mode).
#[derive(Clone, Copy, Debug, Default)]
pub enum Shown<'a> {
    /// The final lightmap (first order + transfer).
    #[default]
    Final,
    /// The first-order lightmap.
    FirstOrder,
    /// Final − first order ([`crate::indirect`]).
    Indirect,
    /// A lightmap of the caller (e.g. a CPU reference), the lightmap size; `dilate: false`
    /// shows it as it is (uncovered texels stay black). A dilated texture must have
    /// `COPY_SRC` (the dilation pass copies it).
    Texture {
        /// The lightmap.
        view: &'a wgpu::TextureView,
        /// Dilate before display.
        dilate: bool,
    },
}

/// What [`Renderer::encode_frame`] records.
#[derive(Clone, Copy, Debug)]
pub struct FrameOptions<'a> {
    /// Stages to record.
    pub stages: Stages,
    /// The lightmap the display shows.
    pub shown: Shown<'a>,
    /// Moving lights: re-render every shadow layer even when the lights did not move
    /// ([`FirstOrderScene::invalidate_shadow_maps`]); otherwise the shadow maps of unchanged
    /// lights are reused.
    pub moving_lights: bool,
    /// Timestamps (at least [`FRAME_TIMESTAMPS`]) to write between the stages.
    pub timestamps: Option<&'a Timestamps>,
}

impl Default for FrameOptions<'_> {
    fn default() -> Self {
        Self {
            stages: Stages::ALL,
            shown: Shown::Final,
            moving_lights: false,
            timestamps: None,
        }
    }
}

/// Everything a frame produced (textures owned by the scene, overwritten next frame).
#[derive(Clone, Debug)]
pub struct FrameOutput {
    /// RGBA32F first-order lightmap (alpha = coverage).
    pub first_order_tex: wgpu::Texture,
    /// Final lightmap (accumulation format), undilated.
    pub final_lightmap_tex: wgpu::Texture,
    /// The dilated shown lightmap (the final map unless [`FrameOptions::shown`] says
    /// otherwise; with per-pixel direct light the transferred light `final − first order`).
    pub dilated_final_tex: wgpu::Texture,
    /// The displayed image (`Rgba8Unorm`, sRGB-encoded values).
    pub color_tex: wgpu::Texture,
}

impl Renderer {
    /// Creates every pass.
    pub fn new(gpu: &Gpu, options: &RendererOptions) -> Result<Self, PassError> {
        Ok(Self {
            first_order: FirstOrderPass::new(gpu, &options.first_order)?,
            transfer: TransferPass::new(gpu, &options.transfer)?,
            dilate: DilatePass::new(gpu, &options.dilate)?,
            display: DisplayPass::with_shadow_layers(
                gpu,
                &options.display,
                LightmapFilter::best_for(gpu),
                options.first_order.max_shadow_layers,
            )?,
            indirect: IndirectPass::new(gpu)?,
            pyramid: PyramidPass::new(gpu)?,
        })
    }

    /// The options of every pass (the display's as last set).
    pub fn options(&self) -> RendererOptions {
        RendererOptions {
            first_order: *self.first_order.options(),
            transfer: *self.transfer.options(),
            dilate: *self.dilate.options(),
            display: *self.display.options(),
        }
    }

    /// The display pass's lightmap filter.
    pub fn display_filter(&self) -> LightmapFilter {
        self.display.filter()
    }

    /// Uploads the scene for every pass (the mesh once). The lightmap size is the albedo
    /// map's. Also renders one first-order map without lights and reads its coverage back,
    /// for the dilation plan. Pieces must all have level 0 (else
    /// [`Renderer::prepare_with_weights`]).
    pub fn prepare(
        &self,
        gpu: &Gpu,
        mesh: &MeshData,
        albedo: &AlbedoMap,
        atlases: &[AtlasData],
        pieces: &[TransferPiece],
    ) -> Result<RenderScene, PassError> {
        self.prepare_with_weights(gpu, mesh, albedo, atlases, pieces, None)
    }

    /// [`Renderer::prepare`] with the texel weights of the first-order pyramid (texel areas
    /// in m², 0 on uncovered texels; kept for [`Renderer::set_pieces`]). Required when some
    /// piece has level > 0: then the scene holds a pyramid up to the highest level and every
    /// frame's transfer stage builds it first.
    ///
    /// Errors: as `prepare`; [`PassError::InvalidInput`] when some piece has level > 0 and
    /// `weights` is `None`, or the weights do not fit the lightmap.
    pub fn prepare_with_weights(
        &self,
        gpu: &Gpu,
        mesh: &MeshData,
        albedo: &AlbedoMap,
        atlases: &[AtlasData],
        pieces: &[TransferPiece],
        weights: Option<&TexelWeights>,
    ) -> Result<RenderScene, PassError> {
        let size = [albedo.width, albedo.height];
        if let Some(w) = weights {
            w.validate(size)?;
        }
        let transfer = self.transfer.prepare(gpu, size, atlases, pieces)?;
        let pyramid = self.pyramid_for(gpu, &transfer, weights)?;
        let mesh = GpuMesh::upload(gpu, mesh)?;
        let first_order = self.first_order.prepare_mesh(gpu, &mesh, albedo)?;
        let coverage = self.coverage(gpu, &first_order)?;
        let dilate_plan = self.dilate.plan(&coverage)?;
        let surface = crate::display::surface_map(gpu, albedo, None, &dilate_plan)?;
        Ok(RenderScene {
            lightmap_size: size,
            transfer,
            weights: weights.cloned(),
            pyramid,
            dilate_final: self.dilate.prepare(gpu, &dilate_plan)?,
            dilate_first_order: self.dilate.prepare(gpu, &dilate_plan)?,
            dilate_plan,
            first_order,
            display: self.display.prepare_mesh(gpu, &mesh)?,
            mesh,
            surface,
            albedo: albedo.clone(),
            subsurface: false,
            triangle_lengths: None,
            indirect: OnceLock::new(),
        })
    }

    /// The scene's lightmap coverage exactly as the GPU rasterised it: the first-order map
    /// of a frame without lights (RGB 0, alpha = coverage of the texel G-buffer), read back.
    /// The next frame re-renders the shadow maps (its lights differ from "none").
    fn coverage(&self, gpu: &Gpu, scene: &FirstOrderScene) -> Result<TexelImage, PassError> {
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.frame.coverage_encoder"),
            });
        let fo =
            self.first_order
                .encode(gpu, &mut enc, &FirstOrderInputs { scene, lights: &[] })?;
        gpu.submit_and_wait("ortm.frame.coverage", enc)?;
        gpu.read_texel_image("ortm.frame.coverage", &fo.first_order_tex)
    }

    /// Replaces the scene's transfer work with `pieces` of `atlases` (uploaded again), e.g.
    /// those of the first K maps.
    pub fn set_pieces(
        &self,
        gpu: &Gpu,
        scene: &mut RenderScene,
        atlases: &[AtlasData],
        pieces: &[TransferPiece],
    ) -> Result<(), PassError> {
        let transfer = self
            .transfer
            .prepare(gpu, scene.lightmap_size, atlases, pieces)?;
        scene.pyramid = self.pyramid_for(gpu, &transfer, scene.weights.as_ref())?;
        scene.transfer = transfer;
        Ok(())
    }

    /// The first-order pyramid the pieces of `transfer` need (`None` when all have level
    /// 0): levels up to the highest piece level, from `weights`.
    fn pyramid_for(
        &self,
        gpu: &Gpu,
        transfer: &TransferScene,
        weights: Option<&TexelWeights>,
    ) -> Result<Option<PyramidScene>, PassError> {
        let max_level = transfer.max_level();
        if max_level == 0 {
            return Ok(None);
        }
        let size = transfer.schedule.lightmap_size;
        let weights = weights.ok_or_else(|| PassError::InvalidInput {
            what: "texel weights".into(),
            problem: format!(
                "are missing but some transfer pieces read pyramid level {max_level}; give the \
                 texel areas (Renderer::prepare_with_weights) or use level-0 pieces only"
            ),
        })?;
        Ok(Some(self.pyramid.prepare(gpu, size, weights, max_level)?))
    }

    /// Sets the diffusion length of every lightmap texel (metres, row-major like the albedo;
    /// 0 on diffuse surfaces): where it exceeds a pixel's footprint the per-pixel direct
    /// light gives way to the lightmap's diffused light (see [`crate::display`]). Texels with
    /// a length > 0 are translucent: with an averaged first order
    /// ([`FirstOrderOptions::samples`] > 1) their first-order term is the average
    /// ([`FirstOrderPass::set_translucent`]).
    pub fn set_diffusion_lengths(
        &self,
        gpu: &Gpu,
        scene: &mut RenderScene,
        lengths_m: &[f32],
    ) -> Result<(), PassError> {
        let texels =
            crate::display::surface_texels(&scene.albedo, Some(lengths_m), &scene.dilate_plan)?;
        let translucent: Vec<bool> = lengths_m.iter().map(|&l| l > 0.0).collect();
        self.first_order
            .set_translucent(gpu, &mut scene.first_order, &translucent)?;
        scene.surface = crate::display::upload_surface(gpu, scene.lightmap_size, &texels)?;
        scene.subsurface = lengths_m.iter().any(|&l| l > 0.0);
        scene.triangle_lengths = scene
            .subsurface
            .then(|| scene.mesh.split().min_lengths(&texels, scene.lightmap_size));
        Ok(())
    }

    /// Rebuilds the display pass and the scene's display targets for `options` (image size,
    /// side-by-side); the mesh is not uploaded again.
    pub fn set_display(
        &mut self,
        gpu: &Gpu,
        scene: &mut RenderScene,
        options: &DisplayOptions,
    ) -> Result<(), PassError> {
        let pass = DisplayPass::with_shadow_layers(
            gpu,
            options,
            self.display.filter(),
            self.first_order.options().max_shadow_layers,
        )?;
        scene.display = pass.prepare_mesh(gpu, &scene.mesh)?;
        self.display = pass;
        Ok(())
    }

    /// Records a frame: the stages of `options.stages`, with timestamps between them.
    pub fn encode_frame(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        params: &FrameParams<'_>,
        options: &FrameOptions<'_>,
    ) -> Result<FrameOutput, PassError> {
        let stamp = |enc: &mut wgpu::CommandEncoder, i: u32| {
            if let Some(t) = options.timestamps {
                t.write(enc, i);
            }
        };
        let stages = options.stages;
        stamp(encoder, 0);
        if stages.first_order {
            if options.moving_lights {
                scene.first_order.invalidate_shadow_maps();
            }
            let inputs = FirstOrderInputs {
                scene: &scene.first_order,
                lights: params.lights,
            };
            self.first_order.encode(gpu, encoder, &inputs)?;
        }
        stamp(encoder, 1);
        let fo_view = util::view(scene.first_order.output());
        if stages.transfer {
            // What the transfer multiplies: the first order, or its averages over the texels'
            // squares (`FirstOrderOptions::samples`; the final then starts from `fo_view`).
            let averaged = self.first_order.options().samples > 1;
            let input_view = util::view(scene.first_order.transfer_input());
            // The pyramid of this frame's first order, when some piece reads a level > 0.
            if let Some(pyramid) = &scene.pyramid {
                let inputs = PyramidInputs {
                    scene: pyramid,
                    first_order: &input_view,
                };
                self.pyramid.encode(gpu, encoder, &inputs);
            }
            let inputs = TransferInputs {
                scene: &scene.transfer,
                first_order: &input_view,
                base: averaged.then_some(&fo_view),
                pyramid: scene.pyramid.as_ref(),
            };
            self.transfer.encode(gpu, encoder, &inputs)?;
        }
        stamp(encoder, 2);
        // Per-pixel direct light for the final and first-order views; the indirect view and
        // a caller's map are shown as lightmaps.
        let per_pixel = self.display.options().direct == DirectLight::PerPixel
            && matches!(options.shown, Shown::Final | Shown::FirstOrder);
        let source = if per_pixel {
            self.transferred_source(gpu, encoder, scene, options, &fo_view)?
        } else {
            self.shown_source(gpu, encoder, scene, options, &fo_view)?
        };
        stamp(encoder, 3);
        let record = stages.dilate;
        let (shown, left) =
            self.dilate_shown(gpu, encoder, scene, (record, per_pixel), source, &fo_view);
        stamp(encoder, 4);
        if stages.display {
            let surface = util::view(&scene.surface);
            let direct = per_pixel.then(|| DirectInputs {
                first_order: &scene.first_order,
                surface: &surface,
                first_order_map: left.as_ref().unwrap_or(&fo_view),
                direct_only: matches!(options.shown, Shown::FirstOrder),
                subsurface: scene.subsurface,
                triangle_lengths: scene.triangle_lengths.as_deref(),
            });
            let inputs = DisplayInputs {
                scene: &scene.display,
                final_lightmap: &shown,
                lightmap_size: scene.lightmap_size,
                first_order: left.as_ref(),
                camera: params.camera,
                exposure: params.exposure,
                lights: params.lights,
                specular: params.specular,
                direct,
            };
            self.display.encode(gpu, encoder, &inputs)?;
        }
        stamp(encoder, 5);
        Ok(FrameOutput {
            first_order_tex: scene.first_order.output().clone(),
            final_lightmap_tex: scene.transfer.output().clone(),
            dilated_final_tex: scene.dilate_final.output().clone(),
            color_tex: scene.display.color().clone(),
        })
    }

    /// The map [`FrameOptions::shown`] names (recording the indirect difference when it is
    /// shown and the dilate stage runs), and whether to dilate it.
    fn shown_source(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        options: &FrameOptions<'_>,
        fo_view: &wgpu::TextureView,
    ) -> Result<(wgpu::TextureView, bool), PassError> {
        Ok(match options.shown {
            Shown::Final => (util::view(scene.transfer.output()), true),
            Shown::FirstOrder => (fo_view.clone(), true),
            Shown::Texture { view, dilate } => (view.clone(), dilate),
            Shown::Indirect => (
                self.indirect_map(gpu, encoder, scene, options, fo_view)?,
                true,
            ),
        })
    }

    /// The map the per-pixel direct light adds: for the final view (dilated) the
    /// transferred light `final − first order`, or on a scene with subsurface texels the
    /// final light itself (the display subtracts its per-pixel share of the first order);
    /// nothing for the first-order view (the first-order map is bound, not read, not
    /// dilated).
    fn transferred_source(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        options: &FrameOptions<'_>,
        fo_view: &wgpu::TextureView,
    ) -> Result<(wgpu::TextureView, bool), PassError> {
        Ok(match options.shown {
            Shown::FirstOrder => (fo_view.clone(), false),
            _ if scene.subsurface => (util::view(scene.transfer.output()), true),
            _ => (
                self.indirect_map(gpu, encoder, scene, options, fo_view)?,
                true,
            ),
        })
    }

    /// The indirect map `final − first order` (allocated on first use), recorded when the
    /// dilate stage runs.
    fn indirect_map(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        options: &FrameOptions<'_>,
        fo_view: &wgpu::TextureView,
    ) -> Result<wgpu::TextureView, PassError> {
        let targets = match scene.indirect.get() {
            Some(t) => t,
            None => {
                let t = self.indirect.prepare(gpu, scene.lightmap_size)?;
                scene.indirect.get_or_init(|| t)
            }
        };
        if options.stages.dilate {
            let final_view = util::view(scene.transfer.output());
            let inputs = IndirectInputs {
                targets,
                first_order: fo_view,
                final_map: &final_view,
            };
            self.indirect.encode(gpu, encoder, &inputs);
        }
        Ok(util::view(targets.output()))
    }

    /// Dilates `source` (when `dilate`) and the first-order map — in side-by-side mode from
    /// lightmaps, or with `per_pixel` direct light on a scene with subsurface texels —
    /// (recording only when `record`); returns the views the display reads: the shown map
    /// and the dilated first-order map.
    fn dilate_shown(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        (record, per_pixel): (bool, bool),
        (source, dilate): (wgpu::TextureView, bool),
        fo_view: &wgpu::TextureView,
    ) -> (wgpu::TextureView, Option<wgpu::TextureView>) {
        let mut dilated = |targets: &DilateTargets, source: &wgpu::TextureView| {
            if record {
                self.dilate
                    .encode(gpu, encoder, &DilateInputs { targets, source });
            }
            util::view(targets.output())
        };
        let shown = if dilate {
            dilated(&scene.dilate_final, &source)
        } else {
            source
        };
        let need_first_order = if per_pixel {
            scene.subsurface
        } else {
            self.display.options().side_by_side
        };
        let left = need_first_order.then(|| dilated(&scene.dilate_first_order, fo_view));
        (shown, left)
    }

    /// Renders a frame and reads the image back.
    pub fn render_image(
        &self,
        gpu: &Gpu,
        scene: &RenderScene,
        params: &FrameParams<'_>,
    ) -> Result<image::RgbaImage, PassError> {
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.frame.encoder"),
            });
        let out = self.encode_frame(gpu, &mut enc, scene, params, &FrameOptions::default())?;
        gpu.submit_and_wait("ortm.frame", enc)?;
        gpu.read_rgba8("ortm.frame.color", &out.color_tex)
    }

    /// Computes and reads back `(first_order, final)` lightmaps (undilated; alpha =
    /// coverage) for `lights`.
    pub fn render_lightmaps(
        &self,
        gpu: &Gpu,
        scene: &RenderScene,
        lights: &[LightDesc],
    ) -> Result<(TexelImage, TexelImage), PassError> {
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.frame.lightmaps_encoder"),
            });
        let params = FrameParams {
            lights,
            // Not used: the display stage is not recorded.
            camera: Camera::default(),
            exposure: 1.0,
            specular: None,
        };
        let options = FrameOptions {
            stages: Stages::LIGHTMAPS,
            ..Default::default()
        };
        let out = self.encode_frame(gpu, &mut enc, scene, &params, &options)?;
        gpu.submit_and_wait("ortm.frame.lightmaps", enc)?;
        Ok((
            gpu.read_texel_image("ortm.frame.first_order", &out.first_order_tex)?,
            gpu.read_texel_image("ortm.frame.final", &out.final_lightmap_tex)?,
        ))
    }
}
