//! The viewer's GPU frame: `passes::Renderer::encode_frame` with the lightmap chosen by the
//! view (first order, final, indirect = final − first order, or a CPU lightmap for the debug
//! and reference views) and the display at the viewport size, then a copy into an
//! `Rgba8Unorm` image that egui shows and screenshots read back.
//!
//! # Data flow
//! ```text
//! lights ─▶ first order ─fo─▶ transfer (first K maps) ─final─▶ [indirect: final − fo]
//!        ─▶ dilation ─▶ display (viewport size, side-by-side) ─▶ copy ─▶ view image
//! ```
//! Dilation uses the scene's plan (built from the GPU's first-order coverage at prepare) for
//! every shown map; a CPU lightmap whose coverage differs keeps its own covered texels (see
//! `passes::dilate`).
//! The transfer pass is re-prepared with the pieces of the first K maps when K changes
//! (atlases are uploaded again); the display pass and its targets are rebuilt when the
//! viewport size or the side-by-side layout changes (the mesh stays uploaded).
//!
//! # Timing
//! With `TIMESTAMP_QUERY_INSIDE_ENCODERS` (lavapipe and most desktop GPUs), the frame writes
//! timestamps between its stages and they are read back after each frame (per-pass
//! milliseconds); without it the stats show only the frame rate.

use anyhow::{Context, Result};
use passes::display::{Camera, DisplayOptions};
use passes::frame::{
    FRAME_TIMESTAMPS, FrameOptions, FrameParams, RenderScene, Renderer, RendererOptions,
    Shown as Map, TIMED_STAGES,
};
use passes::timestamps::Timestamps;
use passes::{AtlasData, Gpu, LightDesc, MeshData, TexelImage, TransferPiece, util};

/// Names of the timed passes, in order.
pub const PASS_NAMES: [&str; 5] = TIMED_STAGES;

/// Which lightmap the display pass shows.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Shown {
    /// The first-order lightmap.
    FirstOrder,
    /// The final lightmap (first order + transfer).
    Final,
    /// Final − first order (GPU).
    Indirect,
    /// First order (left) and final (right).
    SideBySide,
    /// A CPU lightmap uploaded with [`ViewRenderer::set_cpu_lightmap`]; `dilate: false`
    /// keeps uncovered texels black (coverage view).
    Cpu {
        /// Dilate before display.
        dilate: bool,
    },
}

/// GPU state of the viewer.
pub struct ViewRenderer {
    /// The shared device.
    pub gpu: Gpu,
    renderer: Renderer,
    scene: RenderScene,
    atlases: Vec<AtlasData>,
    /// `(size, side by side)` the display pass was last built for.
    display: Option<([u32; 2], bool)>,
    cpu_tex: Option<wgpu::Texture>,
    /// The displayed image of the last frame (`Rgba8Unorm`, sRGB-encoded values).
    pub image: Option<wgpu::Texture>,
    timer: Option<Timestamps>,
}

/// Figures of the last frame.
#[derive(Clone, Debug, Default)]
pub struct FrameStats {
    /// Per-pass GPU milliseconds ([`PASS_NAMES`] order), when timestamps are supported.
    pub pass_ms: Option<[f64; 5]>,
    /// Texel blends of the transfer pass (Σ piece areas).
    pub texel_blends: u64,
}

impl ViewRenderer {
    /// Creates the passes and uploads the scene with every piece.
    pub fn new(
        gpu: Gpu,
        options: &RendererOptions,
        mesh: MeshData,
        albedo: &passes::AlbedoMap,
        weights: &passes::TexelWeights,
        atlases: Vec<AtlasData>,
        pieces: &[TransferPiece],
    ) -> Result<Self> {
        let renderer = Renderer::new(&gpu, options).context("creating the render passes")?;
        let scene = renderer
            .prepare_with_weights(&gpu, &mesh, albedo, &atlases, pieces, Some(weights))
            .context("uploading the scene to the GPU")?;
        let timer = gpu
            .supports_timestamps()
            .then(|| Timestamps::new(&gpu, "ortm.view.timestamps", FRAME_TIMESTAMPS));
        Ok(Self {
            gpu,
            renderer,
            scene,
            atlases,
            display: None,
            cpu_tex: None,
            image: None,
            timer,
        })
    }

    /// Sets the diffusion length of every lightmap texel (m; see
    /// `passes::frame::Renderer::set_diffusion_lengths`).
    pub fn set_diffusion_lengths(&mut self, lengths_m: &[f32]) -> Result<()> {
        self.renderer
            .set_diffusion_lengths(&self.gpu, &mut self.scene, lengths_m)?;
        Ok(())
    }

