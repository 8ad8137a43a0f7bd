//! The transfer-map file codec: one OpenEXR file per map, one *part* per crop rectangle
//! (paper Sec. 5.1: "written to disk as separate OpenEXR files"). Encoding and decoding work on
//! bytes in memory; [`crate::bake_dir::write_map_file`] writes a file and returns its index
//! entry, [`read_map_file`] reads one. Format description in `docs/bake-format.md`.
//!
//! # Layout
//! - **Multi-part scan-line file** (OpenEXR 2.0+; `exrheader`, `exrinfo` and every OpenEXR ≥ 2
//!   reader accept it). Every part has the same display window `(0,0)–(W−1,H−1)`, the full
//!   lightmap, and its own data window = its crop rectangle in lightmap coordinates (row 0 is the
//!   top image row, `v = 1`, as in the lightmap convention). Part `i` is named `rect<i>`, in the
//!   order of [`TransferMap::crops`]. Empty space between rectangles is not stored. (A single part
//!   whose data window is the bounding box would store that space.)
//! - Channels `B`, `G`, `R` (alphabetical, as OpenEXR requires), **32-bit float**, no
//!   subsampling, ZIP compression (16 scan lines per block, lossless).
//! - A map with no non-zero texel has no rectangles, but an OpenEXR file needs at least one part:
//!   it gets a single placeholder part named `ortm-empty`, 1×1 at `(0,0)`, value 0, and
//!   `ortmRectCount = 0`.
//! - Metadata, in ONE custom text attribute `ortmMeta` of the first part, as `name=value` lines in
//!   this fixed order: `ortmFormat` (`ortm-transfer-map`), `ortmVersion` (1), `ortmMapIndex`,
//!   `ortmOffset` (`dx,dy` in texels, +dy down), `ortmVoronoiArea` and `ortmImportance` (the
//!   f64's bit pattern as `0x` + 16 hex digits: exact), `ortmRectCount`, `ortmBakeKey` (see
//!   [`BakeKey`]) and `ortmContentSha256` (SHA-256 of the map content, see below). One attribute,
//!   because the `exr` crate writes custom attributes in hash-map order: with several, two
//!   identical maps would not be byte-identical files. This makes each file self-describing,
//!   which the resumable bake ([`crate::bake_dir::scan_finished_maps`]) relies on.
//!
//! # Why f32 and not f16
//! Transfer values span ≈1e-6…1. Half floats have a relative rounding error of 2⁻¹¹ ≈ 4.9e-4 in
//! their normal range and lose precision below 6.1e-5 (subnormals: a value of 1e-6 keeps only
//! ≈4 significant bits, ≈3 % error), exactly where the many small far-offset contributions live.
//! The final lightmap sums hundreds of maps, so those errors add up (and the small-value
//! truncation is biased, not random). f32 keeps the file bit-identical to the in-memory map, so
//! the CPU reference computed from disk equals the one computed in memory. The price is twice
//! the size, partly recovered by lossless ZIP; a renderer may still convert to f16 on upload.
//!
//! # Receiver blocks (version 3)
//! A map of receiver level `r > 0` ([`TransferMap::receiver_level`]) stores one value per
//! `2^r × 2^r` block of receivers: its display window is the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of
//! blocks, its data windows lie in that grid, and `ortmMeta` ends with `ortmLevel`,
//! `ortmReceiverLevel` (`1..=ortmLevel`) and `ortmLightmapSize` (`W,H`, the lightmap). Such a
//! file has `ortmVersion` 3, so builds that know only versions 1 and 2 refuse it instead of
//! applying its values per texel; its content hash starts with the tag `"ortm-transfer-map-v3\0"`
//! and adds the level, the receiver level and the lightmap size. Maps with `r = 0` are written
//! exactly as before (versions 1 and 2).
//!
//! # Integrity
//! `ortmContentSha256` hashes a canonical byte string of the whole map (tag
//! `"ortm-transfer-map-v1\0"`, map index, bake key, lightmap size, offset, area and importance
//! bits, the rectangles and all values, little-endian). Decoding recomputes it, so any corruption of pixel
//! data or metadata is detected even when the decompressor does not notice it. The index also
//! stores the SHA-256 of the whole file.
//!
//! # Robustness
//! Files are written atomically ([`crate::io::write_atomic`]). The reader first parses and
//! validates the headers (magic number, display window ≤ [`MAX_TEXELS`](crate::maps::MAX_TEXELS),
//! parts, channels, data windows inside the display window) before it decodes (allocates) any
//! pixels; truncated or corrupt files give [`FileError::Exr`] or [`MapsError::BadMapFile`],
//! never a panic.

