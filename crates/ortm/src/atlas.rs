//! Texture atlases of transfer maps (paper Sec. 5.2): the bake's cropped maps packed by the
//! `binning` crate into a few large textures, the piece list the renderer draws, the atlas files
//! on disk, a CPU reference of Eq. 9 evaluated from the pieces, and a picture of the packing.
//!
//! # Data flow
//! 1. [`build_atlas_set`] takes the bake's [`TransferMap`]s (in bake-index order). Every crop
//!    rectangle of every map becomes one binning source (id = a running number, remembered as
//!    `(map, crop)`); [`binning::pack`] cuts them into power-of-two-wide slices and packs them
//!    into the fewest `atlas_w × atlas_h` atlases; [`binning::blit`] copies the values
//!    bit-exactly. Each placement becomes an [`AtlasPiece`]: `src_x, src_y` = its position in
//!    the atlas, `dst_x = crop.x + placement.src_x`, `dst_y = crop.y + placement.src_y` = the
//!    receiver texel of its top-left corner in the lightmap, `offset` = the map's `Δt`,
//!    `map_index` = the map's position in the slice (= its position in `index.json`'s `maps`).
//! 2. [`write_atlas_set`] writes one OpenEXR file per atlas (`atlas_000.exr`, …) and then the
//!    index `atlases.json` (format in `docs/atlas-format.md`), all atomically, the index last.
//! 3. [`read_atlas_set`] reads them back with every check a renderer needs: version, file names,
//!    sizes, SHA-256, piece geometry, and the bake key against the bake's `index.json` if the
//!    directory has one.
//! 4. [`apply_atlas_set`] evaluates `B = B_o + Σ_pieces atlas[src+(i,j)]·B_o[dst+(i,j)+Δt]`, the
//!    same sum as [`crate::maps::apply()`] (bit-identical when the pieces came from the same maps:
//!    see its doc). [`packing_image`] and [`atlas_values_image`] draw an atlas for people.
//!
//! # Units and conventions
//! Atlas texels hold the maps' dimensionless transfer factors (linear RGB, f32). Atlas and
//! lightmap images are row-major, row 0 first (`y` down; lightmap row 0 is `v = 1`). Offsets are
//! texels, `+dy` down; a piece texel at lightmap `t` multiplies `B_o(t + Δt)`, zero outside the
//! lightmap.
//!
//! # Invariants of a valid [`AtlasSet`] (checked by [`AtlasSet::validate`], on write and read)
//! Atlas sides are powers of two in `1..=65536` with `W·H ≤` [`MAX_TEXELS`]; the lightmap is
//! non-empty with `≤ MAX_TEXELS` texels; every atlas holds `W·H` finite values; every piece is
//! non-empty, names an existing atlas, lies inside it and (at `dst`) inside the lightmap; pieces
//! are sorted by `(atlas, src_y, src_x)` and pairwise disjoint in their atlas; the pieces of one
//! map share one offset and are pairwise disjoint in the lightmap.
//!
//! # Limits
//! Checking disjointness costs one `u32` per atlas texel and per lightmap texel (stamp grids).
//! Memory for a set is `12·W·H` bytes per atlas. [`apply_atlas_set`] is single-threaded, `O(Σ
//! piece areas + lightmap texels)`.

use std::collections::HashMap;
use std::fs;
use std::io::Cursor;
use std::path::{Path, PathBuf};

use exr::image::read::read;
use exr::image::{AnyChannel, AnyChannels, Blocks, Encoding, FlatSamples, Image, Layer};
use exr::math::Vec2;
use exr::meta::attribute::{IntegerBounds, SampleType};
use exr::meta::header::{ImageAttributes, LayerAttributes};
use exr::meta::{BlockDescription, MetaData};
use exr::prelude::traits::{ReadChannels, ReadLayers, WritableImage};
use exr::prelude::{Compression, LineOrder, SmallVec};
use image::{Rgb, RgbImage};
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::Lightmap;
use crate::maps::exr_io::{A_META, meta_attribute, parse_meta, sha256_hex, text, write_atomic};
use crate::maps::{
    INDEX_FILE_NAME, INDEX_FORMAT, LightmapSize, MAX_TEXELS, MapsError, TransferMap,
};

/// File name of the atlas index inside an atlas directory.
pub const ATLAS_INDEX_FILE_NAME: &str = "atlases.json";
/// Value of the atlas index's `format` field.
pub const ATLAS_INDEX_FORMAT: &str = "ortm-atlases";
/// The atlas index version this build writes and reads.
pub const ATLAS_INDEX_VERSION: u32 = 1;
/// Value of the `ortmFormat` attribute of an atlas OpenEXR file.
const ATLAS_FILE_FORMAT: &str = "ortm-atlas";

const A_FORMAT: &str = "ortmFormat";
const A_ATLAS: &str = "ortmAtlasIndex";
const A_KEY: &str = "ortmBakeKey";

/// One packed piece: a rectangle of an atlas that holds part of one transfer map.
#[derive(Clone, Copy, Debug, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct AtlasPiece {
    /// Atlas index.
    pub atlas: u32,
    /// Left column of the piece in the atlas.
    pub src_x: u32,
    /// Top row of the piece in the atlas.
    pub src_y: u32,
    /// Width, texels.
    pub w: u32,
    /// Height, texels.
    pub h: u32,
    /// Lightmap column receiving the piece's left column (the receiver `t`).
    pub dst_x: u32,
    /// Lightmap row receiving the piece's top row.
    pub dst_y: u32,
    /// The map's offset `Δt` (texels, +y down): the piece multiplies `B_o(t + Δt)`.
    pub offset: [i32; 2],
    /// Index of the transfer map in the bake index.
    pub map_index: u32,
}

/// A set of atlases in memory.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasSet {
    /// Atlas width and height, texels.
    pub atlas_size: (u32, u32),
    /// Lightmap width and height, texels.
    pub lightmap_size: (u32, u32),
    /// Atlas texels (RGB, dimensionless transfer values), row-major, one `Vec` per atlas.
    pub atlases: Vec<Vec<[f32; 3]>>,
    /// Every piece, sorted by atlas.
    pub pieces: Vec<AtlasPiece>,
}

/// Figures about an [`AtlasSet`] (what `ortm bin` prints).
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasStats {
    /// Number of atlases.
    pub atlases: usize,
    /// Number of pieces.
    pub pieces: usize,
    /// Number of distinct maps with at least one piece.
    pub maps: usize,
    /// Mean pieces per map, over the maps with at least one piece (0 if none).
    pub mean_pieces_per_map: f64,
    /// Largest number of pieces of one map (0 if none).
    pub max_pieces_per_map: u32,
    /// Texels covered by pieces (= stored map texels).
    pub texels: u64,
    /// `texels / (atlases · W · H)`, 0 without atlases.
    pub fill_ratio: f64,
}

/// One atlas file of the index.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasFileEntry {
    /// Plain file name inside the atlas directory, e.g. `atlas_000.exr`.
    pub file: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Lower-case hex SHA-256 of the whole file.
    pub sha256: String,
}

