//! Compute (gather) path of the transfer pass, selected by
//! [`crate::transfer::TransferPath::Compute`]; shader `shaders/transfer_gather.wgsl`,
//! mirror [`crate::cpu::transfer_gather`].
//!
//! # Data flow
//! `cs_init` copies the first-order map into an RGBA32F storage buffer `acc` over the
//! accumulation target ([`crate::schedule::target_size`]: the lightmap, and below it the
//! receiver-block grids `G_r` when some piece has receiver level `r > 0`; zero there), one
//! `vec4` per texel, row-major. Then per atlas one dispatch of `cs_gather`: one 8×8 workgroup
//! per non-empty tile of [`crate::schedule::build_tiles`]; each invocation owns one target
//! texel, sums the tile's pieces that contain it (a piece of level ℓ > 0 reading the packed
//! pyramid at `origin_ℓ + ⌊(t − block_origin_r)/2^(ℓ−r)⌋ + Δ`) and adds the sum into `acc` — no
//! two invocations of a dispatch write the same texel, and dispatches are ordered, so no
//! atomics are needed. `cs_resolve` writes the RGBA32F final texture: `acc[t]` plus, at covered
//! texels (alpha > 0), `Σ_r acc[block_origin(r) + ⌊t/2^r⌋]` (alpha = coverage, untouched).
//!
//! # Limits
//! A tile list with more than 65535 entries is dispatched as a 2D grid (`x` ≤ 65535).
//! The accumulation buffer is 16 bytes per target texel (about 1.5× the lightmap with
//! receiver blocks).

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::schedule::{FrameSchedule, TILE_SIZE, build_tiles};
use crate::util;

/// Largest workgroup count per dispatch dimension used by `cs_gather` (must match the
/// `65535u` in `shaders/transfer_gather.wgsl`).
const MAX_GROUPS_X: u32 = 65535;

/// Pipelines of the compute path.
#[derive(Debug)]
pub struct GatherPass {
    frame_layout: wgpu::BindGroupLayout,
    atlas_layout: wgpu::BindGroupLayout,
    init: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    resolve: wgpu::ComputePipeline,
}

/// Per-scene data of the compute path.
#[derive(Debug)]
pub struct GatherScene {
    lightmap_size: [u32; 2],
    target_size: [u32; 2],
    params: wgpu::Buffer,
    acc: wgpu::Buffer,
    final_view: wgpu::TextureView,
    /// Per atlas: (atlas index, instances, tiles, entries, tile count).
    atlases: Vec<(u32, wgpu::Buffer, wgpu::Buffer, wgpu::Buffer, u32)>,
}

