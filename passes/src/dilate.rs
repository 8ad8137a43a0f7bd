//! Gutter dilation: fills uncovered lightmap texels (alpha = 0) from covered neighbours so
//! that bilinear filtering at chart borders never pulls in black. `shaders/dilate.wgsl`,
//! mirror [`crate::cpu::dilate`].
//!
//! # Data flow
//! [`DilatePass::encode`] runs [`DilateOptions::iterations`] full-screen fragment passes, ping-ponging
//! between two RGBA32F textures owned by [`DilateTargets`]; each iteration grows the filled
//! region by one texel (8-neighbourhood mean of non-empty neighbours). Covered texels
//! (alpha 1) and already-filled ones (alpha [`FILLED_ALPHA`]) are copied unchanged, so a
//! covered texel is never overwritten.
//!
//! # Conventions
//! Input: any float RGBA texture with alpha = coverage (first-order or final lightmap,
//! RGBA32F or RGBA16F). Output alpha: 1 covered, [`FILLED_ALPHA`] filled, 0 still empty.
//! Units are those of the input (W/m²).
//!
//! # Limits
//! Fills at most `iterations` texels beyond a chart; a bilinear lookup needs 1, mip-mapping
//! would need more. Gutters narrower than that between charts get a mix of both charts.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::util;

/// Alpha of texels filled by dilation. Must match `FILLED_ALPHA` in `shaders/dilate.wgsl`.
pub const FILLED_ALPHA: f32 = 0.5;

/// Settings fixed at creation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DilateOptions {
    /// Number of one-texel growth steps (≥ 1).
    pub iterations: u32,
}

impl Default for DilateOptions {
    fn default() -> Self {
        Self { iterations: 4 }
    }
}

/// Uniform of `dilate.wgsl`. 16 bytes. Must match `Params` there.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct DilateParams {
    /// Map `[W, H]`.
    pub size: [u32; 2],
    /// Padding.
    pub _pad: [u32; 2],
}

/// The dilation pass.
#[derive(Debug)]
pub struct DilatePass {
    options: DilateOptions,
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::RenderPipeline,
}

/// Ping-pong targets for one map size.
#[derive(Debug)]
pub struct DilateTargets {
    params: wgpu::Buffer,
    textures: [wgpu::Texture; 2],
    views: [wgpu::TextureView; 2],
    /// Bind groups reading texture `i` (the pass renders into texture `1 − i`).
    swap_groups: [wgpu::BindGroup; 2],
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct DilateInputs<'a> {
    /// Targets from [`DilatePass::prepare`].
    pub targets: &'a DilateTargets,
    /// The map to dilate (same size as the targets).
    pub source: &'a wgpu::TextureView,
}

/// Output of the pass.
#[derive(Clone, Debug)]
pub struct DilateOutput {
    /// RGBA32F dilated map, owned by the targets.
    pub dilated_tex: wgpu::Texture,
}

impl DilatePass {
    /// Builds the render pipeline.
    pub fn new(gpu: &Gpu, options: &DilateOptions) -> Result<Self, PassError> {
        if options.iterations == 0 {
            return Err(PassError::InvalidInput {
                what: "DilateOptions.iterations".into(),
                problem: "must be ≥ 1 (skip the pass instead)".into(),
            });
        }
        gpu.scoped("ortm.dilate.new", || {
            let device = &gpu.device;
            let module = util::shader(
                device,
                "ortm.dilate.shader",
                include_str!("../shaders/dilate.wgsl"),
            );
            let fs = wgpu::ShaderStages::FRAGMENT;
            // Order = @binding order in dilate.wgsl.
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.dilate.layout"),
                entries: &[util::uniform_entry(0, fs), util::texture_entry(1, fs)],
            });
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.dilate.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let pipeline = util::fullscreen_pipeline(
                device,
                "ortm.dilate.pipeline",
                Some(&pl),
                &module,
                "fs_dilate",
                wgpu::TextureFormat::Rgba32Float,
                None,
            );
            Self {
                options: *options,
                layout,
                pipeline,
            }
        })
    }

    /// Allocates ping-pong targets for `size`.
    pub fn prepare(&self, gpu: &Gpu, size: [u32; 2]) -> Result<DilateTargets, PassError> {
        gpu.check_texture_size("dilation target", size[0], size[1])?;
        let device = &gpu.device;
        let params = util::buffer_init(
            device,
            "ortm.dilate.params",
            bytemuck::bytes_of(&DilateParams { size, _pad: [0; 2] }),
            wgpu::BufferUsages::UNIFORM,
        );
        let make = |i: usize| {
            util::texture_2d(
                device,
                &format!("ortm.dilate.target{i}"),
                size,
                wgpu::TextureFormat::Rgba32Float,
                wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC,
            )
        };
        let textures = [make(0), make(1)];
        let views = [util::view(&textures[0]), util::view(&textures[1])];
        let group = |from: usize| self.bind_group(device, &params, &views[from]);
        let swap_groups = [group(0), group(1)];
        Ok(DilateTargets {
            params,
            textures,
            views,
            swap_groups,
        })
    }

    fn bind_group(
        &self,
        device: &wgpu::Device,
        params: &wgpu::Buffer,
        src: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        // Order = @binding order in dilate.wgsl.
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.dilate.bind_group"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(src),
                },
            ],
        })
    }

    /// Records the dilation iterations.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &DilateInputs<'_>,
    ) -> DilateOutput {
        let t = inputs.targets;
        let first = self.bind_group(&gpu.device, &t.params, inputs.source);
        // Iteration 0: source → target0; iteration k: target((k−1)%2) → target(k%2).
        let mut last = 0;
        for k in 0..self.options.iterations as usize {
            let mut pass = util::clear_pass(encoder, "ortm.dilate.pass", &t.views[k % 2]);
            pass.set_pipeline(&self.pipeline);
            if k == 0 {
                pass.set_bind_group(0, &first, &[]);
            } else {
                pass.set_bind_group(0, &t.swap_groups[(k - 1) % 2], &[]);
            }
            pass.draw(0..3, 0..1);
            last = k % 2;
        }
        DilateOutput {
            dilated_tex: t.textures[last].clone(),
        }
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn params_size_matches_wgsl() {
        assert_eq!(std::mem::size_of::<super::DilateParams>(), 16);
    }
}
