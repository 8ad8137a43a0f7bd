//! Gutter dilation: fills uncovered lightmap texels (alpha = 0) near a chart with the value
//! of the nearest covered texel, so that bilinear filtering at chart borders never pulls in
//! black. `shaders/dilate.wgsl`, mirror [`crate::cpu::dilate`].
//!
//! # Rule: nearest-texel copy
//! A lightmap's coverage is static (the first-order pass rasterises the mesh by its UVs once
//! per scene), so the whole dilation is planned once per scene on the CPU
//! ([`dilation_sources`], kept in a [`DilatePlan`]): every texel gets a *source*
//! - a covered texel: itself;
//! - an empty texel within [`DilateOptions::rings`] of coverage (Chebyshev distance, i.e.
//!   the texels that `rings` one-texel growth steps of an 8-neighbourhood would reach): the
//!   covered texel within that Chebyshev distance that is nearest in Euclidean distance,
//!   ties broken by scan order (smallest `y·W + x`);
//! - any other texel: none (it stays 0).
//!
//! A filled texel gets its source's RGB with alpha [`FILLED_ALPHA`]. This is the usual
//! practice of lightmap tools; the plan makes the per-frame cost one copy plus the gutter
//! rectangles (timings in `docs/render.md`, section *Dilation*).
//!
//! # Data flow
//! [`DilatePass::prepare`] uploads a plan once: its sources as an `R32Uint` texture
//! (`x | y << 16` of the source texel, [`NO_SOURCE`] for none) and the rectangles of
//! [`DilatePlan::gutter_rects`] (every texel the plan does not mark covered, in
//! [`GUTTER_BLOCK`]² cells); it allocates the RGBA32F output. [`DilatePass::encode`] then
//! either ([`DilatePath::CopyAndGutter`], an RGBA32F input with `COPY_SRC`) copies the input
//! into the output and runs `fs_dilate` over the rectangles only, or
//! ([`DilatePath::FullScreen`], any other float input) runs `fs_dilate` over one full-screen
//! triangle. Both give the same map, since `fs_dilate` returns the input at texels the plan
//! marks covered.
//!
//! `fs_dilate` also trusts the input's own alpha: a texel with alpha > 0 is copied unchanged
//! whatever the plan says, and a source that is empty in the input gives 0 — so a covered
//! texel is never overwritten, even in a map whose coverage differs from the plan's (the
//! viewer's CPU-made lightmaps). A texel the plan marks covered is always copied unchanged.

//! # Conventions
//! Input: any float RGBA texture with alpha = coverage (first-order or final lightmap,
//! RGBA32F or RGBA16F). Output alpha: 1 (or the input's alpha) covered, [`FILLED_ALPHA`]
//! filled, 0 still empty. Units are those of the input (W/m²).
//!
//! # Limits
//! Fills at most `rings` texels beyond a chart; a bilinear lookup needs 1, mip-mapping would
//! need more. A gutter narrower than `2·rings` between two charts is split between them
//! (each empty texel copies whichever chart is nearer).

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::types::TexelImage;
use crate::util;

/// Alpha of texels filled by dilation. Must match `FILLED_ALPHA` in `shaders/dilate.wgsl`.
pub const FILLED_ALPHA: f32 = 0.5;

/// Source index of a texel that stays empty (in [`DilatePlan::sources`]); also the packed
/// value the shader reads for it. Must match `NO_SOURCE` in `shaders/dilate.wgsl`.
pub const NO_SOURCE: u32 = u32::MAX;

/// Settings fixed at creation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DilateOptions {
    /// Gutter width in texels (≥ 1): empty texels within this Chebyshev distance of a
    /// covered texel are filled.
    pub rings: u32,
}

impl Default for DilateOptions {
    fn default() -> Self {
        Self { rings: 4 }
    }
}