use std::io::Cursor;
use std::path::{Path, PathBuf};

use exr::image::{AnyChannels, FlatSamples, Layer};
use exr::math::Vec2;
use exr::meta::BlockDescription;
use exr::meta::MetaData;
use exr::meta::attribute::{IntegerBounds, SampleType};
use exr::meta::header::{Header, LayerAttributes};
use glam::IVec2;
use sha2::{Digest, Sha256};

use super::key::{BakeKey, map_file_name};
use crate::io::exr::{
    A_META, Meta, ZIP_SCAN_LINES, check_compression, decode_layers, encode_layers, has_magic,
    meta_attribute, parse_meta, rgb_channels, rgb_values, text,
};
use crate::io::{DirKind, FileError};
use crate::maps::transfer_map::check_size;
use crate::maps::{Crop, CropRect, MapsError, TransferMap};

/// Value of the `ortmFormat` attribute.
const FILE_FORMAT: &str = "ortm-transfer-map";
/// Value of the `ortmVersion` attribute of a level-0 map (the paper's maps).
const FILE_VERSION: i32 = 1;
/// Value of the `ortmVersion` attribute of a multi-resolution map of level > 0 (it adds
/// `ortmLevel`; older builds refuse it instead of applying it as a level-0 map).
const FILE_VERSION_LEVELS: i32 = 2;
/// Value of the `ortmVersion` attribute of a map with receiver level > 0 (it adds
/// `ortmReceiverLevel` and `ortmLightmapSize`; older builds refuse it).
const FILE_VERSION_RECEIVERS: i32 = 3;
/// Name of the placeholder part of an empty map.
const EMPTY_PART: &str = "ortm-empty";

const A_FORMAT: &str = "ortmFormat";
const A_VERSION: &str = "ortmVersion";
const A_INDEX: &str = "ortmMapIndex";
const A_OFFSET: &str = "ortmOffset";
const A_AREA: &str = "ortmVoronoiArea";
const A_IMPORTANCE: &str = "ortmImportance";
const A_RECTS: &str = "ortmRectCount";
const A_KEY: &str = "ortmBakeKey";
const A_HASH: &str = "ortmContentSha256";
const A_LEVEL: &str = "ortmLevel";
const A_RECEIVER_LEVEL: &str = "ortmReceiverLevel";
const A_LIGHTMAP: &str = "ortmLightmapSize";

/// A decoded transfer-map file.
#[derive(Clone, Debug, PartialEq)]
pub struct MapFile {
    /// The map's index in the bake (from `ortmMapIndex`).
    pub index: u32,
    /// The bake key the file was stamped with (from `ortmBakeKey`).
    pub bake_key: String,
    /// The map itself.
    pub map: TransferMap,
}

/// SHA-256 of the canonical content of map `index` (see the module doc).
pub(crate) fn content_hash(index: u32, bake_key: &str, map: &TransferMap) -> String {
    let mut h = Sha256::new();
    if map.receiver_level() > 0 {
        h.update(b"ortm-transfer-map-v3\0");
        h.update(map.level().to_le_bytes());
        h.update(map.receiver_level().to_le_bytes());
        let (w, hh) = map.lightmap_size();
        h.update(w.to_le_bytes());
        h.update(hh.to_le_bytes());
    } else if map.level() == 0 {
        h.update(b"ortm-transfer-map-v1\0");
    } else {
        h.update(b"ortm-transfer-map-v2\0");
        h.update(map.level().to_le_bytes());
    }
    h.update(index.to_le_bytes());
    h.update((bake_key.len() as u64).to_le_bytes());
    h.update(bake_key.as_bytes());
    h.update(map.width().to_le_bytes());
    h.update(map.height().to_le_bytes());
    h.update(map.offset.x.to_le_bytes());
    h.update(map.offset.y.to_le_bytes());
    h.update(map.voronoi_area.to_bits().to_le_bytes());
    h.update(map.importance.to_bits().to_le_bytes());
    h.update((map.crops().len() as u64).to_le_bytes());
    let mut buf = Vec::new();
    for c in map.crops() {
        for v in [c.rect.x, c.rect.y, c.rect.w, c.rect.h] {
            h.update(v.to_le_bytes());
        }
        buf.clear();
        buf.extend(
            c.data
                .iter()
                .flat_map(|t| t.iter().flat_map(|x| x.to_le_bytes())),
        );
        h.update(&buf);
    }
    crate::io::hex(&h.finalize())
}

