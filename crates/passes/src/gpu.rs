//! The headless GPU context shared by every pass: adapter, device, queue, error capture,
//! and upload / read-back helpers.
//!
//! # Data flow
//! [`Gpu::new_headless`] picks an adapter (a real GPU, or Mesa's lavapipe software Vulkan
//! driver), requests a device with the optional features the passes can use
//! (`FLOAT32_BLENDABLE` for RGBA32F blending, `FLOAT32_FILTERABLE` for the display pass's
//! hardware bilinear lookup, `TIMESTAMP_QUERY*` for the bench), and installs
//! handlers that *record* uncaptured wgpu errors and device loss instead of panicking.
//! [`Gpu::submit_and_wait`] submits, waits with a timeout, and turns any recorded error,
//! device loss or timeout into a [`PassError`].
//!
//! [`Gpu::new_headless_exclusive`] is the same device, but only one such device is alive in
//! the process at a time: what tests and tools that make many devices on parallel threads
//! need on NVIDIA's Linux driver, which crashes (SIGSEGV) or deadlocks when devices are
//! created, used and destroyed on several threads at once (wgpu issues #5930 and #8365; seen
//! in about half of the parallel runs of `passes`' transfer tests on an H100).
//!
//! # Limits
//! - Waiting uses `Device::poll` with a timeout ([`Gpu::timeout`], 120 s by default); a hung
//!   device gives [`PassError::Timeout`], never a hang.
//! - Read-back helpers handle the 256-byte row alignment of texture→buffer copies and
//!   support `Rgba32Float`, `Rgba16Float` and `Rgba8Unorm` textures.

use std::cell::Cell;
use std::sync::{Arc, Mutex, MutexGuard};
use std::time::Duration;

use crate::error::PassError;
use crate::types::TexelImage;

/// Errors recorded by the uncaptured-error and device-lost handlers.
#[derive(Default, Debug)]
struct Recorded {
    errors: Vec<String>,
    lost: Option<String>,
}

/// Adapter, device and queue, plus error bookkeeping.
pub struct Gpu {
    /// The wgpu device.
    pub device: wgpu::Device,
    /// Its queue.
    pub queue: wgpu::Queue,
    /// Adapter name, backend and driver (for reports).
    pub adapter_info: wgpu::AdapterInfo,
    /// How long [`Gpu::submit_and_wait`] waits before giving up.
    pub timeout: Duration,
    /// See [`Gpu::supports_storage_reads`].
    storage_reads: bool,
    recorded: Arc<Mutex<Recorded>>,
}

impl std::fmt::Debug for Gpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Gpu")
            .field("adapter", &self.adapter_info.name)
            .field("backend", &self.adapter_info.backend)
            .finish_non_exhaustive()
    }
}

/// Optional features the passes use when the adapter has them.
fn wanted_features() -> wgpu::Features {
    wgpu::Features::FLOAT32_BLENDABLE
        | wgpu::Features::FLOAT32_FILTERABLE
        | wgpu::Features::TIMESTAMP_QUERY
        | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
}

/// A [`Gpu`] that is the only one from [`Gpu::new_headless_exclusive`] alive in the process
/// (dereferences to the [`Gpu`]). Its device is dropped before the next one can be created.
pub struct ExclusiveGpu {
    gpu: Gpu,
    _turn: MutexGuard<'static, ()>,
}

/// The turn of [`Gpu::new_headless_exclusive`].
static EXCLUSIVE_TURN: Mutex<()> = Mutex::new(());

thread_local! {
    /// Whether this thread holds an [`ExclusiveGpu`] (a second one would wait for itself).
    static HOLDS_EXCLUSIVE: Cell<bool> = const { Cell::new(false) };
}

impl std::ops::Deref for ExclusiveGpu {
    type Target = Gpu;
    fn deref(&self) -> &Gpu {
        &self.gpu
    }
}

impl Drop for ExclusiveGpu {
    fn drop(&mut self) {
        // The fields (device first, then the turn) are dropped after this.
        HOLDS_EXCLUSIVE.with(|h| h.set(false));
    }
}