/// The contents of `atlases.json` (without `format` and `version`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasIndex {
    /// Atlas size, texels.
    pub atlas_size: LightmapSize,
    /// Lightmap size, texels.
    pub lightmap: LightmapSize,
    /// Bake key of the bake whose maps were packed (64 lower-case hex digits).
    pub bake_key: String,
    /// One entry per atlas, in atlas order.
    pub atlases: Vec<AtlasFileEntry>,
    /// Every piece, sorted by `(atlas, src_y, src_x)`.
    pub pieces: Vec<AtlasPiece>,
}

/// Everything that can go wrong while building, writing, reading or applying atlases.
#[derive(Debug, thiserror::Error)]
pub enum AtlasError {
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

    /// An in-memory atlas set or the bake key passed to [`write_atlas_set`] is inconsistent.
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

    /// A file-system operation failed.
    #[error("{op} {}: {source}; check that the path exists, is readable/writable and the disk has space", path.display())]
    Io {
        /// What was being done.
        op: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
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

    /// An atlas file name in the index is not a plain file name.
    #[error(
        "{}: atlas file name {name:?} is not allowed (it must be a plain file name: no '/', '\\', \
         ':', '..', not absolute); re-run `ortm bin`",
        path.display()
    )]
    BadFileName {
        /// The index file.
        path: PathBuf,
        /// The rejected name.
        name: String,
    },

    /// A file named in the atlas index resolves (through a symbolic link) outside the atlas
    /// directory, or is not a regular file.
    #[error(
        "atlas file {} {problem}; an atlas directory must hold its files itself (copy the file \
         instead of linking to it, or re-run `ortm bin`)",
        path.display()
    )]
    PathEscape {
        /// The path named by the index.
        path: PathBuf,
        /// What is wrong (where it resolves to).
        problem: String,
    },

    /// An atlas file listed in the index does not exist.
    #[error(
        "atlas file {} listed in the atlas index is missing; copy the complete atlas directory \
         or re-run `ortm bin`",
        path.display()
    )]
    MissingFile {
        /// The missing file.
        path: PathBuf,
    },

    /// An atlas file's size differs from the index.
    #[error(
        "atlas file {} has {found} bytes but the atlas index says {expected}; the file is \
         truncated or was replaced, re-run `ortm bin`",
        path.display()
    )]
    FileSize {
        /// The file.
        path: PathBuf,
        /// Size recorded in the index.
        expected: u64,
        /// Size on disk.
        found: u64,
    },

    /// An atlas file's SHA-256 differs from the index.
    #[error(
        "atlas file {} has SHA-256 {found} but the atlas index says {expected}; the file is \
         corrupt or was replaced, re-run `ortm bin`",
        path.display()
    )]
    Checksum {
        /// The file.
        path: PathBuf,
        /// Hex digest recorded in the index.
        expected: String,
        /// Hex digest of the file on disk.
        found: String,
    },

    /// The OpenEXR decoder or encoder failed.
    #[error(
        "cannot {op} OpenEXR atlas file {}: {source}; the file is corrupt or truncated, re-run \
         `ortm bin`",
        path.display()
    )]
    Exr {
        /// "decode" or "encode".
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The codec's error.
        #[source]
        source: exr::error::Error,
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
}

/// File name of atlas `i`: `atlas_000.exr`, `atlas_001.exr`, … (at least three digits).
pub fn atlas_file_name(i: u32) -> String {
    format!("atlas_{i:03}.exr")
}

/// Packs `maps` into `atlas_w × atlas_h` atlases (see the module doc) and returns the set.
///
/// # Errors
/// [`AtlasError::NoMaps`], [`AtlasError::LightmapMismatch`], [`AtlasError::TooManyCrops`],
/// [`AtlasError::Pack`] (e.g. an atlas side that is not a power of two).
pub fn build_atlas_set(
    maps: &[TransferMap],
    atlas_w: u32,
    atlas_h: u32,
) -> Result<AtlasSet, AtlasError> {
    build_atlas_set_with_stats(maps, atlas_w, atlas_h).map(|(set, _)| set)
}

/// Most set bits allowed in a padded crop width.
pub const PAD_WIDTH_BITS: u32 = 3;

/// Column padding that cuts the number of power-of-two slices of a crop: the smallest width
/// `w' ≥ w` with at most [`PAD_WIDTH_BITS`] set bits (e.g. 447 = 8 slices → 448 = 256 + 128 +
/// 64, 3 slices), kept inside the lightmap (the crop is extended to the right, or to the left
/// at the border). The added columns hold zeros: they add nothing when blended, and cost at
/// most a quarter of the width (in practice a few columns) of atlas space. Applied to maps made
/// of a single crop rectangle (so padding can never overlap another crop of the same map).
/// Returns the padded `(x, w)`, or `None` when the width is kept.
pub fn padded_columns(x: u32, w: u32, lightmap_w: u32) -> Option<(u32, u32)> {
    if w.count_ones() <= PAD_WIDTH_BITS {
        return None;
    }
    let mut wp = w;
    while wp.count_ones() > PAD_WIDTH_BITS {
        // Clear the lowest set bit's run by adding it: strictly fewer or equal bits, larger.
        wp += wp & wp.wrapping_neg();
    }
    if wp > lightmap_w {
        return None;
    }
    let xp = x.min(lightmap_w - wp);
    Some((xp, wp))
}

/// [`build_atlas_set`], also returning the packer's figures (slices, splits, merges; its
/// `pieces_per_source` counts pieces per *crop rectangle*, in map then crop order).
///
/// # Errors
/// As [`build_atlas_set`].
pub fn build_atlas_set_with_stats(
    maps: &[TransferMap],
    atlas_w: u32,
    atlas_h: u32,
) -> Result<(AtlasSet, binning::PackStats), AtlasError> {
    let first = maps.first().ok_or(AtlasError::NoMaps)?;
    let lightmap_size = (first.width(), first.height());
    // Column padding of single-crop maps (see [`padded_columns`]): (x, w, padded data).
    type Padded = Option<(u32, u32, Vec<[f32; 3]>)>;
    let padded: Vec<Padded> = maps
        .iter()
        .map(|m| match m.crops() {
            [c] => padded_columns(c.rect.x, c.rect.w, lightmap_size.0).map(|(x, w)| {
                let mut buf = vec![[0.0f32; 3]; w as usize * c.rect.h as usize];
                let shift = (c.rect.x - x) as usize;
                for row in 0..c.rect.h as usize {
                    let src = &c.data[row * c.rect.w as usize..(row + 1) * c.rect.w as usize];
                    buf[row * w as usize + shift..row * w as usize + shift + src.len()]
                        .copy_from_slice(src);
                }
                (x, w, buf)
            }),
            _ => None,
        })
        .collect();
    let mut owners = Vec::new(); // id -> (map, crop)
    let mut rects = Vec::new();
    let mut data: Vec<&[[f32; 3]]> = Vec::new();
    for (mi, m) in maps.iter().enumerate() {
        if (m.width(), m.height()) != lightmap_size {
            return Err(AtlasError::LightmapMismatch {
                map: mi,
                expected: lightmap_size,
                found: (m.width(), m.height()),
            });
        }
        for (ci, c) in m.crops().iter().enumerate() {
            let id = u32::try_from(owners.len()).map_err(|_| AtlasError::TooManyCrops {
                count: maps.iter().map(|m| m.crops().len()).sum(),
            })?;
            owners.push((mi, ci));
            let (w, d): (u32, &[[f32; 3]]) = match &padded[mi] {
                Some((_, w, buf)) => (*w, buf),
                None => (c.rect.w, &c.data),
            };
            rects.push(binning::SourceRect { id, w, h: c.rect.h });
            data.push(d);
        }
    }
    let map_index =
        |mi: usize| u32::try_from(mi).map_err(|_| AtlasError::TooManyCrops { count: maps.len() });
    let packing = binning::pack(&rects, atlas_w, atlas_h)?;
    let atlases = binning::blit(&packing, &data)?;
    let mut pieces = Vec::with_capacity(packing.placements.len());
    for p in &packing.placements {
        let (mi, ci) = owners[p.source as usize];
        let m = &maps[mi];
        let mut r = m.crops()[ci].rect;
        if let Some((x, w, _)) = &padded[mi] {
            r.x = *x;
            r.w = *w;
        }
        pieces.push(AtlasPiece {
            atlas: p.atlas,
            src_x: p.dst_x,
            src_y: p.dst_y,
            w: p.w,
            h: p.h,
            dst_x: r.x + p.src_x,
            dst_y: r.y + p.src_y,
            offset: m.offset.to_array(),
            map_index: map_index(mi)?,
        });
    }
    pieces.sort_by_key(|p| (p.atlas, p.src_y, p.src_x));
    let set = AtlasSet {
        atlas_size: (atlas_w, atlas_h),
        lightmap_size,
        atlases,
        pieces,
    };
    Ok((set, packing.stats))
}

