//! Cropping a full transfer map to a few disjoint rectangles: minimal bounding boxes with axial
//! slicing (paper Sec. 5.1).
//!
//! # Rule
//! The input is a `W×H` RGB image; a texel is *non-empty* when any channel is `!= 0.0`.
//! `crop(R)` for a region `R` (initially the whole map) is:
//! 1. `B` = the minimal bounding box of the non-empty texels inside `R`. If there are none, the
//!    result is no rectangle.
//! 2. In `B`, find the *empty columns* (every texel of the column inside `B` is empty) and the
//!    *empty rows*. Along an axis that has any, `B` splits into its maximal runs of non-empty
//!    lines ("axial slicing"): the parts are the slabs between the empty lines.
//! 3. If both axes have empty lines, slice along the one whose empty lines cover more texels
//!    (`#empty columns · B.h` vs. `#empty rows · B.w`); ties go to columns. Only this one axis
//!    is tried (greedy), so the work stays linear in the number of nodes.
//! 4. Recurse: `children = crop(part)` for every part (each part gets its own tight box, which
//!    may expose new empty lines along the other axis).
//! 5. Keep the children only if they are cheaper: with cost(set) = Σ area + `k`·count, where `k`
//!    is [`CropOptions::rect_overhead_texels`], slice iff `cost(children) < area(B) + k`;
//!    otherwise `B` itself is the result (a leaf).
//!
//! Stop criteria: recursion ends at a box without empty rows and columns, and a slice is kept
//! only when the texels it saves exceed `k` per extra rectangle. With `k = 0` every kept
//! rectangle is free of empty full rows/columns. Every output rectangle is tight (each of its
//! four border lines contains a non-empty texel), the rectangles are disjoint, and together they
//! contain every non-empty texel exactly once.
//!
//! # Cost
//! A summed-area table of non-empty counts (`u32`, `(W+1)·(H+1)` entries) makes every line
//! emptiness test O(1), so cropping is O(W·H + nodes·(W+H)). Recursion depth is at most the
//! number of nested slices (≤ W + H).

use serde::{Deserialize, Serialize};

use crate::Lightmap;

/// A rectangle of lightmap texels: columns `x..x+w`, rows `y..y+h` (row 0 is `v = 1`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
pub struct CropRect {
    /// First column.
    pub x: u32,
    /// First row.
    pub y: u32,
    /// Width in texels (≥ 1 for a valid crop).
    pub w: u32,
    /// Height in texels (≥ 1 for a valid crop).
    pub h: u32,
}

impl CropRect {
    /// Number of texels, `w·h`.
    #[inline]
    pub fn area(&self) -> u64 {
        self.w as u64 * self.h as u64
    }

    /// One past the last column, `x + w` (as `u64`, cannot overflow).
    #[inline]
    pub fn x_end(&self) -> u64 {
        self.x as u64 + self.w as u64
    }

    /// One past the last row, `y + h` (as `u64`, cannot overflow).
    #[inline]
    pub fn y_end(&self) -> u64 {
        self.y as u64 + self.h as u64
    }

    /// Whether texel `(x, y)` lies inside.
    #[inline]
    pub fn contains(&self, x: u32, y: u32) -> bool {
        x >= self.x && (x as u64) < self.x_end() && y >= self.y && (y as u64) < self.y_end()
    }

    /// Whether the two rectangles share at least one texel.
    #[inline]
    pub fn intersects(&self, other: &CropRect) -> bool {
        (self.x as u64) < other.x_end()
            && (other.x as u64) < self.x_end()
            && (self.y as u64) < other.y_end()
            && (other.y as u64) < self.y_end()
    }

    /// Whether the rectangle is non-empty and lies inside a `width×height` map.
    #[inline]
    pub fn fits_in(&self, width: u32, height: u32) -> bool {
        self.w > 0 && self.h > 0 && self.x_end() <= width as u64 && self.y_end() <= height as u64
    }
}

/// Tuning of the cropper.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct CropOptions {
    /// Cost of one extra rectangle, in texels: a slice is kept only if it saves more stored
    /// texels than this per additional rectangle. Default 64 (an OpenEXR part header plus offset
    /// table is ≈ 500–700 bytes ≈ 50 f32 RGB texels; atlas packing adds per-rect padding too).
    pub rect_overhead_texels: u64,
}

