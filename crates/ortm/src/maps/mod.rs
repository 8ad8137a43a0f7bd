//! Offset transfer maps in memory (paper Sec. 3, Eq. 9–10, and Sec. 5.1): storage, cropping
//! with axial slicing, and the CPU reference for applying the maps. Their files and the bake
//! index are [`crate::bake_dir`].
//!
//! # Data flow
//! 1. The bake computes, for each chosen offset `Δt`, a full `W×H` image of
//!    `TR(t, t+Δt)·TVA(t, Δt)` (Eq. 10, dimensionless RGB) and hands it to
//!    [`TransferMap::from_full`], which crops it to a few disjoint rectangles ([`crop`]).
//! 2. [`crate::bake_dir`] writes each map to its own OpenEXR file and the bake index, and reads
//!    them back.
//! 3. [`apply()`] evaluates `B(t) = B_o(t) + Σ_maps map(t)·B_o(t+Δt)` (Eq. 9 plus the first-order
//!    term) on the CPU; it is the reference the GPU renderer is checked against.
//!
//! # Units and conventions
//! - Map values are dimensionless transfer factors (`TR·TVA`; the Voronoi area is already folded
//!   in, Eq. 8–10); multiplied by first-order radiosity `B_o` in W/m² they give W/m².
//! - Texel `(x, y)` is column `x`, row `y`, row 0 at `v = 1` (see [`crate::lightmap`]). An offset
//!   `Δt = (dx, dy)` is in texels, `+dy` goes *down* the image; the map's value at `t` multiplies
//!   `B_o(t + Δt)`, and `B_o` is zero outside the lightmap.
//! - A texel is *empty* when all three channels compare equal to `0.0` (so `-0.0` is empty too);
//!   empty texels are not stored.
//!
//! # Limits
//! Lightmaps are limited to [`MAX_TEXELS`] texels (so sizes and counts fit in `u32` and a corrupt
//! file cannot request an absurd allocation).

pub mod apply;
pub mod crop;
pub mod levels;
pub mod transfer_map;

use std::path::PathBuf;

pub use apply::{apply, apply_indirect};
pub use crop::{CropOptions, CropRect, crop_rects};
pub use transfer_map::{Crop, MAX_MAP_LEVEL, TransferMap, receiver_grid};

/// Largest lightmap (width × height, in texels) this module accepts: 2²⁸ texels, e.g. 16384²
/// (the same value as [`crate::io::limits::MAX_TEXELS`], where every limit is listed).
pub const MAX_TEXELS: u64 = crate::io::limits::MAX_TEXELS;