impl AtlasSet {
    /// Figures about the set: atlases, pieces, pieces per map, texels, fill ratio.
    pub fn stats(&self) -> AtlasStats {
        let mut per_map: HashMap<u32, u32> = HashMap::new();
        let mut texels = 0u64;
        for p in &self.pieces {
            *per_map.entry(p.map_index).or_default() += 1;
            texels += u64::from(p.w) * u64::from(p.h);
        }
        let capacity =
            self.atlases.len() as f64 * f64::from(self.atlas_size.0) * f64::from(self.atlas_size.1);
        AtlasStats {
            atlases: self.atlases.len(),
            pieces: self.pieces.len(),
            maps: per_map.len(),
            mean_pieces_per_map: if per_map.is_empty() {
                0.0
            } else {
                self.pieces.len() as f64 / per_map.len() as f64
            },
            max_pieces_per_map: per_map.values().copied().max().unwrap_or(0),
            texels,
            fill_ratio: if capacity > 0.0 {
                texels as f64 / capacity
            } else {
                0.0
            },
        }
    }

    /// Checks every invariant listed in the module doc.
    ///
    /// # Errors
    /// [`AtlasError::InvalidSet`] naming the first violation.
    pub fn validate(&self) -> Result<(), AtlasError> {
        let invalid = |reason: String| AtlasError::InvalidSet { reason };
        check_geometry(
            self.atlas_size,
            self.lightmap_size,
            self.atlases.len(),
            &self.pieces,
        )
        .map_err(invalid)?;
        let texels = self.atlas_size.0 as usize * self.atlas_size.1 as usize;
        for (i, a) in self.atlases.iter().enumerate() {
            if a.len() != texels {
                return Err(invalid(format!(
                    "atlas {i} holds {} texels, expected {}×{} = {texels}",
                    a.len(),
                    self.atlas_size.0,
                    self.atlas_size.1
                )));
            }
            if let Some(k) = a.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
                return Err(invalid(format!(
                    "atlas {i} texel ({}, {}) is {:?}",
                    k % self.atlas_size.0 as usize,
                    k / self.atlas_size.0 as usize,
                    a[k]
                )));
            }
        }
        Ok(())
    }
}

/// `1 ≤ w, h` and `w·h ≤ MAX_TEXELS`.
fn size_ok(w: u32, h: u32) -> bool {
    w >= 1 && h >= 1 && u64::from(w) * u64::from(h) <= MAX_TEXELS
}

/// Checks sizes and piece geometry (module doc, "Invariants"), except the atlas data.
fn check_geometry(
    atlas_size: (u32, u32),
    lightmap_size: (u32, u32),
    atlas_count: usize,
    pieces: &[AtlasPiece],
) -> Result<(), String> {
    let (aw, ah) = atlas_size;
    let side_ok = |s: u32| s.is_power_of_two() && s <= binning::MAX_ATLAS_SIDE;
    if !side_ok(aw) || !side_ok(ah) || !size_ok(aw, ah) {
        return Err(format!(
            "atlas size {aw}×{ah} is invalid (sides must be powers of two ≤ {}, at most {MAX_TEXELS} \
             texels)",
            binning::MAX_ATLAS_SIDE
        ));
    }
    let (lw, lh) = lightmap_size;
    if !size_ok(lw, lh) {
        return Err(format!(
            "lightmap size {lw}×{lh} is invalid (sides ≥ 1, at most {MAX_TEXELS} texels)"
        ));
    }
    let inside = |o: u32, len: u32, size: u32| u64::from(o) + u64::from(len) <= u64::from(size);
    let mut offsets: HashMap<u32, [i32; 2]> = HashMap::new();
    for (i, p) in pieces.iter().enumerate() {
        if p.w == 0 || p.h == 0 {
            return Err(format!("piece {i} is empty ({}×{})", p.w, p.h));
        }
        if p.atlas as usize >= atlas_count {
            return Err(format!(
                "piece {i} names atlas {} but there are {atlas_count} atlases",
                p.atlas
            ));
        }
        if !inside(p.src_x, p.w, aw) || !inside(p.src_y, p.h, ah) {
            return Err(format!(
                "piece {i} ({}×{} at ({}, {}) of atlas {}) lies outside the {aw}×{ah} atlas",
                p.w, p.h, p.src_x, p.src_y, p.atlas
            ));
        }
        if !inside(p.dst_x, p.w, lw) || !inside(p.dst_y, p.h, lh) {
            return Err(format!(
                "piece {i} ({}×{} at lightmap ({}, {})) lies outside the {lw}×{lh} lightmap",
                p.w, p.h, p.dst_x, p.dst_y
            ));
        }
        if i > 0 {
            let q = &pieces[i - 1];
            if (q.atlas, q.src_y, q.src_x) >= (p.atlas, p.src_y, p.src_x) {
                return Err(format!(
                    "pieces {} and {i} are not sorted by (atlas, src_y, src_x)",
                    i - 1
                ));
            }
        }
        if let Some(o) = offsets.insert(p.map_index, p.offset)
            && o != p.offset
        {
            return Err(format!(
                "piece {i} of map {} has offset {:?} but another piece of that map has {o:?}",
                p.map_index, p.offset
            ));
        }
    }
    // Σ piece areas ≤ the atlases' texels (necessary for disjointness); this also bounds the
    // memory and time of the span checks below by the atlases, not by the piece list.
    let capacity = atlas_count as u64 * u64::from(aw) * u64::from(ah);
    let area: u64 = pieces.iter().map(|p| u64::from(p.w) * u64::from(p.h)).sum();
    if area > capacity {
        return Err(format!(
            "the pieces cover {area} texels but {atlas_count} atlases of {aw}×{ah} hold only \
             {capacity}: pieces overlap"
        ));
    }
    // Disjoint in the atlases: row spans (atlas, row, x0, x1, piece) sorted; two spans of one
    // row overlap iff some consecutive pair does.
    let spans = |key: &dyn Fn(&AtlasPiece) -> (u32, u32, u32)| {
        let mut s: Vec<(u32, u32, u32, u32, usize)> = Vec::new();
        for (i, p) in pieces.iter().enumerate() {
            let (group, x, y) = key(p);
            s.extend((y..y + p.h).map(|row| (group, row, x, x + p.w, i)));
        }
        s.sort_unstable();
        s.windows(2)
            .find(|w| w[0].0 == w[1].0 && w[0].1 == w[1].1 && w[1].2 < w[0].3)
            .map(|w| (w[1].4, w[1].0, w[1].1))
    };
    if let Some((i, atlas, y)) = spans(&|p| (p.atlas, p.src_x, p.src_y)) {
        return Err(format!(
            "piece {i} overlaps another piece in atlas {atlas} at row {y}"
        ));
    }
    // The pieces of one map are disjoint in the lightmap.
    if let Some((i, map, y)) = spans(&|p| (p.map_index, p.dst_x, p.dst_y)) {
        return Err(format!(
            "piece {i} of map {map} overlaps another piece of the same map at lightmap row {y}"
        ));
    }
    Ok(())
}