impl std::fmt::Debug for ExclusiveGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_tuple("ExclusiveGpu").field(&self.gpu).finish()
    }
}

impl Gpu {
    /// [`Gpu::new_headless`], waiting until no other [`ExclusiveGpu`] is alive in the process
    /// (see the module docs: NVIDIA's driver races on devices used on several threads at
    /// once). For test suites and tools; an application with one device needs no turn.
    ///
    /// Panics if this thread already holds one (it would wait for itself forever).
    pub fn new_headless_exclusive() -> Result<ExclusiveGpu, PassError> {
        assert!(
            !HOLDS_EXCLUSIVE.with(Cell::get),
            "Gpu::new_headless_exclusive called on a thread that already holds an ExclusiveGpu; \
             drop it first"
        );
        let turn = EXCLUSIVE_TURN
            .lock()
            .unwrap_or_else(|poisoned| poisoned.into_inner());
        let gpu = Self::new_headless()?;
        HOLDS_EXCLUSIVE.with(|h| h.set(true));
        Ok(ExclusiveGpu { gpu, _turn: turn })
    }

    /// Opens the best available adapter without a window.
    ///
    /// Errors: [`PassError::NoAdapter`] (with installation advice) when there is none,
    /// [`PassError::RequestDevice`] when the adapter refuses a device.
    pub fn new_headless() -> Result<Self, PassError> {
        pollster::block_on(Self::new_headless_async())
    }