/// For a `width × height` coverage mask (row-major, row 0 first; `true` = covered), the
/// source of every texel as an index `y·width + x`, or [`NO_SOURCE`]: covered → itself;
/// empty with a covered texel within Chebyshev distance `rings` → among those, the one
/// nearest in Euclidean distance, ties broken by the smallest index (scan order); otherwise
/// [`NO_SOURCE`]. Pure; `O(W·H·(2·rings + 1)²)` at worst.
///
/// # Errors
/// [`PassError::BadLength`] when `covered.len() != width·height`.
pub fn dilation_sources(
    width: u32,
    height: u32,
    covered: &[bool],
    rings: u32,
) -> Result<Vec<u32>, PassError> {
    let n = width as usize * height as usize;
    if covered.len() != n {
        return Err(PassError::BadLength {
            what: "dilation coverage mask".into(),
            expected: n,
            got: covered.len(),
            hint: "one bool per texel of the W×H lightmap, row-major".into(),
        });
    }
    if n > NO_SOURCE as usize {
        return Err(PassError::InvalidInput {
            what: "dilation coverage mask".into(),
            problem: format!("{width}×{height} texels do not fit 32-bit indices"),
        });
    }
    // Window offsets in the order the rule prefers them: Euclidean distance, then scan order
    // of the source texel (dy, then dx) — so the first covered one is the answer.
    let r = rings as i64;
    let mut offsets: Vec<(i64, i64)> = (-r..=r)
        .flat_map(|dy| (-r..=r).map(move |dx| (dx, dy)))
        .filter(|&(dx, dy)| (dx, dy) != (0, 0))
        .collect();
    offsets.sort_by_key(|&(dx, dy)| (dx * dx + dy * dy, dy, dx));
    let (w, h) = (width as i64, height as i64);
    let mut sources = vec![NO_SOURCE; n];
    for y in 0..h {
        for x in 0..w {
            let i = (y * w + x) as usize;
            if covered[i] {
                sources[i] = i as u32;
                continue;
            }
            let hit = offsets.iter().find_map(|&(dx, dy)| {
                let (qx, qy) = (x + dx, y + dy);
                let inside = qx >= 0 && qy >= 0 && qx < w && qy < h;
                let j = (qy * w + qx) as usize;
                (inside && covered[j]).then_some(j as u32)
            });
            if let Some(j) = hit {
                sources[i] = j;
            }
        }
    }
    Ok(sources)
}

/// The per-scene dilation plan: every texel's source (see the module docs).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct DilatePlan {
    /// Map width in texels.
    pub width: u32,
    /// Map height in texels.
    pub height: u32,
    /// Gutter width it was built for.
    pub rings: u32,
    /// [`dilation_sources`] of the coverage: `width·height` indices `y·width + x`, or
    /// [`NO_SOURCE`].
    pub sources: Vec<u32>,
}

impl DilatePlan {
    /// Checks that every source index lies inside the plan's `width × height` map, which
    /// holds `sources.len()` texels (the GPU pass and the CPU mirror check it before use).
    ///
    /// # Errors
    /// [`PassError::InvalidInput`] naming `DilatePlan.sources`.
    pub fn check_sources(&self) -> Result<(), PassError> {
        let n = self.sources.len();
        if self
            .sources
            .iter()
            .any(|&s| s != NO_SOURCE && s as usize >= n)
        {
            return Err(PassError::InvalidInput {
                what: "DilatePlan.sources".into(),
                problem: "a source index lies outside the map; build the plan with \
                          DilatePlan::new"
                    .into(),
            });
        }
        Ok(())
    }

    /// The plan of a coverage mask (see [`dilation_sources`]).
    ///
    /// # Errors
    /// As [`dilation_sources`].
    pub fn new(width: u32, height: u32, covered: &[bool], rings: u32) -> Result<Self, PassError> {
        Ok(Self {
            width,
            height,
            rings,
            sources: dilation_sources(width, height, covered, rings)?,
        })
    }

    /// The plan of a map whose alpha is its coverage (alpha > 0 = covered), e.g. a read-back
    /// first-order lightmap.
    pub fn from_alpha(map: &TexelImage, rings: u32) -> Result<Self, PassError> {
        let covered: Vec<bool> = map.rgba.iter().map(|t| t[3] > 0.0).collect();
        Self::new(map.width, map.height, &covered, rings)
    }

    /// Source texel `(x, y)` of texel `(x, y)`, or `None` when it stays empty.
    pub fn source(&self, x: u32, y: u32) -> Option<(u32, u32)> {
        let s = self.sources[y as usize * self.width as usize + x as usize];
        (s != NO_SOURCE).then(|| (s % self.width, s / self.width))
    }

    /// Number of texels the plan fills (empty with a source).
    pub fn filled_texels(&self) -> usize {
        self.sources
            .iter()
            .enumerate()
            .filter(|&(i, &s)| s != NO_SOURCE && s as usize != i)
            .count()
    }

