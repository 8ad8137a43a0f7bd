//! Benchmarks of the passes on the current adapter, returned as plain data for the CLI to
//! print as a table.
//!
//! # What is timed
//! [`bench_frame`] times each pass of a [`Renderer`] frame separately (first order incl.
//! shadow maps, transfer, dilation, display — its row names the display's lightmap filter)
//! and reports texel blends per second for the
//! transfer pass (`FrameSchedule::texel_blends` per frame: one blend per piece texel, plus
//! the initial copy). [`bench_blend_roofline`] times pure full-screen additive blends
//! (`shaders/bench.wgsl`) into a target of the accumulation format: the roofline for the
//! blend path on this adapter.
//!
//! # How
//! With `TIMESTAMP_QUERY` + `TIMESTAMP_QUERY_INSIDE_ENCODERS` the GPU time between two
//! timestamps around the recorded commands is used ([`TimingSource::GpuTimestamps`]);
//! otherwise the wall time of submit + wait ([`TimingSource::WallClock`], which includes
//! submission and synchronisation overhead). Every measurement is the median (or, with
//! [`Statistic::Min`], the minimum: on a CPU shared with other work, the run least disturbed
//! by it) of `iterations` runs after one warm-up run; each run is its own submission.
//!
//! The first-order row times moving lights: the shadow-map cache is invalidated before every
//! run, so each run renders every shadow layer. A last row times the same pass with static
//! lights (shadow maps reused, only the per-texel lighting runs), the viewer's case when
//! only the camera moves.
//!
//! # Limits
//! Software adapters (lavapipe) are orders of magnitude slower than GPUs; compare numbers
//! only on the same adapter. At most 1024 iterations.

use std::time::Instant;

use crate::error::PassError;
use crate::frame::{FrameParams, RenderScene, Renderer};
use crate::gpu::Gpu;
use crate::util;

/// Where the times come from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum TimingSource {
    /// GPU timestamps around the commands.
    GpuTimestamps,
    /// Wall clock around submit + wait.
    WallClock,
}

impl std::fmt::Display for TimingSource {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(match self {
            TimingSource::GpuTimestamps => "GPU timestamps",
            TimingSource::WallClock => "wall clock (submit + wait)",
        })
    }
}

/// Which statistic of the timed runs a row reports.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Statistic {
    /// The median run.
    #[default]
    Median,
    /// The fastest run.
    Min,
}

impl Statistic {
    fn of(self, sorted: &[f64]) -> f64 {
        match self {
            Statistic::Median => sorted[sorted.len() / 2],
            Statistic::Min => sorted[0],
        }
    }
}

/// One line of the table.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchRow {
    /// What was timed.
    pub name: String,
    /// Median milliseconds per run.
    pub ms: f64,
    /// Texel blends per run (0 where not meaningful): map-texel contributions (one per
    /// piece texel, plus the initial copy), whether or not pieces are paired.
    pub texel_blends: u64,
    /// Fragments blended into the target per run: equal to `texel_blends` except with
    /// paired pieces, where one fragment carries two contributions (and pair bounding
    /// boxes add fragments carrying none).
    pub fragments: u64,
    /// `texel_blends / seconds` (0 where not meaningful).
    pub blends_per_s: f64,
    /// CPU time the whole process (every thread, so lavapipe's too) spent per timed run, in
    /// milliseconds, from `/proc/self/task/*/schedstat` (`None` where unavailable). On a
    /// software adapter this is the work done, independent of waiting for cores that other
    /// processes hold.
    pub cpu_ms: Option<f64>,
}

impl BenchRow {
    fn new(name: impl Into<String>, ms: f64, texel_blends: u64) -> Self {
        Self {
            name: name.into(),
            ms,
            cpu_ms: None,
            texel_blends,
            fragments: texel_blends,
            blends_per_s: if ms > 0.0 {
                texel_blends as f64 / (ms * 1e-3)
            } else {
                0.0
            },
        }
    }

    /// Fragments blended per second (`fragments / seconds`).
    pub fn fragments_per_s(&self) -> f64 {
        if self.ms > 0.0 {
            self.fragments as f64 / (self.ms * 1e-3)
        } else {
            0.0
        }
    }

    fn with_cpu(mut self, cpu_ms: Option<f64>) -> Self {
        self.cpu_ms = cpu_ms;
        self
    }
}