    async fn new_headless_async() -> Result<Self, PassError> {
        let instance =
            wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = instance
            .request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                force_fallback_adapter: false,
                compatible_surface: None,
                apply_limit_buckets: false,
            })
            .await
            .map_err(|e| PassError::NoAdapter {
                details: e.to_string(),
            })?;
        Self::open_async(&adapter).await
    }

    /// Opens a device on `adapter` (chosen by the caller, e.g. one compatible with a window
    /// surface) with the same optional features, limits and error capture as
    /// [`Gpu::new_headless`].
    ///
    /// Errors: [`PassError::RequestDevice`] when the adapter refuses a device.
    pub fn from_adapter(adapter: &wgpu::Adapter) -> Result<Self, PassError> {
        pollster::block_on(Self::open_async(adapter))
    }

    async fn open_async(adapter: &wgpu::Adapter) -> Result<Self, PassError> {
        let adapter_info = adapter.get_info();
        let features = adapter.features() & wanted_features();
        let limits = adapter.limits();
        let (device, queue) = adapter
            .request_device(&wgpu::DeviceDescriptor {
                label: Some("ortm.gpu.device"),
                required_features: features,
                required_limits: limits.clone(),
                experimental_features: wgpu::ExperimentalFeatures::disabled(),
                memory_hints: wgpu::MemoryHints::Performance,
                trace: wgpu::Trace::Off,
            })
            .await
            .map_err(|e| PassError::RequestDevice {
                adapter: adapter_info.name.clone(),
                details: e.to_string(),
            })?;
        // RGBA32F and RGBA32Uint guarantee read-only storage use; fragment shaders need the
        // downlevel flag, and the passes bind up to 4 such textures per stage.
        let storage_reads = adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::FRAGMENT_STORAGE)
            && limits.max_storage_textures_per_shader_stage >= 4;
        let recorded = Arc::new(Mutex::new(Recorded::default()));
        let rec = Arc::clone(&recorded);
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            if let Ok(mut r) = rec.lock() {
                r.errors.push(e.to_string());
            }
        }));
        let rec = Arc::clone(&recorded);
        device.set_device_lost_callback(move |reason, msg| {
            if let Ok(mut r) = rec.lock() {
                r.lost = Some(format!("{reason:?}: {msg}"));
            }
        });
        Ok(Self {
            device,
            queue,
            adapter_info,
            timeout: Duration::from_secs(120),
            storage_reads,
            recorded,
        })
    }

    /// Whether RGBA32F render targets can be blended (`FLOAT32_BLENDABLE`).
    pub fn supports_float32_blend(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::FLOAT32_BLENDABLE)
    }

    /// Whether fragment and compute shaders can read RGBA32F and RGBA32Uint textures as
    /// read-only storage textures ([`crate::util::TexelReads::Storage`]).
    pub fn supports_storage_reads(&self) -> bool {
        self.storage_reads
    }

    /// The cheaper way of reading textures texel by texel that this device supports:
    /// [`TexelReads::Storage`](crate::util::TexelReads) where it can, else `Sampled`.
    pub fn best_texel_reads(&self) -> crate::util::TexelReads {
        if self.storage_reads {
            crate::util::TexelReads::Storage
        } else {
            crate::util::TexelReads::Sampled
        }
    }

    /// Whether RGBA32F textures can be sampled with a linear filter (`FLOAT32_FILTERABLE`).
    pub fn supports_float32_filter(&self) -> bool {
        self.device
            .features()
            .contains(wgpu::Features::FLOAT32_FILTERABLE)
    }

    /// Whether timestamps can be written between commands of an encoder.
    pub fn supports_timestamps(&self) -> bool {
        self.device.features().contains(
            wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS,
        )
    }

    /// Returns (and clears) any error recorded since the last check; device loss is sticky.
    pub fn check(&self, what: &str) -> Result<(), PassError> {
        let mut r = self.recorded.lock().map_err(|_| PassError::Gpu {
            what: what.into(),
            message: "error bookkeeping poisoned by a panic in another thread".into(),
        })?;
        if let Some(reason) = &r.lost {
            return Err(PassError::DeviceLost {
                reason: reason.clone(),
            });
        }
        if !r.errors.is_empty() {
            let message = r.errors.join("; ");
            r.errors.clear();
            return Err(PassError::Gpu {
                what: what.into(),
                message,
            });
        }
        Ok(())
    }

    /// Runs `f` inside a validation + out-of-memory error scope and returns its value, or the
    /// first error wgpu reported while it ran (e.g. a shader that fails to compile).
    pub fn scoped<T>(&self, what: &str, f: impl FnOnce() -> T) -> Result<T, PassError> {
        let oom = self.device.push_error_scope(wgpu::ErrorFilter::OutOfMemory);
        let val = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let out = f();
        let e1 = pollster::block_on(val.pop());
        let e2 = pollster::block_on(oom.pop());
        if let Some(e) = e1.or(e2) {
            return Err(PassError::Gpu {
                what: what.into(),
                message: e.to_string(),
            });
        }
        self.check(what)?;
        Ok(out)
    }

    /// Submits `encoder`, waits until the GPU is done (at most [`Gpu::timeout`]) and reports
    /// any recorded error.
    pub fn submit_and_wait(
        &self,
        what: &str,
        encoder: wgpu::CommandEncoder,
    ) -> Result<(), PassError> {
        let val = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let index = self.queue.submit([encoder.finish()]);
        let scope_err = pollster::block_on(val.pop());
        if let Some(e) = scope_err {
            return Err(PassError::Gpu {
                what: what.into(),
                message: e.to_string(),
            });
        }
        self.wait(what, Some(index))
    }

    /// Waits for `index` (or everything submitted) with the timeout.
    pub fn wait(&self, what: &str, index: Option<wgpu::SubmissionIndex>) -> Result<(), PassError> {
        let res = self.device.poll(wgpu::PollType::Wait {
            submission_index: index,
            timeout: Some(self.timeout),
        });
        self.check(what)?;
        match res {
            Ok(_) => Ok(()),
            Err(wgpu::PollError::Timeout) => Err(PassError::Timeout {
                what: what.into(),
                seconds: self.timeout.as_secs(),
            }),
            Err(e) => {
                // A lost or destroyed device rejects the wait; one more maintenance poll
                // lets wgpu run the device-lost callback, so the error names the cause.
                let _ = self.device.poll(wgpu::PollType::Poll);
                self.check(what)?;
                Err(PassError::Gpu {
                    what: what.into(),
                    message: e.to_string(),
                })
            }
        }
    }

    /// Checks a 2D texture size against the device limit.
    pub fn check_texture_size(&self, what: &str, width: u32, height: u32) -> Result<(), PassError> {
        let limit = self.device.limits().max_texture_dimension_2d;
        if width == 0 || height == 0 {
            return Err(PassError::InvalidInput {
                what: what.into(),
                problem: format!("size {width}×{height} is empty"),
            });
        }
        if width.max(height) > limit {
            return Err(PassError::TooLarge {
                what: format!("{what} ({width}×{height})"),
                size: width.max(height) as u64,
                limit: limit as u64,
            });
        }
        Ok(())
    }

    /// Creates an `Rgba32Float` texture filled with `rgba` (row-major, row 0 first).
    pub fn create_rgba32f_texture(
        &self,
        label: &str,
        width: u32,
        height: u32,
        rgba: &[[f32; 4]],
        usage: wgpu::TextureUsages,
    ) -> Result<wgpu::Texture, PassError> {
        self.check_texture_size(label, width, height)?;
        let n = width as usize * height as usize;
        if rgba.len() != n {
            return Err(PassError::BadLength {
                what: label.into(),
                expected: n,
                got: rgba.len(),
                hint: "width·height RGBA texels".into(),
            });
        }
        let tex = self.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: wgpu::TextureFormat::Rgba32Float,
            usage: usage | wgpu::TextureUsages::COPY_DST,
            view_formats: &[],
        });
        self.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &tex,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytemuck::cast_slice(rgba),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(width * 16),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d {
                width,
                height,
                depth_or_array_layers: 1,
            },
        );
        Ok(tex)
    }

    /// Records a copy of a 2D texture (layer 0, mip 0) of `bytes_per_texel` into a new
    /// `MAP_READ` buffer labelled `label`, rows padded to `COPY_BYTES_PER_ROW_ALIGNMENT`;
    /// returns the buffer and its row length in bytes. Read it with [`Gpu::map_read`] after
    /// the encoder was submitted.
    pub fn record_readback(
        &self,
        label: &str,
        encoder: &mut wgpu::CommandEncoder,
        tex: &wgpu::Texture,
        bytes_per_texel: u32,
    ) -> (wgpu::Buffer, u32) {
        let (w, h) = (tex.width(), tex.height());
        let padded = (w * bytes_per_texel).div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT)
            * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
        let buffer = self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: u64::from(padded) * u64::from(h),
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        encoder.copy_texture_to_buffer(
            tex.as_image_copy(),
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(h),
                },
            },
            wgpu::Extent3d {
                width: w,
                height: h,
                depth_or_array_layers: 1,
            },
        );
        (buffer, padded)
    }

    /// Copies a 2D texture (layer 0, mip 0) into a CPU byte vector with tight rows.
    fn read_texture_bytes(
        &self,
        what: &str,
        tex: &wgpu::Texture,
        bytes_per_texel: u32,
    ) -> Result<Vec<u8>, PassError> {
        let tight = tex.width() * bytes_per_texel;
        let mut enc = self
            .device
            .create_command_encoder(&wgpu::CommandEncoderDescriptor {
                label: Some("ortm.gpu.readback"),
            });
        let (buffer, padded) =
            self.record_readback("ortm.gpu.readback", &mut enc, tex, bytes_per_texel);
        self.submit_and_wait(what, enc)?;
        let bytes = self.map_read(what, &buffer)?;
        let mut out = Vec::with_capacity(tight as usize * tex.height() as usize);
        for row in 0..tex.height() as usize {
            let start = row * padded as usize;
            out.extend_from_slice(&bytes[start..start + tight as usize]);
        }
        Ok(out)
    }

    /// Maps a `MAP_READ` buffer (after its writes were submitted), copies it out, unmaps.
    pub fn map_read(&self, what: &str, buffer: &wgpu::Buffer) -> Result<Vec<u8>, PassError> {
        let (tx, rx) = std::sync::mpsc::channel();
        buffer.map_async(wgpu::MapMode::Read, .., move |r| {
            let _ = tx.send(r);
        });
        self.wait(what, None)?;
        let mapped = rx
            .recv_timeout(self.timeout)
            .map_err(|e| PassError::Readback {
                what: what.into(),
                message: e.to_string(),
            })?;
        mapped.map_err(|e| PassError::Readback {
            what: what.into(),
            message: e.to_string(),
        })?;
        let view = buffer
            .get_mapped_range(..)
            .map_err(|e| PassError::Readback {
                what: what.into(),
                message: e.to_string(),
            })?;
        let out = view.to_vec();
        drop(view);
        buffer.unmap();
        Ok(out)
    }

    /// Reads an `Rgba32Float` or `Rgba16Float` texture back as a [`TexelImage`].
    pub fn read_texel_image(
        &self,
        what: &str,
        tex: &wgpu::Texture,
    ) -> Result<TexelImage, PassError> {
        let (w, h) = (tex.width(), tex.height());
        let rgba: Vec<[f32; 4]> = match tex.format() {
            wgpu::TextureFormat::Rgba32Float => {
                let bytes = self.read_texture_bytes(what, tex, 16)?;
                bytes
                    .chunks_exact(16)
                    .map(|c| {
                        let f = |i: usize| {
                            f32::from_le_bytes([c[4 * i], c[4 * i + 1], c[4 * i + 2], c[4 * i + 3]])
                        };
                        [f(0), f(1), f(2), f(3)]
                    })
                    .collect()
            }
            wgpu::TextureFormat::Rgba16Float => {
                let bytes = self.read_texture_bytes(what, tex, 8)?;
                bytes
                    .chunks_exact(8)
                    .map(|c| {
                        let f = |i: usize| f16_to_f32(u16::from_le_bytes([c[2 * i], c[2 * i + 1]]));
                        [f(0), f(1), f(2), f(3)]
                    })
                    .collect()
            }
            other => {
                return Err(PassError::Readback {
                    what: what.into(),
                    message: format!("format {other:?} is not a float RGBA format"),
                });
            }
        };
        Ok(TexelImage {
            width: w,
            height: h,
            rgba,
        })
    }

    /// Reads an `Rgba8Unorm` texture back as an image (row 0 = top).
    pub fn read_rgba8(
        &self,
        what: &str,
        tex: &wgpu::Texture,
    ) -> Result<image::RgbaImage, PassError> {
        if tex.format() != wgpu::TextureFormat::Rgba8Unorm {
            return Err(PassError::Readback {
                what: what.into(),
                message: format!("format {:?} is not Rgba8Unorm", tex.format()),
            });
        }
        let bytes = self.read_texture_bytes(what, tex, 4)?;
        image::RgbaImage::from_raw(tex.width(), tex.height(), bytes).ok_or_else(|| {
            PassError::Readback {
                what: what.into(),
                message: "read-back size does not match the texture".into(),
            }
        })
    }
}

