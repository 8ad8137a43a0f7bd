//! The whole real-time frame as a script: first order → transfer → dilation (of both
//! maps) → display. [`Renderer`] owns one instance of each pass; [`RenderScene`] the
//! per-scene GPU data; [`Renderer::encode`] records a frame, and [`Renderer::render_image`]
//! / [`Renderer::render_lightmaps`] also submit and read back (for the CLI and for a
//! reference comparison against the CPU mirrors in [`crate::cpu`]).
//!
//! # Data flow
//! ```text
//! lights ─▶ FirstOrderPass ─first_order─▶ TransferPass ─final─▶ DilatePass ─▶ DisplayPass ─▶ RGBA8
//!                              └──────────▶ DilatePass (left half in side-by-side) ─┘
//! ```
//! The transfer pass reads the *undilated* first-order map (first order is 0 outside
//! coverage, as in the bake); only the display sees dilated maps. Both dilations use one
//! [`DilatePlan`], built at [`Renderer::prepare`] from the coverage the first-order pass
//! rasterises (the maps share it).

use crate::dilate::{DilateInputs, DilateOptions, DilatePass, DilatePlan, DilateTargets};
use crate::display::{Camera, DisplayInputs, DisplayOptions, DisplayPass, DisplayScene, Specular};
use crate::error::PassError;
use crate::first_order::{FirstOrderInputs, FirstOrderOptions, FirstOrderPass, FirstOrderScene};
use crate::gpu::Gpu;
use crate::transfer::{TransferInputs, TransferOptions, TransferPass, TransferScene};
use crate::types::{AlbedoMap, AtlasData, LightDesc, MeshData, TexelImage, TransferPiece};
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
    /// First-order pass.
    pub first_order: FirstOrderPass,
    /// Transfer pass.
    pub transfer: TransferPass,
    /// Dilation pass.
    pub dilate: DilatePass,
    /// Display pass.
    pub display: DisplayPass,
    side_by_side: bool,
}

/// Per-scene data of every pass.
#[derive(Debug)]
pub struct RenderScene {
    /// Lightmap `[W, H]` (= albedo size).
    pub lightmap_size: [u32; 2],
    /// First-order data.
    pub first_order: FirstOrderScene,
    /// Transfer data (atlases, schedule).
    pub transfer: TransferScene,
    /// The dilation plan, built from the first-order pass's coverage (shared by both maps;
    /// apply it with [`crate::cpu::dilate::dilate`] for a CPU reference).
    pub dilate_plan: DilatePlan,
    /// Dilation targets of the final map.
    pub dilate_final: DilateTargets,
    /// Dilation targets of the first-order map.
    pub dilate_first_order: DilateTargets,
    /// Display data.
    pub display: DisplayScene,
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

/// Everything a frame produced (textures owned by the scene, overwritten next frame).
#[derive(Clone, Debug)]
pub struct FrameOutput {
    /// RGBA32F first-order lightmap (alpha = coverage).
    pub first_order_tex: wgpu::Texture,
    /// Final lightmap (accumulation format), undilated.
    pub final_lightmap_tex: wgpu::Texture,
    /// Dilated final lightmap.
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
            display: DisplayPass::new(gpu, &options.display)?,
            side_by_side: options.display.side_by_side,
        })
    }

    /// Uploads the scene for every pass. The lightmap size is the albedo map's. Also renders
    /// one first-order map without lights and reads its coverage back, for the dilation plan.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        mesh: &MeshData,
        albedo: &AlbedoMap,
        atlases: &[AtlasData],
        pieces: &[TransferPiece],
    ) -> Result<RenderScene, PassError> {
        let size = [albedo.width, albedo.height];
        let first_order = self.first_order.prepare(gpu, mesh, albedo)?;
        let coverage = self.coverage(gpu, &first_order)?;
        let dilate_plan = self.dilate.plan(&coverage)?;
        Ok(RenderScene {
            lightmap_size: size,
            transfer: self.transfer.prepare(gpu, size, atlases, pieces)?,
            dilate_final: self.dilate.prepare(gpu, &dilate_plan)?,
            dilate_first_order: self.dilate.prepare(gpu, &dilate_plan)?,
            dilate_plan,
            first_order,
            display: self.display.prepare(gpu, mesh)?,
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

    /// Records the lightmap passes only (first order, transfer); returns
    /// `(first_order_tex, final_lightmap_tex)`.
    pub fn encode_lightmaps(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        lights: &[LightDesc],
    ) -> Result<(wgpu::Texture, wgpu::Texture), PassError> {
        let fo = self.first_order.encode(
            gpu,
            encoder,
            &FirstOrderInputs {
                scene: &scene.first_order,
                lights,
            },
        )?;
        let fo_view = util::view(&fo.first_order_tex);
        let tr = self.transfer.encode(
            gpu,
            encoder,
            &TransferInputs {
                scene: &scene.transfer,
                first_order: &fo_view,
            },
        );
        Ok((fo.first_order_tex, tr.final_lightmap_tex))
    }

    /// Records a whole frame.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RenderScene,
        params: &FrameParams<'_>,
    ) -> Result<FrameOutput, PassError> {
        let (fo_tex, final_tex) = self.encode_lightmaps(gpu, encoder, scene, params.lights)?;
        let final_view = util::view(&final_tex);
        let dil_final = self.dilate.encode(
            gpu,
            encoder,
            &DilateInputs {
                targets: &scene.dilate_final,
                source: &final_view,
            },
        );
        let dil_final_view = util::view(&dil_final.dilated_tex);
        let dil_fo_view = if self.side_by_side {
            let fo_view = util::view(&fo_tex);
            let d = self.dilate.encode(
                gpu,
                encoder,
                &DilateInputs {
                    targets: &scene.dilate_first_order,
                    source: &fo_view,
                },
            );
            Some(util::view(&d.dilated_tex))
        } else {
            None
        };
        let out = self.display.encode(
            gpu,
            encoder,
            &DisplayInputs {
                scene: &scene.display,
                final_lightmap: &dil_final_view,
                lightmap_size: scene.lightmap_size,
                first_order: dil_fo_view.as_ref(),
                camera: params.camera,
                exposure: params.exposure,
                lights: params.lights,
                specular: params.specular,
            },
        )?;
        Ok(FrameOutput {
            first_order_tex: fo_tex,
            final_lightmap_tex: final_tex,
            dilated_final_tex: dil_final.dilated_tex,
            color_tex: out.color_tex,
        })
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
        let out = self.encode(gpu, &mut enc, scene, params)?;
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
        let (fo, fin) = self.encode_lightmaps(gpu, &mut enc, scene, lights)?;
        gpu.submit_and_wait("ortm.frame.lightmaps", enc)?;
        Ok((
            gpu.read_texel_image("ortm.frame.first_order", &fo)?,
            gpu.read_texel_image("ortm.frame.final", &fin)?,
        ))
    }
}
