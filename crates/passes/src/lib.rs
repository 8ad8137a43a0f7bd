//! ortm's real-time wgpu passes: first-order lightmap, its area-weighted pyramid (for
//! multi-resolution pieces), offset radiance transfer (paper Eq. 9: blend, compute and rows paths),
//! indirect light, gutter dilation and display.
//!
//! # Frame
//! ```text
//! lights ─▶ first_order ─▶ [pyramid] ─▶ transfer (blend | compute | rows) ─▶ [indirect] ─▶ dilate ─▶ display ─▶ RGBA8 image
//!              ▲ mesh, albedo  ▲ texel weights  ▲ atlases + pieces (from the binning stage)
//! ```
//! The pyramid pass ([`pyramid`]) runs only for multi-resolution pieces (level > 0).
//! Each pass is a struct built once with `new(&Gpu, &Options)`, given its per-scene data
//! by `prepare`, and recorded per frame with `encode(&Gpu, encoder, &inputs) -> Output`.
//! [`frame::Renderer`] owns one of each and is the one frame script:
//! [`Renderer::prepare`] uploads a scene (the mesh once, [`mesh::GpuMesh`]) and
//! [`Renderer::encode_frame`] records a frame; its [`frame::FrameOptions`] choose the
//! stages (the benchmarks time one at a time), the lightmap shown (final, first order,
//! indirect, or a caller's texture), moving or static lights, and timestamps
//! ([`timestamps::Timestamps`]). Every pass has a CPU mirror of the same name in [`cpu`];
//! the tests compare them on the lavapipe software adapter. See `docs/render.md` for
//! measurements and the file map.
//!
//! # Conventions
//! See [`types`]: SI units (m, W/sr, W/m²), lightmap texel `(x, y)` centre
//! `u = (x+0.5)/W`, `v = 1 − (y+0.5)/H` (row 0 = `v = 1`), offsets in texels with `+y` down,
//! alpha = coverage.
//!
//! This crate does not depend on `ortm`; the CLI converts its types into [`types`].

pub mod cpu;
pub mod dilate;
pub mod display;
pub mod display_split;
pub mod error;
pub mod first_order;
pub mod frame;
pub mod gpu;
pub mod indirect;
pub mod mesh;
pub mod pairing;
pub mod pyramid;
pub mod rows;
pub mod schedule;
pub mod timestamps;
pub mod transfer;
pub mod transfer_gather;
pub mod transfer_rows;
pub mod types;
pub mod util;

pub use error::PassError;
pub use frame::{FrameOptions, FrameParams, Renderer, RendererOptions};
pub use gpu::Gpu;
pub use types::{
    AlbedoMap, AtlasData, LightDesc, MeshData, TexelImage, TexelWeights, TransferPiece,
};
