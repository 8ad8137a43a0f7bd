//! [`AtlasError`]: everything that can go wrong while building, writing, reading or applying
//! atlases. The file-level failures shared with bake directories are [`FileError`]s worded for
//! an atlas directory ([`crate::io::DirKind::Atlas`]).

use std::path::PathBuf;

use super::index::{ATLAS_INDEX_FORMAT, ATLAS_INDEX_VERSION};
use crate::io::FileError;

/// Everything that can go wrong while building, writing, reading or applying atlases.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
    /// Multi-resolution pieces were applied without the texel weights of the pyramid.
    #[error(
        "the atlases hold multi-resolution maps (pyramid level up to {level}): applying them \
         needs the lightmap's texel areas (open the bake with its scene)"
    )]
    NeedsWeights {
        /// The highest level among the pieces.
        level: u32,
    },
    /// There are no maps to pack, so the lightmap size is unknown.
    #[error(
        "no transfer maps to pack: the bake index lists no maps; re-run the bake with at least \
         one offset"
    )]
    NoMaps,

    /// Two maps have different lightmap sizes.
    #[error(
        "transfer map {map} is {}×{} but map 0 is {}×{}: all maps of one bake must share the \
         lightmap size; re-run the bake",
        found.0, found.1, expected.0, expected.1
    )]
    LightmapMismatch {
        /// Position of the offending map.
        map: usize,
        /// Size of map 0.
        expected: (u32, u32),
        /// Size of the offending map.
        found: (u32, u32),
    },

    /// The maps have more crop rectangles than fit in a `u32` id.
    #[error("the maps have {count} crop rectangles, more than 2^32; bake fewer or larger maps")]
    TooManyCrops {
        /// Number of crop rectangles.
        count: usize,
    },

    /// The packer refused the input (atlas size not a power of two, too many pieces, …).
    #[error("cannot pack the transfer maps: {0}")]
    Pack(#[from] binning::BinError),

    /// Another process is writing the atlas directory.
    #[error(transparent)]
    Lock(#[from] crate::io::LockError),

    /// An in-memory atlas set or the bake key passed to [`super::write_atlas_set`] is inconsistent.
    #[error("invalid atlas set: {reason}; build it with build_atlas_set")]
    InvalidSet {
        /// What is wrong.
        reason: String,
    },

    /// The first-order lightmap does not fit the atlas set.
    #[error(
        "first-order lightmap is {}×{} with {len} texels but the atlas set was packed for a \
         {}×{} lightmap; render the first-order light at the bake's lightmap size",
        found.0, found.1, expected.0, expected.1
    )]
    FirstOrderSize {
        /// The atlas set's lightmap size.
        expected: (u32, u32),
        /// The first-order lightmap's declared size.
        found: (u32, u32),
        /// Its number of texels.
        len: usize,
    },

    /// The directory has no `atlases.json`.
    #[error(
        "{} does not exist: this directory holds no atlases; run `ortm bin BAKE_DIR -o DIR` \
         first",
        path.display()
    )]
    MissingIndex {
        /// The expected index path.
        path: PathBuf,
    },

    /// `atlases.json` is not valid JSON or does not match the schema.
    #[error(
        "cannot parse {}: {source}; the atlas index is corrupt, re-run `ortm bin` (schema in \
         docs/atlas-format.md)",
        path.display()
    )]
    Json {
        /// The index file.
        path: PathBuf,
        /// The parser's error.
        #[source]
        source: serde_json::Error,
    },

    /// `atlases.json` has the wrong `format` field.
    #[error(
        "{}: field \"format\" is {found}, expected \"{ATLAS_INDEX_FORMAT}\"; this is not an ortm \
         atlas index",
        path.display()
    )]
    Format {
        /// The index file.
        path: PathBuf,
        /// The value found (or `<missing>`).
        found: String,
    },

    /// `atlases.json` has an unsupported `version`.
    #[error(
        "{}: atlas index version {found} is not supported, this build reads version \
         {ATLAS_INDEX_VERSION}; re-run `ortm bin` with this version of ortm",
        path.display()
    )]
    Version {
        /// The index file.
        path: PathBuf,
        /// The version found (as written, or `<missing>`).
        found: String,
    },

    /// `atlases.json` is well-formed but inconsistent (sizes, pieces, digests).
    #[error("{}: {reason}; the atlas index is corrupt, re-run `ortm bin`", path.display())]
    BadIndex {
        /// The index file.
        path: PathBuf,
        /// What is wrong (names the atlas / piece / field).
        reason: String,
    },

    /// The atlas file decodes but is not what the index describes.
    #[error(
        "{} is not a valid ortm atlas file for this index: {reason}; re-run `ortm bin`",
        path.display()
    )]
    BadAtlasFile {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },

    /// The bake's `index.json` next to the atlases cannot be read.
    #[error(
        "{}: {reason}; the atlas directory's bake index is unreadable, fix or remove it (it is \
         only used to check the bake key)",
        path.display()
    )]
    BakeIndex {
        /// The bake index file.
        path: PathBuf,
        /// What is wrong.
        reason: String,
    },

    /// The atlases were packed from another bake than the `index.json` beside them.
    #[error(
        "{} was packed from bake {atlas_key} ({what}) but {} belongs to bake {bake_key}; the \
         atlases are stale, re-run `ortm bin` on this bake",
        index.display(), bake.display()
    )]
    BakeMismatch {
        /// The atlas index.
        index: PathBuf,
        /// The bake index.
        bake: PathBuf,
        /// Bake key recorded in the atlas index.
        atlas_key: String,
        /// Bake key of the bake index.
        bake_key: String,
        /// What differs ("bake key" or "lightmap size").
        what: &'static str,
    },

    /// An atlas file cannot be read, written or trusted (missing, wrong size or SHA-256, a
    /// name or link leading outside the directory, an OpenEXR codec failure).
    #[error(transparent)]
    File(#[from] FileError),
}
