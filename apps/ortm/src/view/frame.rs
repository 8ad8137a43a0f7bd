//! The viewer's GPU frame: the `passes` crate's first-order and transfer passes, then the
//! lightmap chosen by the view (first order, final, indirect = final − first order, or a CPU
//! lightmap for the debug and reference views), dilation, and the display pass into an
//! `Rgba8Unorm` image that egui shows and screenshots read back.
//!
//! # Data flow
//! ```text
//! lights ─▶ FirstOrderPass ─fo─▶ TransferPass (first K maps) ─final─▶ [indirect: final − fo]
//!        ─▶ DilatePass ─▶ DisplayPass (viewport size, side-by-side) ─▶ copy ─▶ view image
//! ```
//! Dilation uses the scene's plan (built from the GPU's first-order coverage at prepare) for
//! every shown map; a CPU lightmap whose coverage differs keeps its own covered texels (see
//! `passes::dilate`).
//! The transfer pass is re-prepared with the pieces of the first K maps when K changes
//! (atlases are uploaded again); the display pass and its targets are rebuilt when the
//! viewport size or the side-by-side layout changes.
//!
//! # Timing
//! With `TIMESTAMP_QUERY_INSIDE_ENCODERS` (lavapipe and most desktop GPUs), timestamps are
//! written between the passes and read back after each frame (per-pass milliseconds);
//! without it the stats show only the frame rate.

use anyhow::{Context, Result};
use passes::dilate::DilateInputs;
use passes::display::{Camera, DisplayInputs, DisplayOptions, DisplayPass, DisplayScene};
use passes::first_order::FirstOrderInputs;
use passes::frame::{RenderScene, Renderer, RendererOptions};
use passes::transfer::TransferInputs;
use passes::{AtlasData, Gpu, LightDesc, MeshData, TexelImage, TransferPiece, util};

/// Names of the timed passes, in order.
pub const PASS_NAMES: [&str; 5] = ["first order", "transfer", "indirect", "dilate", "display"];

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
    mesh: MeshData,
    atlases: Vec<AtlasData>,
    display: Option<(DisplayPass, DisplayScene, [u32; 2], bool)>,
    indirect: IndirectOp,
    cpu_tex: Option<wgpu::Texture>,
    /// The displayed image of the last frame (`Rgba8Unorm`, sRGB-encoded values).
    pub image: Option<wgpu::Texture>,
    timer: Option<Timer>,
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
        atlases: Vec<AtlasData>,
        pieces: &[TransferPiece],
    ) -> Result<Self> {
        let renderer = Renderer::new(&gpu, options).context("creating the render passes")?;
        let scene = renderer
            .prepare(&gpu, &mesh, albedo, &atlases, pieces)
            .context("uploading the scene to the GPU")?;
        let indirect = IndirectOp::new(&gpu, scene.lightmap_size);
        let timer = gpu.supports_timestamps().then(|| Timer::new(&gpu));
        Ok(Self {
            gpu,
            renderer,
            scene,
            mesh,
            atlases,
            display: None,
            indirect,
            cpu_tex: None,
            image: None,
            timer,
        })
    }

    /// Replaces the transfer work with `pieces` (e.g. those of the first K maps).
    pub fn set_pieces(&mut self, pieces: &[TransferPiece]) -> Result<()> {
        self.scene.transfer = self
            .renderer
            .transfer
            .prepare(&self.gpu, self.scene.lightmap_size, &self.atlases, pieces)
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
        let sbs = shown == Shown::SideBySide;
        let size = [size[0].max(2), size[1].max(1)];
        if !matches!(&self.display, Some((_, _, s, b)) if *s == size && *b == sbs) {
            let pass = DisplayPass::new(
                &self.gpu,
                &DisplayOptions {
                    width: size[0],
                    height: size[1],
                    side_by_side: sbs,
                },
            )?;
            let dscene = pass.prepare(&self.gpu, &self.mesh)?;
            self.display = Some((pass, dscene, size, sbs));
            self.image = Some(util::texture_2d(
                &self.gpu.device,
                "ortm.view.image",
                size,
                wgpu::TextureFormat::Rgba8Unorm,
                wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_DST
                    | wgpu::TextureUsages::COPY_SRC,
            ));
        }
        let Some((dpass, dscene, _, _)) = &self.display else {
            anyhow::bail!("internal: display pass missing");
        };
        let Some(image) = &self.image else {
            anyhow::bail!("internal: view image missing");
        };
        let gpu = &self.gpu;
        let mut enc = gpu
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.view.frame"),
            });
        let ts = |enc: &mut wgpu::CommandEncoder, i: u32| {
            if let Some(t) = &self.timer {
                enc.write_timestamp(&t.queries, i);
            }
        };
        ts(&mut enc, 0);
        let fo = self.renderer.first_order.encode(
            gpu,
            &mut enc,
            &FirstOrderInputs {
                scene: &self.scene.first_order,
                lights,
            },
        )?;
        ts(&mut enc, 1);
        let fo_view = util::view(&fo.first_order_tex);
        let tr = self.renderer.transfer.encode(
            gpu,
            &mut enc,
            &TransferInputs {
                scene: &self.scene.transfer,
                first_order: &fo_view,
            },
        );
        ts(&mut enc, 2);
        let final_view = util::view(&tr.final_lightmap_tex);
        let (source, dilate) = match shown {
            Shown::FirstOrder => (fo_view.clone(), true),
            Shown::Final | Shown::SideBySide => (final_view, true),
            Shown::Indirect => {
                self.indirect.encode(gpu, &mut enc, &fo_view, &final_view);
                (util::view(&self.indirect.out), true)
            }
            Shown::Cpu { dilate } => match &self.cpu_tex {
                Some(t) => (util::view(t), dilate),
                None => (final_view, true),
            },
        };
        ts(&mut enc, 3);
        let shown_view = if dilate {
            let d = self.renderer.dilate.encode(
                gpu,
                &mut enc,
                &DilateInputs {
                    targets: &self.scene.dilate_final,
                    source: &source,
                },
            );
            util::view(&d.dilated_tex)
        } else {
            source
        };
        let left = if sbs {
            let d = self.renderer.dilate.encode(
                gpu,
                &mut enc,
                &DilateInputs {
                    targets: &self.scene.dilate_first_order,
                    source: &fo_view,
                },
            );
            Some(util::view(&d.dilated_tex))
        } else {
            None
        };
        ts(&mut enc, 4);
        let out = dpass.encode(
            gpu,
            &mut enc,
            &DisplayInputs {
                scene: dscene,
                final_lightmap: &shown_view,
                lightmap_size: self.scene.lightmap_size,
                first_order: left.as_ref(),
                camera,
                exposure,
                lights,
                specular: None,
            },
        )?;
        ts(&mut enc, 5);
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
            enc.resolve_query_set(&t.queries, 0..6, &t.resolve, 0);
            enc.copy_buffer_to_buffer(&t.resolve, 0, &t.read, 0, 48);
        }
        gpu.submit_and_wait("ortm.view.frame", enc)?;
        let pass_ms = match &self.timer {
            Some(t) => {
                let bytes = gpu.map_read("ortm.view.timestamps", &t.read)?;
                let stamp = |i: usize| {
                    let mut b = [0u8; 8];
                    b.copy_from_slice(&bytes[8 * i..8 * i + 8]);
                    u64::from_le_bytes(b)
                };
                let mut ms = [0.0; 5];
                for (i, m) in ms.iter_mut().enumerate() {
                    *m = stamp(i + 1).saturating_sub(stamp(i)) as f64 * t.period_ns * 1e-6;
                }
                Some(ms)
            }
            None => None,
        };
        Ok(FrameStats {
            pass_ms,
            texel_blends: self.scene.transfer.schedule.texel_blends(),
        })
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

