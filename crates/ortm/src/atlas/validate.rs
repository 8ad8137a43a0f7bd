//! The invariants of a valid [`AtlasSet`] (module doc of [`crate::atlas`], "Invariants"),
//! checked when a set is written, read or applied.

use std::collections::HashMap;

use super::{AtlasError, AtlasPiece, AtlasSet};
use crate::maps::MAX_TEXELS;

impl AtlasSet {
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

/// The pieces of each map cover exactly that map's crop rectangles, each texel once
/// (`docs/atlas-format.md`, "Invariants"). `rects[m]` are map `m`'s crop rectangles
/// `[x, y, w, h]` from the bake index; every piece's `map_index` is below `rects.len()` and the
/// pieces of one map are already known to be disjoint ([`check_geometry`]).
///
/// Per map the areas must agree first (which also bounds the work below by the pieces' area,
/// itself bounded by the atlases); then the row spans of the pieces and of the rectangles,
/// merged, must be equal. Equal unions and equal area sums of disjoint pieces make the
/// rectangles disjoint too, so every texel of every rectangle is covered exactly once.
pub(super) fn check_coverage(pieces: &[AtlasPiece], rects: &[Vec<[u32; 4]>]) -> Result<(), String> {
    let mut piece_area = vec![0u64; rects.len()];
    for p in pieces {
        piece_area[p.map_index as usize] += u64::from(p.w) * u64::from(p.h);
    }
    for (m, r) in rects.iter().enumerate() {
        if let Some(k) = r.iter().position(|r| r[2] == 0 || r[3] == 0) {
            return Err(format!("map {m}: crop rectangle {k} is empty"));
        }
        let area: u64 = r.iter().map(|r| u64::from(r[2]) * u64::from(r[3])).sum();
        if area != piece_area[m] {
            return Err(format!(
                "the pieces of map {m} cover {} texels but its crop rectangles hold {area}: a \
                 piece is missing or extra",
                piece_area[m]
            ));
        }
    }
    let merged = |mut spans: Vec<(u32, u64, u64, u64)>| {
        spans.sort_unstable();
        let mut out: Vec<(u32, u64, u64, u64)> = Vec::with_capacity(spans.len());
        for s in spans {
            match out.last_mut() {
                Some(l) if l.0 == s.0 && l.1 == s.1 && s.2 <= l.3 => l.3 = l.3.max(s.3),
                _ => out.push(s),
            }
        }
        out
    };
    let row_spans = |m: u32, x: u32, y: u32, w: u32, h: u32| {
        (u64::from(y)..u64::from(y) + u64::from(h))
            .map(move |row| (m, row, u64::from(x), u64::from(x) + u64::from(w)))
    };
    let have = merged(
        pieces
            .iter()
            .flat_map(|p| row_spans(p.map_index, p.dst_x, p.dst_y, p.w, p.h))
            .collect(),
    );
    let want = merged(
        rects
            .iter()
            .enumerate()
            .flat_map(|(m, r)| {
                r.iter()
                    .flat_map(move |r| row_spans(m as u32, r[0], r[1], r[2], r[3]))
            })
            .collect(),
    );
    if let Some(k) = (0..have.len().max(want.len())).find(|&k| have.get(k) != want.get(k)) {
        let (m, row) = have.get(k).or(want.get(k)).map_or((0, 0), |s| (s.0, s.1));
        return Err(format!(
            "the pieces of map {m} do not cover its crop rectangles exactly (first difference at \
             lightmap row {row}): a piece is shifted, missing or extra"
        ));
    }
    Ok(())
}

/// `1 ≤ w, h` and `w·h ≤ MAX_TEXELS`.
fn size_ok(w: u32, h: u32) -> bool {
    w >= 1 && h >= 1 && u64::from(w) * u64::from(h) <= MAX_TEXELS
}

/// Checks sizes and piece geometry (module doc, "Invariants"), except the atlas data: the
/// sizes ([`check_sizes`]), each piece on its own ([`check_piece`]), then the pieces together
/// ([`check_disjoint`]).
pub(super) fn check_geometry(
    atlas_size: (u32, u32),
    lightmap_size: (u32, u32),
    atlas_count: usize,
    pieces: &[AtlasPiece],
) -> Result<(), String> {
    check_sizes(atlas_size, lightmap_size)?;
    let mut offsets: HashMap<u32, ([i32; 2], u32, u32)> = HashMap::new();
    for (i, p) in pieces.iter().enumerate() {
        if p.level > crate::maps::MAX_MAP_LEVEL || p.receiver_level > p.level {
            return Err(format!(
                "piece {i} of map {} has pyramid level {} and receiver_level {} (0 ≤ \
                 receiver_level ≤ level ≤ {})",
                p.map_index,
                p.level,
                p.receiver_level,
                crate::maps::MAX_MAP_LEVEL
            ));
        }
        check_piece(i, pieces, atlas_size, lightmap_size, atlas_count)?;
        let key = (p.offset, p.level, p.receiver_level);
        if let Some(o) = offsets.insert(p.map_index, key)
            && o != key
        {
            return Err(format!(
                "piece {i} of map {} has offset {:?} at level {} (receiver level {}) but another \
                 piece of that map has {:?} at level {} (receiver level {})",
                p.map_index, p.offset, p.level, p.receiver_level, o.0, o.1, o.2
            ));
        }
    }
    check_disjoint(pieces, atlas_size, atlas_count)
}

/// Atlas sides are powers of two `≤ binning::MAX_ATLAS_SIDE`, both sizes non-empty and at most
/// [`MAX_TEXELS`] texels.
fn check_sizes(atlas_size: (u32, u32), lightmap_size: (u32, u32)) -> Result<(), String> {
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
    Ok(())
}

/// Piece `i` is non-empty, names an existing atlas, lies inside it and (at `dst`) inside the
/// lightmap — for receiver level `r > 0`, inside the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of receiver
/// blocks — and comes after piece `i − 1` in `(atlas, src_y, src_x)` order.
fn check_piece(
    i: usize,
    pieces: &[AtlasPiece],
    (aw, ah): (u32, u32),
    lightmap_size: (u32, u32),
    atlas_count: usize,
) -> Result<(), String> {
    let p = &pieces[i];
    let (lw, lh) = crate::maps::receiver_grid(lightmap_size, p.receiver_level);
    let inside = |o: u32, len: u32, size: u32| u64::from(o) + u64::from(len) <= u64::from(size);
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
        return Err(if p.receiver_level > 0 {
            format!(
                "piece {i} ({}×{} blocks at ({}, {}), receiver_level {}) lies outside the \
                 {lw}×{lh} grid of receiver blocks of the {}×{} lightmap",
                p.w, p.h, p.dst_x, p.dst_y, p.receiver_level, lightmap_size.0, lightmap_size.1
            )
        } else {
            format!(
                "piece {i} ({}×{} at lightmap ({}, {})) lies outside the {lw}×{lh} lightmap",
                p.w, p.h, p.dst_x, p.dst_y
            )
        });
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
    Ok(())
}

/// The pieces are pairwise disjoint in their atlases, and the pieces of one map pairwise
/// disjoint in the lightmap.
fn check_disjoint(
    pieces: &[AtlasPiece],
    (aw, ah): (u32, u32),
    atlas_count: usize,
) -> Result<(), String> {
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

#[cfg(test)]
mod coverage_tests {
    use super::*;

    fn piece(map: u32, dst: (u32, u32), w: u32, h: u32) -> AtlasPiece {
        AtlasPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w,
            h,
            dst_x: dst.0,
            dst_y: dst.1,
            offset: [0, 0],
            level: 0,
            receiver_level: 0,
            map_index: map,
        }
    }

    #[test]
    fn pieces_must_tile_the_crop_rectangles() {
        // Map 0: one 4×3 rectangle at (2, 1) cut into a 4×1 and a 4×2 piece; map 1: two
        // rectangles side by side stored as one 5×2 piece.
        let rects = vec![vec![[2, 1, 4, 3]], vec![[0, 0, 2, 2], [2, 0, 3, 2]]];
        let ok = [
            piece(0, (2, 1), 4, 1),
            piece(0, (2, 2), 4, 2),
            piece(1, (0, 0), 5, 2),
        ];
        assert_eq!(check_coverage(&ok, &rects), Ok(()));
        let mut shifted = ok;
        shifted[1].dst_x += 1;
        let e = check_coverage(&shifted, &rects).unwrap_err();
        assert!(e.contains("map 0") && e.contains("row 2"), "{e}");
        let e = check_coverage(&ok[1..], &rects).unwrap_err();
        assert!(
            e.contains("cover 8 texels but its crop rectangles hold 12"),
            "{e}"
        );
        // Overlapping rectangles cannot be covered exactly once by disjoint pieces.
        let overlapping = vec![vec![[2, 1, 4, 3], [2, 1, 4, 1]], vec![[0, 0, 5, 2]]];
        assert!(check_coverage(&ok, &overlapping).is_err());
    }
}