/// Removes temporary files an interrupted `write_atlas_set` left (`.atlas_*.tmp`,
/// `.atlases.json.*.tmp`: never read, since final names are only created by rename).
fn remove_stale_temp_files(dir: &Path) {
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        let ours = name.starts_with(".atlas_") || name.starts_with(".atlases.json.");
        if ours && name.ends_with(".tmp") && e.file_type().is_ok_and(|t| t.is_file()) {
            let _ = fs::remove_file(e.path());
        }
    }
}

/// Whether `name` is a plain file name (one normal path component, no `..`, no separators).
fn plain_file_name(name: &str) -> bool {
    !name.is_empty()
        && !name.contains(['/', '\\', ':', '\0'])
        && !name.contains("..")
        && !name.chars().any(char::is_control)
        && matches!(
            Path::new(name).components().collect::<Vec<_>>().as_slice(),
            [std::path::Component::Normal(_)]
        )
}

fn is_hex_digest(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
}

fn io_err<'a>(op: &'static str, path: &'a Path) -> impl FnOnce(std::io::Error) -> AtlasError + 'a {
    move |source| AtlasError::Io {
        op,
        path: path.to_owned(),
        source,
    }
}

/// Atomic write via the maps module's writer, with its error mapped to [`AtlasError::Io`].
fn write_file(path: &Path, bytes: &[u8]) -> Result<(), AtlasError> {
    write_atomic(path, bytes).map_err(|e| match e {
        MapsError::Io { source, .. } => AtlasError::Io {
            op: "cannot write",
            path: path.to_owned(),
            source,
        },
        other => AtlasError::Io {
            op: "cannot write",
            path: path.to_owned(),
            source: std::io::Error::other(other.to_string()),
        },
    })
}

/// Encodes atlas `index` as a single-part OpenEXR file (channels `B, G, R` f32, ZIP).
fn encode_atlas(
    path: &Path,
    index: u32,
    size: (u32, u32),
    data: &[[f32; 3]],
    bake_key: &str,
) -> Result<Vec<u8>, AtlasError> {
    let encoding = Encoding {
        compression: Compression::ZIP16,
        blocks: Blocks::ScanLines,
        line_order: LineOrder::Increasing,
    };
    let chan = |c: usize| FlatSamples::F32(data.iter().map(|v| v[c]).collect());
    let channels = AnyChannels::sort(SmallVec::from_vec(vec![
        AnyChannel::new("R", chan(0)),
        AnyChannel::new("G", chan(1)),
        AnyChannel::new("B", chan(2)),
    ]));
    let mut layer = Layer::new(
        Vec2(size.0 as usize, size.1 as usize),
        LayerAttributes::named("atlas"),
        encoding,
        channels,
    );
    let meta = meta_attribute(&[
        (A_FORMAT, ATLAS_FILE_FORMAT.to_owned()),
        (A_ATLAS, index.to_string()),
        (A_KEY, bake_key.to_owned()),
    ]);
    layer.attributes.other.insert(text(A_META), meta);
    let display = IntegerBounds::from_dimensions(Vec2(size.0 as usize, size.1 as usize));
    let image = Image::from_layers(ImageAttributes::new(display), vec![layer]);
    let mut bytes = Vec::new();
    image
        .write()
        .non_parallel()
        .to_buffered(Cursor::new(&mut bytes))
        .map_err(|source| AtlasError::Exr {
            op: "encode",
            path: path.to_owned(),
            source,
        })?;
    Ok(bytes)
}

/// Decodes and checks atlas file `index` (size, channels, attributes, finite values).
fn decode_atlas(
    path: &Path,
    bytes: &[u8],
    index: u32,
    size: (u32, u32),
    bake_key: &str,
) -> Result<Vec<[f32; 3]>, AtlasError> {
    const MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];
    let bad = |reason: String| AtlasError::BadAtlasFile {
        path: path.to_owned(),
        reason,
    };
    if bytes.len() < 4 || bytes[..4] != MAGIC {
        return Err(bad("not an OpenEXR file (wrong magic number)".into()));
    }
    let exr_err = |source| AtlasError::Exr {
        op: "decode",
        path: path.to_owned(),
        source,
    };
    // Headers first, before any pixel allocation.
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), true).map_err(exr_err)?;
    MetaData::validate(&meta.headers, true).map_err(exr_err)?;
    let [h] = meta.headers.as_slice() else {
        return Err(bad(format!(
            "{} parts, expected exactly one",
            meta.headers.len()
        )));
    };
    let want = Vec2(size.0 as usize, size.1 as usize);
    let display = h.shared_attributes.display_window;
    if display.position != Vec2(0, 0)
        || display.size != want
        || h.layer_size != want
        || h.own_attributes.layer_position != Vec2(0, 0)
    {
        return Err(bad(format!(
            "image is {:?} at {:?}, expected {}×{} at (0, 0) (the index's atlas size)",
            h.layer_size, h.own_attributes.layer_position, size.0, size.1
        )));
    }
    if h.deep || !matches!(h.blocks, BlockDescription::ScanLines) {
        return Err(bad("not a flat scan-line image".into()));
    }
    crate::maps::exr_io::check_compression(h.compression).map_err(&bad)?;
    crate::io::limits::check_exr_pixels(
        &path.display().to_string(),
        u64::from(size.0) * u64::from(size.1),
        bytes.len() as u64,
    )
    .map_err(|e| bad(e.to_string()))?;
    let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    if names != ["B", "G", "R"]
        || h.channels
            .list
            .iter()
            .any(|c| c.sample_type != SampleType::F32 || c.sampling != Vec2(1, 1))
    {
        return Err(bad(format!(
            "channels {names:?} are not exactly B, G, R as 32-bit float without subsampling"
        )));
    }
    let fields = parse_meta(&h.own_attributes.other).map_err(&bad)?;
    let get_text = |name: &str| fields.get(name).cloned();
    if get_text(A_FORMAT).as_deref() != Some(ATLAS_FILE_FORMAT) {
        return Err(bad(format!(
            "attribute {A_FORMAT} is not \"{ATLAS_FILE_FORMAT}\""
        )));
    }
    match get_text(A_ATLAS).and_then(|v| v.parse::<i64>().ok()) {
        Some(i) if i == i64::from(index) => {}
        other => {
            return Err(bad(format!(
                "attribute {A_ATLAS} is {other:?}, expected {index} (files swapped?)"
            )));
        }
    }
    if get_text(A_KEY).as_deref() != Some(bake_key) {
        return Err(bad(format!(
            "attribute {A_KEY} is {:?}, the index says {bake_key}",
            get_text(A_KEY)
        )));
    }
    let image = read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .pedantic()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
        .map_err(exr_err)?;
    let n = size.0 as usize * size.1 as usize;
    let list = &image
        .layer_data
        .first()
        .ok_or_else(|| bad("no image data".into()))?
        .channel_data
        .list;
    let samples = |c: usize| match list.get(c).map(|ch| &ch.sample_data) {
        Some(FlatSamples::F32(v)) if v.len() == n => Ok(v),
        _ => Err(bad(format!("channel {c} is not {n} f32 samples"))),
    };
    let (b, g, r) = (samples(0)?, samples(1)?, samples(2)?);
    let data: Vec<[f32; 3]> = (0..n).map(|k| [r[k], g[k], b[k]]).collect();
    if let Some(k) = data.iter().position(|v| v.iter().any(|c| !c.is_finite())) {
        return Err(bad(format!(
            "texel ({}, {}) is {:?}",
            k % size.0 as usize,
            k / size.0 as usize,
            data[k]
        )));
    }
    Ok(data)
}