/// The `ortmMeta` fields of map `index` (module doc), in their fixed order.
fn map_fields(index: u32, map: &TransferMap, key: &BakeKey) -> Vec<(&'static str, String)> {
    let version = if map.receiver_level() > 0 {
        FILE_VERSION_RECEIVERS
    } else if map.level() > 0 {
        FILE_VERSION_LEVELS
    } else {
        FILE_VERSION
    };
    let mut fields = vec![
        (A_FORMAT, FILE_FORMAT.to_owned()),
        (A_VERSION, version.to_string()),
        (A_INDEX, index.to_string()),
        (A_OFFSET, format!("{},{}", map.offset.x, map.offset.y)),
        (A_AREA, format!("0x{:016x}", map.voronoi_area.to_bits())),
        (A_IMPORTANCE, format!("0x{:016x}", map.importance.to_bits())),
        (A_RECTS, map.crops().len().to_string()),
        (A_KEY, key.as_str().to_owned()),
        (A_HASH, content_hash(index, key.as_str(), map)),
    ];
    if map.level() > 0 {
        fields.push((A_LEVEL, map.level().to_string()));
    }
    if map.receiver_level() > 0 {
        let (w, h) = map.lightmap_size();
        fields.push((A_RECEIVER_LEVEL, map.receiver_level().to_string()));
        fields.push((A_LIGHTMAP, format!("{w},{h}")));
    }
    fields
}

/// Encodes map `index` as an OpenEXR file in memory (layout in the module doc).
///
/// # Errors
/// [`FileError::Exr`] if the encoder fails (not expected for a valid map).
pub fn encode_map(index: u32, map: &TransferMap, key: &BakeKey) -> Result<Vec<u8>, MapsError> {
    encode_with_fields(index, map, &map_fields(index, map, key))
}

/// [`encode_map`] with the given `ortmMeta` fields.
fn encode_with_fields(
    index: u32,
    map: &TransferMap,
    fields: &[(&str, String)],
) -> Result<Vec<u8>, MapsError> {
    let mut layers: Vec<Layer<AnyChannels<FlatSamples>>> = if map.crops().is_empty() {
        vec![Layer::new(
            Vec2(1, 1),
            LayerAttributes::named(EMPTY_PART),
            ZIP_SCAN_LINES,
            rgb_channels(&[[0.0; 3]]),
        )]
    } else {
        map.crops()
            .iter()
            .enumerate()
            .map(|(i, c)| {
                let attrs = LayerAttributes::named(text(&format!("rect{i}")))
                    .with_position(Vec2(c.rect.x as i32, c.rect.y as i32));
                Layer::new(
                    Vec2(c.rect.w as usize, c.rect.h as usize),
                    attrs,
                    ZIP_SCAN_LINES,
                    rgb_channels(&c.data),
                )
            })
            .collect()
    };
    let meta = meta_attribute(fields);
    layers[0].attributes.other.insert(text(A_META), meta);
    encode_layers((map.width(), map.height()), layers).map_err(|source| {
        MapsError::from(FileError::Exr {
            op: "encode",
            path: PathBuf::from(map_file_name(index, map.offset)),
            source,
            kind: DirKind::Bake,
        })
    })
}

/// Reads and fully validates one map file. If `expected_size` is given, the lightmap size
/// stored in the file must equal it.
///
/// # Errors
/// [`FileError::Io`], and those of [`decode_map`].
pub fn read_map_file(path: &Path, expected_size: Option<(u32, u32)>) -> Result<MapFile, MapsError> {
    let bytes = crate::io::read_bounded(path, crate::io::limits::MAX_EXR_BYTES, "MAX_EXR_BYTES")
        .map_err(FileError::io("cannot read", path, DirKind::Bake))?;
    decode_map(path, &bytes, expected_size)
}

/// The `ortmMeta` fields of a map file's first part, parsed.
struct MapHeader {
    index: u32,
    level: u32,
    /// Receiver level and lightmap size (`ortmReceiverLevel`, `ortmLightmapSize`): `(0, None)`
    /// in versions 1 and 2.
    receiver_level: u32,
    lightmap: Option<(u32, u32)>,
    offset: IVec2,
    area: f64,
    importance: f64,
    rect_count: usize,
    bake_key: String,
    stored_hash: String,
}

