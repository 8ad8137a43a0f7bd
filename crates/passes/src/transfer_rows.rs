//! Rows path of the transfer pass, selected by [`crate::transfer::TransferPath::Rows`]; shader
//! `shaders/transfer_rows.wgsl`, mirror [`crate::cpu::transfer_rows`], rows built by
//! [`crate::rows::build_rows`].
//!
//! # Data flow
//! Once per scene: the pieces and atlases become every texel's row of `(weight, source)`
//! entries ([`crate::rows`]), uploaded in *bands* of lightmap rows whose entries fit one
//! RGBA32Uint texture (`TEXTURE_WIDTH × max_texture_dimension_2d` entries) and whose row
//! offsets fit one storage binding. Per frame: `cs_pack` copies the transfer's input (the
//! first-order map) and the packed pyramid into one RGBA32F source texture, then one
//! `cs_rows` dispatch per band writes `final = base + Σ_row w · source` into the RGBA32F
//! final texture (one invocation per texel; no atomics, no blending).
//!
//! # Why textures
//! The entries and the source are read with `textureLoad`, not from storage buffers: on
//! lavapipe a storage-buffer load at an address that differs between invocations is done one
//! invocation and one component at a time, a texel fetch as one gather. With both in storage
//! buffers and one entry per loop iteration the pass took 27.5 ms (55 ms of CPU) on the head
//! at 256²; with textures and two entries per iteration 22.2 ms (44 ms;
//! `ortm bench render --bake DIR --paths rows`, three runs of each alternating, see
//! `docs/render.md`, "Rows path").
//!
//! # Cost
//! 16 bytes per entry (RGB weight, source index), 4 per texel of offsets, 16 per source
//! texel; per frame every entry is read once with one source read. The atlases are not
//! uploaded: the rows hold the maps' values.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::rows::{RowEntry, RowSchedule};
use crate::util;

/// Invocations per `cs_pack` workgroup (must match `PACK_GROUP` in the shader).
const PACK_GROUP: u32 = 64;
/// Largest workgroup count per dispatch dimension (must match `MAX_GROUPS_X` in the shader).
const MAX_GROUPS_X: u32 = 65535;

/// Width of the source and entries textures: element `i` lies at `(i mod TEXTURE_WIDTH,
/// i / TEXTURE_WIDTH)`. Must match `TEXTURE_WIDTH` in the shader.
const TEXTURE_WIDTH: u32 = 4096;

/// One band's entries as an RGBA32Uint texture, `TEXTURE_WIDTH` wide (the tail of the last
/// row zero): [`RowEntry`]'s 16 bytes per texel.
fn entry_texture(gpu: &Gpu, band: usize, entries: &[RowEntry]) -> wgpu::TextureView {
    let height = (entries.len() as u32).div_ceil(TEXTURE_WIDTH);
    let size = wgpu::Extent3d {
        width: TEXTURE_WIDTH,
        height,
        depth_or_array_layers: 1,
    };
    let tex = gpu.device.create_texture(&wgpu::TextureDescriptor {
        label: Some(&format!("ortm.transfer_rows.entries.band{band}")),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Rgba32Uint,
        usage: wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    // The full rows straight from `entries` (no copy of them all), the last one padded.
    let full = (entries.len() / TEXTURE_WIDTH as usize) as u32;
    let write = |y: u32, rows: u32, bytes: &[u8]| {
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &tex,
                mip_level: 0,
                origin: wgpu::Origin3d { x: 0, y, z: 0 },
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(TEXTURE_WIDTH * 16),
                rows_per_image: Some(rows),
            },
            wgpu::Extent3d {
                width: TEXTURE_WIDTH,
                height: rows,
                depth_or_array_layers: 1,
            },
        );
    };
    let split = (full * TEXTURE_WIDTH) as usize;
    if full > 0 {
        write(0, full, bytemuck::cast_slice(&entries[..split]));
    }
    if split < entries.len() {
        let mut tail = bytemuck::cast_slice::<RowEntry, u8>(&entries[split..]).to_vec();
        tail.resize(TEXTURE_WIDTH as usize * 16, 0);
        write(full, 1, &tail);
    }
    util::view(&tex)
}

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
    /// At most this many entries per band (`None`: what one texture holds).
    band_entries: Option<u64>,
    pack_layout: wgpu::BindGroupLayout,
    layout: wgpu::BindGroupLayout,
    pack: wgpu::ComputePipeline,
    rows: wgpu::ComputePipeline,
}

/// One band of lightmap rows: its uniform, offsets and entries, and its row count.
#[derive(Debug)]
struct Band {
    params: wgpu::Buffer,
    offsets: wgpu::Buffer,
    entries: wgpu::TextureView,
    rows: u32,
}

/// Per-scene data of the rows path.
#[derive(Debug)]
pub struct RowsScene {
    lightmap_size: [u32; 2],
    source_len: u32,
    source: wgpu::TextureView,
    bands: Vec<Band>,
    final_view: wgpu::TextureView,
    /// Entries uploaded (for benchmarks: the reads per frame).
    pub entries: u64,
}