impl Default for CropOptions {
    fn default() -> Self {
        Self {
            rect_overhead_texels: 64,
        }
    }
}

/// Whether a texel is empty (all channels equal `0.0`; `-0.0` counts as empty).
#[inline]
pub(crate) fn is_empty_texel(v: [f32; 3]) -> bool {
    v[0] == 0.0 && v[1] == 0.0 && v[2] == 0.0
}

/// Crop rectangles of `map` (see the module doc for the exact rule), in a deterministic order
/// (depth-first, slabs left-to-right / top-to-bottom).
///
/// `map.data` must hold `width·height` texels and `width·height ≤` [`crate::maps::MAX_TEXELS`];
/// [`crate::maps::TransferMap::from_full`] checks both. If not, this returns no rectangles
/// rather than panicking.
pub fn crop_rects(map: &Lightmap, options: &CropOptions) -> Vec<CropRect> {
    let (w, h) = (map.width as usize, map.height as usize);
    if w == 0
        || h == 0
        || map.data.len() != w * h
        || (w as u64) * (h as u64) > crate::maps::MAX_TEXELS
    {
        return Vec::new();
    }
    let sat = Sat::new(map);
    let mut out = Vec::new();
    let full = CropRect {
        x: 0,
        y: 0,
        w: map.width,
        h: map.height,
    };
    crop_region(&sat, full, options.rect_overhead_texels, &mut out);
    out
}

/// Summed-area table of non-empty texel counts.
struct Sat {
    /// `(w+1)·(h+1)` entries; `s[y·(w+1) + x]` = count in columns `< x`, rows `< y`.
    s: Vec<u32>,
    stride: usize,
}

impl Sat {
    fn new(map: &Lightmap) -> Self {
        let (w, h) = (map.width as usize, map.height as usize);
        let stride = w + 1;
        let mut s = vec![0u32; stride * (h + 1)];
        for y in 0..h {
            let mut row_sum = 0u32;
            for x in 0..w {
                row_sum += u32::from(!is_empty_texel(map.data[y * w + x]));
                s[(y + 1) * stride + x + 1] = s[y * stride + x + 1] + row_sum;
            }
        }
        Self { s, stride }
    }

    /// Non-empty count in columns `x0..x1`, rows `y0..y1`.
    #[inline]
    fn count(&self, x0: u32, y0: u32, x1: u32, y1: u32) -> u32 {
        let at = |x: u32, y: u32| self.s[y as usize * self.stride + x as usize];
        at(x1, y1) + at(x0, y0) - at(x0, y1) - at(x1, y0)
    }
}

/// Tight bounding box of the non-empty texels in `r`, or `None`.
fn tight_box(sat: &Sat, r: CropRect) -> Option<CropRect> {
    let (x0, y0, x1, y1) = (r.x, r.y, r.x + r.w, r.y + r.h);
    if sat.count(x0, y0, x1, y1) == 0 {
        return None;
    }
    let col = |x: u32| sat.count(x, y0, x + 1, y1) > 0;
    let row = |y: u32| sat.count(x0, y, x1, y + 1) > 0;
    let bx0 = (x0..x1).find(|&x| col(x))?;
    let bx1 = (x0..x1).rev().find(|&x| col(x))? + 1;
    let by0 = (y0..y1).find(|&y| row(y))?;
    let by1 = (y0..y1).rev().find(|&y| row(y))? + 1;
    Some(CropRect {
        x: bx0,
        y: by0,
        w: bx1 - bx0,
        h: by1 - by0,
    })
}

/// Maximal runs of `true` in `occupied` over `start..end`, as `(first, len)`.
fn runs(start: u32, end: u32, occupied: impl Fn(u32) -> bool) -> (Vec<(u32, u32)>, u32) {
    let mut parts = Vec::new();
    let mut empty = 0;
    let mut run_start = None;
    for i in start..end {
        if occupied(i) {
            run_start.get_or_insert(i);
        } else {
            empty += 1;
            if let Some(s) = run_start.take() {
                parts.push((s, i - s));
            }
        }
    }
    if let Some(s) = run_start {
        parts.push((s, end - s));
    }
    (parts, empty)
}

