//! Texture atlases of transfer maps (paper Sec. 5.2): the bake's cropped maps packed by the
//! `binning` crate into a few large textures, the piece list the renderer draws, the atlas files
//! on disk (format in `docs/atlas-format.md`), a CPU reference of Eq. 9 evaluated from the
//! pieces, and pictures of the packing.
//!
//! # Modules
//! [`build`] (packing), [`validate`] (the invariants below), [`file`](mod@file) (the atlas OpenEXR codec),
//! [`index`] (`atlases.json` and reading/writing a directory), [`apply`] (CPU Eq. 9),
//! [`pictures`] (PNG pictures), [`error`]. Everything public is re-exported here.
//!
//! # Data flow
//! 1. [`build_atlas_set`] takes the bake's [`TransferMap`](crate::maps::TransferMap)s (in bake-index order). Every crop
//!    rectangle of every map becomes one binning source (id = a running number, remembered as
//!    `(map, crop)`); [`binning::pack`] cuts them into power-of-two-wide slices and packs them
//!    into the fewest `atlas_w × atlas_h` atlases; [`binning::blit`] copies the values
//!    bit-exactly. Each placement becomes an [`AtlasPiece`]: `src_x, src_y` = its position in
//!    the atlas, `dst_x = crop.x + placement.src_x`, `dst_y = crop.y + placement.src_y` = the
//!    receiver texel of its top-left corner in the lightmap (for a map of receiver level
//!    `r > 0`: the receiver block, in the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid), `offset` = the map's `Δt`,
//!    `level` and `receiver_level` = the map's, `map_index` = the map's position in the slice
//!    (= its position in `index.json`'s `maps`).
//! 2. [`write_atlas_set`] writes one OpenEXR file per atlas (`atlas_000.exr`, …) and then the
//!    index `atlases.json` (format in `docs/atlas-format.md`), all atomically, the index last.
//! 3. [`read_atlas_set`] reads them back with every check a renderer needs: version, file names,
//!    sizes, SHA-256, piece geometry, and the bake key against the bake's `index.json` if the
//!    directory has one.
//! 4. [`apply_atlas_set`] evaluates `B = B_o + Σ_pieces atlas[src+(i,j)]·B_o[dst+(i,j)+Δt]`, the
//!    same sum as [`crate::maps::apply()`] (bit-identical when the pieces came from the same maps:
//!    see its doc); [`apply_atlas_pieces`] also applies multi-resolution pieces and receiver
//!    blocks (added into the covered texels of their block) as
//!    [`crate::maps::levels::apply_levels`] does. [`packing_image`] and [`atlas_values_image`] draw an atlas for people.
//!
//! # Units and conventions
//! Atlas texels hold the maps' dimensionless transfer factors (linear RGB, f32). Atlas and
//! lightmap images are row-major, row 0 first (`y` down; lightmap row 0 is `v = 1`). Offsets are
//! texels, `+dy` down; a piece texel at lightmap `t` multiplies `B_o(t + Δt)`, zero outside the
//! lightmap.
//!
//! # Invariants of a valid [`AtlasSet`] (checked by [`AtlasSet::validate`], on write and read)
//! Atlas sides are powers of two in `1..=65536` with `W·H ≤` [`MAX_TEXELS`](crate::maps::MAX_TEXELS); the lightmap is
//! non-empty with `≤ MAX_TEXELS` texels; every atlas holds `W·H` finite values; every piece is
//! non-empty, names an existing atlas, lies inside it and (at `dst`) inside the lightmap, or
//! for a piece of receiver level `r > 0` inside the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of receiver
//! blocks, with `r ≤ level`; pieces
//! are sorted by `(atlas, src_y, src_x)` and pairwise disjoint in their atlas; the pieces of one
//! map share one offset, level and receiver level and are pairwise disjoint in the lightmap (in
//! their grid).
//!
//! # Limits
//! Checking disjointness costs one `u32` per atlas texel and per lightmap texel (stamp grids).
//! Memory for a set is `12·W·H` bytes per atlas. [`apply_atlas_set`] is single-threaded, `O(Σ
//! piece areas + lightmap texels)`.

pub mod apply;
pub mod build;
pub mod error;
pub mod file;
pub mod index;
pub mod pictures;
pub mod validate;

pub use apply::{apply_atlas_pieces, apply_atlas_set};
pub use build::{
    AtlasStats, PAD_WIDTH_BITS, build_atlas_set, build_atlas_set_with_stats, padded_columns,
};
pub use error::AtlasError;
pub use file::atlas_file_name;
pub use index::{
    ATLAS_INDEX_FILE_NAME, ATLAS_INDEX_FORMAT, ATLAS_INDEX_VERSION, AtlasFileEntry, AtlasIndex,
    read_atlas_index, read_atlas_set, write_atlas_set, write_atlas_set_locked,
};
pub use pictures::{
    PACKING_BACKGROUND, atlas_values_image, map_color, packing_image, packing_scale,
};

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
    /// The map's pyramid level ([`crate::maps::levels`]): the piece multiplies
    /// `P_ℓ(⌊t/2^ℓ⌋ + Δ)`, its offset in blocks of `2^ℓ` texels; absent (0) for the paper's maps.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub level: u32,
    /// The map's receiver level `r ≤ level` ([`crate::maps::TransferMap::receiver_level`]):
    /// for `r > 0`, `dst_x, dst_y, w, h` count `2^r × 2^r` receiver blocks in the
    /// `⌈W/2^r⌉ × ⌈H/2^r⌉` grid, and the piece's value at block `c` multiplies
    /// `P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)` and adds into every covered texel of the block; absent (0) for
    /// one value per texel.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub receiver_level: u32,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::maps::{Crop, CropRect, TransferMap};
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