    /// Rectangles `[x0, y0, x1, y1]` (texels, `x1`/`y1` exclusive) that together contain
    /// every texel the plan does not mark covered (source ≠ itself): the `block × block`
    /// cells holding such a texel, merged into runs along each row of cells, and runs with
    /// the same columns in consecutive rows of cells merged into one rectangle. Clipped to
    /// the map; disjoint.
    pub fn gutter_rects(&self, block: u32) -> Vec<[u32; 4]> {
        let (w, h) = (self.width, self.height);
        let b = block.max(1);
        let (bw, bh) = (w.div_ceil(b), h.div_ceil(b));
        let mut marked = vec![false; bw as usize * bh as usize];
        for (i, &s) in self.sources.iter().enumerate() {
            if s as usize != i {
                let (x, y) = (i as u32 % w, i as u32 / w);
                marked[((y / b) * bw + x / b) as usize] = true;
            }
        }
        // Runs per row of cells: (first column, end column).
        let mut open: Vec<([u32; 2], u32)> = Vec::new(); // run, first cell row
        let mut rects = Vec::new();
        let emit = |run: [u32; 2], r0: u32, r1: u32, rects: &mut Vec<[u32; 4]>| {
            rects.push([run[0] * b, r0 * b, (run[1] * b).min(w), (r1 * b).min(h)]);
        };
        for by in 0..=bh {
            let mut runs = Vec::new();
            if by < bh {
                let mut bx = 0;
                while bx < bw {
                    if marked[(by * bw + bx) as usize] {
                        let x0 = bx;
                        while bx < bw && marked[(by * bw + bx) as usize] {
                            bx += 1;
                        }
                        runs.push([x0, bx]);
                    } else {
                        bx += 1;
                    }
                }
            }
            // Both lists are sorted by first column and disjoint: merge them. A run equal to
            // an open one extends it; an open run with no equal run ends.
            let mut next = Vec::with_capacity(runs.len());
            let mut k = 0;
            for run in runs {
                while k < open.len() && open[k].0[0] < run[0] {
                    emit(open[k].0, open[k].1, by, &mut rects);
                    k += 1;
                }
                if k < open.len() && open[k].0 == run {
                    next.push(open[k]);
                    k += 1;
                } else {
                    next.push((run, by));
                }
            }
            for &(run, r0) in &open[k..] {
                emit(run, r0, by, &mut rects);
            }
            open = next;
        }
        rects
    }

    /// The sources as the shader reads them: `x | y << 16` of the source texel, or
    /// [`NO_SOURCE`].
    fn packed(&self) -> Vec<u32> {
        let w = self.width;
        self.sources
            .iter()
            .map(|&s| {
                if s == NO_SOURCE {
                    NO_SOURCE
                } else {
                    (s % w) | ((s / w) << 16)
                }
            })
            .collect()
    }
}

/// The dilation pass.
#[derive(Debug)]
pub struct DilatePass {
    options: DilateOptions,
    layout: wgpu::BindGroupLayout,
    /// `vs_fullscreen` / `fs_dilate`.
    fullscreen: wgpu::RenderPipeline,
    /// `vs_rect` / `fs_dilate`, instanced rectangles.
    gutter: wgpu::RenderPipeline,
}

/// How [`DilatePass::encode`] ran (it picks by the input texture).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DilatePath {
    /// The input (RGBA32F, `COPY_SRC`) was copied into the output, then only the rectangles
    /// of [`DilatePlan::gutter_rects`] were drawn (`fs_dilate` on them).
    CopyAndGutter,
    /// One full-screen pass (any other float input, e.g. RGBA16F).
    FullScreen,
}

/// Cell size (texels) of [`DilatePlan::gutter_rects`] for the gutter draw: llvmpipe shades
/// 4×4 pixel blocks.
pub const GUTTER_BLOCK: u32 = 4;

/// Instance of the gutter draw: one rectangle in clip space (`x` right, `y` up).
/// 16 bytes; must match `vs_rect` in `dilate.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GutterRect {
    /// Clip-space `(x, y)` of the rectangle's left, top corner.
    pub clip_min: [f32; 2],
    /// Clip-space `(x, y)` of its right, bottom corner.
    pub clip_max: [f32; 2],
}

/// Per-scene data: the uploaded plan and the output texture.
#[derive(Debug)]
pub struct DilateTargets {
    size: [u32; 2],
    sources: wgpu::TextureView,
    gutter: wgpu::Buffer,
    gutter_count: u32,
    output: wgpu::Texture,
    output_view: wgpu::TextureView,
}