/// Writes `set` into `dir` (created if needed): one OpenEXR file per atlas
/// ([`atlas_file_name`]) and then `atlases.json`, each atomically (temporary name, `fsync`,
/// rename). An existing `atlases.json` is removed first, so an interrupted run never leaves an
/// index that points at half-replaced atlases. Files from an earlier run that the new index does
/// not list are left alone (and ignored by readers). Returns the index written.
///
/// `bake_key` is the key of the bake the maps came from (`BakeIndex::bake_key`, 64 lower-case
/// hex digits); [`read_atlas_set`] compares it with the bake's `index.json`.
///
/// # Errors
/// [`AtlasError::InvalidSet`] for an inconsistent set or a malformed key, [`AtlasError::Io`],
/// [`AtlasError::Exr`].
pub fn write_atlas_set(
    dir: &Path,
    set: &AtlasSet,
    bake_key: &str,
) -> Result<AtlasIndex, AtlasError> {
    set.validate()?;
    if !is_hex_digest(bake_key) {
        return Err(AtlasError::InvalidSet {
            reason: format!("bake key {bake_key:?} is not 64 lower-case hex digits"),
        });
    }
    let atlas_count = u32::try_from(set.atlases.len()).map_err(|_| AtlasError::InvalidSet {
        reason: format!("{} atlases is too many", set.atlases.len()),
    })?;
    fs::create_dir_all(dir).map_err(io_err("cannot create directory", dir))?;
    remove_stale_temp_files(dir);
    let index_path = dir.join(ATLAS_INDEX_FILE_NAME);
    match fs::remove_file(&index_path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => return Err(io_err("cannot remove the old atlas index", &index_path)(e)),
    }
    let entries: Vec<Result<AtlasFileEntry, AtlasError>> = (0..atlas_count)
        .into_par_iter()
        .map(|i| {
            let file = atlas_file_name(i);
            let path = dir.join(&file);
            let bytes = encode_atlas(&path, i, set.atlas_size, &set.atlases[i as usize], bake_key)?;
            write_file(&path, &bytes)?;
            Ok(AtlasFileEntry {
                file,
                bytes: bytes.len() as u64,
                sha256: sha256_hex(&bytes),
            })
        })
        .collect();
    let index = AtlasIndex {
        atlas_size: LightmapSize {
            width: set.atlas_size.0,
            height: set.atlas_size.1,
        },
        lightmap: LightmapSize {
            width: set.lightmap_size.0,
            height: set.lightmap_size.1,
        },
        bake_key: bake_key.to_owned(),
        atlases: entries.into_iter().collect::<Result<_, _>>()?,
        pieces: set.pieces.clone(),
    };
    #[derive(Serialize)]
    struct Wire<'a> {
        format: &'static str,
        version: u32,
        #[serde(flatten)]
        body: &'a AtlasIndex,
    }
    let wire = Wire {
        format: ATLAS_INDEX_FORMAT,
        version: ATLAS_INDEX_VERSION,
        body: &index,
    };
    let mut json = serde_json::to_string_pretty(&wire).map_err(|source| AtlasError::Json {
        path: index_path.clone(),
        source,
    })?;
    json.push('\n');
    write_file(&index_path, json.as_bytes())?;
    Ok(index)
}

/// Reads and validates `dir/atlases.json` (format, version, schema, sizes, file names, digest
/// syntax, piece geometry) and, if `dir/index.json` exists, checks that it is the bake the
/// atlases were packed from (same bake key and lightmap size). Atlas files are not opened.
///
/// # Errors
/// [`AtlasError::MissingIndex`], [`AtlasError::Io`], [`AtlasError::Json`],
/// [`AtlasError::Format`], [`AtlasError::Version`], [`AtlasError::BadIndex`],
/// [`AtlasError::BadFileName`], [`AtlasError::BakeIndex`], [`AtlasError::BakeMismatch`].
pub fn read_atlas_index(dir: &Path) -> Result<AtlasIndex, AtlasError> {
    let path = dir.join(ATLAS_INDEX_FILE_NAME);
    let text =
        match crate::io::limits::read_bounded(&path, crate::io::limits::MAX_JSON_BYTES, "MAX_JSON_BYTES") {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(AtlasError::MissingIndex { path });
            }
            Err(e) => return Err(io_err("cannot read atlas index", &path)(e)),
        };
    let json_err = |source| AtlasError::Json {
        path: path.clone(),
        source,
    };
    let bad = |reason: String| AtlasError::BadIndex {
        path: path.clone(),
        reason,
    };
    let mut value: serde_json::Value = serde_json::from_slice(&text).map_err(json_err)?;
    let obj = value
        .as_object_mut()
        .ok_or_else(|| bad("the top level is not a JSON object".into()))?;
    let found =
        |v: Option<serde_json::Value>| v.map_or_else(|| "<missing>".into(), |v| v.to_string());
    match obj.remove("format") {
        Some(serde_json::Value::String(f)) if f == ATLAS_INDEX_FORMAT => {}
        other => {
            return Err(AtlasError::Format {
                path,
                found: found(other),
            });
        }
    }
    match obj.remove("version") {
        Some(v) if v.as_u64() == Some(u64::from(ATLAS_INDEX_VERSION)) => {}
        other => {
            return Err(AtlasError::Version {
                path,
                found: found(other),
            });
        }
    }
    let index: AtlasIndex = serde_json::from_value(value).map_err(json_err)?;
    if !is_hex_digest(&index.bake_key) {
        return Err(bad(format!(
            "bake_key {:?} is not 64 lower-case hex digits",
            index.bake_key
        )));
    }
    let mut names = std::collections::HashSet::new();
    for (i, a) in index.atlases.iter().enumerate() {
        if !plain_file_name(&a.file) {
            return Err(AtlasError::BadFileName {
                path,
                name: a.file.clone(),
            });
        }
        if !names.insert(a.file.as_str()) {
            return Err(bad(format!(
                "atlases[{i}]: file {:?} appears twice",
                a.file
            )));
        }
        if !is_hex_digest(&a.sha256) {
            return Err(bad(format!(
                "atlases[{i}]: sha256 {:?} is not 64 lower-case hex digits",
                a.sha256
            )));
        }
    }
    // The atlas files exist inside `dir` with the recorded sizes, and those sizes can hold the
    // declared atlas size: this bounds the work of the geometry checks below by the files on
    // disk, not by numbers in the JSON.
    let atlas_texels = u64::from(index.atlas_size.width) * u64::from(index.atlas_size.height);
    for a in &index.atlases {
        let (file, len) = resolve_atlas_file(dir, &a.file)?;
        if len != a.bytes {
            return Err(AtlasError::FileSize {
                path: file,
                expected: a.bytes,
                found: len,
            });
        }
        crate::io::limits::check_exr_pixels(
            &format!("atlas size in {} for {}", path.display(), file.display()),
            atlas_texels,
            len,
        )
        .map_err(|e| bad(e.to_string()))?;
    }
    check_geometry(
        (index.atlas_size.width, index.atlas_size.height),
        (index.lightmap.width, index.lightmap.height),
        index.atlases.len(),
        &index.pieces,
    )
    .map_err(bad)?;
    check_bake(dir, &path, &index)?;
    Ok(index)
}