/// IEEE 754 binary16 → binary32 (exact; handles subnormals, infinities and NaN).
pub fn f16_to_f32(h: u16) -> f32 {
    let sign = ((h >> 15) as u32) << 31;
    let exp = ((h >> 10) & 0x1f) as u32;
    let man = (h & 0x3ff) as u32;
    let bits = match (exp, man) {
        (0, 0) => sign,
        (0, m) => {
            // Subnormal: value = m · 2^-24.
            let v = m as f32 * (1.0 / 16_777_216.0);
            return if sign != 0 { -v } else { v };
        }
        (31, 0) => sign | 0x7f80_0000,
        (31, m) => sign | 0x7f80_0000 | (m << 13),
        (e, m) => sign | ((e + 112) << 23) | (m << 13),
    };
    f32::from_bits(bits)
}

#[cfg(test)]
mod tests {
    use super::f16_to_f32;

    #[test]
    fn f16_decoding_matches_definition() {
        // Normal numbers: (-1)^s · 2^(e-15) · (1 + m/1024), checked over every exponent.
        for e in 1u16..31 {
            for m in [0u16, 1, 511, 1023] {
                let h = (e << 10) | m;
                let want = 2f64.powi(e as i32 - 15) * (1.0 + m as f64 / 1024.0);
                assert_eq!(f16_to_f32(h) as f64, want);
                assert_eq!(f16_to_f32(h | 0x8000) as f64, -want);
            }
        }
        assert_eq!(f16_to_f32(1) as f64, 2f64.powi(-24));
        assert!(f16_to_f32(0x7c00).is_infinite());
        assert!(f16_to_f32(0x7e00).is_nan());
    }
}
