//! CPU mirror of the rows path of the transfer pass (`shaders/transfer_rows.wgsl`,
//! [`crate::rows`]).
//!
//! `cs_pack` copies the first-order map and the packed pyramid levels into one source array
//! ([`source`]); `cs_rows` gives each texel `base[t] + Σ_row w · source[s]`, summed in `f32`
//! in row order, skipping receiver-block entries ([`crate::rows::COVERED_ONLY`]) where the
//! base's alpha (coverage) is 0; the alpha is the base's.

use crate::pyramid::level_origin;
use crate::rows::{COVERED_ONLY, RowSchedule};
use crate::types::TexelImage;

/// The source array (`cs_pack`): `first_order` row-major, then the packed pyramid
/// (`levels[ℓ − 1]` = level `ℓ`, placed at [`level_origin`] in rows of
/// [`RowSchedule::packed_width`] texels; gaps of the packing are 0).
///
/// Panics when `levels` lacks a level the rows read.
pub fn source(
    rows: &RowSchedule,
    first_order: &TexelImage,
    levels: &[TexelImage],
) -> Vec<[f32; 4]> {
    let [w, h] = rows.lightmap_size;
    assert_eq!((first_order.width, first_order.height), (w, h));
    let mut out = vec![[0.0f32; 4]; rows.source_len as usize];
    out[..(w * h) as usize].copy_from_slice(&first_order.rgba);
    let pw = rows.packed_width() as usize;
    for l in 1..=rows.max_level {
        let img = levels.get(l as usize - 1).unwrap_or_else(|| {
            panic!(
                "the rows read level {l} but the pyramid holds levels 1..={}",
                levels.len()
            )
        });
        let o = level_origin(rows.lightmap_size, l);
        for y in 0..img.height {
            for x in 0..img.width {
                let i = (w * h) as usize + (o[1] + y) as usize * pw + (o[0] + x) as usize;
                out[i] = img.get(x, y);
            }
        }
    }
    out
}

/// `final = base + Σ rows` (`base` = `first_order` when `None`), every texel's row summed in
/// `f32` in order; `levels[ℓ − 1]` is pyramid level `ℓ` of `first_order`.
pub fn transfer_rows(
    rows: &RowSchedule,
    first_order: &TexelImage,
    base: Option<&TexelImage>,
    levels: &[TexelImage],
) -> TexelImage {
    let src = source(rows, first_order, levels);
    let base = base.unwrap_or(first_order);
    let [w, h] = rows.lightmap_size;
    let mut out = TexelImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let b = base.get(x, y);
            let covered = b[3] > 0.0;
            let mut sum = [0.0f32; 3];
            for e in rows.row(x, y) {
                if e.source & COVERED_ONLY != 0 && !covered {
                    continue;
                }
                let s = src[(e.source & !COVERED_ONLY) as usize];
                for c in 0..3 {
                    sum[c] += e.w[c] * s[c];
                }
            }
            *out.at_mut(x, y) = [b[0] + sum[0], b[1] + sum[1], b[2] + sum[2], b[3]];
        }
    }
    out
}