/// Timestamp queries around the passes.
struct Timer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    period_ns: f64,
}

impl Timer {
    fn new(gpu: &Gpu) -> Self {
        let d = &gpu.device;
        Self {
            queries: d.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("ortm.view.timestamps"),
                ty: wgpu::QueryType::Timestamp,
                count: 6,
            }),
            resolve: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("ortm.view.timestamps.resolve"),
                size: 48,
                usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            }),
            read: d.create_buffer(&wgpu::BufferDescriptor {
                label: Some("ortm.view.timestamps.read"),
                size: 48,
                usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                mapped_at_creation: false,
            }),
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
        }
    }
}

/// `out = final − first order` per texel (RGB), alpha = first-order coverage; a compute
/// shader (`indirect.wgsl`).
struct IndirectOp {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
    out: wgpu::Texture,
    size: [u32; 2],
}

impl IndirectOp {
    fn new(gpu: &Gpu, size: [u32; 2]) -> Self {
        let d = &gpu.device;
        let layout = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("ortm.view.indirect.layout"),
            entries: &[
                util::texture_entry(0, wgpu::ShaderStages::COMPUTE),
                util::texture_entry(1, wgpu::ShaderStages::COMPUTE),
                util::storage_texture_entry(2, wgpu::TextureFormat::Rgba32Float),
            ],
        });
        let pl = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("ortm.view.indirect.pipeline_layout"),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let module = util::shader(d, "ortm.view.indirect", include_str!("indirect.wgsl"));
        let pipeline = d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some("ortm.view.indirect"),
            layout: Some(&pl),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        });
        let out = util::texture_2d(
            d,
            "ortm.view.indirect.out",
            size,
            wgpu::TextureFormat::Rgba32Float,
            // COPY_SRC: the dilation pass copies it and redraws only the gutter.
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        Self {
            pipeline,
            layout,
            out,
            size,
        }
    }

    fn encode(
        &self,
        gpu: &Gpu,
        enc: &mut wgpu::CommandEncoder,
        first_order: &wgpu::TextureView,
        final_map: &wgpu::TextureView,
    ) {
        let out_view = util::view(&self.out);
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.view.indirect.group"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(first_order),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(final_map),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: wgpu::BindingResource::TextureView(&out_view),
                },
            ],
        });
        let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ortm.view.indirect"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(self.size[0].div_ceil(8), self.size[1].div_ceil(8), 1);
    }
}
