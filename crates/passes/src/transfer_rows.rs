//! Rows path of the transfer pass, selected by [`crate::transfer::TransferPath::Rows`]; shader
//! `shaders/transfer_rows.wgsl`, mirror [`crate::cpu::transfer_rows`], rows built by
//! [`crate::rows::build_rows`].
//!
//! # Data flow
//! Once per scene: the pieces and atlases become every texel's row of `(weight, source)`
//! entries ([`crate::rows`]), uploaded in *bands* of lightmap rows whose entries fit one
//! storage binding (`max_storage_buffer_binding_size`). Per frame: `cs_pack` copies the
//! transfer's input (the first-order map) and the packed pyramid into one RGBA32F source
//! buffer, then one `cs_rows` dispatch per band writes `final = base + Σ_row w · source` into
//! the RGBA32F final texture (one invocation per texel; no atomics, no blending).
//!
//! # Cost
//! 16 bytes per entry (RGB weight, source index), 4 per texel of offsets, 16 per source
//! texel; per frame every entry is read once with one source read. The atlases are not read
//! at render time: the rows hold the maps' values.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::rows::{RowEntry, RowSchedule};
use crate::util;

/// Invocations per `cs_pack` workgroup (must match `PACK_GROUP` in the shader).
const PACK_GROUP: u32 = 64;
/// Largest workgroup count per dispatch dimension (must match `MAX_GROUPS_X` in the shader).
const MAX_GROUPS_X: u32 = 65535;

/// Uniform of one band. 32 bytes. Must match `RowParams` in `shaders/transfer_rows.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
struct RowParams {
    lightmap_size: [u32; 2],
    y0: u32,
    rows: u32,
    source_len: u32,
    packed_width: u32,
    _pad: [u32; 2],
}

/// Pipelines of the rows path.
#[derive(Debug)]
pub struct RowsPass {
    layout: wgpu::BindGroupLayout,
    pack: wgpu::ComputePipeline,
    rows: wgpu::ComputePipeline,
}

/// One band of lightmap rows: its uniform, offsets and entries, and its row count.
#[derive(Debug)]
struct Band {
    params: wgpu::Buffer,
    offsets: wgpu::Buffer,
    entries: wgpu::Buffer,
    rows: u32,
}

/// Per-scene data of the rows path.
#[derive(Debug)]
pub struct RowsScene {
    lightmap_size: [u32; 2],
    source_len: u32,
    source: wgpu::Buffer,
    bands: Vec<Band>,
    final_view: wgpu::TextureView,
    /// Entries uploaded (for benchmarks: the reads per frame).
    pub entries: u64,
}

