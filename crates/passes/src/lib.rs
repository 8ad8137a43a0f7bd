//! ortm's real-time wgpu passes: first-order lightmap, offset radiance transfer (paper
//! Eq. 9, blend and compute paths), gutter dilation, display, and benchmarks.
//!
//! # Frame
//! ```text
//! lights ─▶ first_order ─▶ transfer (blend | compute) ─▶ dilate ─▶ display ─▶ RGBA8 image
//!              ▲ mesh, albedo     ▲ atlases + pieces (from the binning stage)
//! ```
//! Each pass is a struct built once with `new(&Gpu, &Options)` and recorded per frame with
//! `encode(&Gpu, encoder, &inputs) -> Output`; [`frame::Renderer`] chains them. Every
//! pass has a CPU mirror of the same name in [`cpu`]; the tests compare them on the
//! lavapipe software adapter. See `docs/render.md` for measurements and the file map.
//!
//! # Conventions
//! See [`types`]: SI units (m, W/sr, W/m²), lightmap texel `(x, y)` centre
//! `u = (x+0.5)/W`, `v = 1 − (y+0.5)/H` (row 0 = `v = 1`), offsets in texels with `+y` down,
//! alpha = coverage.
//!
//! This crate does not depend on `ortm`; the CLI converts its types into [`types`].

pub mod bench;
pub mod cpu;
pub mod demo;
pub mod dilate;
pub mod display;
pub mod error;
pub mod first_order;
pub mod frame;
pub mod gpu;
pub mod pairing;
pub mod schedule;
pub mod transfer;
pub mod transfer_gather;
pub mod types;
pub mod util;

pub use error::PassError;
pub use frame::{FrameParams, Renderer, RendererOptions};
pub use gpu::Gpu;
pub use types::{AlbedoMap, AtlasData, LightDesc, MeshData, TexelImage, TransferPiece};