impl DilateTargets {
    /// Map `[W, H]`.
    pub fn size(&self) -> [u32; 2] {
        self.size
    }
    /// The RGBA32F output texture (the last [`DilatePass::encode`]'s result).
    pub fn output(&self) -> &wgpu::Texture {
        &self.output
    }
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
    /// Which way it ran.
    pub path: DilatePath,
}

impl DilatePass {
    /// Builds the render pipeline.
    pub fn new(gpu: &Gpu, options: &DilateOptions) -> Result<Self, PassError> {
        if options.rings == 0 || options.rings > 1024 {
            return Err(PassError::InvalidInput {
                what: "DilateOptions.rings".into(),
                problem: format!(
                    "{} is outside 1..=1024 (skip the pass instead of 0 rings)",
                    options.rings
                ),
            });
        }
        gpu.scoped("ortm.dilate.new", || {
            let device = &gpu.device;
            let module = util::shader(
                device,
                "ortm.dilate.shader",
                &[
                    util::FULLSCREEN_WGSL,
                    include_str!("../shaders/dilate.wgsl"),
                ]
                .concat(),
            );
            let fs = wgpu::ShaderStages::FRAGMENT;
            // Order = @binding order in dilate.wgsl.
            let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.dilate.layout"),
                entries: &[
                    util::texture_entry(0, fs),
                    wgpu::BindGroupLayoutEntry {
                        binding: 1,
                        visibility: fs,
                        ty: wgpu::BindingType::Texture {
                            sample_type: wgpu::TextureSampleType::Uint,
                            view_dimension: wgpu::TextureViewDimension::D2,
                            multisampled: false,
                        },
                        count: None,
                    },
                ],
            });
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.dilate.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            let fullscreen = util::fullscreen_pipeline(
                device,
                "ortm.dilate.fullscreen_pipeline",
                Some(&pl),
                &module,
                "fs_dilate",
                wgpu::TextureFormat::Rgba32Float,
                None,
            );
            let gutter = util::colour_pipeline(
                device,
                "ortm.dilate.gutter_pipeline",
                Some(&pl),
                &module,
                (
                    "vs_rect",
                    &[Some(wgpu::VertexBufferLayout {
                        array_stride: std::mem::size_of::<GutterRect>() as u64,
                        step_mode: wgpu::VertexStepMode::Instance,
                        attributes: &wgpu::vertex_attr_array![0 => Float32x2, 1 => Float32x2],
                    })],
                ),
                "fs_dilate",
                wgpu::TextureFormat::Rgba32Float,
                None,
            );
            Self {
                options: *options,
                layout,
                fullscreen,
                gutter,
            }
        })
    }

    /// The options the pass was created with.
    pub fn options(&self) -> &DilateOptions {
        &self.options
    }

    /// The plan of a coverage map (alpha > 0 = covered) with this pass's ring count.
    pub fn plan(&self, coverage: &TexelImage) -> Result<DilatePlan, PassError> {
        DilatePlan::from_alpha(coverage, self.options.rings)
    }

    /// Uploads `plan` and allocates the output for its size.
    pub fn prepare(&self, gpu: &Gpu, plan: &DilatePlan) -> Result<DilateTargets, PassError> {
        let size = [plan.width, plan.height];
        gpu.check_texture_size("dilation target", size[0], size[1])?;
        let n = size[0] as usize * size[1] as usize;
        if plan.sources.len() != n {
            return Err(PassError::BadLength {
                what: "DilatePlan.sources".into(),
                expected: n,
                got: plan.sources.len(),
                hint: "build the plan with DilatePlan::new".into(),
            });
        }
        plan.check_sources()?;
        gpu.scoped("ortm.dilate.prepare", || {
            let device = &gpu.device;
            let sources = util::texture_2d(
                device,
                "ortm.dilate.sources",
                size,
                wgpu::TextureFormat::R32Uint,
                wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
            );
            gpu.queue.write_texture(
                sources.as_image_copy(),
                bytemuck::cast_slice(&plan.packed()),
                wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(size[0] * 4),
                    rows_per_image: Some(size[1]),
                },
                wgpu::Extent3d {
                    width: size[0],
                    height: size[1],
                    depth_or_array_layers: 1,
                },
            );
            let output = util::texture_2d(
                device,
                "ortm.dilate.output",
                size,
                wgpu::TextureFormat::Rgba32Float,
                wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC
                    | wgpu::TextureUsages::COPY_DST,
            );
            let (w, h) = (size[0] as f32, size[1] as f32);
            let mut rects: Vec<GutterRect> = plan
                .gutter_rects(GUTTER_BLOCK)
                .iter()
                .map(|r| GutterRect {
                    clip_min: [r[0] as f32 / w * 2.0 - 1.0, 1.0 - r[1] as f32 / h * 2.0],
                    clip_max: [r[2] as f32 / w * 2.0 - 1.0, 1.0 - r[3] as f32 / h * 2.0],
                })
                .collect();
            let gutter_count = rects.len() as u32;
            if rects.is_empty() {
                rects.push(GutterRect::default()); // a buffer may not be empty; not drawn
            }
            let gutter = util::buffer_init(
                device,
                "ortm.dilate.gutter_rects",
                bytemuck::cast_slice(&rects),
                wgpu::BufferUsages::VERTEX,
            );
            DilateTargets {
                size,
                sources: util::view(&sources),
                gutter,
                gutter_count,
                output_view: util::view(&output),
                output,
            }
        })
    }

    /// Records the dilation: one full-screen pass into the targets' output.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &DilateInputs<'_>,
    ) -> DilateOutput {
        let t = inputs.targets;
        // Order = @binding order in dilate.wgsl.
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.dilate.bind_group"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::TextureView(inputs.source),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::TextureView(&t.sources),
                },
            ],
        });
        let input = inputs.source.texture();
        let copyable = input.format() == wgpu::TextureFormat::Rgba32Float
            && input.usage().contains(wgpu::TextureUsages::COPY_SRC)
            && [input.width(), input.height()] == t.size
            && input.mip_level_count() == 1
            && input.depth_or_array_layers() == 1;
        let path = if copyable {
            encoder.copy_texture_to_texture(
                input.as_image_copy(),
                t.output.as_image_copy(),
                wgpu::Extent3d {
                    width: t.size[0],
                    height: t.size[1],
                    depth_or_array_layers: 1,
                },
            );
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("ortm.dilate.gutter_pass"),
                color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                    view: &t.output_view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Load,
                        store: wgpu::StoreOp::Store,
                    },
                })],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            if t.gutter_count > 0 {
                pass.set_pipeline(&self.gutter);
                pass.set_bind_group(0, &group, &[]);
                pass.set_vertex_buffer(0, t.gutter.slice(..));
                pass.draw(0..6, 0..t.gutter_count);
            }
            DilatePath::CopyAndGutter
        } else {
            let mut pass = util::clear_pass(encoder, "ortm.dilate.pass", &t.output_view);
            pass.set_pipeline(&self.fullscreen);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
            DilatePath::FullScreen
        };
        DilateOutput {
            dilated_tex: t.output.clone(),
            path,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sources_of_a_single_texel_and_ties() {
        // 5×3, one covered texel at (2, 1); 1 ring fills its 8 neighbours from it.
        let mut cov = vec![false; 15];
        cov[7] = true;
        let s = dilation_sources(5, 3, &cov, 1).unwrap();
        let want: Vec<u32> = (0..15u32)
            .map(|i| {
                if (i % 5).abs_diff(2) <= 1 {
                    7
                } else {
                    NO_SOURCE
                }
            })
            .collect();
        assert_eq!(s, want);
        // Two covered texels at equal distance from (1, 0): (0, 0) and (2, 0) → scan order
        // picks (0, 0); (1, 1) has (0, 0), (2, 0) diagonal and nothing nearer → (0, 0) too.
        let cov = [true, false, true, false, false, false];
        let s = dilation_sources(3, 2, &cov, 1).unwrap();
        assert_eq!(s, vec![0, 0, 2, 0, 0, 2]);
    }

    #[test]
    fn gutter_rect_matches_wgsl_size() {
        assert_eq!(std::mem::size_of::<GutterRect>(), 16);
    }

    #[test]
    fn bad_mask_length_is_an_error() {
        let e = dilation_sources(4, 4, &[true; 15], 2).unwrap_err();
        assert!(e.to_string().contains("16"), "{e}");
    }

    #[test]
    fn packed_coordinates() {
        let plan = DilatePlan {
            width: 3,
            height: 2,
            rings: 1,
            sources: vec![0, 5, NO_SOURCE, 4, 4, 5],
        };
        assert_eq!(
            plan.packed(),
            vec![
                0,
                2 | 1 << 16,
                NO_SOURCE,
                1 | 1 << 16,
                1 | 1 << 16,
                2 | 1 << 16
            ]
        );
        assert_eq!(plan.source(1, 0), Some((2, 1)));
        assert_eq!(plan.source(2, 0), None);
        assert_eq!(plan.filled_texels(), 2);
    }
}
