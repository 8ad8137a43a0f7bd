//! Indirect-light pass: `final − first order` per texel (RGB, W/m²), alpha = first-order
//! coverage — the light the transfer added, shown by the viewer's indirect view.
//! `shaders/indirect.wgsl` (one compute dispatch, 8×8 workgroups), mirror
//! [`crate::cpu::indirect`].
//!
//! # Data flow
//! [`IndirectPass::new`] builds the pipeline; [`IndirectPass::prepare`] allocates the
//! RGBA32F output of the lightmap size; [`IndirectPass::encode`] reads both maps (any float
//! format, `textureLoad`) and writes the output, which the dilation pass may copy
//! (`COPY_SRC`) and the display pass samples.

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::util;

/// The indirect-light pass.
#[derive(Debug)]
pub struct IndirectPass {
    pipeline: wgpu::ComputePipeline,
    layout: wgpu::BindGroupLayout,
}

/// The output texture of one lightmap size.
#[derive(Debug)]
pub struct IndirectTargets {
    out: wgpu::Texture,
}

impl IndirectTargets {
    /// The indirect map the last `encode` wrote (RGBA32F).
    pub fn output(&self) -> &wgpu::Texture {
        &self.out
    }
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct IndirectInputs<'a> {
    /// Output of [`IndirectPass::prepare`].
    pub targets: &'a IndirectTargets,
    /// First-order lightmap (alpha = coverage), the targets' size.
    pub first_order: &'a wgpu::TextureView,
    /// Final lightmap, the targets' size.
    pub final_map: &'a wgpu::TextureView,
}

/// Output of the pass.
#[derive(Clone, Debug)]
pub struct IndirectOutput {
    /// RGBA32F `final − first order`, alpha = coverage; owned by the targets.
    pub indirect_tex: wgpu::Texture,
}

impl IndirectPass {
    /// Builds the compute pipeline.
    pub fn new(gpu: &Gpu) -> Result<Self, PassError> {
        gpu.scoped("ortm.indirect.new", || {
            let d = &gpu.device;
            // Order = @binding order in indirect.wgsl.
            let layout = d.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.indirect.layout"),
                entries: &[
                    util::texture_entry(0, wgpu::ShaderStages::COMPUTE),
                    util::texture_entry(1, wgpu::ShaderStages::COMPUTE),
                    util::storage_texture_entry(2, wgpu::TextureFormat::Rgba32Float),
                ],
            });
            let pl = d.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.indirect.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let module = util::shader(
                d,
                "ortm.indirect.shader",
                include_str!("../shaders/indirect.wgsl"),
            );
            let pipeline = d.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("ortm.indirect.pipeline"),
                layout: Some(&pl),
                module: &module,
                entry_point: Some("main"),
                compilation_options: Default::default(),
                cache: None,
            });
            Self { pipeline, layout }
        })
    }

    /// Allocates the output for a `size` lightmap.
    pub fn prepare(&self, gpu: &Gpu, size: [u32; 2]) -> Result<IndirectTargets, PassError> {
        gpu.check_texture_size("indirect map", size[0], size[1])?;
        let out = util::texture_2d(
            &gpu.device,
            "ortm.indirect.out",
            size,
            wgpu::TextureFormat::Rgba32Float,
            // COPY_SRC: the dilation pass copies it and redraws only the gutter.
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        Ok(IndirectTargets { out })
    }

    /// Records the dispatch.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &IndirectInputs<'_>,
    ) -> IndirectOutput {
        let out = &inputs.targets.out;
        let out_view = util::view(out);
        let texture = |binding, view| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(view),
        };
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.indirect.group"),
            layout: &self.layout,
            entries: &[
                texture(0, inputs.first_order),
                texture(1, inputs.final_map),
                texture(2, &out_view),
            ],
        });
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ortm.indirect"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &group, &[]);
        pass.dispatch_workgroups(out.width().div_ceil(8), out.height().div_ceil(8), 1);
        drop(pass);
        IndirectOutput {
            indirect_tex: out.clone(),
        }
    }
}
