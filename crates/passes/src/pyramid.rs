//! Pyramid pass: the area-weighted pyramid of the first-order lightmap that transfer pieces of
//! level > 0 read ([`crate::types::TransferPiece::level`]; multi-resolution maps). Shader
//! `shaders/pyramid.wgsl`, mirror [`crate::cpu::pyramid`].
//!
//! # What
//! `P_0` is the first-order map (RGB, W/m²). For `ℓ ≥ 1`, block `b` of level `ℓ` covers the
//! level-0 texels `[b·2^ℓ, (b+1)·2^ℓ)` (per axis, clipped to the map) and holds their
//! area-weighted mean `P_ℓ(b) = Σ_j w_j·B_o(j) / Σ_j w_j` (0 where `Σ w_j = 0`), `w` the static
//! [`TexelWeights`] (texel areas in m², 0 on uncovered texels). Level `ℓ` is
//! `⌈W/2^ℓ⌉ × ⌈H/2^ℓ⌉` blocks ([`level_size`]).
//!
//! # Data flow
//! Once per scene: [`PyramidPass::prepare`] uploads the weights (R32Float) and allocates the
//! sums buffer and the packed pyramid texture for levels `1..=max_level`. Per frame, after
//! the first-order pass: [`PyramidPass::encode`] records one compute dispatch per level.
//! Level 1 reads the first-order texture and the weights; level `ℓ ≥ 2` reads level `ℓ − 1`'s
//! sums. Each block stores its sums `(Σ w·B, Σ w)` in an RGBA32F storage buffer (the next
//! level's input: a 2×2 reduction of the sums gives exactly the block sums) and its mean
//! `(Σ w·B / Σ w, Σ w)` (RGB W/m², alpha m²) in the packed texture the transfer pass reads.
//!
//! Why compute with a sums buffer: a level is read and the next written in the same pass; a
//! storage *buffer* may be read and written by one dispatch (and wgpu orders consecutive
//! dispatches), whereas one texture cannot be bound for reading and writing at once (the
//! packed texture is only written here) and read-write storage textures of RGBA32F are not
//! core WebGPU. A render pass per level would need a texture per level (or a mip chain)
//! plus ping-pong. Storing sums (not means) keeps the reduction a plain sum.
//!
//! # Packed texture layout ([`level_origin`], [`packed_size`])
//! One RGBA32F texture holds levels `1..=max_level` side by side, as in a classic packed mip
//! chain: level 1 at `(0, 0)`, levels `ℓ ≥ 2` stacked in the column right of it, at
//! `x = ⌈W/2⌉`, `y = Σ_{k=2}^{ℓ−1} ⌈H/2^k⌉`. A level's origin depends only on `W, H, ℓ`, so the
//! schedule can put it into each piece's instance ([`crate::schedule::PieceInstance::origin`]).
//! Why packed rather than a mip chain: read-only storage textures (the cheap
//! [`crate::util::TexelReads::Storage`] reads) have no mip-level argument, and wgpu's mip
//! sizes round down (`⌊W/2^ℓ⌋`), where levels here need `⌈W/2^ℓ⌉`. Texels outside every
//! level's rectangle are never read (the schedule crops pieces so their reads stay inside
//! their level, [`crate::schedule`]).
//!
//! # Units and conventions
//! Texel `(x, y)`, `y` down, row 0 = `v = 1` (as the lightmap). Means in W/m², weights m².
//! Arithmetic is f32 on the GPU (the mirror sums in f64; `tests/pyramid.rs` checks the
//! derived bound).
//!
//! # Cost
//! Nothing at all when no piece has level > 0 (the renderer creates no pyramid scene). Else
//! `≈ W·H/3` block writes per frame and `16·W·H/3` bytes of sums plus the packed texture.

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::types::{MAX_PIECE_LEVEL, TexelWeights};
use crate::util;