/// Decodes and validates a map file held in memory; `path` is only used in error messages.
///
/// Checks: OpenEXR magic number; headers parse (pedantic); display window at the origin, non-
/// empty, ≤ [`MAX_TEXELS`](crate::maps::MAX_TEXELS), the same in every part and equal to
/// `expected_size` if given; scan-line, non-deep parts named `rect0, rect1, …` (or the single
/// `ortm-empty` placeholder) with exactly `B, G, R` f32 channels; data windows inside the display
/// window and disjoint; all `ortm*` attributes present with the right types; finite values; and
/// finally the content hash. Every header is checked before any pixel is decoded.
///
/// # Errors
/// [`MapsError::NotExr`], [`FileError::Exr`] (decoder failure: truncated/corrupt),
/// [`MapsError::BadMapFile`] (anything else listed above), [`MapsError::SizeMismatch`].
pub fn decode_map(
    path: &Path,
    bytes: &[u8],
    expected_size: Option<(u32, u32)>,
) -> Result<MapFile, MapsError> {
    if !has_magic(bytes) {
        return Err(MapsError::NotExr {
            path: path.to_owned(),
        });
    }
    let bad = |reason: String| MapsError::BadMapFile {
        path: path.to_owned(),
        reason,
    };
    let (header, (width, height)) = check_headers(path, bytes, expected_size)?;
    // The placeholder part of an empty map is decoded too: a corrupt one is refused.
    let image = decode_layers(bytes).map_err(exr_error(path))?;
    let crops = if header.rect_count > 0 {
        decode_crops(&image.layer_data).map_err(&bad)?
    } else {
        Vec::new()
    };
    let map = TransferMap::from_crops(
        &path.display().to_string(),
        header.offset,
        header.area,
        header.importance,
        width,
        height,
        crops,
    )
    .and_then(|m| m.with_level(header.level))
    .and_then(|m| m.with_receiver_level(header.receiver_level))
    .map_err(|e| bad(e.to_string()))?;
    let hash = content_hash(header.index, &header.bake_key, &map);
    if hash != header.stored_hash {
        return Err(bad(format!(
            "content SHA-256 is {hash} but {A_HASH} says {} (data or metadata corrupted)",
            header.stored_hash
        )));
    }
    Ok(MapFile {
        index: header.index,
        bake_key: header.bake_key,
        map,
    })
}

/// The decoder's error on `path`, as [`FileError::Exr`].
fn exr_error(path: &Path) -> impl Fn(exr::error::Error) -> MapsError + '_ {
    move |source| {
        MapsError::from(FileError::Exr {
            op: "decode",
            path: path.to_owned(),
            source,
            kind: DirKind::Bake,
        })
    }
}

/// Phase 1 of [`decode_map`]: parses and validates every header (display window, metadata,
/// parts, declared pixels against the file size) without allocating pixels. Returns the
/// metadata and the lightmap size.
fn check_headers(
    path: &Path,
    bytes: &[u8],
    expected_size: Option<(u32, u32)>,
) -> Result<(MapHeader, (u32, u32)), MapsError> {
    let bad = |reason: String| MapsError::BadMapFile {
        path: path.to_owned(),
        reason,
    };
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), true).map_err(exr_error(path))?;
    MetaData::validate(&meta.headers, true).map_err(exr_error(path))?;
    let headers = &meta.headers;
    let first = headers
        .first()
        .ok_or_else(|| bad("the file has no parts".into()))?;
    let display = first.shared_attributes.display_window;
    let (width, height) = (
        u32::try_from(display.size.0).unwrap_or(u32::MAX),
        u32::try_from(display.size.1).unwrap_or(u32::MAX),
    );
    if display.position != Vec2(0, 0) {
        return Err(bad(format!(
            "display window starts at {:?}, expected (0, 0)",
            display.position
        )));
    }
    check_size(&path.display().to_string(), width, height)?;
    let header =
        parse_map_header(&parse_meta(&first.own_attributes.other).map_err(&bad)?).map_err(&bad)?;
    // The lightmap: the display window, or for receiver blocks `ortmLightmapSize`, whose
    // level-r grid the display window must be.
    let (width, height) = match header.lightmap {
        None => (width, height),
        Some((lw, lh)) => {
            check_size(&format!("{} ({A_LIGHTMAP})", path.display()), lw, lh)?;
            let grid = crate::maps::receiver_grid((lw, lh), header.receiver_level);
            if grid != (width, height) {
                return Err(bad(format!(
                    "the display window is {width}×{height} but {A_LIGHTMAP} = {lw},{lh} at                      {A_RECEIVER_LEVEL} = {} has a {}×{} grid of receiver blocks",
                    header.receiver_level, grid.0, grid.1
                )));
            }
            (lw, lh)
        }
    };
    if let Some((ew, eh)) = expected_size
        && (ew, eh) != (width, height)
    {
        return Err(MapsError::SizeMismatch {
            what: format!(
                "lightmap size of {}{}",
                path.display(),
                if header.lightmap.is_some() {
                    format!(" ({A_LIGHTMAP})")
                } else {
                    String::new()
                }
            ),
            expected: (ew, eh),
            found: (width, height),
        });
    }
    let rect_count = header.rect_count;
    if headers.len() != rect_count.max(1) {
        return Err(bad(format!(
            "{} parts but {A_RECTS} = {rect_count}",
            headers.len()
        )));
    }
    for (i, h) in headers.iter().enumerate() {
        check_header(h, i, rect_count, display).map_err(&bad)?;
    }
    // Declared pixels against the file size, before any pixel is allocated.
    let declared: u64 = headers.iter().map(|h| h.layer_size.area() as u64).sum();
    crate::io::limits::check_exr_pixels(
        &format!("{} (sum of the parts' data windows)", path.display()),
        declared,
        bytes.len() as u64,
    )
    .map_err(|e| bad(e.to_string()))?;
    Ok((header, (width, height)))
}

