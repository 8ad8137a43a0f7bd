//! One measurement: `iterations` runs of a recorded command sequence after one warm-up
//! run, each its own submission.
//!
//! With `TIMESTAMP_QUERY` + `TIMESTAMP_QUERY_INSIDE_ENCODERS` the GPU time between two
//! timestamps around the recorded commands is used ([`TimingSource::GpuTimestamps`]);
//! otherwise the wall time of submit + wait ([`TimingSource::WallClock`], which includes
//! submission and synchronisation overhead). A row reports the median (or, with
//! [`Statistic::Min`], the minimum: on a CPU shared with other work, the run least disturbed
//! by it) in milliseconds, and the mean CPU time of the whole process per run.

use std::time::Instant;

use passes::timestamps::Timestamps;
use passes::{Gpu, PassError};

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
    /// Milliseconds per run ([`BenchReport::statistic`] of the runs).
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
    /// A row of `texel_blends` per run (as many fragments), no CPU time.
    pub fn new(name: impl Into<String>, ms: f64, texel_blends: u64) -> Self {
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

    /// The row with `cpu_ms`.
    pub fn with_cpu(mut self, cpu_ms: Option<f64>) -> Self {
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
/// warm-up; returns `statistic` of the runs in milliseconds, the timing source, and the
/// mean process CPU time per run in milliseconds ([`process_cpu_ns`]; `None` where
/// unavailable).
pub fn time_encoded(
    gpu: &Gpu,
    label: &str,
    iterations: u32,
    statistic: Statistic,
    mut record: impl FnMut(&mut wgpu::CommandEncoder) -> Result<(), PassError>,
) -> Result<(f64, TimingSource, Option<f64>), PassError> {
    let iterations = iterations.clamp(1, 1024);
    let new_encoder = || {
        gpu.device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
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
        let stamps = Timestamps::new(gpu, "ortm.bench.timestamps", 2);
        for _ in 0..iterations {
            let mut enc = new_encoder();
            stamps.write(&mut enc, 0);
            record(&mut enc)?;
            stamps.write(&mut enc, 1);
            stamps.resolve(&mut enc);
            gpu.submit_and_wait(label, enc)?;
            times.push(stamps.intervals_ms(gpu, label)?[0]);
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