impl GatherPass {
    /// Builds the three compute pipelines.
    pub fn new(gpu: &Gpu) -> Result<Self, PassError> {
        gpu.scoped("ortm.transfer_gather.new", || {
            let device = &gpu.device;
            let module = util::shader(
                device,
                "ortm.transfer_gather.shader",
                &format!(
                    "{}{}",
                    crate::transfer::PARAMS_WGSL,
                    include_str!("../shaders/transfer_gather.wgsl")
                ),
            );
            let cs = wgpu::ShaderStages::COMPUTE;
            // Order = @binding order in transfer_gather.wgsl.
            let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.transfer_gather.frame_layout"),
                entries: &[
                    util::uniform_entry(0, cs),
                    util::texture_entry(1, cs),
                    util::storage_entry(2, cs, false),
                    util::storage_texture_entry(3, wgpu::TextureFormat::Rgba32Float),
                    util::texture_entry(4, cs),
                ],
            });
            let atlas_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.transfer_gather.atlas_layout"),
                entries: &[
                    util::texture_entry(0, cs),
                    util::storage_entry(1, cs, true),
                    util::storage_entry(2, cs, true),
                    util::storage_entry(3, cs, true),
                ],
            });
            let frame_only = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.transfer_gather.frame_pipeline_layout"),
                bind_group_layouts: &[Some(&frame_layout)],
                immediate_size: 0,
            });
            let both = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.transfer_gather.gather_pipeline_layout"),
                bind_group_layouts: &[Some(&frame_layout), Some(&atlas_layout)],
                immediate_size: 0,
            });
            let make = |layout: &wgpu::PipelineLayout, entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(&format!("ortm.transfer_gather.{entry}")),
                    layout: Some(layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
            Self {
                init: make(&frame_only, "cs_init"),
                gather: make(&both, "cs_gather"),
                resolve: make(&frame_only, "cs_resolve"),
                frame_layout,
                atlas_layout,
            }
        })
    }

    /// Builds tile lists and buffers; returns the scene and the final texture.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        schedule: &FrameSchedule,
        params: &wgpu::Buffer,
    ) -> Result<(GatherScene, wgpu::Texture), PassError> {
        let device = &gpu.device;
        let lightmap_size = schedule.lightmap_size;
        let target_size = schedule.target_size();
        let texels = target_size[0] as u64 * target_size[1] as u64;
        let max_buf = device.limits().max_storage_buffer_binding_size;
        if texels * 16 > max_buf {
            return Err(PassError::TooLarge {
                what: "compute-path accumulation buffer (bytes)".into(),
                size: texels * 16,
                limit: max_buf,
            });
        }
        let acc = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.transfer_gather.acc"),
            size: texels * 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let final_tex = util::texture_2d(
            device,
            "ortm.transfer_gather.final_lightmap",
            lightmap_size,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let storage = wgpu::BufferUsages::STORAGE;
        let atlases = build_tiles(schedule)
            .into_iter()
            .map(|t| {
                let a = t.atlas;
                (
                    a,
                    util::buffer_init(
                        device,
                        &format!("ortm.transfer_gather.instances.atlas{a}"),
                        bytemuck::cast_slice(&t.instances),
                        storage,
                    ),
                    util::buffer_init(
                        device,
                        &format!("ortm.transfer_gather.tiles.atlas{a}"),
                        bytemuck::cast_slice(&t.tiles),
                        storage,
                    ),
                    util::buffer_init(
                        device,
                        &format!("ortm.transfer_gather.entries.atlas{a}"),
                        bytemuck::cast_slice(&t.entries),
                        storage,
                    ),
                    t.tiles.len() as u32,
                )
            })
            .collect();
        Ok((
            GatherScene {
                lightmap_size,
                target_size,
                params: params.clone(),
                acc,
                final_view: util::view(&final_tex),
                atlases,
            },
            final_tex,
        ))
    }

    /// Records init, one gather dispatch per atlas, and resolve. `pyramid` is the packed
    /// first-order pyramid (levels ≥ 1) or any RGBA32F texture when every piece has level 0;
    /// the init copies `base` when given (the first-order term; same coverage as
    /// `first_order`, which the pieces read), else `first_order`.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        scene: &GatherScene,
        (first_order, base, pyramid): (
            &wgpu::TextureView,
            Option<&wgpu::TextureView>,
            &wgpu::TextureView,
        ),
        atlas_views: &[wgpu::TextureView],
    ) {
        let frame_bg = self.frame_bind_group(device, scene, first_order, pyramid);
        let init_bg = base.map(|b| self.frame_bind_group(device, scene, b, pyramid));
        let atlas_bgs: Vec<(wgpu::BindGroup, u32)> = scene
            .atlases
            .iter()
            .map(|(a, inst, tiles, entries, n)| {
                let bg = device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&format!("ortm.transfer_gather.atlas{a}_bind_group")),
                    layout: &self.atlas_layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: wgpu::BindingResource::TextureView(&atlas_views[*a as usize]),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: inst.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: tiles.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: entries.as_entire_binding(),
                        },
                    ],
                });
                (bg, *n)
            })
            .collect();
        let [tw, th] = scene.target_size;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ortm.transfer_gather.pass"),
            timestamp_writes: None,
        });
        pass.set_bind_group(0, init_bg.as_ref().unwrap_or(&frame_bg), &[]);
        pass.set_pipeline(&self.init);
        pass.dispatch_workgroups(tw.div_ceil(8), th.div_ceil(8), 1);
        pass.set_bind_group(0, &frame_bg, &[]);
        pass.set_pipeline(&self.gather);
        for (bg, n) in &atlas_bgs {
            pass.set_bind_group(1, bg, &[]);
            pass.dispatch_workgroups((*n).min(MAX_GROUPS_X), n.div_ceil(MAX_GROUPS_X), 1);
        }
        let [w, h] = scene.lightmap_size;
        pass.set_pipeline(&self.resolve);
        pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        debug_assert_eq!(TILE_SIZE, 8);
    }

    /// Group 0 of the gather pipelines with `first_order` at binding 1; order = @binding
    /// order in transfer_gather.wgsl.
    fn frame_bind_group(
        &self,
        device: &wgpu::Device,
        scene: &GatherScene,
        first_order: &wgpu::TextureView,
        pyramid: &wgpu::TextureView,
    ) -> wgpu::BindGroup {
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.transfer_gather.frame_bind_group"),
            layout: &self.frame_layout,
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
                    resource: scene.acc.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 3,
                    resource: wgpu::BindingResource::TextureView(&scene.final_view),
                },
                wgpu::BindGroupEntry {
                    binding: 4,
                    resource: wgpu::BindingResource::TextureView(pyramid),
                },
            ],
        })
    }
}