/// A whole report.
#[derive(Clone, Debug, PartialEq)]
pub struct BenchReport {
    /// Adapter name and backend.
    pub adapter: String,
    /// How times were measured.
    pub timing: TimingSource,
    /// Iterations per measurement.
    pub iterations: u32,
    /// Statistic of the runs each row reports.
    pub statistic: Statistic,
    /// One row per pass, then the roofline.
    pub rows: Vec<BenchRow>,
}

impl std::fmt::Display for BenchReport {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        writeln!(f, "adapter: {}", self.adapter)?;
        writeln!(
            f,
            "timing:  {} ({:?} of {})",
            self.timing, self.statistic, self.iterations
        )?;
        writeln!(
            f,
            "{:<48} {:>10} {:>10} {:>14} {:>14} {:>14}",
            "pass", "ms", "cpu ms", "texel blends", "blends/s", "fragments"
        )?;
        for r in &self.rows {
            writeln!(
                f,
                "{:<48} {:>10.3} {:>10} {:>14} {:>14.3e} {:>14}",
                r.name,
                r.ms,
                r.cpu_ms.map_or("—".to_string(), |c| format!("{c:.3}")),
                r.texel_blends,
                r.blends_per_s,
                r.fragments
            )?;
        }
        Ok(())
    }
}

/// CPU time of every thread of this process so far, in nanoseconds (Linux
/// `/proc/self/task/*/schedstat`, first field); `None` elsewhere. Threads that exited are
/// not counted, so only differences over a span in which lavapipe's threads live are
/// meaningful.
pub fn process_cpu_ns() -> Option<u64> {
    let mut total = 0u64;
    for entry in std::fs::read_dir("/proc/self/task").ok()? {
        let path = entry.ok()?.path().join("schedstat");
        let text = std::fs::read_to_string(path).ok()?;
        total += text.split_whitespace().next()?.parse::<u64>().ok()?;
    }
    Some(total)
}

/// Times `record` (which records commands into a fresh encoder) `iterations` times after a
/// warm-up; returns the median in milliseconds.
pub fn time_encoded(
    gpu: &Gpu,
    label: &str,
    iterations: u32,
    record: impl FnMut(&mut wgpu::CommandEncoder) -> Result<(), PassError>,
) -> Result<(f64, TimingSource), PassError> {
    time_encoded_stat(gpu, label, iterations, Statistic::Median, record).map(|(ms, s, _)| (ms, s))
}

/// [`time_encoded`] reporting `statistic` of the runs, and the mean process CPU time per
/// run in milliseconds ([`process_cpu_ns`]; `None` where unavailable).
pub fn time_encoded_stat(
    gpu: &Gpu,
    label: &str,
    iterations: u32,
    statistic: Statistic,
    mut record: impl FnMut(&mut wgpu::CommandEncoder) -> Result<(), PassError>,
) -> Result<(f64, TimingSource, Option<f64>), PassError> {
    let iterations = iterations.clamp(1, 1024);
    let device = &gpu.device;
    let new_encoder = || {
        device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ortm.bench.encoder"),
        })
    };
    // Warm-up (pipeline compilation, first-use allocations).
    let mut enc = new_encoder();
    record(&mut enc)?;
    gpu.submit_and_wait(label, enc)?;

    let mut times = Vec::with_capacity(iterations as usize);
    let cpu_start = process_cpu_ns();
    let source = if gpu.supports_timestamps() {
        let qs = device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("ortm.bench.timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 2,
        });
        let resolve = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.bench.resolve"),
            size: 16,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.bench.readback"),
            size: 16,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let period_ns = gpu.queue.get_timestamp_period() as f64;
        for _ in 0..iterations {
            let mut enc = new_encoder();
            enc.write_timestamp(&qs, 0);
            record(&mut enc)?;
            enc.write_timestamp(&qs, 1);
            enc.resolve_query_set(&qs, 0..2, &resolve, 0);
            enc.copy_buffer_to_buffer(&resolve, 0, &read, 0, 16);
            gpu.submit_and_wait(label, enc)?;
            let bytes = gpu.map_read(label, &read)?;
            let t0 = u64::from_le_bytes(bytes[0..8].try_into().unwrap_or_default());
            let t1 = u64::from_le_bytes(bytes[8..16].try_into().unwrap_or_default());
            times.push(t1.saturating_sub(t0) as f64 * period_ns * 1e-6);
        }
        TimingSource::GpuTimestamps
    } else {
        for _ in 0..iterations {
            let mut enc = new_encoder();
            let start = Instant::now();
            record(&mut enc)?;
            gpu.submit_and_wait(label, enc)?;
            times.push(start.elapsed().as_secs_f64() * 1e3);
        }
        TimingSource::WallClock
    };
    let cpu_ms = cpu_start
        .zip(process_cpu_ns())
        .map(|(a, b)| b.saturating_sub(a) as f64 * 1e-6 / iterations as f64);
    times.sort_by(f64::total_cmp);
    Ok((statistic.of(&times), source, cpu_ms))
}