/// Reads the `ortmMeta` fields: format and version first, then every field of [`MapHeader`].
fn parse_map_header(attrs: &Meta) -> Result<MapHeader, String> {
    let format = get_text(attrs, A_FORMAT)?;
    if format != FILE_FORMAT {
        return Err(format!(
            "{A_FORMAT} is {format:?}, expected {FILE_FORMAT:?}"
        ));
    }
    let version = get_i32(attrs, A_VERSION)?;
    let get_level = || {
        u32::try_from(get_i32(attrs, A_LEVEL)?)
            .ok()
            .filter(|l| (1..=crate::maps::MAX_MAP_LEVEL).contains(l))
            .ok_or_else(|| {
                format!(
                    "{A_LEVEL} must be 1..={} in a version-{version} map",
                    crate::maps::MAX_MAP_LEVEL
                )
            })
    };
    let (level, receiver_level, lightmap) = match version {
        FILE_VERSION => (0, 0, None),
        FILE_VERSION_LEVELS => (get_level()?, 0, None),
        FILE_VERSION_RECEIVERS => {
            let level = get_level()?;
            let r = u32::try_from(get_i32(attrs, A_RECEIVER_LEVEL)?)
                .ok()
                .filter(|r| (1..=level).contains(r))
                .ok_or_else(|| {
                    format!(
                        "{A_RECEIVER_LEVEL} must be 1..={level} ({A_LEVEL}) in a \
                         version-{FILE_VERSION_RECEIVERS} map"
                    )
                })?;
            let size = get_text(attrs, A_LIGHTMAP)?;
            let lightmap = size
                .split_once(',')
                .and_then(|(w, h)| Some((w.parse().ok()?, h.parse().ok()?)))
                .ok_or_else(|| {
                    format!("field {A_LIGHTMAP} of {A_META} is {size:?}, expected width,height")
                })?;
            (level, r, Some(lightmap))
        }
        _ => {
            return Err(format!(
                "file version {version} is not supported, this build reads versions \
                 {FILE_VERSION}, {FILE_VERSION_LEVELS} and {FILE_VERSION_RECEIVERS}; re-bake \
                 with this build"
            ));
        }
    };
    Ok(MapHeader {
        index: u32::try_from(get_i32(attrs, A_INDEX)?)
            .map_err(|_| format!("{A_INDEX} is negative"))?,
        level,
        receiver_level,
        lightmap,
        offset: get_offset(attrs, A_OFFSET)?,
        area: get_f64(attrs, A_AREA)?,
        importance: get_f64(attrs, A_IMPORTANCE)?,
        rect_count: usize::try_from(get_i32(attrs, A_RECTS)?)
            .map_err(|_| format!("{A_RECTS} is negative"))?,
        bake_key: get_text(attrs, A_KEY)?,
        stored_hash: get_text(attrs, A_HASH)?,
    })
}

/// Phase 2 of [`decode_map`]: one crop per decoded part, at the part's data window.
fn decode_crops(layers: &[Layer<AnyChannels<FlatSamples>>]) -> Result<Vec<Crop>, String> {
    layers
        .iter()
        .enumerate()
        .map(|(i, layer)| {
            let (w, h) = (layer.size.0, layer.size.1);
            let pos = layer.attributes.layer_position;
            let data = rgb_values(layer, w * h)
                .ok_or_else(|| format!("part {i}: channel data is not {w}×{h} f32 samples"))?;
            Ok(Crop {
                rect: CropRect {
                    x: pos.0 as u32,
                    y: pos.1 as u32,
                    w: w as u32,
                    h: h as u32,
                },
                data,
            })
        })
        .collect()
}