/// Size in blocks of level `level` of a `size` lightmap: `⌈W/2^ℓ⌉ × ⌈H/2^ℓ⌉` (level 0 = the
/// lightmap).
pub fn level_size(size: [u32; 2], level: u32) -> [u32; 2] {
    size.map(|n| ((n as u64).div_ceil(1u64 << level)) as u32)
}

/// Top-left texel of level `level ≥ 1` in the packed pyramid texture (module docs); `(0, 0)`
/// for level 0 (the first-order texture itself).
pub fn level_origin(size: [u32; 2], level: u32) -> [u32; 2] {
    if level <= 1 {
        return [0, 0];
    }
    let y = (2..level).map(|k| level_size(size, k)[1]).sum();
    [level_size(size, 1)[0], y]
}

/// Size of the packed texture holding levels `1..=max_level` (`max_level ≥ 1`).
pub fn packed_size(size: [u32; 2], max_level: u32) -> [u32; 2] {
    let l1 = level_size(size, 1);
    if max_level < 2 {
        return l1;
    }
    let column_h: u32 = (2..=max_level).map(|k| level_size(size, k)[1]).sum();
    [l1[0] + level_size(size, 2)[0], l1[1].max(column_h)]
}

/// The levels `1..=max_level` cut out of a read-back packed texture (index `ℓ − 1` = level
/// `ℓ`); for tests and CPU references (mirrors take levels as images).
pub fn unpack_levels(
    packed: &crate::types::TexelImage,
    size: [u32; 2],
    max_level: u32,
) -> Vec<crate::types::TexelImage> {
    (1..=max_level)
        .map(|l| {
            let [w, h] = level_size(size, l);
            let [ox, oy] = level_origin(size, l);
            let mut img = crate::types::TexelImage::new(w, h);
            for y in 0..h {
                for x in 0..w {
                    *img.at_mut(x, y) = packed.get(ox + x, oy + y);
                }
            }
            img
        })
        .collect()
}

/// Uniform of one level's dispatch. 48 bytes.
/// Must match `Params` in `shaders/pyramid.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct PyramidParams {
    /// Size of level `ℓ − 1` in blocks (level 0: the lightmap).
    pub src_size: [u32; 2],
    /// Size of level `ℓ` in blocks.
    pub dst_size: [u32; 2],
    /// First element of level `ℓ − 1` in the sums buffer (unused for `ℓ = 1`).
    pub src_base: u32,
    /// First element of level `ℓ` in the sums buffer.
    pub dst_base: u32,
    /// Origin of level `ℓ` in the packed texture.
    pub dst_origin: [u32; 2],
    /// The level `ℓ ≥ 1`.
    pub level: u32,
    /// Padding to 48 bytes.
    pub _pad: [u32; 3],
}

/// The pyramid pass's pipeline.
#[derive(Debug)]
pub struct PyramidPass {
    layout: wgpu::BindGroupLayout,
    reduce: wgpu::ComputePipeline,
}

/// Per-scene data: weights, sums buffer, packed texture, one uniform per level.
#[derive(Debug)]
pub struct PyramidScene {
    lightmap_size: [u32; 2],
    max_level: u32,
    weights_view: wgpu::TextureView,
    sums: wgpu::Buffer,
    params: Vec<wgpu::Buffer>,
    packed: wgpu::Texture,
    packed_view: wgpu::TextureView,
}

impl PyramidScene {
    /// Lightmap `[W, H]`.
    pub fn lightmap_size(&self) -> [u32; 2] {
        self.lightmap_size
    }

    /// The highest level held (levels `1..=max_level`).
    pub fn max_level(&self) -> u32 {
        self.max_level
    }

    /// The packed RGBA32F texture of levels `1..=max_level` (module docs; RGB = block mean in
    /// W/m², alpha = the block's summed weight in m²), overwritten by every `encode`.
    pub fn texture(&self) -> &wgpu::Texture {
        &self.packed
    }