    /// Replaces the transfer work with `pieces` (e.g. those of the first K maps).
    pub fn set_pieces(&mut self, pieces: &[TransferPiece]) -> Result<()> {
        self.renderer
            .set_pieces(&self.gpu, &mut self.scene, &self.atlases, pieces)
            .context("re-preparing the transfer pass")?;
        Ok(())
    }

    /// Uploads a CPU lightmap for [`Shown::Cpu`].
    pub fn set_cpu_lightmap(&mut self, img: &TexelImage) -> Result<()> {
        self.cpu_tex = Some(self.gpu.create_rgba32f_texture(
            "ortm.view.cpu_lightmap",
            img.width,
            img.height,
            &img.rgba,
            // COPY_SRC: the dilation pass copies it and redraws only the gutter.
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC,
        )?);
        Ok(())
    }

    /// Reads back `(first_order, final)` for `lights` (for auto exposure and the CPU views).
    pub fn lightmaps(&self, lights: &[LightDesc]) -> Result<(TexelImage, TexelImage)> {
        Ok(self
            .renderer
            .render_lightmaps(&self.gpu, &self.scene, lights)?)
    }

    /// Renders one frame of `size` pixels into [`ViewRenderer::image`] and returns its stats.
    pub fn render(
        &mut self,
        size: [u32; 2],
        shown: Shown,
        lights: &[LightDesc],
        camera: Camera,
        exposure: f32,
    ) -> Result<FrameStats> {
        let size = [size[0].max(2), size[1].max(1)];
        self.fit_display(size, shown == Shown::SideBySide)?;
        let Some(image) = &self.image else {
            anyhow::bail!("internal: view image missing");
        };
        let gpu = &self.gpu;
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.view.frame"),
            });
        let cpu_view = self.cpu_tex.as_ref().map(util::view);
        let map = match (shown, &cpu_view) {
            (Shown::FirstOrder, _) => Map::FirstOrder,
            (Shown::Final | Shown::SideBySide, _) | (Shown::Cpu { .. }, None) => Map::Final,
            (Shown::Indirect, _) => Map::Indirect,
            (Shown::Cpu { dilate }, Some(view)) => Map::Texture { view, dilate },
        };
        let params = FrameParams {
            lights,
            camera,
            exposure,
            specular: None,
        };
        let options = FrameOptions {
            shown: map,
            timestamps: self.timer.as_ref(),
            ..Default::default()
        };
        let out = self
            .renderer
            .encode_frame(gpu, &mut enc, &self.scene, &params, &options)?;
        enc.copy_texture_to_texture(
            out.color_tex.as_image_copy(),
            image.as_image_copy(),
            wgpu::Extent3d {
                width: size[0],
                height: size[1],
                depth_or_array_layers: 1,
            },
        );
        if let Some(t) = &self.timer {
            t.resolve(&mut enc);
        }
        gpu.submit_and_wait("ortm.view.frame", enc)?;
        let pass_ms = match &self.timer {
            Some(t) => {
                let ms = t.intervals_ms(gpu, "ortm.view.timestamps")?;
                let mut out = [0.0; 5];
                out.copy_from_slice(&ms[..5]);
                Some(out)
            }
            None => None,
        };
        Ok(FrameStats {
            pass_ms,
            texel_blends: self.scene.transfer.schedule.texel_blends(),
        })
    }

    /// Rebuilds the display pass and the view image when the viewport size or the
    /// side-by-side layout changed.
    fn fit_display(&mut self, size: [u32; 2], side_by_side: bool) -> Result<()> {
        if self.display == Some((size, side_by_side)) {
            return Ok(());
        }
        let options = DisplayOptions {
            width: size[0],
            height: size[1],
            side_by_side,
            ..self.renderer.options().display
        };
        self.renderer
            .set_display(&self.gpu, &mut self.scene, &options)?;
        self.display = Some((size, side_by_side));
        self.image = Some(util::texture_2d(
            &self.gpu.device,
            "ortm.view.image",
            size,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_DST
                | wgpu::TextureUsages::COPY_SRC,
        ));
        Ok(())
    }

    /// Reads back the last frame's image (what the window shows in the 3D view).
    pub fn read_image(&self) -> Result<image::RgbaImage> {
        let tex = self
            .image
            .as_ref()
            .context("no frame has been rendered yet")?;
        Ok(self.gpu.read_rgba8("ortm.view.screenshot", tex)?)
    }
}