/// Pure additive blending: `draws` full-screen triangles into a `size` target of `format`.
/// Texel blends per run = `size.x · size.y · draws`.
pub fn bench_blend_roofline(
    gpu: &Gpu,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    draws: u32,
    iterations: u32,
) -> Result<(BenchRow, TimingSource), PassError> {
    bench_blend_roofline_stat(gpu, size, format, draws, iterations, Statistic::Median)
}

/// [`bench_blend_roofline`] reporting `statistic` of the runs.
pub fn bench_blend_roofline_stat(
    gpu: &Gpu,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    draws: u32,
    iterations: u32,
    statistic: Statistic,
) -> Result<(BenchRow, TimingSource), PassError> {
    gpu.check_texture_size("roofline target", size[0], size[1])?;
    let device = &gpu.device;
    let pipeline = gpu.scoped("ortm.bench.new", || {
        let module = util::shader(
            device,
            "ortm.bench.shader",
            include_str!("../shaders/bench.wgsl"),
        );
        util::fullscreen_pipeline(
            device,
            "ortm.bench.roofline_pipeline",
            None,
            &module,
            "fs_const",
            format,
            Some(util::ADDITIVE),
        )
    })?;
    let target = util::texture_2d(
        device,
        "ortm.bench.roofline_target",
        size,
        format,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let view = util::view(&target);
    let (ms, source, cpu) =
        time_encoded_stat(gpu, "ortm.bench.roofline", iterations, statistic, |enc| {
            let mut pass = util::clear_pass(enc, "ortm.bench.roofline_pass", &view);
            pass.set_pipeline(&pipeline);
            for _ in 0..draws {
                pass.draw(0..3, 0..1);
            }
            Ok(())
        })?;
    let blends = size[0] as u64 * size[1] as u64 * draws as u64;
    Ok((
        BenchRow::new(
            format!("roofline: {draws}× full-screen blend {format:?}"),
            ms,
            blends,
        )
        .with_cpu(cpu),
        source,
    ))
}

/// Times every pass of `renderer` on `scene` (median of the runs), then the roofline at the
/// lightmap size with as many full-screen draws as the transfer pass's blends need. Rows:
/// first order with moving lights (shadow maps re-rendered every run), transfer, dilation,
/// display, roofline, first order with static lights (shadow maps reused).
pub fn bench_frame(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    params: &FrameParams<'_>,
    iterations: u32,
) -> Result<BenchReport, PassError> {
    bench_frame_stat(gpu, renderer, scene, params, iterations, Statistic::Median)
}

/// [`bench_frame`] reporting `statistic` of the runs.
pub fn bench_frame_stat(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    params: &FrameParams<'_>,
    iterations: u32,
    statistic: Statistic,
) -> Result<BenchReport, PassError> {
    use crate::dilate::DilateInputs;
    use crate::display::DisplayInputs;
    use crate::first_order::FirstOrderInputs;
    use crate::transfer::{TransferInputs, TransferPath};

    // One full frame first: fills the first-order and final maps the later passes read.
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let frame = renderer.encode(gpu, &mut enc, scene, params)?;
    gpu.submit_and_wait("ortm.bench.frame", enc)?;
    let fo_view = util::view(&frame.first_order_tex);
    let final_view = util::view(&frame.final_lightmap_tex);
    let dil_view = util::view(&frame.dilated_final_tex);

    let mut rows = Vec::new();
    let first_order = |enc: &mut wgpu::CommandEncoder| {
        renderer
            .first_order
            .encode(
                gpu,
                enc,
                &FirstOrderInputs {
                    scene: &scene.first_order,
                    lights: params.lights,
                },
            )
            .map(|_| ())
    };
    let (ms, timing, cpu) = time_encoded_stat(
        gpu,
        "ortm.bench.first_order",
        iterations,
        statistic,
        |enc| {
            // Moving lights: every run renders every shadow layer.
            scene.first_order.invalidate_shadow_maps();
            first_order(enc)
        },
    )?;
    rows.push(BenchRow::new("first order, moving lights (+ shadow maps)", ms, 0).with_cpu(cpu));

    let schedule = &scene.transfer.schedule;
    let [w, h] = scene.lightmap_size;
    let blends = schedule.texel_blends() + w as u64 * h as u64;
    let path = renderer.transfer.options().path;
    let (ms, _, cpu) =
        time_encoded_stat(gpu, "ortm.bench.transfer", iterations, statistic, |enc| {
            renderer.transfer.encode(
                gpu,
                enc,
                &TransferInputs {
                    scene: &scene.transfer,
                    first_order: &fo_view,
                },
            );
            Ok(())
        })?;
    let pieces = schedule
        .batches
        .iter()
        .map(|b| b.instances.len())
        .sum::<usize>();
    let name = match (path, &scene.transfer.paired) {
        (TransferPath::Blend, Some(p)) => format!(
            "transfer, blend {:?} ({pieces} pieces, {} pairs)",
            renderer.transfer.options().accum_format,
            p.pairs
        ),
        (TransferPath::Blend, None) => format!(
            "transfer, blend {:?} ({pieces} pieces)",
            renderer.transfer.options().accum_format,
        ),
        (TransferPath::Compute, _) => "transfer, compute gather".to_string(),
    };
    let mut row = BenchRow::new(name, ms, blends).with_cpu(cpu);
    if let Some(p) = &scene.transfer.paired {
        row.fragments = p.fragments() + w as u64 * h as u64;
    }
    rows.push(row);

    let (ms, _, cpu) = time_encoded_stat(gpu, "ortm.bench.dilate", iterations, statistic, |enc| {
        renderer.dilate.encode(
            gpu,
            enc,
            &DilateInputs {
                targets: &scene.dilate_final,
                source: &final_view,
            },
        );
        Ok(())
    })?;
    rows.push(BenchRow::new("dilate (final map)", ms, 0).with_cpu(cpu));

    let (ms, _, cpu) =
        time_encoded_stat(gpu, "ortm.bench.display", iterations, statistic, |enc| {
            renderer
                .display
                .encode(
                    gpu,
                    enc,
                    &DisplayInputs {
                        scene: &scene.display,
                        final_lightmap: &dil_view,
                        lightmap_size: scene.lightmap_size,
                        first_order: Some(&dil_view),
                        camera: params.camera,
                        exposure: params.exposure,
                        lights: params.lights,
                        specular: params.specular,
                    },
                )
                .map(|_| ())
        })?;
    let filter = match renderer.display.filter() {
        crate::display::LightmapFilter::Hardware => "sampler",
        crate::display::LightmapFilter::Manual => "manual",
    };
    rows.push(BenchRow::new(format!("display ({filter} bilinear)"), ms, 0).with_cpu(cpu));

    let draws = blends.div_ceil(w as u64 * h as u64).clamp(1, 4096) as u32;
    let format = match path {
        TransferPath::Blend => renderer.transfer.options().accum_format.texture_format(),
        TransferPath::Compute => wgpu::TextureFormat::Rgba32Float,
    };
    let format = if format == wgpu::TextureFormat::Rgba32Float && !gpu.supports_float32_blend() {
        wgpu::TextureFormat::Rgba16Float
    } else {
        format
    };
    let (row, _) = bench_blend_roofline_stat(gpu, [w, h], format, draws, iterations, statistic)?;
    rows.push(row);
    // Static lights: the warm-up run renders the shadow maps, the timed runs reuse them.
    scene.first_order.invalidate_shadow_maps();
    let (ms, _, cpu) = time_encoded_stat(
        gpu,
        "ortm.bench.first_order_static",
        iterations,
        statistic,
        first_order,
    )?;
    rows.push(
        BenchRow::new("first order, static lights (shadow maps reused)", ms, 0).with_cpu(cpu),
    );
    Ok(BenchReport {
        adapter: format!("{} ({:?})", gpu.adapter_info.name, gpu.adapter_info.backend),
        timing,
        iterations,
        statistic,
        rows,
    })
}
