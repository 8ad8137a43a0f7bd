//! The atlas file codec: one single-part OpenEXR image per atlas, channels `B, G, R` f32 with
//! ZIP compression, stamped (in `ortmMeta`) with its atlas number and the bake key. Layout in
//! `docs/atlas-format.md`; the pieces shared with map files are in [`crate::io::exr`].

use std::io::Cursor;
use std::path::Path;

use exr::math::Vec2;
use exr::meta::attribute::SampleType;
use exr::meta::header::{Header, LayerAttributes};
use exr::meta::{BlockDescription, MetaData};

use super::AtlasError;
use crate::io::exr::{
    A_META, Meta, ZIP_SCAN_LINES, check_compression, decode_layers, encode_layers, has_magic,
    meta_attribute, parse_meta, rgb_channels, rgb_values, text,
};
use crate::io::{DirKind, FileError};

/// Value of the `ortmFormat` attribute of an atlas OpenEXR file.
const ATLAS_FILE_FORMAT: &str = "ortm-atlas";

const A_FORMAT: &str = "ortmFormat";
const A_ATLAS: &str = "ortmAtlasIndex";
const A_KEY: &str = "ortmBakeKey";

/// File name of atlas `i`: `atlas_000.exr`, `atlas_001.exr`, … (at least three digits).
pub fn atlas_file_name(i: u32) -> String {
    format!("atlas_{i:03}.exr")
}

/// The codec's error on `path`, as [`FileError::Exr`].
fn exr_error<'a>(
    op: &'static str,
    path: &'a Path,
) -> impl Fn(exr::error::Error) -> AtlasError + 'a {
    move |source| {
        AtlasError::from(FileError::Exr {
            op,
            path: path.to_owned(),
            source,
            kind: DirKind::Atlas,
        })
    }
}

/// Encodes atlas `index` as a single-part OpenEXR file (channels `B, G, R` f32, ZIP).
pub(super) fn encode_atlas(
    path: &Path,
    index: u32,
    size: (u32, u32),
    data: &[[f32; 3]],
    bake_key: &str,
) -> Result<Vec<u8>, AtlasError> {
    let mut layer = exr::image::Layer::new(
        Vec2(size.0 as usize, size.1 as usize),
        LayerAttributes::named("atlas"),
        ZIP_SCAN_LINES,
        rgb_channels(data),
    );
    let meta = meta_attribute(&[
        (A_FORMAT, ATLAS_FILE_FORMAT.to_owned()),
        (A_ATLAS, index.to_string()),
        (A_KEY, bake_key.to_owned()),
    ]);
    layer.attributes.other.insert(text(A_META), meta);
    encode_layers(size, vec![layer]).map_err(exr_error("encode", path))
}

/// Decodes and checks atlas file `index`: magic number, one part whose header fits the index
/// ([`check_part`], [`check_stamp`]) before any pixel is allocated, then the pixels (finite).
pub(super) fn decode_atlas(
    path: &Path,
    bytes: &[u8],
    index: u32,
    size: (u32, u32),
    bake_key: &str,
) -> Result<Vec<[f32; 3]>, AtlasError> {
    let bad = |reason: String| AtlasError::BadAtlasFile {
        path: path.to_owned(),
        reason,
    };
    if !has_magic(bytes) {
        return Err(bad("not an OpenEXR file (wrong magic number)".into()));
    }
    // Headers first, before any pixel allocation.
    let meta = MetaData::read_from_buffered(Cursor::new(bytes), true)
        .map_err(exr_error("decode", path))?;
    MetaData::validate(&meta.headers, true).map_err(exr_error("decode", path))?;
    let [h] = meta.headers.as_slice() else {
        return Err(bad(format!(
            "{} parts, expected exactly one",
            meta.headers.len()
        )));
    };
    check_part(path, h, size, bytes.len() as u64).map_err(&bad)?;
    let fields = parse_meta(&h.own_attributes.other).map_err(&bad)?;
    check_stamp(&fields, index, bake_key).map_err(&bad)?;
    let image = decode_layers(bytes).map_err(exr_error("decode", path))?;
    let n = size.0 as usize * size.1 as usize;
    let layer = image
        .layer_data
        .first()
        .ok_or_else(|| bad("no image data".into()))?;
    let data =
        rgb_values(layer, n).ok_or_else(|| bad(format!("channels are not {n} f32 samples")))?;
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

/// The part is a flat scan-line `size` image at the origin, compressed in a way
/// [`crate::io::limits::check_exr_pixels`] bounds for a `file_bytes`-byte file, with exactly the
/// channels `B, G, R` as f32 without subsampling.
fn check_part(path: &Path, h: &Header, size: (u32, u32), file_bytes: u64) -> Result<(), String> {
    let want = Vec2(size.0 as usize, size.1 as usize);
    let display = h.shared_attributes.display_window;
    if display.position != Vec2(0, 0)
        || display.size != want
        || h.layer_size != want
        || h.own_attributes.layer_position != Vec2(0, 0)
    {
        return Err(format!(
            "image is {:?} at {:?}, expected {}×{} at (0, 0) (the index's atlas size)",
            h.layer_size, h.own_attributes.layer_position, size.0, size.1
        ));
    }
    if h.deep || !matches!(h.blocks, BlockDescription::ScanLines) {
        return Err("not a flat scan-line image".into());
    }
    check_compression(h.compression)?;
    crate::io::limits::check_exr_pixels(
        &path.display().to_string(),
        u64::from(size.0) * u64::from(size.1),
        file_bytes,
    )
    .map_err(|e| e.to_string())?;
    let names: Vec<String> = h.channels.list.iter().map(|c| c.name.to_string()).collect();
    if names != ["B", "G", "R"]
        || h.channels
            .list
            .iter()
            .any(|c| c.sample_type != SampleType::F32 || c.sampling != Vec2(1, 1))
    {
        return Err(format!(
            "channels {names:?} are not exactly B, G, R as 32-bit float without subsampling"
        ));
    }
    Ok(())
}

/// The `ortmMeta` fields name an ortm atlas, atlas number `index` and the bake key `bake_key`.
fn check_stamp(fields: &Meta, index: u32, bake_key: &str) -> Result<(), String> {
    let get_text = |name: &str| fields.get(name).cloned();
    if get_text(A_FORMAT).as_deref() != Some(ATLAS_FILE_FORMAT) {
        return Err(format!(
            "attribute {A_FORMAT} is not \"{ATLAS_FILE_FORMAT}\""
        ));
    }
    match get_text(A_ATLAS).and_then(|v| v.parse::<i64>().ok()) {
        Some(i) if i == i64::from(index) => {}
        other => {
            return Err(format!(
                "attribute {A_ATLAS} is {other:?}, expected {index} (files swapped?)"
            ));
        }
    }
    if get_text(A_KEY).as_deref() != Some(bake_key) {
        return Err(format!(
            "attribute {A_KEY} is {:?}, the index says {bake_key}",
            get_text(A_KEY)
        ));
    }
    Ok(())
}
