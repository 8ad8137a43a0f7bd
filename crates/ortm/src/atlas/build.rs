//! Packing: every crop rectangle of every transfer map becomes one `binning` source; the
//! packer's placements become [`AtlasPiece`]s (module doc of [`crate::atlas`], step 1).

use std::collections::HashMap;

use super::{AtlasError, AtlasPiece, AtlasSet};
use crate::maps::TransferMap;

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
    let lightmap_size = first.lightmap_size();
    let padded = pad_single_crops(maps);
    let sources = binning_sources(maps, &padded, lightmap_size)?;
    let packing = binning::pack(&sources.rects, atlas_w, atlas_h)?;
    let atlases = binning::blit(&packing, &sources.data)?;
    let pieces = pieces_of(&packing, &sources.owners, maps, &padded)?;
    let set = AtlasSet {
        atlas_size: (atlas_w, atlas_h),
        lightmap_size,
        atlases,
        pieces,
    };
    Ok((set, packing.stats))
}

/// Column padding of a single-crop map (see [`padded_columns`]): `(x, w, padded data)`.
type Padded = Option<(u32, u32, Vec<[f32; 3]>)>;

/// The padded crop of every map that has exactly one crop and whose width pads
/// ([`padded_columns`], inside the map's receiver grid); `None` for the others.
fn pad_single_crops(maps: &[TransferMap]) -> Vec<Padded> {
    maps.iter()
        .map(|m| match m.crops() {
            [c] => padded_columns(c.rect.x, c.rect.w, m.width()).map(|(x, w)| {
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
        .collect()
}

/// The packer's input: one source per crop rectangle (padded where [`pad_single_crops`] padded
/// it), its values, and which `(map, crop)` each source id came from.
struct Sources<'a> {
    owners: Vec<(usize, usize)>,
    rects: Vec<binning::SourceRect>,
    data: Vec<&'a [[f32; 3]]>,
}

/// Lists every crop of every map as a binning source (id = running number), checking that all
/// maps share the lightmap size.
fn binning_sources<'a>(
    maps: &'a [TransferMap],
    padded: &'a [Padded],
    lightmap_size: (u32, u32),
) -> Result<Sources<'a>, AtlasError> {
    let mut s = Sources {
        owners: Vec::new(),
        rects: Vec::new(),
        data: Vec::new(),
    };
    for (mi, m) in maps.iter().enumerate() {
        if m.lightmap_size() != lightmap_size {
            return Err(AtlasError::LightmapMismatch {
                map: mi,
                expected: lightmap_size,
                found: m.lightmap_size(),
            });
        }
        for (ci, c) in m.crops().iter().enumerate() {
            let id = u32::try_from(s.owners.len()).map_err(|_| AtlasError::TooManyCrops {
                count: maps.iter().map(|m| m.crops().len()).sum(),
            })?;
            s.owners.push((mi, ci));
            let (w, d): (u32, &[[f32; 3]]) = match &padded[mi] {
                Some((_, w, buf)) => (*w, buf),
                None => (c.rect.w, &c.data),
            };
            s.rects.push(binning::SourceRect { id, w, h: c.rect.h });
            s.data.push(d);
        }
    }
    Ok(s)
}

/// One [`AtlasPiece`] per placement: atlas position from the packer, lightmap position from the
/// (padded) crop plus the placement's offset inside it; sorted by `(atlas, src_y, src_x)`.
fn pieces_of(
    packing: &binning::Packing,
    owners: &[(usize, usize)],
    maps: &[TransferMap],
    padded: &[Padded],
) -> Result<Vec<AtlasPiece>, AtlasError> {
    let map_index =
        |mi: usize| u32::try_from(mi).map_err(|_| AtlasError::TooManyCrops { count: maps.len() });
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
            level: m.level(),
            receiver_level: m.receiver_level(),
        });
    }
    pieces.sort_by_key(|p| (p.atlas, p.src_y, p.src_x));
    Ok(pieces)
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
}

#[cfg(test)]
mod tests {
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
