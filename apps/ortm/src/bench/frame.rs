//! Every stage of a [`Renderer`] frame timed on its own, each recorded through
//! [`Renderer::encode_frame`] with only that stage on (the others' outputs stay in the
//! scene from one full frame first).
//!
//! # Rows
//! 0. first order with moving lights: the shadow-map cache is invalidated before every run
//!    ([`FrameOptions::moving_lights`]), so each run renders every shadow layer;
//! 1. transfer, with texel blends per second (`FrameSchedule::texel_blends` per frame: one
//!    blend per piece texel, plus the initial copy) and, on the paired path, fragments;
//! 2. dilation of the final map (and of the first-order map in side-by-side mode);
//! 3. display (its row names the lightmap filter);
//! 4. the roofline ([`super::roofline`]) at the lightmap size with as many full-screen
//!    draws as the transfer's blends need;
//! 5. first order with static lights (shadow maps reused, only the per-texel lighting runs),
//!    the viewer's case when only the camera moves.

use passes::display::LightmapFilter;
use passes::frame::{FrameOptions, FrameParams, RenderScene, Renderer, Stages};
use passes::transfer::TransferPath;
use passes::{Gpu, PassError};

use super::roofline::bench_blend_roofline;
use super::timing::{BenchReport, BenchRow, Statistic, TimingSource, time_encoded};

/// Times every stage of `renderer` on `scene` (rows in the module doc).
pub fn bench_frame(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    params: &FrameParams<'_>,
    iterations: u32,
    statistic: Statistic,
) -> Result<BenchReport, PassError> {
    // One full frame first: fills the maps the later stages read.
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    renderer.encode_frame(gpu, &mut enc, scene, params, &FrameOptions::default())?;
    gpu.submit_and_wait("ortm.bench.frame", enc)?;

    let stage = StageTimer {
        gpu,
        renderer,
        scene,
        params,
        iterations,
        statistic,
    };
    let (moving, timing) = stage.time(
        "ortm.bench.first_order",
        "first order, moving lights (+ shadow maps)",
        Stages::FIRST_ORDER,
        true,
    )?;
    let transfer = stage.time(
        "ortm.bench.transfer",
        &transfer_name(renderer, scene),
        Stages::TRANSFER,
        false,
    )?;
    let transfer = transfer_counts(transfer.0, scene);
    let dilated = if renderer.options().display.side_by_side {
        "dilate (final + first-order maps)"
    } else {
        "dilate (final map)"
    };
    let dilate = stage.time("ortm.bench.dilate", dilated, Stages::DILATE, false)?;
    let filter = match renderer.display_filter() {
        LightmapFilter::Hardware => "sampler",
        LightmapFilter::Manual => "manual",
    };
    let name = format!("display ({filter} bilinear)");
    let display = stage.time("ortm.bench.display", &name, Stages::DISPLAY, false)?;
    let blends = transfer.texel_blends;
    let roof = roofline(gpu, renderer, scene, blends, iterations, statistic)?;
    // Static lights: the warm-up run renders the shadow maps, the timed runs reuse them.
    scene.first_order.invalidate_shadow_maps();
    let name = "first order, static lights (shadow maps reused)";
    let fixed = stage.time(
        "ortm.bench.first_order_static",
        name,
        Stages::FIRST_ORDER,
        false,
    )?;
    let rows = vec![moving, transfer, dilate.0, display.0, roof, fixed.0];
    Ok(BenchReport {
        adapter: format!("{} ({:?})", gpu.adapter_info.name, gpu.adapter_info.backend),
        timing,
        iterations,
        statistic,
        rows,
    })
}

/// Times single stages of one renderer and scene.
struct StageTimer<'a> {
    gpu: &'a Gpu,
    renderer: &'a Renderer,
    scene: &'a RenderScene,
    params: &'a FrameParams<'a>,
    iterations: u32,
    statistic: Statistic,
}

impl StageTimer<'_> {
    /// A row `name` timing the frame's `stages` (no blends counted).
    fn time(
        &self,
        label: &str,
        name: &str,
        stages: Stages,
        moving_lights: bool,
    ) -> Result<(BenchRow, TimingSource), PassError> {
        let options = FrameOptions {
            stages,
            moving_lights,
            ..Default::default()
        };
        let (ms, timing, cpu) =
            time_encoded(self.gpu, label, self.iterations, self.statistic, |enc| {
                self.renderer
                    .encode_frame(self.gpu, enc, self.scene, self.params, &options)
                    .map(|_| ())
            })?;
        Ok((BenchRow::new(name, ms, 0).with_cpu(cpu), timing))
    }
}

/// The transfer row's name: path, accumulation format, pieces and pairs.
fn transfer_name(renderer: &Renderer, scene: &RenderScene) -> String {
    let options = renderer.options().transfer;
    let pieces = scene
        .transfer
        .schedule
        .batches
        .iter()
        .map(|b| b.instances.len())
        .sum::<usize>();
    match (options.path, &scene.transfer.paired) {
        (TransferPath::Blend, Some(p)) => format!(
            "transfer, blend {:?} ({pieces} pieces, {} pairs)",
            options.accum_format, p.pairs
        ),
        (TransferPath::Blend, None) => {
            format!(
                "transfer, blend {:?} ({pieces} pieces)",
                options.accum_format
            )
        }
        (TransferPath::Compute, _) => "transfer, compute gather".to_string(),
        (TransferPath::Rows, _) => format!(
            "transfer, rows ({} entries)",
            scene.transfer.rows.as_ref().map_or(0, |r| r.entries)
        ),
    }
}