/// Validates part `i`'s header against the layout (name, channels, blocks, data window).
fn check_header(
    h: &Header,
    i: usize,
    rect_count: usize,
    display: IntegerBounds,
) -> Result<(), String> {
    let name = h
        .own_attributes
        .layer_name
        .as_ref()
        .map(ToString::to_string);
    let want = if rect_count == 0 {
        EMPTY_PART.to_owned()
    } else {
        format!("rect{i}")
    };
    if name.as_deref() != Some(want.as_str()) {
        return Err(format!("part {i} is named {name:?}, expected {want:?}"));
    }
    if h.deep || !matches!(h.blocks, BlockDescription::ScanLines) {
        return Err(format!("part {i} is not a flat scan-line image"));
    }
    check_compression(h.compression).map_err(|e| format!("part {i}: {e}"))?;
    if h.shared_attributes.display_window != display {
        return Err(format!("part {i} has a different display window"));
    }
    let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    if names != ["B", "G", "R"] {
        return Err(format!(
            "part {i} has channels {names:?}, expected [\"B\", \"G\", \"R\"]"
        ));
    }
    for c in &h.channels.list {
        if c.sample_type != SampleType::F32 || c.sampling != Vec2(1, 1) {
            return Err(format!(
                "part {i} channel {} is {:?} with sampling {:?}, expected F32 without subsampling",
                c.name, c.sample_type, c.sampling
            ));
        }
    }
    let pos = h.own_attributes.layer_position;
    let size = h.layer_size;
    let fits = pos.0 >= 0
        && pos.1 >= 0
        && size.0 >= 1
        && size.1 >= 1
        && pos.0 as u64 + size.0 as u64 <= display.size.0 as u64
        && pos.1 as u64 + size.1 as u64 <= display.size.1 as u64;
    if !fits {
        return Err(format!(
            "part {i} data window at {pos:?} size {size:?} is outside the {}×{} lightmap",
            display.size.0, display.size.1
        ));
    }
    Ok(())
}

fn get_text(meta: &Meta, name: &str) -> Result<String, String> {
    meta.get(name)
        .cloned()
        .ok_or_else(|| format!("field {name} of {A_META} is missing"))
}

fn get_i32(meta: &Meta, name: &str) -> Result<i32, String> {
    get_text(meta, name)?
        .parse()
        .map_err(|_| format!("field {name} of {A_META} is not an integer"))
}

fn get_f64(meta: &Meta, name: &str) -> Result<f64, String> {
    let v = get_text(meta, name)?;
    v.strip_prefix("0x")
        .and_then(|h| u64::from_str_radix(h, 16).ok())
        .map(f64::from_bits)
        .ok_or_else(|| format!("field {name} of {A_META} is not a 0x-prefixed f64 bit pattern"))
}