impl RowsPass {
    /// Builds the two compute pipelines.
    pub fn new(gpu: &Gpu) -> Result<Self, PassError> {
        gpu.scoped("ortm.transfer_rows.new", || {
            let device = &gpu.device;
            let module = util::shader(
                device,
                "ortm.transfer_rows.shader",
                include_str!("../shaders/transfer_rows.wgsl"),
            );
            let cs = wgpu::ShaderStages::COMPUTE;
            // Order = @binding order in transfer_rows.wgsl.
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.transfer_rows.layout"),
                entries: &[
                    util::uniform_entry(0, cs),
                    util::texture_entry(1, cs),
                    util::texture_entry(2, cs),
                    util::texture_entry(3, cs),
                    util::storage_entry(4, cs, false),
                    util::storage_texture_entry(5, wgpu::TextureFormat::Rgba32Float),
                    util::storage_entry(6, cs, true),
                    util::storage_entry(7, cs, true),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.transfer_rows.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let make = |entry: &str| {
                device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                    label: Some(&format!("ortm.transfer_rows.{entry}")),
                    layout: Some(&pipeline_layout),
                    module: &module,
                    entry_point: Some(entry),
                    compilation_options: Default::default(),
                    cache: None,
                })
            };
            Self {
                pack: make("cs_pack"),
                rows: make("cs_rows"),
                layout,
            }
        })
    }

    /// Uploads `rows` in bands; returns the scene and the final texture (RGBA32F).
    ///
    /// Errors: [`PassError::TooLarge`] when the source buffer, or one lightmap row's entries,
    /// exceed the device's storage binding size.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        rows: &RowSchedule,
    ) -> Result<(RowsScene, wgpu::Texture), PassError> {
        let device = &gpu.device;
        let [w, h] = rows.lightmap_size;
        let max_buf = device.limits().max_storage_buffer_binding_size;
        let source_bytes = rows.source_len as u64 * 16;
        if source_bytes > max_buf {
            return Err(PassError::TooLarge {
                what: "rows path: source buffer (bytes)".into(),
                size: source_bytes,
                limit: max_buf,
            });
        }
        let source = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.transfer_rows.source"),
            size: source_bytes.max(16),
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let final_tex = util::texture_2d(
            device,
            "ortm.transfer_rows.final_lightmap",
            rows.lightmap_size,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        let max_entries = max_buf / std::mem::size_of::<RowEntry>() as u64;
        let mut bands = Vec::new();
        let mut y0 = 0u32;
        while y0 < h {
            let start = rows.offsets[(y0 * w) as usize];
            let mut y1 = y0;
            while y1 < h && (rows.offsets[((y1 + 1) * w) as usize] - start) as u64 <= max_entries {
                y1 += 1;
            }
            if y1 == y0 {
                let n = rows.offsets[((y0 + 1) * w) as usize] - start;
                return Err(PassError::TooLarge {
                    what: format!("rows path: entries of lightmap row {y0} (bytes)"),
                    size: n as u64 * 16,
                    limit: max_buf,
                });
            }
            let end = rows.offsets[(y1 * w) as usize];
            let offsets: Vec<u32> = rows.offsets[(y0 * w) as usize..=(y1 * w) as usize]
                .iter()
                .map(|o| o - start)
                .collect();
            let mut entries = &rows.entries[start as usize..end as usize];
            let empty = [RowEntry::default()];
            if entries.is_empty() {
                entries = &empty; // a binding may not be empty
            }
            let storage = wgpu::BufferUsages::STORAGE;
            let params = RowParams {
                lightmap_size: rows.lightmap_size,
                y0,
                rows: y1 - y0,
                source_len: rows.source_len,
                packed_width: rows.packed_width(),
                _pad: [0; 2],
            };
            bands.push(Band {
                params: util::buffer_init(
                    device,
                    &format!("ortm.transfer_rows.params.band{}", bands.len()),
                    bytemuck::bytes_of(&params),
                    wgpu::BufferUsages::UNIFORM,
                ),
                offsets: util::buffer_init(
                    device,
                    &format!("ortm.transfer_rows.offsets.band{}", bands.len()),
                    bytemuck::cast_slice(&offsets),
                    storage,
                ),
                entries: util::buffer_init(
                    device,
                    &format!("ortm.transfer_rows.entries.band{}", bands.len()),
                    bytemuck::cast_slice(entries),
                    storage,
                ),
                rows: y1 - y0,
            });
            y0 = y1;
        }
        Ok((
            RowsScene {
                lightmap_size: rows.lightmap_size,
                source_len: rows.source_len,
                source,
                bands,
                final_view: util::view(&final_tex),
                entries: rows.entries.len() as u64,
            },
            final_tex,
        ))
    }

    /// Records the pack and one rows dispatch per band. `first_order` is what the pieces
    /// read, `base` the first-order term the final starts from (`first_order` when `None`),
    /// `pyramid` the packed pyramid (any RGBA32F texture when no row reads a level > 0).
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        scene: &RowsScene,
        (first_order, base, pyramid): (
            &wgpu::TextureView,
            Option<&wgpu::TextureView>,
            &wgpu::TextureView,
        ),
    ) {
        let base = base.unwrap_or(first_order);
        let groups: Vec<wgpu::BindGroup> = scene
            .bands
            .iter()
            .enumerate()
            .map(|(i, band)| {
                let entries = [
                    (0, band.params.as_entire_binding()),
                    (1, wgpu::BindingResource::TextureView(first_order)),
                    (2, wgpu::BindingResource::TextureView(base)),
                    (3, wgpu::BindingResource::TextureView(pyramid)),
                    (4, scene.source.as_entire_binding()),
                    (5, wgpu::BindingResource::TextureView(&scene.final_view)),
                    (6, band.offsets.as_entire_binding()),
                    (7, band.entries.as_entire_binding()),
                ]
                .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource });
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&format!("ortm.transfer_rows.band{i}_bind_group")),
                    layout: &self.layout,
                    entries: &entries,
                })
            })
            .collect();
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ortm.transfer_rows.pass"),
            timestamp_writes: None,
        });
        let Some(first) = groups.first() else {
            return;
        };
        let groups_needed = scene.source_len.div_ceil(PACK_GROUP);
        pass.set_pipeline(&self.pack);
        pass.set_bind_group(0, first, &[]);
        pass.dispatch_workgroups(
            groups_needed.min(MAX_GROUPS_X),
            groups_needed.div_ceil(MAX_GROUPS_X),
            1,
        );
        pass.set_pipeline(&self.rows);
        for (bg, band) in groups.iter().zip(&scene.bands) {
            pass.set_bind_group(0, bg, &[]);
            pass.dispatch_workgroups(scene.lightmap_size[0].div_ceil(8), band.rows.div_ceil(8), 1);
        }
    }
}