/// The transfer row with its texel blends (the schedule's plus the initial copy) and, on
/// the paired path, its fragments.
fn transfer_counts(row: BenchRow, scene: &RenderScene) -> BenchRow {
    let [w, h] = scene.lightmap_size;
    let copy = w as u64 * h as u64;
    let blends = scene.transfer.schedule.texel_blends() + copy;
    let mut out = BenchRow::new(row.name, row.ms, blends).with_cpu(row.cpu_ms);
    if let Some(p) = &scene.transfer.paired {
        out.fragments = p.fragments() + copy;
    }
    out
}

/// The roofline row: as many full-screen draws at the lightmap size as `blends` need, into
/// the transfer's accumulation format (RGBA16F where RGBA32F cannot be blended).
fn roofline(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    blends: u64,
    iterations: u32,
    statistic: Statistic,
) -> Result<BenchRow, PassError> {
    let [w, h] = scene.lightmap_size;
    let draws = blends.div_ceil(w as u64 * h as u64).clamp(1, 4096) as u32;
    let options = renderer.options().transfer;
    let format = match options.path {
        TransferPath::Blend => options.accum_format.texture_format(),
        TransferPath::Compute | TransferPath::Rows => wgpu::TextureFormat::Rgba32Float,
    };
    let format = if format == wgpu::TextureFormat::Rgba32Float && !gpu.supports_float32_blend() {
        wgpu::TextureFormat::Rgba16Float
    } else {
        format
    };
    Ok(bench_blend_roofline(gpu, [w, h], format, draws, iterations, statistic)?.0)
}

#[cfg(test)]
mod tests {
    use passes::display::{Camera, DisplayOptions};
    use passes::first_order::FirstOrderOptions;
    use passes::frame::RendererOptions;
    use passes::transfer::TransferOptions;
    use passes::{AlbedoMap, AtlasData, LightDesc, MeshData, TransferPiece};

    use super::*;

    /// A 2 m floor quad filling a `size²` lightmap, lit by one point light, with a constant
    /// transfer from the right and lower neighbours.
    fn floor(size: u32) -> (MeshData, AlbedoMap, Vec<AtlasData>, Vec<TransferPiece>) {
        let mesh = MeshData {
            positions_m: vec![
                [-1.0, 0.0, 1.0],
                [1.0, 0.0, 1.0],
                [1.0, 0.0, -1.0],
                [-1.0, 0.0, -1.0],
            ],
            normals: vec![[0.0, 1.0, 0.0]; 4],
            lightmap_uvs: vec![[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]],
            indices: vec![0, 1, 2, 0, 2, 3],
        };
        let atlas = AtlasData {
            width: size,
            height: size,
            rgb: vec![[0.05; 3]; (size * size) as usize],
        };
        let piece = |offset: [i32; 2]| TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w: size - offset[0] as u32,
            h: size - offset[1] as u32,
            dst_x: 0,
            dst_y: 0,
            offset,
            level: 0,
            receiver_level: 0,
        };
        let albedo = AlbedoMap::uniform(size, size, [0.5; 3]);
        (
            mesh,
            albedo,
            vec![atlas],
            vec![piece([1, 0]), piece([0, 1])],
        )
    }

    #[test]
    fn bench_reports_every_stage() {
        let gpu = Gpu::new_headless_exclusive().unwrap_or_else(|e| panic!("{e}"));
        let size = 64;
        let options = RendererOptions {
            first_order: FirstOrderOptions {
                shadow_map_size: 256,
                max_shadow_layers: 8,
                ..Default::default()
            },
            transfer: TransferOptions {
                path: TransferPath::Blend,
                ..TransferOptions::best_for(&gpu)
            },
            display: DisplayOptions {
                width: 64,
                height: 32,
                side_by_side: false,
                ..Default::default()
            },
            ..Default::default()
        };
        let renderer = Renderer::new(&gpu, &options).unwrap();
        let (mesh, albedo, atlases, pieces) = floor(size);
        let scene = renderer
            .prepare(&gpu, &mesh, &albedo, &atlases, &pieces)
            .unwrap();
        let lights = [LightDesc::Point {
            position_m: [0.3, 1.5, 0.2],
            color: [1.0; 3],
            intensity_w_sr: 2.0,
        }];
        let params = FrameParams {
            lights: &lights,
            camera: Camera {
                eye: [2.0, 2.0, 3.0],
                ..Camera::default()
            },
            exposure: 1.0,
            specular: None,
        };
        let report = bench_frame(&gpu, &renderer, &scene, &params, 2, Statistic::Median).unwrap();
        // first order (moving lights), transfer, dilation, display, roofline, first order
        // (static lights).
        assert_eq!(report.rows.len(), 6);
        assert!(
            report.rows[5].name.contains("static"),
            "{:?}",
            report.rows[5]
        );
        let expected_blends = scene.transfer.schedule.texel_blends() + (size * size) as u64;
        assert_eq!(report.rows[1].texel_blends, expected_blends);
        assert_eq!(
            report.timing == TimingSource::GpuTimestamps,
            gpu.supports_timestamps()
        );
        for r in &report.rows {
            assert!(r.ms.is_finite() && r.ms >= 0.0, "{r:?}");
        }
        assert!(report.to_string().contains("roofline"));
    }
}