fn get_offset(meta: &Meta, name: &str) -> Result<IVec2, String> {
    let v = get_text(meta, name)?;
    let (x, y) = v
        .split_once(',')
        .ok_or_else(|| format!("field {name} of {A_META} is not dx,dy"))?;
    match (x.parse(), y.parse()) {
        (Ok(x), Ok(y)) => Ok(IVec2::new(x, y)),
        _ => Err(format!("field {name} of {A_META} is not dx,dy")),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Lightmap;
    use crate::bake_dir::write_map_file;
    use crate::io::sha256_hex;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;
    use std::fs;

    fn key() -> BakeKey {
        BakeKey::new("scene-abc", &serde_json::json!({"maps": 3}))
    }

    fn sample_map(seed: u64) -> TransferMap {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let (w, h) = (40, 24);
        let mut full = Lightmap::new(w, h);
        // Two blobs far apart, so the map has two crops.
        for (x0, y0) in [(2, 3), (30, 15)] {
            for y in y0..y0 + 5 {
                for x in x0..x0 + 6 {
                    full.set(
                        x,
                        y,
                        [rng.random(), rng.random_range(1e-7..1e-5), rng.random()],
                    );
                }
            }
        }
        TransferMap::from_full(IVec2::new(-5, 7), 0.0123, 4.5, &full).unwrap()
    }

    #[test]
    fn round_trip_is_bit_exact() {
        let map = sample_map(1);
        assert_eq!(map.crops().len(), 2);
        let bytes = encode_map(17, &map, &key()).unwrap();
        let f = decode_map(Path::new("mem.exr"), &bytes, Some((40, 24))).unwrap();
        assert_eq!(f.index, 17);
        assert_eq!(f.bake_key, key().as_str());
        assert_eq!(f.map.offset, map.offset);
        assert_eq!(f.map.voronoi_area.to_bits(), map.voronoi_area.to_bits());
        assert_eq!(f.map.importance.to_bits(), map.importance.to_bits());
        assert_eq!(f.map.rects(), map.rects());
        for (a, b) in f.map.crops().iter().zip(map.crops()) {
            let bits = |c: &Crop| -> Vec<[u32; 3]> {
                c.data.iter().map(|v| v.map(f32::to_bits)).collect()
            };
            assert_eq!(bits(a), bits(b));
        }
        // The file is a genuine multi-part file: the exr crate's metadata sees one part per
        // rect with data windows at the rect positions.
        let meta = MetaData::read_from_buffered(Cursor::new(&bytes), true).unwrap();
        let windows: Vec<_> = meta
            .headers
            .iter()
            .map(|h| (h.own_attributes.layer_position, h.layer_size))
            .collect();
        let rects = map.rects();
        assert_eq!(
            windows,
            rects
                .iter()
                .map(|r| (
                    Vec2(r.x as i32, r.y as i32),
                    Vec2(r.w as usize, r.h as usize)
                ))
                .collect::<Vec<_>>()
        );
        // Stored pixels: only the crops, not the bounding box.
        let stored: usize = meta.headers.iter().map(|h| h.layer_size.area()).sum();
        assert_eq!(stored as u64, map.stored_texels());
        assert!(map.stored_texels() < 29 * 18);
    }

    #[test]
    fn empty_map_round_trips() {
        let map = TransferMap::from_full(IVec2::new(1, 0), 0.5, 0.0, &Lightmap::new(8, 8)).unwrap();
        let bytes = encode_map(0, &map, &key()).unwrap();
        let f = decode_map(Path::new("e.exr"), &bytes, None).unwrap();
        assert!(f.map.crops().is_empty());
        assert_eq!((f.map.width(), f.map.height()), (8, 8));
    }

    #[test]
    fn size_mismatch_is_reported() {
        let bytes = encode_map(0, &sample_map(2), &key()).unwrap();
        let e = decode_map(Path::new("m.exr"), &bytes, Some((41, 24))).unwrap_err();
        assert!(matches!(e, MapsError::SizeMismatch { .. }), "{e}");
    }

    #[test]
    fn not_exr_truncated_and_corrupt_files_are_errors() {
        let bytes = encode_map(3, &sample_map(3), &key()).unwrap();
        let p = Path::new("m.exr");
        assert!(matches!(
            decode_map(p, b"P6\n1 1\n255\n...", None),
            Err(MapsError::NotExr { .. })
        ));
        assert!(matches!(
            decode_map(p, &[], None),
            Err(MapsError::NotExr { .. })
        ));
        // Every truncation must fail (header truncations and pixel truncations alike).
        let step = (bytes.len() / 97).max(1);
        for len in (4..bytes.len()).step_by(step).chain([bytes.len() - 1]) {
            let e = decode_map(p, &bytes[..len], None);
            assert!(
                e.is_err(),
                "truncated to {len} of {} bytes decoded",
                bytes.len()
            );
        }
        // Every single-byte flip must fail or decode to exactly the original map; a flip in a
        // byte that carries content must never be accepted silently.
        let original = decode_map(p, &bytes, None).unwrap();
        let mut accepted = 0;
        for i in (4..bytes.len()).step_by(3) {
            let mut b = bytes.clone();
            b[i] ^= 0x5a;
            if let Ok(f) = decode_map(p, &b, None) {
                assert_eq!(f, original, "flip at byte {i} changed the map silently");
                accepted += 1;
            }
        }
        // Only header fields this format does not use (screen window, pixel aspect, ...) may
        // be ignorable; most flips must be detected (≈8 % are ignorable for this file).
        assert!(accepted * 4 < bytes.len() / 3, "{accepted} flips accepted");
    }

    #[test]
    fn write_is_atomic_and_named_deterministically() {
        let dir = tempfile::tempdir().unwrap();
        let map = sample_map(4);
        let e = write_map_file(dir.path(), 5, &map, &key()).unwrap();
        assert_eq!(e.file, "map_00005_-5_+7.exr");
        let bytes = fs::read(dir.path().join(&e.file)).unwrap();
        assert_eq!(e.bytes, bytes.len() as u64);
        assert_eq!(e.sha256, sha256_hex(&bytes));
        // Only the final file remains (no temporary files).
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|d| d.unwrap().file_name().into_string().unwrap())
            .collect();
        assert_eq!(names, vec![e.file.clone()]);
        let f = read_map_file(&dir.path().join(&e.file), Some((40, 24))).unwrap();
        assert_eq!(f.map, map);
        // Writing into a path whose parent is a file fails cleanly.
        let blocker = dir.path().join("blocker");
        fs::write(&blocker, b"x").unwrap();
        assert!(matches!(
            write_map_file(&blocker, 0, &map, &key()),
            Err(MapsError::File(FileError::Io { .. }))
        ));
    }

    /// A level-2 map with receiver level 1 over a 40×24 lightmap (grid 20×12).
    fn block_map(seed: u64) -> TransferMap {
        let mut rng = ChaCha8Rng::seed_from_u64(seed);
        let mut grid = Lightmap::new(20, 12);
        for y in 2..7 {
            for x in 13..20 {
                grid.set(x, y, [rng.random(), rng.random(), rng.random()]);
            }
        }
        let cropped = TransferMap::from_full(IVec2::new(-1, 2), 0.0, 0.0, &grid).unwrap();
        TransferMap::from_crops(
            "t",
            IVec2::new(-1, 2),
            0.0,
            0.0,
            40,
            24,
            cropped.crops().to_vec(),
        )
        .unwrap()
        .with_level(2)
        .unwrap()
        .with_receiver_level(1)
        .unwrap()
    }

    #[test]
    fn receiver_block_map_round_trips_as_version_3() {
        let map = block_map(5);
        assert_eq!((map.width(), map.height()), (20, 12));
        assert_eq!(map.lightmap_size(), (40, 24));
        let bytes = encode_map(4, &map, &key()).unwrap();
        let f = decode_map(Path::new("b.exr"), &bytes, Some((40, 24))).unwrap();
        assert_eq!(f.map, map);
        assert_eq!(f.map.receiver_level(), 1);
        let f = decode_map(Path::new("b.exr"), &bytes, None).unwrap();
        assert_eq!(f.map.lightmap_size(), (40, 24));
        // The display window is the receiver grid; the lightmap size is checked against it.
        let meta = MetaData::read_from_buffered(Cursor::new(&bytes), true).unwrap();
        assert_eq!(
            meta.headers[0].shared_attributes.display_window.size,
            Vec2(20, 12)
        );
        let e = decode_map(Path::new("b.exr"), &bytes, Some((20, 12))).unwrap_err();
        assert!(matches!(e, MapsError::SizeMismatch { .. }), "{e}");
        assert!(e.to_string().contains("ortmLightmapSize"), "{e}");
        // Receiver level 0 keeps versions 1 and 2, byte for byte: no new field.
        let plain = encode_map(4, &sample_map(1), &key()).unwrap();
        let text = String::from_utf8_lossy(&plain);
        assert!(text.contains("ortmVersion=1\n") && !text.contains(A_RECEIVER_LEVEL));
        assert!(String::from_utf8_lossy(&bytes).contains("ortmVersion=3\n"));
    }

    #[test]
    fn version_3_files_with_wrong_fields_are_refused() {
        let map = block_map(6);
        let fields = map_fields(9, &map, &key());
        let with = |name: &str, value: Option<&str>| {
            let f: Vec<(&str, String)> = fields
                .iter()
                .filter(|(k, _)| *k != name || value.is_some())
                .map(|(k, v)| {
                    if *k == name {
                        (*k, value.unwrap().to_owned())
                    } else {
                        (*k, v.clone())
                    }
                })
                .collect();
            let bytes = encode_with_fields(9, &map, &f).unwrap();
            decode_map(Path::new("w.exr"), &bytes, Some((40, 24)))
                .unwrap_err()
                .to_string()
        };
        for (name, value, says) in [
            (
                A_RECEIVER_LEVEL,
                Some("3"),
                "ortmReceiverLevel must be 1..=2",
            ),
            (
                A_RECEIVER_LEVEL,
                Some("0"),
                "ortmReceiverLevel must be 1..=2",
            ),
            (
                A_RECEIVER_LEVEL,
                None,
                "ortmReceiverLevel of ortmMeta is missing",
            ),
            (A_LEVEL, None, "ortmLevel"),
            (A_LIGHTMAP, Some("38,24"), "ortmLightmapSize = 38,24"),
            (A_LIGHTMAP, Some("40"), "ortmLightmapSize"),
            (A_LIGHTMAP, None, "ortmLightmapSize of ortmMeta is missing"),
            (A_VERSION, Some("2"), "size mismatch"),
            (A_VERSION, Some("4"), "file version 4 is not supported"),
        ] {
            let e = with(name, value);
            assert!(e.contains(says), "{name}={value:?}: {e}");
        }
    }
}
