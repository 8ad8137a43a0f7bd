//! GPU timestamps written between recorded commands and read back as milliseconds, for
//! the viewer's per-pass stats and the benchmarks. Needs
//! [`Gpu::supports_timestamps`] (`TIMESTAMP_QUERY` + `TIMESTAMP_QUERY_INSIDE_ENCODERS`).
//!
//! # Use
//! [`Timestamps::write`] `i` at each boundary (`0..count`), [`Timestamps::resolve`] at the
//! end of the encoder, submit and wait, then [`Timestamps::intervals_ms`]: `count − 1`
//! differences of consecutive stamps, converted with the queue's timestamp period.

use crate::error::PassError;
use crate::gpu::Gpu;

/// A query set of `count` timestamps with its resolve and read-back buffers.
#[derive(Debug)]
pub struct Timestamps {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    count: u32,
    period_ns: f64,
}

impl Timestamps {
    /// `count` (≥ 2) timestamps; buffers labelled `{label}.resolve` and `{label}.read`.
    pub fn new(gpu: &Gpu, label: &str, count: u32) -> Self {
        let d = &gpu.device;
        let count = count.max(2);
        let size = 8 * u64::from(count);
        let buffer = |suffix: &str, usage| {
            d.create_buffer(&wgpu::BufferDescriptor {
                label: Some(&format!("{label}.{suffix}")),
                size,
                usage,
                mapped_at_creation: false,
            })
        };
        Self {
            queries: d.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some(label),
                ty: wgpu::QueryType::Timestamp,
                count,
            }),
            resolve: buffer(
                "resolve",
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read: buffer(
                "read",
                wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            ),
            count,
            period_ns: f64::from(gpu.queue.get_timestamp_period()),
        }
    }

    /// Records timestamp `i`.
    pub fn write(&self, encoder: &mut wgpu::CommandEncoder, i: u32) {
        encoder.write_timestamp(&self.queries, i);
    }

    /// Records the resolve of every timestamp and its copy into the read-back buffer.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder) {
        encoder.resolve_query_set(&self.queries, 0..self.count, &self.resolve, 0);
        encoder.copy_buffer_to_buffer(&self.resolve, 0, &self.read, 0, 8 * u64::from(self.count));
    }

    /// After the resolving submission completed: milliseconds between consecutive stamps
    /// (`count − 1` values; a stamp earlier than its predecessor gives 0).
    pub fn intervals_ms(&self, gpu: &Gpu, what: &str) -> Result<Vec<f64>, PassError> {
        let bytes = gpu.map_read(what, &self.read)?;
        let stamp = |i: usize| {
            let mut b = [0u8; 8];
            b.copy_from_slice(&bytes[8 * i..8 * i + 8]);
            u64::from_le_bytes(b)
        };
        Ok((1..self.count as usize)
            .map(|i| stamp(i).saturating_sub(stamp(i - 1)) as f64 * self.period_ns * 1e-6)
            .collect())
    }
}