/// Everything that can go wrong while building, storing, loading or applying transfer maps.
#[derive(Debug, thiserror::Error)]
pub enum MapsError {
    /// A multi-resolution map was applied without the first-order pyramid.
    #[error(
        "transfer map {map} reads pyramid level {level}: apply multi-resolution maps with \
         maps::levels::apply_levels, which needs the texel areas"
    )]
    NeedsPyramid {
        /// Index of the map in the list.
        map: usize,
        /// Its level.
        level: u32,
    },
    /// A lightmap's `data` does not hold `width * height` texels.
    #[error(
        "{what}: lightmap is {width}×{height} but holds {len} texels (expected {}); build it with \
         Lightmap::new or fill `data` with exactly width*height values",
        *width as u64 * *height as u64
    )]
    LightmapDataLength {
        /// Which lightmap (e.g. "first-order lightmap").
        what: String,
        /// Declared width.
        width: u32,
        /// Declared height.
        height: u32,
        /// Actual `data.len()`.
        len: usize,
    },

    /// A lightmap is empty or larger than [`MAX_TEXELS`].
    #[error(
        "{what}: lightmap size {width}×{height} is not supported (each side must be ≥ 1 and \
         width*height ≤ {MAX_TEXELS}); use a smaller, non-empty lightmap"
    )]
    LightmapSize {
        /// Which lightmap or file.
        what: String,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
    },

    /// Two images that must have the same size do not.
    #[error(
        "{what}: size mismatch, expected {}×{} but found {}×{}; all transfer maps of a bake and \
         the first-order lightmap must share one lightmap size",
        expected.0, expected.1, found.0, found.1
    )]
    SizeMismatch {
        /// What was compared (names the map or file).
        what: String,
        /// Expected (width, height).
        expected: (u32, u32),
        /// Found (width, height).
        found: (u32, u32),
    },

    /// A transfer-map value, Voronoi area or importance is NaN or infinite (or the area is
    /// negative).
    #[error(
        "transfer map for offset ({}, {}): {what}; fix the transport/offset computation that \
         produced it (transfer values must be finite, the Voronoi area finite and ≥ 0)",
        offset.0, offset.1
    )]
    InvalidValue {
        /// The map's offset `(dx, dy)`.
        offset: (i32, i32),
        /// What is wrong, naming the texel or field.
        what: String,
    },

    /// Crop rectangles are out of bounds, overlap, or their data has the wrong length.
    #[error(
        "{what}: invalid crop rectangles: {reason}; rebuild the map with TransferMap::from_full"
    )]
    InvalidCrop {
        /// Which map or file.
        what: String,
        /// What is wrong.
        reason: String,
    },

    /// The file does not start with the OpenEXR magic number.
    #[error(
        "{} is not an OpenEXR file (wrong magic number); delete it and re-run the bake to \
         regenerate it",
        path.display()
    )]
    NotExr {
        /// The file.
        path: PathBuf,
    },

    /// The OpenEXR file decodes but is not a valid ortm transfer-map file.
    #[error(
        "{} is not a valid ortm transfer-map file: {reason}; delete it and re-run the bake to \
         regenerate it",
        path.display()
    )]
    BadMapFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },

    /// `index.json` is not valid JSON or does not match the schema.
    #[error(
        "cannot parse {}: {source}; the index is corrupt, re-run the bake (see docs/bake-format.md \
         for the schema)",
        path.display()
    )]
    Json {
        /// The index file.
        path: PathBuf,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },

    /// `index.json` has the wrong `format` field.
    #[error(
        "{}: field \"format\" is {found:?}, expected \"{expected}\"; this is not an ortm bake \
         index",
        path.display()
    )]
    IndexFormat {
        /// The index file.
        path: PathBuf,
        /// The format this build reads ([`crate::bake_dir::INDEX_FORMAT`]).
        expected: &'static str,
        /// The value found (or `<missing>`).
        found: String,
    },

    /// `index.json` has an unsupported `version`.
    #[error(
        "{}: bake index version {found} is not supported, this build reads version \
         {expected}; re-bake with this version of ortm",
        path.display()
    )]
    IndexVersion {
        /// The index file.
        path: PathBuf,
        /// The version this build reads ([`crate::bake_dir::INDEX_VERSION`]).
        expected: u32,
        /// The version found (as written, or `<missing>`).
        found: String,
    },

    /// `index.json` is well-formed JSON but its content is inconsistent.
    #[error("{}: {reason}; the index is corrupt, re-run the bake", path.display())]
    BadIndex {
        /// The index file.
        path: PathBuf,
        /// What is wrong (names the map entry / field).
        reason: String,
    },

    /// A map file's own header disagrees with its index entry or the bake key.
    #[error(
        "map file {} does not match its index entry: {reason}; the bake directory mixes files \
         from different bakes, re-run the bake",
        path.display()
    )]
    EntryMismatch {
        /// The file.
        path: PathBuf,
        /// What differs.
        reason: String,
    },

    /// A file of the bake directory cannot be read, written or trusted (missing, wrong size or
    /// SHA-256, a name or link leading outside the directory, an OpenEXR codec failure).
    #[error(transparent)]
    File(#[from] crate::io::FileError),
}
