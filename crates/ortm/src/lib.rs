//! # ortm — Offset Radiance Transfer Mapping
//!
//! A Rust implementation of Sunshine-Hill & Faloutsos, *Photorealistic Lighting with Offset
//! Radiance Transfer Mapping* (I3D 2006). The pipeline, one module family per stage:
//!
//! 1. **Bake** (offline): [`scene`] → [`bake`] → [`maps`], stored by [`bake_dir`].
//! 2. **Bin**: the `binning` crate packs cropped maps into atlases.
//! 3. **Render**: the `passes` crate (wgpu).
//!
//! Units are SI throughout: metres, W/sr (point and spot lights), W/m² (directional lights,
//! lightmaps). See `docs/ARCHITECTURE.md` for the file layout.

pub mod accuracy;
pub mod atlas;
pub mod bake;
pub mod bake_dir;
pub mod io;
pub mod lightmap;
pub mod maps;
#[cfg(feature = "render")]
pub mod render;
pub mod scene;

pub use lightmap::Lightmap;
