//! The one error type of the `passes` crate.
//!
//! Every fallible function in this crate returns [`PassError`]. Messages say what is wrong
//! (which input, which field, which index) and how to fix it. GPU-side failures (validation
//! errors, out-of-memory, device loss, a queue that never finishes) are turned into errors
//! instead of panics or hangs: see [`crate::gpu::Gpu`].

use thiserror::Error;

/// Everything that can go wrong while creating or running a pass.
#[derive(Debug, Error)]
pub enum PassError {
    /// No wgpu adapter (GPU or software rasteriser) could be found.
    #[error(
        "no GPU adapter found ({details}). Install a GPU driver, or the software Vulkan \
         driver: `apt-get install mesa-vulkan-drivers` (lavapipe), then retry"
    )]
    NoAdapter {
        /// What wgpu said.
        details: String,
    },
    /// The adapter refused to create a device.
    #[error(
        "the GPU adapter `{adapter}` refused to create a device: {details}. Update the driver or try another adapter (WGPU_ADAPTER_NAME)"
    )]
    RequestDevice {
        /// Adapter name.
        adapter: String,
        /// What wgpu said.
        details: String,
    },
    /// The device was lost (driver reset, GPU removed, or destroyed).
    #[error("the GPU device was lost ({reason}); recreate the `Gpu` and every pass built on it")]
    DeviceLost {
        /// Reason given by the driver.
        reason: String,
    },
    /// Submitted work did not finish in time.
    #[error(
        "GPU work `{what}` did not finish within {seconds} s; the device may be hung or far too slow for this size (try smaller maps)"
    )]
    Timeout {
        /// What was being waited for.
        what: String,
        /// The timeout in seconds.
        seconds: u64,
    },
    /// wgpu reported a validation, internal or out-of-memory error.
    #[error("GPU error during `{what}`: {message}")]
    Gpu {
        /// The operation (pass label) during which it happened.
        what: String,
        /// wgpu's message.
        message: String,
    },
    /// Reading a GPU buffer back to the CPU failed.
    #[error("reading `{what}` back from the GPU failed: {message}")]
    Readback {
        /// What was being read.
        what: String,
        /// Details.
        message: String,
    },
    /// An input array has the wrong length.
    #[error("`{what}` has {got} elements but {expected} are required ({hint})")]
    BadLength {
        /// Which input (e.g. `MeshData.normals`).
        what: String,
        /// Required length.
        expected: usize,
        /// Actual length.
        got: usize,
        /// How to fix it.
        hint: String,
    },
    /// An input value is out of its valid range.
    #[error("`{what}` is invalid: {problem}")]
    InvalidInput {
        /// Which input and field (e.g. `pieces[3].src_x`).
        what: String,
        /// What is wrong and how to fix it.
        problem: String,
    },
    /// A size exceeds what the device supports.
    #[error(
        "`{what}` is {size} but this device supports at most {limit}; use smaller maps or atlases"
    )]
    TooLarge {
        /// What is too large.
        what: String,
        /// The requested size.
        size: u64,
        /// The device limit.
        limit: u64,
    },
    /// The requested option needs a device feature the adapter lacks.
    #[error(
        "option `{option}` needs the device feature {feature}, which adapter `{adapter}` lacks; choose {fallback} instead"
    )]
    MissingFeature {
        /// Which option.
        option: String,
        /// The missing wgpu feature.
        feature: String,
        /// Adapter name.
        adapter: String,
        /// The option value to use instead.
        fallback: String,
    },
}