impl RowsScene {
    /// The number of bands (one `cs_rows` dispatch each).
    pub fn bands(&self) -> usize {
        self.bands.len()
    }
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
            let pack_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.transfer_rows.pack_layout"),
                entries: &[
                    util::uniform_entry(0, cs),
                    util::texture_entry(1, cs),
                    util::texture_entry(3, cs),
                    util::storage_texture_entry(4, wgpu::TextureFormat::Rgba32Float),
                ],
            });
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.transfer_rows.layout"),
                entries: &[
                    util::uniform_entry(0, cs),
                    util::texture_entry(2, cs),
                    util::storage_texture_entry(5, wgpu::TextureFormat::Rgba32Float),
                    util::storage_entry(6, cs, true),
                    wgpu::BindGroupLayoutEntry {
                        binding: 7,
                        visibility: cs,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Uint,
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    },
                    util::texture_entry(8, cs),
                ],
            });
            let make = |layout: &wgpu::BindGroupLayout, entry: &str| {
                let pipeline_layout =
                    device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                        label: Some(&format!("ortm.transfer_rows.{entry}_layout")),
                        bind_group_layouts: &[Some(layout)],
                        immediate_size: 0,
                    });
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
                band_entries: None,
                pack: make(&pack_layout, "cs_pack"),
                rows: make(&layout, "cs_rows"),
                pack_layout,
                layout,
            }
        })
    }

    /// Splits the rows into bands of at most `n` entries instead of what one texture holds
    /// (tests: many bands on small maps).
    pub fn with_band_entries(mut self, n: u64) -> Self {
        self.band_entries = Some(n);
        self
    }

    /// Uploads `rows` in bands; returns the scene and the final texture (RGBA32F).
    ///
    /// Errors: [`PassError::TooLarge`] when the source, or one lightmap row's entries, exceed
    /// a texture of `TEXTURE_WIDTH × max_texture_dimension_2d` texels, or a band's offsets the
    /// storage binding size.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        rows: &RowSchedule,
    ) -> Result<(RowsScene, wgpu::Texture), PassError> {
        let device = &gpu.device;
        let [w, h] = rows.lightmap_size;
        let max_buf = device.limits().max_storage_buffer_binding_size;
        let max_texels = TEXTURE_WIDTH as u64 * device.limits().max_texture_dimension_2d as u64;
        if rows.source_len as u64 > max_texels {
            return Err(PassError::TooLarge {
                what: "rows path: source texture (first-order texels and pyramid blocks)".into(),
                size: rows.source_len as u64,
                limit: max_texels,
            });
        }
        let source = util::view(&util::texture_2d(
            device,
            "ortm.transfer_rows.source",
            [
                TEXTURE_WIDTH,
                rows.source_len.div_ceil(TEXTURE_WIDTH).max(1),
            ],
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING,
        ));
        let final_tex = util::texture_2d(
            device,
            "ortm.transfer_rows.final_lightmap",
            rows.lightmap_size,
            wgpu::TextureFormat::Rgba32Float,
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        // A band: the most lightmap rows whose entries fit one texture and whose offsets fit
        // one storage binding.
        let max_rows = ((max_buf / 4).saturating_sub(1) / w as u64).max(1) as u32;
        let band_entries = self.band_entries.unwrap_or(max_texels).min(max_texels);
        let mut bands = Vec::new();
        let mut y0 = 0u32;
        while y0 < h {
            let start = rows.offsets[(y0 * w) as usize];
            let mut y1 = y0;
            while y1 < h
                && y1 - y0 < max_rows
                && (rows.offsets[((y1 + 1) * w) as usize] - start) as u64 <= band_entries
            {
                y1 += 1;
            }
            if y1 == y0 {
                let n = rows.offsets[((y0 + 1) * w) as usize] - start;
                return Err(PassError::TooLarge {
                    what: format!("rows path: entries of lightmap row {y0}"),
                    size: n as u64,
                    limit: band_entries,
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
                entries = &empty; // a texture may not be empty
            }
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
                    wgpu::BufferUsages::STORAGE,
                ),
                entries: entry_texture(gpu, bands.len(), entries),
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
                    (2, wgpu::BindingResource::TextureView(base)),
                    (5, wgpu::BindingResource::TextureView(&scene.final_view)),
                    (6, band.offsets.as_entire_binding()),
                    (7, wgpu::BindingResource::TextureView(&band.entries)),
                    (8, wgpu::BindingResource::TextureView(&scene.source)),
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
        let Some(first) = scene.bands.first() else {
            return;
        };
        let pack_entries = [
            (0, first.params.as_entire_binding()),
            (1, wgpu::BindingResource::TextureView(first_order)),
            (3, wgpu::BindingResource::TextureView(pyramid)),
            (4, wgpu::BindingResource::TextureView(&scene.source)),
        ]
        .map(|(binding, resource)| wgpu::BindGroupEntry { binding, resource });
        let pack_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.transfer_rows.pack_bind_group"),
            layout: &self.pack_layout,
            entries: &pack_entries,
        });
        let groups_needed = scene.source_len.div_ceil(PACK_GROUP);
        pass.set_pipeline(&self.pack);
        pass.set_bind_group(0, &pack_group, &[]);
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
