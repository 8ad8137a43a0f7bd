//! The CPU reference of the renderer's transfer pass, evaluated from atlas pieces (paper Eq. 9
//! plus the first-order term; module doc of [`crate::atlas`], step 4).

use super::{AtlasError, AtlasPiece, AtlasSet};
use crate::Lightmap;

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
    apply_atlas_pieces(set, |_| true, first_order, None)
}

/// [`apply_atlas_set`] with only the pieces for which `keep` is true (e.g. the maps of one
/// offset, or the first K maps by importance, as `ortm view` shows them); same order and
/// arithmetic. Pieces of multi-resolution maps (level > 0) read the first-order pyramid
/// ([`crate::maps::levels::Pyramid`]) built with the texel weights `weights` (texel areas, 0
/// where uncovered; `W × H`), which they then need. A piece of receiver level `r > 0` holds
/// one value per `2^r × 2^r` receiver block `c` (its `dst`, `w`, `h` count blocks): the value
/// times `P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)` adds into every covered texel `t` of the block (`⌊t/2^r⌋ = c`,
/// covered: `weights[t] > 0`), as [`crate::maps::levels::apply_levels`] does.
///
/// # Errors
/// As [`apply_atlas_set`]; [`AtlasError::NeedsWeights`] when a kept piece has level > 0 (so
/// also any with receiver level > 0) and `weights` is `None` or not `W × H`.
pub fn apply_atlas_pieces(
    set: &AtlasSet,
    keep: impl Fn(&AtlasPiece) -> bool,
    first_order: &Lightmap,
    weights: Option<&[f32]>,
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
    let pyramid = match order.iter().map(|p| p.level.max(p.receiver_level)).max() {
        Some(top) if top > 0 => {
            let weights = weights
                .filter(|wt| wt.len() == w as usize * h as usize)
                .ok_or(AtlasError::NeedsWeights { level: top })?;
            let levels = (top + 1).max(crate::maps::levels::level_count(w, h));
            Some(
                crate::maps::levels::Pyramid::new(first_order, weights, levels).map_err(|e| {
                    AtlasError::InvalidSet {
                        reason: format!("first-order pyramid: {e}"),
                    }
                })?,
            )
        }
        _ => None,
    };
    for p in order {
        let atlas = &set.atlases[p.atlas as usize];
        if p.level > 0 {
            // Receiver level r ≥ 0: each value at block c reads ⌊c/2^(ℓ−r)⌋ + Δ and adds into
            // the covered texels of c (for r = 0, the texel c itself, covered or not).
            let pyr = pyramid.as_ref().expect("built for levels > 0");
            let lv = &pyr.levels[p.level as usize];
            let covered = &pyr.levels[0].weight;
            let (r, s) = (p.receiver_level, p.level - p.receiver_level);
            for j in 0..p.h {
                let cy = p.dst_y + j;
                let sy = i64::from(cy >> s) + i64::from(p.offset[1]);
                for i in 0..p.w {
                    let cx = p.dst_x + i;
                    let sv = lv.get(i64::from(cx >> s) + i64::from(p.offset[0]), sy);
                    let v = atlas[(p.src_y + j) as usize * aw + (p.src_x + i) as usize];
                    for y in (cy << r)..((cy + 1) << r).min(h) {
                        for x in (cx << r)..((cx + 1) << r).min(w) {
                            let t = y as usize * w as usize + x as usize;
                            if r > 0 && covered[t] <= 0.0 {
                                continue;
                            }
                            for c in 0..3 {
                                acc[t][c] += f64::from(v[c]) * f64::from(sv[c]);
                            }
                        }
                    }
                }
            }
            continue;
        }
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
