//! What only the benchmarks need, as plain data for `ortm bench render` (`src/cli/bench_render.rs`)
//! to print as tables.
//!
//! - [`timing`]: how one measurement is taken (GPU timestamps or wall clock, median or
//!   minimum of the runs, process CPU time) and the report rows;
//! - [`frame`]: every stage of a `passes::Renderer` frame timed on its own, recorded through
//!   `Renderer::encode_frame`;
//! - [`roofline`]: pure full-screen additive blends (`roofline.wgsl`), the upper bound of
//!   the transfer pass's blend path on this adapter;
//! - [`synthetic`]: synthetic transfer maps of the paper's Table 1 configurations.
//!
//! # Limits
//! Software adapters (lavapipe) are orders of magnitude slower than GPUs; compare numbers
//! only on the same adapter. At most 1024 iterations.

pub mod frame;
pub mod roofline;
pub mod synthetic;
pub mod timing;