/// Appends the crop of region `r` to `out`; returns the cost (Σ area + k·count) appended.
fn crop_region(sat: &Sat, r: CropRect, k: u64, out: &mut Vec<CropRect>) -> u64 {
    let Some(b) = tight_box(sat, r) else {
        return 0;
    };
    let (x0, y0, x1, y1) = (b.x, b.y, b.x + b.w, b.y + b.h);
    let (col_parts, empty_cols) = runs(x0, x1, |x| sat.count(x, y0, x + 1, y1) > 0);
    let (row_parts, empty_rows) = runs(y0, y1, |y| sat.count(x0, y, x1, y + 1) > 0);
    let leaf_cost = b.area() + k;
    let col_gain = empty_cols as u64 * b.h as u64;
    let row_gain = empty_rows as u64 * b.w as u64;
    let parts: Vec<CropRect> = if empty_cols > 0 && col_gain >= row_gain {
        col_parts
            .into_iter()
            .map(|(x, w)| CropRect {
                x,
                y: y0,
                w,
                h: b.h,
            })
            .collect()
    } else if empty_rows > 0 {
        row_parts
            .into_iter()
            .map(|(y, h)| CropRect {
                x: x0,
                y,
                w: b.w,
                h,
            })
            .collect()
    } else {
        out.push(b);
        return leaf_cost;
    };
    let mark = out.len();
    let mut child_cost = 0;
    for p in parts {
        child_cost += crop_region(sat, p, k, out);
    }
    if child_cost < leaf_cost {
        child_cost
    } else {
        out.truncate(mark);
        out.push(b);
        leaf_cost
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    fn map_from_mask(w: u32, h: u32, mask: &[&str]) -> Lightmap {
        let mut m = Lightmap::new(w, h);
        for (y, row) in mask.iter().enumerate() {
            for (x, c) in row.chars().enumerate() {
                if c == '#' {
                    m.set(x as u32, y as u32, [1.0, 0.5, 0.25]);
                }
            }
        }
        m
    }

    /// Checks the invariants every crop must satisfy, against brute force.
    fn check_invariants(m: &Lightmap, rects: &[CropRect]) {
        for (i, a) in rects.iter().enumerate() {
            assert!(a.fits_in(m.width, m.height), "rect {a:?} out of bounds");
            for b in &rects[i + 1..] {
                assert!(!a.intersects(b), "rects {a:?} and {b:?} overlap");
            }
            // Tight: each border line has a non-empty texel.
            let ne = |x: u32, y: u32| !is_empty_texel(m.get(x, y));
            assert!((a.x..a.x + a.w).any(|x| ne(x, a.y)), "top of {a:?} empty");
            assert!(
                (a.x..a.x + a.w).any(|x| ne(x, a.y + a.h - 1)),
                "bottom of {a:?} empty"
            );
            assert!((a.y..a.y + a.h).any(|y| ne(a.x, y)), "left of {a:?} empty");
            assert!(
                (a.y..a.y + a.h).any(|y| ne(a.x + a.w - 1, y)),
                "right of {a:?} empty"
            );
        }
        for y in 0..m.height {
            for x in 0..m.width {
                let n = rects.iter().filter(|r| r.contains(x, y)).count();
                if is_empty_texel(m.get(x, y)) {
                    assert!(n <= 1);
                } else {
                    assert_eq!(n, 1, "non-empty texel ({x},{y}) in {n} rects");
                }
            }
        }
    }

    /// Brute force: does `r` contain a full empty row or column?
    fn has_empty_line(m: &Lightmap, r: &CropRect) -> bool {
        let col_empty = |x: u32| (r.y..r.y + r.h).all(|y| is_empty_texel(m.get(x, y)));
        let row_empty = |y: u32| (r.x..r.x + r.w).all(|x| is_empty_texel(m.get(x, y)));
        (r.x..r.x + r.w).any(col_empty) || (r.y..r.y + r.h).any(row_empty)
    }

    #[test]
    fn all_zero_map_has_no_rects() {
        let m = Lightmap::new(7, 5);
        assert!(crop_rects(&m, &CropOptions::default()).is_empty());
        // Negative zero is empty as well.
        let mut m = Lightmap::new(3, 3);
        m.set(1, 1, [-0.0, 0.0, -0.0]);
        assert!(crop_rects(&m, &CropOptions::default()).is_empty());
    }

    #[test]
    fn single_texel_and_bounding_box() {
        let m = map_from_mask(6, 4, &["......", "...#..", "......", "......"]);
        let r = crop_rects(&m, &CropOptions::default());
        assert_eq!(
            r,
            vec![CropRect {
                x: 3,
                y: 1,
                w: 1,
                h: 1
            }]
        );
        let m = map_from_mask(6, 4, &["......", ".#....", "....#.", "......"]);
        let r = crop_rects(&m, &CropOptions::default());
        assert_eq!(
            r,
            vec![CropRect {
                x: 1,
                y: 1,
                w: 4,
                h: 2
            }]
        );
    }

    #[test]
    fn axial_slicing_obeys_overhead() {
        // Two 2×2 blobs separated by 4 empty columns; the slice saves 8 texels.
        let mask = ["##....##", "##....##"];
        let m = map_from_mask(8, 2, &mask);
        let keep = crop_rects(
            &m,
            &CropOptions {
                rect_overhead_texels: 7,
            },
        );
        assert_eq!(
            keep,
            vec![
                CropRect {
                    x: 0,
                    y: 0,
                    w: 2,
                    h: 2
                },
                CropRect {
                    x: 6,
                    y: 0,
                    w: 2,
                    h: 2
                }
            ]
        );
        // Saving 8 texels for one extra rect costing 8 is not worth it (strict inequality).
        let single = crop_rects(
            &m,
            &CropOptions {
                rect_overhead_texels: 8,
            },
        );
        assert_eq!(
            single,
            vec![CropRect {
                x: 0,
                y: 0,
                w: 8,
                h: 2
            }]
        );
    }

    #[test]
    fn nested_slicing_along_both_axes() {
        // Columns split first (4 empty columns × 5 rows = 20 > 1 empty row × 9 = 9), then the
        // left slab splits along its empty row.
        let mask = [
            "##....###",
            "##....###",
            ".........",
            "##.......",
            "##.......",
        ];
        let m = map_from_mask(9, 5, &mask);
        let r = crop_rects(
            &m,
            &CropOptions {
                rect_overhead_texels: 0,
            },
        );
        assert_eq!(
            r,
            vec![
                CropRect {
                    x: 0,
                    y: 0,
                    w: 2,
                    h: 2
                },
                CropRect {
                    x: 0,
                    y: 3,
                    w: 2,
                    h: 2
                },
                CropRect {
                    x: 6,
                    y: 0,
                    w: 3,
                    h: 2
                },
            ]
        );
        check_invariants(&m, &r);
    }

    #[test]
    fn random_maps_satisfy_invariants() {
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for case in 0..200 {
            let w = rng.random_range(1..24u32);
            let h = rng.random_range(1..24u32);
            let density: f64 = rng.random_range(0.0..0.3);
            let mut m = Lightmap::new(w, h);
            // Sparse blobs: random small rectangles of non-zero values.
            let blobs = rng.random_range(0..6);
            for _ in 0..blobs {
                let bx = rng.random_range(0..w);
                let by = rng.random_range(0..h);
                let bw = rng.random_range(1..=(w - bx).min(5));
                let bh = rng.random_range(1..=(h - by).min(5));
                for y in by..by + bh {
                    for x in bx..bx + bw {
                        if rng.random_bool(0.8) {
                            m.set(x, y, [rng.random(), 0.0, 0.0]);
                        }
                    }
                }
            }
            for v in m.data.iter_mut() {
                if rng.random_bool(density * 0.1) {
                    v[2] = 1.0;
                }
            }
            for k in [0, 4, 64] {
                let r = crop_rects(
                    &m,
                    &CropOptions {
                        rect_overhead_texels: k,
                    },
                );
                check_invariants(&m, &r);
                if k == 0 {
                    for rect in &r {
                        assert!(
                            !has_empty_line(&m, rect),
                            "case {case}: {rect:?} has empty line"
                        );
                    }
                }
                let stored: u64 = r.iter().map(CropRect::area).sum();
                assert!(stored <= w as u64 * h as u64);
            }
        }
    }
}