/// Resolves the atlas index's file `name` inside `dir` ([`crate::io::limits::resolve_in_dir`]).
fn resolve_atlas_file(dir: &Path, name: &str) -> Result<(PathBuf, u64), AtlasError> {
    use crate::io::limits::Unresolved;
    let path = dir.join(name);
    crate::io::limits::resolve_in_dir(dir, name).map_err(|e| match e {
        Unresolved::Missing => AtlasError::MissingFile { path: path.clone() },
        Unresolved::Escapes(real) => AtlasError::PathEscape {
            path: path.clone(),
            problem: format!(
                "resolves to {}, outside the atlas directory {}",
                real.display(),
                dir.display()
            ),
        },
        Unresolved::NotRegular => AtlasError::PathEscape {
            path: path.clone(),
            problem: "is not a regular file".into(),
        },
    })
}

/// If `dir/index.json` exists, checks its bake key and lightmap size against the atlas index,
/// and that every piece's map exists in it with the piece's offset.
fn check_bake(dir: &Path, atlas_index: &Path, index: &AtlasIndex) -> Result<(), AtlasError> {
    let path = dir.join(INDEX_FILE_NAME);
    let text =
        match crate::io::limits::read_bounded(&path, crate::io::limits::MAX_JSON_BYTES, "MAX_JSON_BYTES") {
            Ok(t) => t,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(io_err("cannot read bake index", &path)(e)),
        };
    let bad = |reason: String| AtlasError::BakeIndex {
        path: path.clone(),
        reason,
    };
    let v: serde_json::Value =
        serde_json::from_slice(&text).map_err(|e| bad(format!("not valid JSON ({e})")))?;
    if v.get("format").and_then(|f| f.as_str()) != Some(INDEX_FORMAT) {
        return Err(bad(format!("field \"format\" is not \"{INDEX_FORMAT}\"")));
    }
    let key = v
        .get("bake_key")
        .and_then(|k| k.as_str())
        .ok_or_else(|| bad("field \"bake_key\" is missing".into()))?;
    let lightmap: LightmapSize = v
        .get("lightmap")
        .and_then(|l| serde_json::from_value(l.clone()).ok())
        .ok_or_else(|| bad("field \"lightmap\" is missing or malformed".into()))?;
    let mismatch = |what| AtlasError::BakeMismatch {
        index: atlas_index.to_owned(),
        bake: path.clone(),
        atlas_key: index.bake_key.clone(),
        bake_key: key.to_owned(),
        what,
    };
    if key != index.bake_key {
        return Err(mismatch("bake key"));
    }
    if lightmap != index.lightmap {
        return Err(mismatch("lightmap size"));
    }
    // Every piece's map is in the bake index with the piece's offset.
    let offsets: Vec<Option<[i32; 2]>> = v
        .get("maps")
        .and_then(|m| m.as_array())
        .ok_or_else(|| bad("field \"maps\" is missing or not an array".into()))?
        .iter()
        .map(|m| {
            m.get("offset")
                .and_then(|o| serde_json::from_value(o.clone()).ok())
        })
        .collect();
    for (i, p) in index.pieces.iter().enumerate() {
        match offsets.get(p.map_index as usize) {
            Some(Some(o)) if *o == p.offset => {}
            found => {
                return Err(AtlasError::BadIndex {
                    path: atlas_index.to_owned(),
                    reason: format!(
                        "piece {i} is map {} with offset {:?}, but the bake index {} has {}; the \
                         atlases were packed from another bake: re-run `ortm bin`",
                        p.map_index,
                        p.offset,
                        path.display(),
                        match found {
                            None => format!("{} maps", offsets.len()),
                            Some(o) => format!("offset {o:?} for that map"),
                        }
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Reads an atlas directory written by [`write_atlas_set`]: [`read_atlas_index`]'s checks, then
/// every atlas file (in parallel): present, recorded size and SHA-256, a single-part `B, G, R`
/// f32 OpenEXR image of the atlas size stamped with its atlas number and the bake key, finite
/// values. On several bad files the first atlas's error is returned.
///
/// # Errors
/// Those of [`read_atlas_index`], and [`AtlasError::MissingFile`], [`AtlasError::FileSize`],
/// [`AtlasError::Checksum`], [`AtlasError::Exr`], [`AtlasError::BadAtlasFile`],
/// [`AtlasError::Io`].
pub fn read_atlas_set(dir: &Path) -> Result<AtlasSet, AtlasError> {
    let index = read_atlas_index(dir)?;
    let size = (index.atlas_size.width, index.atlas_size.height);
    let atlases: Vec<Result<Vec<[f32; 3]>, AtlasError>> = index
        .atlases
        .par_iter()
        .enumerate()
        .map(|(i, a)| {
            let (path, _) = resolve_atlas_file(dir, &a.file)?;
            let bytes = match crate::io::limits::read_bounded(&path, a.bytes, "the recorded size") {
                Ok(b) => b,
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                    return Err(AtlasError::MissingFile { path });
                }
                Err(e) => return Err(io_err("cannot read", &path)(e)),
            };
            if bytes.len() as u64 != a.bytes {
                return Err(AtlasError::FileSize {
                    path,
                    expected: a.bytes,
                    found: bytes.len() as u64,
                });
            }
            let digest = sha256_hex(&bytes);
            if digest != a.sha256 {
                return Err(AtlasError::Checksum {
                    path,
                    expected: a.sha256.clone(),
                    found: digest,
                });
            }
            decode_atlas(&path, &bytes, i as u32, size, &index.bake_key)
        })
        .collect();
    Ok(AtlasSet {
        atlas_size: size,
        lightmap_size: (index.lightmap.width, index.lightmap.height),
        atlases: atlases.into_iter().collect::<Result<_, _>>()?,
        pieces: index.pieces,
    })
}

/// CPU reference of the renderer's transfer pass from the pieces (paper Eq. 9 plus the
/// first-order term): `B[t] = B_o[t] + Σ_pieces atlas[src+(i,j)]·B_o[dst+(i,j)+Δt]`, per RGB
/// channel, with `B_o = 0` outside the lightmap.
///
/// Each texel is accumulated in f64, starting at `B_o`, adding the pieces' terms in increasing
/// `map_index` (a map's pieces are disjoint in the lightmap, so each map adds at most one term
/// per texel), and rounded to f32 once. That is exactly the order and arithmetic of
/// [`crate::maps::apply()`], so for a set built from `maps` the result is bit-identical to
/// `maps::apply(maps, first_order)`.
///
/// # Errors
/// [`AtlasError::InvalidSet`] if the set is inconsistent, [`AtlasError::FirstOrderSize`] if
/// `first_order` does not have the set's lightmap size.
pub fn apply_atlas_set(set: &AtlasSet, first_order: &Lightmap) -> Result<Lightmap, AtlasError> {
    apply_atlas_pieces(set, |_| true, first_order)
}

/// [`apply_atlas_set`] with only the pieces for which `keep` is true (e.g. the maps of one
/// offset, or the first K maps by importance, as `ortm view` shows them); same order and
/// arithmetic.
///
/// # Errors
/// As [`apply_atlas_set`].
pub fn apply_atlas_pieces(
    set: &AtlasSet,
    keep: impl Fn(&AtlasPiece) -> bool,
    first_order: &Lightmap,
) -> Result<Lightmap, AtlasError> {
    set.validate()?;
    let (w, h) = set.lightmap_size;
    if (first_order.width, first_order.height) != (w, h)
        || first_order.data.len() != w as usize * h as usize
    {
        return Err(AtlasError::FirstOrderSize {
            expected: (w, h),
            found: (first_order.width, first_order.height),
            len: first_order.data.len(),
        });
    }
    let mut acc: Vec<[f64; 3]> = first_order.data.iter().map(|v| v.map(f64::from)).collect();
    let mut order: Vec<&AtlasPiece> = set.pieces.iter().filter(|p| keep(p)).collect();
    order.sort_by_key(|p| p.map_index); // stable: ties keep atlas order
    let aw = set.atlas_size.0 as usize;
    for p in order {
        let atlas = &set.atlases[p.atlas as usize];
        for j in 0..p.h {
            let y = i64::from(p.dst_y + j);
            let sy = y + i64::from(p.offset[1]);
            if sy < 0 || sy >= i64::from(h) {
                continue;
            }
            for i in 0..p.w {
                let x = i64::from(p.dst_x + i);
                let sx = x + i64::from(p.offset[0]);
                if sx < 0 || sx >= i64::from(w) {
                    continue;
                }
                let v = atlas[(p.src_y + j) as usize * aw + (p.src_x + i) as usize];
                let s = first_order.data[sy as usize * w as usize + sx as usize];
                let a = &mut acc[y as usize * w as usize + x as usize];
                for c in 0..3 {
                    a[c] += f64::from(v[c]) * f64::from(s[c]);
                }
            }
        }
    }
    Ok(Lightmap {
        width: w,
        height: h,
        data: acc.into_iter().map(|a| a.map(|v| v as f32)).collect(),
    })
}

/// Colour of map `map_index` in [`packing_image`]: a hash of the index, mid-bright.
pub fn map_color(map_index: u32) -> Rgb<u8> {
    // SplitMix64 finaliser: neighbouring indices get unrelated colours.
    let mut z = u64::from(map_index).wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    let c = |k: u32| 70 + ((z >> (8 * k)) & 0xff) as u8 % 170;
    Rgb([c(0), c(1), c(2)])
}

/// Background of [`packing_image`] (atlas texels outside every piece).
pub const PACKING_BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);

/// 3×5 digit glyphs, one row per `u8` (bit 2 = left column).
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b001, 0b001, 0b001],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// Pixels per atlas texel in [`packing_image`]: small atlases are enlarged to about 512 pixels
/// (at most 16×), large ones drawn 1:1.
pub fn packing_scale(atlas_size: (u32, u32)) -> u32 {
    (512 / atlas_size.0.max(atlas_size.1).max(1)).clamp(1, 16)
}

/// A picture of atlas `atlas`'s packing for people: each piece filled with its map's
/// [`map_color`], outlined one pixel darker, and labelled with its map index (3×5 digits,
/// scaled up to 8×) where the piece is big enough; free texels are [`PACKING_BACKGROUND`].
/// Each atlas texel is [`packing_scale`] pixels square. `None` if the atlas does not exist.
pub fn packing_image(set: &AtlasSet, atlas: u32) -> Option<RgbImage> {
    if atlas as usize >= set.atlases.len() {
        return None;
    }
    let k = packing_scale(set.atlas_size);
    let (iw, ih) = (set.atlas_size.0 * k, set.atlas_size.1 * k);
    let mut img = RgbImage::from_pixel(iw, ih, PACKING_BACKGROUND);
    for p in set.pieces.iter().filter(|p| p.atlas == atlas) {
        let fill = map_color(p.map_index);
        let edge = Rgb(fill.0.map(|c| (u16::from(c) * 9 / 20) as u8));
        let (x0, y0, pw, ph) = (p.src_x * k, p.src_y * k, p.w * k, p.h * k);
        for y in y0..(y0 + ph).min(ih) {
            for x in x0..(x0 + pw).min(iw) {
                let border = x == x0 || y == y0 || x + 1 == x0 + pw || y + 1 == y0 + ph;
                img.put_pixel(x, y, if border { edge } else { fill });
            }
        }
        let label = p.map_index.to_string();
        let n = label.len() as u32;
        let (tw, th) = (4 * n - 1, 5);
        let s = ((pw.saturating_sub(4)) / tw)
            .min(ph.saturating_sub(4) / th)
            .min(8);
        if s == 0 {
            continue;
        }
        let luma = 299 * u32::from(fill[0]) + 587 * u32::from(fill[1]) + 114 * u32::from(fill[2]);
        let ink = if luma > 128_000 {
            Rgb([0, 0, 0])
        } else {
            Rgb([255, 255, 255])
        };
        let lx = x0 + (pw - tw * s) / 2;
        let ly = y0 + (ph - th * s) / 2;
        for (d, ch) in label.bytes().enumerate() {
            let glyph = DIGITS[usize::from(ch - b'0')];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..3u32 {
                    if bits >> (2 - col) & 1 == 0 {
                        continue;
                    }
                    let gx = lx + (d as u32 * 4 + col) * s;
                    let gy = ly + row as u32 * s;
                    for yy in gy..gy + s {
                        for xx in gx..gx + s {
                            img.put_pixel(xx, yy, ink);
                        }
                    }
                }
            }
        }
    }
    Some(img)
}

/// A tone-mapped picture of atlas `atlas`'s values (linear RGB scaled so the 99th percentile of
/// the non-zero texels is white, sRGB-encoded), each texel [`packing_scale`] pixels square like
/// [`packing_image`]. `None` if the atlas does not exist.
pub fn atlas_values_image(set: &AtlasSet, atlas: u32) -> Option<RgbImage> {
    let data = set.atlases.get(atlas as usize)?;
    let map = Lightmap {
        width: set.atlas_size.0,
        height: set.atlas_size.1,
        data: data.clone(),
    };
    let white = crate::bake::report::percentile_99(&map);
    let texels = crate::bake::report::lightmap_image(&map, white);
    let k = packing_scale(set.atlas_size);
    Some(RgbImage::from_fn(map.width * k, map.height * k, |x, y| {
        *texels.get_pixel(x / k, y / k)
    }))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::{Crop, CropRect};
    use glam::IVec2;

    fn map(offset: (i32, i32), rects: &[(u32, u32, u32, u32)], seed: f32) -> TransferMap {
        let crops = rects
            .iter()
            .map(|&(x, y, w, h)| Crop {
                rect: CropRect { x, y, w, h },
                data: (0..w * h)
                    .map(|k| [seed + k as f32, seed * 0.5, 1.0 / (k as f32 + 1.0)])
                    .collect(),
            })
            .collect();
        TransferMap::from_crops("t", IVec2::new(offset.0, offset.1), 0.1, 1.0, 32, 16, crops)
            .unwrap()
    }

    #[test]
    fn pieces_reference_their_crops() {
        // Map 0: an 8×3 crop (one slice) and a 5×2 crop (slices 4 and 1). Map 1: 3×4 (2 | 1).
        let maps = vec![
            map((1, 0), &[(0, 0, 8, 3), (20, 10, 5, 2)], 1.0),
            map((-2, 3), &[(4, 6, 3, 4)], 100.0),
        ];
        let set = build_atlas_set(&maps, 8, 4).unwrap();
        set.validate().unwrap();
        assert_eq!(set.lightmap_size, (32, 16));
        // 24 + 10 + 12 = 46 texels: one 8×4 atlas is not enough, two are.
        assert_eq!(set.atlases.len(), 2);
        let mut covered = 0;
        for p in &set.pieces {
            let m = &maps[p.map_index as usize];
            assert_eq!(p.offset, m.offset.to_array());
            for j in 0..p.h {
                for i in 0..p.w {
                    let a =
                        set.atlases[p.atlas as usize][((p.src_y + j) * 8 + p.src_x + i) as usize];
                    assert_eq!(a, m.value_at(p.dst_x + i, p.dst_y + j));
                    covered += 1;
                }
            }
        }
        assert_eq!(covered, 46);
        let st = set.stats();
        assert_eq!((st.atlases, st.maps, st.texels), (2, 2, 46));
        assert!((st.fill_ratio - 46.0 / 64.0).abs() < 1e-12);
        assert_eq!(st.pieces, set.pieces.len());
    }

    #[test]
    fn build_rejects_bad_input() {
        assert!(matches!(
            build_atlas_set(&[], 8, 8),
            Err(AtlasError::NoMaps)
        ));
        let a = map((0, 0), &[(0, 0, 2, 2)], 1.0);
        assert!(matches!(
            build_atlas_set(std::slice::from_ref(&a), 6, 8),
            Err(AtlasError::Pack(binning::BinError::AtlasSize { .. }))
        ));
        let other = TransferMap::from_crops("o", IVec2::ZERO, 0.0, 0.0, 8, 8, vec![]).unwrap();
        assert!(matches!(
            build_atlas_set(&[a, other], 8, 8),
            Err(AtlasError::LightmapMismatch { map: 1, .. })
        ));
    }

    #[test]
    fn validate_catches_overlaps_and_bad_offsets() {
        let maps = vec![
            map((1, 0), &[(0, 0, 4, 2)], 1.0),
            map((0, 1), &[(0, 4, 4, 2)], 2.0),
        ];
        let set = build_atlas_set(&maps, 4, 4).unwrap();
        set.validate().unwrap();
        let mut s = set.clone();
        s.pieces[1].src_y = s.pieces[0].src_y; // same atlas rows: overlap (or order) error
        s.pieces[1].src_x = s.pieces[0].src_x + 1;
        assert!(s.validate().is_err());
        let mut s = set.clone();
        s.pieces[1].map_index = s.pieces[0].map_index; // same map, different offset
        assert!(matches!(s.validate(), Err(AtlasError::InvalidSet { .. })));
        let mut s = set.clone();
        s.pieces[1].offset = s.pieces[0].offset;
        s.pieces[1].map_index = s.pieces[0].map_index;
        s.pieces[1].dst_y = s.pieces[0].dst_y; // same map, same lightmap texels
        let e = s.validate().unwrap_err();
        assert!(e.to_string().contains("overlaps"), "{e}");
        let mut s = set;
        s.atlases[0][3] = [f32::NAN, 0.0, 0.0];
        assert!(s.validate().is_err());
    }

    #[test]
    fn packing_image_shows_pieces_and_labels() {
        let maps: Vec<TransferMap> = (0..3)
            .map(|i| map((i, 0), &[(i as u32 * 8, 0, 8, 5)], i as f32))
            .collect();
        let set = build_atlas_set(&maps, 16, 16).unwrap();
        let k = packing_scale(set.atlas_size);
        assert_eq!(k, 16);
        let img = packing_image(&set, 0).unwrap();
        assert_eq!(img.dimensions(), (16 * k, 16 * k));
        for p in &set.pieces {
            // Inside the outline, away from the centred label: the map's colour.
            let px = img.get_pixel(p.src_x * k + 1, p.src_y * k + 1);
            assert_eq!(*px, map_color(p.map_index));
            // Outline darker.
            let edge = img.get_pixel(p.src_x * k, p.src_y * k);
            assert!(edge.0.iter().zip(px.0).all(|(e, f)| *e < f));
            // The label puts some ink in the middle of every large piece.
            let (cx, cy) = ((p.src_x * k + p.w * k / 2), (p.src_y * k + p.h * k / 2));
            let fill = map_color(p.map_index);
            let ink = (cy - 10..cy + 10)
                .flat_map(|y| (cx - 10..cx + 10).map(move |x| (x, y)))
                .any(|(x, y)| *img.get_pixel(x, y) != fill);
            assert!(ink, "no label drawn on piece {p:?}");
        }
        // 120 of 256 texels are used; the last rows of the atlas are free.
        assert_eq!(*img.get_pixel(0, 16 * k - 1), PACKING_BACKGROUND);
        assert!(packing_image(&set, 1).is_none());
        assert_ne!(map_color(0), map_color(1));
    }
}

#[cfg(test)]
mod padding_tests {
    use super::*;

    #[test]
    fn padded_width_is_the_smallest_with_few_bits() {
        for w in 1..2000u32 {
            let brute = (w..=4096)
                .find(|v| v.count_ones() <= PAD_WIDTH_BITS)
                .unwrap();
            match padded_columns(10, w, 4096) {
                None => assert_eq!(brute, w),
                Some((x, wp)) => {
                    assert_eq!(wp, brute, "w = {w}");
                    assert!(x <= 10 && x + wp <= 4096 && x + wp >= 10 + w);
                }
            }
        }
        // At the border the crop is extended to the left; too wide → unchanged.
        assert_eq!(padded_columns(500, 11, 512), None); // 0b1011: 3 bits already
        assert_eq!(padded_columns(500, 15, 512), Some((496, 16)));
        assert_eq!(padded_columns(505, 7, 512), None);
        assert_eq!(padded_columns(0, 511, 511), None);
        assert_eq!(padded_columns(200, 300, 512), Some((200, 304)));
        assert_eq!(padded_columns(210, 300, 512), Some((208, 304)));
    }
}
