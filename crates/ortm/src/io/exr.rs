//! OpenEXR pieces shared by the transfer-map files (`crate::bake_dir`, `docs/bake-format.md`)
//! and the atlas files (`crate::atlas`, `docs/atlas-format.md`): RGB f32 channels stored as
//! `B, G, R` with ZIP compression, and all metadata in one text attribute `ortmMeta`.
//!
//! One attribute, because the `exr` crate writes custom attributes in hash-map order: with
//! several, two identical images would not be byte-identical files.

use std::collections::HashMap;
use std::io::Cursor;

use exr::image::read::read;
use exr::image::{AnyChannel, AnyChannels, Blocks, Encoding, FlatSamples, Image, Layer};
use exr::meta::attribute::{AttributeValue, IntegerBounds, Text};
use exr::meta::header::ImageAttributes;
use exr::prelude::traits::{ReadChannels, ReadLayers, WritableImage};
use exr::prelude::{Compression, LineOrder, SmallVec};

/// The first four bytes of every OpenEXR file.
const MAGIC: [u8; 4] = [0x76, 0x2f, 0x31, 0x01];

/// Whether `bytes` starts with the OpenEXR magic number.
pub fn has_magic(bytes: &[u8]) -> bool {
    bytes.len() >= 4 && bytes[..4] == MAGIC
}

/// The single custom attribute holding every metadata field as `name=value` lines.
pub const A_META: &str = "ortmMeta";

/// The metadata fields of the `ortmMeta` attribute.
pub type Meta = std::collections::BTreeMap<String, String>;

/// An image of flat RGB f32 layers as the `exr` crate decodes it.
pub type FlatImage = Image<exr::image::Layers<AnyChannels<FlatSamples>>>;

/// Text attribute value; the caller guarantees ASCII.
pub fn text(s: &str) -> Text {
    Text::from_slice_unchecked(s.as_bytes())
}

/// The encoding ortm writes: ZIP (16 scan lines per block, lossless), scan lines, increasing.
pub const ZIP_SCAN_LINES: Encoding = Encoding {
    compression: Compression::ZIP16,
    blocks: Blocks::ScanLines,
    line_order: LineOrder::Increasing,
};

/// Channels `B, G, R` (sorted, as OpenEXR requires) of f32 samples from RGB `data`.
pub fn rgb_channels(data: &[[f32; 3]]) -> AnyChannels<FlatSamples> {
    let chan = |c: usize| FlatSamples::F32(data.iter().map(|v| v[c]).collect());
    AnyChannels::sort(SmallVec::from_vec(vec![
        AnyChannel::new("R", chan(0)),
        AnyChannel::new("G", chan(1)),
        AnyChannel::new("B", chan(2)),
    ]))
}

/// Encodes `layers` with display window `(0,0)–(w−1,h−1)` into an OpenEXR file in memory
/// (single-threaded, so the bytes do not depend on scheduling).
///
/// # Errors
/// The encoder's error.
pub fn encode_layers(
    display: (u32, u32),
    layers: Vec<Layer<AnyChannels<FlatSamples>>>,
) -> exr::error::Result<Vec<u8>> {
    let display =
        IntegerBounds::from_dimensions(exr::math::Vec2(display.0 as usize, display.1 as usize));
    let image = Image::from_layers(ImageAttributes::new(display), layers);
    let mut bytes = Vec::new();
    image
        .write()
        .non_parallel()
        .to_buffered(Cursor::new(&mut bytes))?;
    Ok(bytes)
}

/// Decodes every layer's pixels (all channels, all attributes, pedantic, single-threaded).
/// Call it only after the headers were checked: it allocates what they declare.
///
/// # Errors
/// The decoder's error (truncated or corrupt file).
pub fn decode_layers(bytes: &[u8]) -> exr::error::Result<FlatImage> {
    read()
        .no_deep_data()
        .largest_resolution_level()
        .all_channels()
        .all_layers()
        .all_attributes()
        .pedantic()
        .non_parallel()
        .from_buffered(Cursor::new(bytes))
}

/// The RGB values of a decoded layer whose channels are `B, G, R` f32 with `n` samples each;
/// `None` when they are not.
pub fn rgb_values(layer: &Layer<AnyChannels<FlatSamples>>, n: usize) -> Option<Vec<[f32; 3]>> {
    let list = &layer.channel_data.list;
    let samples = |c: usize| match list.get(c).map(|ch| &ch.sample_data) {
        Some(FlatSamples::F32(v)) if v.len() == n => Some(v),
        _ => None,
    };
    let (b, g, r) = (samples(0)?, samples(1)?, samples(2)?);
    Some((0..n).map(|k| [r[k], g[k], b[k]]).collect())
}

/// Accepts the lossless compressions whose expansion is bounded by deflate's (`ZIP`, `ZIPS`,
/// `RLE`, none), so [`crate::io::limits::check_exr_pixels`] bounds the decoded size. ortm
/// writes ZIP.
///
/// # Errors
/// A sentence naming the compression.
pub fn check_compression(c: Compression) -> Result<(), String> {
    match c {
        Compression::Uncompressed | Compression::RLE | Compression::ZIP1 | Compression::ZIP16 => {
            Ok(())
        }
        other => Err(format!(
            "compression {other:?} is not supported (ortm reads ZIP, RLE or uncompressed files)"
        )),
    }
}

/// The `ortmMeta` attribute value: one `name=value` line per field, in the given order.
pub fn meta_attribute(fields: &[(&str, String)]) -> AttributeValue {
    let lines: String = fields.iter().map(|(k, v)| format!("{k}={v}\n")).collect();
    AttributeValue::Text(text(&lines))
}

/// Parses the `ortmMeta` attribute of a part (see [`meta_attribute`]).
///
/// # Errors
/// A sentence when the attribute is missing or a line is not `name=value`.
pub fn parse_meta(attrs: &HashMap<Text, AttributeValue>) -> Result<Meta, String> {
    let Some(AttributeValue::Text(t)) = attrs.get(A_META.as_bytes()) else {
        return Err(format!("attribute {A_META} (string) is missing"));
    };
    let mut meta = Meta::new();
    for line in t.to_string().lines() {
        let (k, v) = line
            .split_once('=')
            .ok_or_else(|| format!("{A_META}: line {line:?} is not name=value"))?;
        meta.insert(k.to_owned(), v.to_owned());
    }
    Ok(meta)
}