    /// The view of [`PyramidScene::texture`] the transfer pass binds.
    pub fn view(&self) -> &wgpu::TextureView {
        &self.packed_view
    }
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct PyramidInputs<'a> {
    /// Prepared scene.
    pub scene: &'a PyramidScene,
    /// First-order lightmap (RGBA32F, the scene's size), read with `textureLoad`.
    pub first_order: &'a wgpu::TextureView,
}

impl PyramidPass {
    /// Builds the compute pipeline.
    pub fn new(gpu: &Gpu) -> Result<Self, PassError> {
        gpu.scoped("ortm.pyramid.new", || {
            let device = &gpu.device;
            let module = util::shader(
                device,
                "ortm.pyramid.shader",
                include_str!("../shaders/pyramid.wgsl"),
            );
            let cs = wgpu::ShaderStages::COMPUTE;
            // Order = @binding order in pyramid.wgsl.
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.pyramid.layout"),
                entries: &[
                    util::uniform_entry(0, cs),
                    util::texture_entry(1, cs),
                    util::texture_entry(2, cs),
                    util::storage_entry(3, cs, false),
                    util::storage_texture_entry(4, wgpu::TextureFormat::Rgba32Float),
                ],
            });
            let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.pyramid.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let reduce = device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
                label: Some("ortm.pyramid.cs_reduce"),
                layout: Some(&pipeline_layout),
                module: &module,
                entry_point: Some("cs_reduce"),
                compilation_options: Default::default(),
                cache: None,
            });
            Self { layout, reduce }
        })
    }

    /// Validates and uploads `weights`, allocates levels `1..=max_level`.
    ///
    /// Errors: [`PassError::InvalidInput`] / [`PassError::BadLength`] for weights that do not
    /// fit `lightmap_size` or are negative or not finite, or `max_level` outside
    /// `1..=MAX_PIECE_LEVEL`; [`PassError::TooLarge`] beyond the device's limits.
    pub fn prepare(
        &self,
        gpu: &Gpu,
        lightmap_size: [u32; 2],
        weights: &TexelWeights,
        max_level: u32,
    ) -> Result<PyramidScene, PassError> {
        weights.validate(lightmap_size)?;
        if !(1..=MAX_PIECE_LEVEL).contains(&max_level) {
            return Err(PassError::InvalidInput {
                what: "pyramid max_level".into(),
                problem: format!("is {max_level}; it must be in 1..={MAX_PIECE_LEVEL}"),
            });
        }
        gpu.check_texture_size("lightmap", lightmap_size[0], lightmap_size[1])?;
        let device = &gpu.device;
        let weights_tex = util::texture_2d(
            device,
            "ortm.pyramid.weights",
            lightmap_size,
            wgpu::TextureFormat::R32Float,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        gpu.queue.write_texture(
            weights_tex.as_image_copy(),
            bytemuck::cast_slice(&weights.weights),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(lightmap_size[0] * 4),
                rows_per_image: Some(lightmap_size[1]),
            },
            wgpu::Extent3d {
                width: lightmap_size[0],
                height: lightmap_size[1],
                depth_or_array_layers: 1,
            },
        );
        let mut params = Vec::new();
        let mut base = 0u64;
        let mut src_base = 0u32;
        for l in 1..=max_level {
            let dst_size = level_size(lightmap_size, l);
            let p = PyramidParams {
                src_size: level_size(lightmap_size, l - 1),
                dst_size,
                src_base,
                dst_base: base as u32,
                dst_origin: level_origin(lightmap_size, l),
                level: l,
                _pad: [0; 3],
            };
            params.push(util::buffer_init(
                device,
                &format!("ortm.pyramid.params.level{l}"),
                bytemuck::bytes_of(&p),
                wgpu::BufferUsages::UNIFORM,
            ));
            src_base = base as u32;
            base += dst_size[0] as u64 * dst_size[1] as u64;
        }
        let max_buf = device.limits().max_storage_buffer_binding_size;
        if base * 16 > max_buf {
            return Err(PassError::TooLarge {
                what: "pyramid sums buffer (bytes)".into(),
                size: base * 16,
                limit: max_buf,
            });
        }
        let sums = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.pyramid.sums"),
            size: base * 16,
            usage: wgpu::BufferUsages::STORAGE,
            mapped_at_creation: false,
        });
        let psize = packed_size(lightmap_size, max_level);
        gpu.check_texture_size("packed pyramid", psize[0], psize[1])?;
        let packed = util::texture_2d(
            device,
            "ortm.pyramid.packed",
            psize,
            wgpu::TextureFormat::Rgba32Float,
            // Written as a storage texture here; the transfer pass reads it sampled or as a
            // read-only storage texture (`TexelReads`); read back by the tests.
            wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
        );
        gpu.check("ortm.pyramid.prepare")?;
        Ok(PyramidScene {
            lightmap_size,
            max_level,
            weights_view: util::view(&weights_tex),
            sums,
            params,
            packed_view: util::view(&packed),
            packed,
        })
    }

    /// Records one dispatch per level, `1..=max_level` in order (each reads the previous).
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PyramidInputs<'_>,
    ) {
        let scene = inputs.scene;
        let device = &gpu.device;
        // Order = @binding order in pyramid.wgsl.
        let groups: Vec<wgpu::BindGroup> = scene
            .params
            .iter()
            .enumerate()
            .map(|(i, p)| {
                device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some(&format!("ortm.pyramid.level{}_bind_group", i + 1)),
                    layout: &self.layout,
                    entries: &[
                        wgpu::BindGroupEntry {
                            binding: 0,
                            resource: p.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 1,
                            resource: wgpu::BindingResource::TextureView(inputs.first_order),
                        },
                        wgpu::BindGroupEntry {
                            binding: 2,
                            resource: wgpu::BindingResource::TextureView(&scene.weights_view),
                        },
                        wgpu::BindGroupEntry {
                            binding: 3,
                            resource: scene.sums.as_entire_binding(),
                        },
                        wgpu::BindGroupEntry {
                            binding: 4,
                            resource: wgpu::BindingResource::TextureView(&scene.packed_view),
                        },
                    ],
                })
            })
            .collect();
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
            label: Some("ortm.pyramid.pass"),
            timestamp_writes: None,
        });
        pass.set_pipeline(&self.reduce);
        for (i, bg) in groups.iter().enumerate() {
            let [w, h] = level_size(scene.lightmap_size, i as u32 + 1);
            pass.set_bind_group(0, bg, &[]);
            pass.dispatch_workgroups(w.div_ceil(8), h.div_ceil(8), 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn params_size_matches_wgsl() {
        assert_eq!(std::mem::size_of::<PyramidParams>(), 48);
    }

    /// Levels lie inside the packed texture and never overlap (brute force).
    #[test]
    fn packed_levels_are_disjoint_and_inside() {
        for size in [[1, 1], [2, 2], [37, 29], [64, 64], [5, 130], [130, 3]] {
            for max in 1..=MAX_PIECE_LEVEL {
                let [pw, ph] = packed_size(size, max);
                let mut owner = vec![0u32; (pw * ph) as usize];
                for l in 1..=max {
                    let [w, h] = level_size(size, l);
                    let [ox, oy] = level_origin(size, l);
                    assert!(ox + w <= pw && oy + h <= ph, "{size:?} level {l} of {max}");
                    for y in oy..oy + h {
                        for x in ox..ox + w {
                            let o = &mut owner[(y * pw + x) as usize];
                            assert_eq!(*o, 0, "{size:?}: levels {o} and {l} overlap");
                            *o = l;
                        }
                    }
                }
            }
        }
        assert_eq!(level_size([37, 29], 1), [19, 15]);
        assert_eq!(level_size([37, 29], 3), [5, 4]);
        assert_eq!(level_size([37, 29], 15), [1, 1]);
    }
}
