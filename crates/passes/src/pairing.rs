//! Paired transfer pieces (an option of the blend path, [`crate::transfer::TransferOptions::pair_pieces`]):
//! two pieces drawn by one quad, so each fragment does one atlas fetch and one blend for two
//! maps' contributions. Pure functions (no GPU), built at `TransferPass::prepare` from the
//! cropped [`FrameSchedule`] and the atlases; nothing on disk changes.
//!
//! # Data flow
//! [`pair_schedule`]: the schedule's instances (all atlases together) → greedy pairing by
//! fragments saved → per pair a quad over the bounding box of both destination rectangles →
//! the pairs' texels packed into RGBA32Uint *pair pages* (shelf packing, [`PairPage`]) →
//! one [`PairInstance`] per pair. Unpaired instances stay in [`PairedSchedule::singles`] and
//! are drawn by the ordinary blend path.
//!
//! # Pair texel layout (RGBA32Uint, must match `shaders/transfer_pair.wgsl`)
//! Texel `(i, j)` of a pair holds, for lightmap texel `t = dst + (i, j)`, the values
//! `a = atlas_A[src_A + t − dst_A]·2^k_A` (0 when `t` is outside A's rectangle) and the same
//! for B, as IEEE binary16: `x = a.r | a.g << 16`, `y = a.b | b.r << 16`,
//! `z = b.g | b.b << 16` (`pack2x16float` order: first component in the low bits), `w = 0`.
//! The shader multiplies by `2^−k` (per instance, exact in f32).
//!
//! # Error bound (derived; checked by `tests/transfer.rs`)
//! `k` is chosen per piece so that the piece's largest magnitude `M` lands in
//! `M·2^k ∈ [2^14, 2^15)` (below binary16's maximum 65504, so nothing overflows). A scaled
//! value `|v|·2^k ≥ 2^−14` is a *normal* binary16 after rounding to nearest: relative error
//! `≤ u = 2^−11`. No value is stored subnormal (so no decoder's flush-to-zero mode can change
//! it): a smaller one is stored as 0 or `±2^−14`, whichever is nearer, absolute error
//! `≤ 2^−15` scaled, i.e. `≤ 2^−15·2^−k ≤ 2^−15·M·2^−14 = 2^−29·M` unscaled. So every stored
//! value has `|â − a| ≤ 2^−11·|a| + 2^−29·M`, and values `≥ 2^−28·M` keep the pure relative
//! bound. (`k` is clamped to `[−126, 126]`; only a piece with `M < 2^−112` has `M·2^k` below
//! `2^14`, and its flushed values err by `≤ 2^−141` absolute.) Scaling by powers of two is
//! exact in f32. A texel's transfer sum then errs by at
//! most `2^−11·Σ|a·f| + 2^−29·Σ M·|f|` plus f32 summation-order rounding.
//!
//! # Pairing rule
//! A pair fragment costs more than a single-piece fragment (one more first-order fetch and the
//! unpacking), about [`PAIR_FRAGMENT_COST`] of one. Two instances are paired when
//! `area_A + area_B − PAIR_FRAGMENT_COST·area(bbox) > 0`, greedily by that saving (ties by
//! index, deterministic). Only pieces of the same pyramid level are paired (a pair instance
//! carries one level and its origin; each piece's read `⌊t/2^ℓ⌋ + Δ` is clamped into that
//! level in the bounding box). Pieces with a non-finite value stay unpaired (binary16 cannot carry
//! them with a per-piece scale). The search is over all instance pairs (`O(n²)`; n ≈ 130
//! at 256²/100, ≈ 520 at 256²/400).
//!
//! # Limits
//! Pair pages are at most [`PAGE_WIDTH_MAX`] wide and at most the device's 2D limit high;
//! 16 bytes per pair texel (the bounding box's area, texels outside both rectangles included).

use bytemuck::{Pod, Zeroable};

use crate::error::PassError;
use crate::schedule::{AtlasBatch, FrameSchedule, PieceInstance};
use crate::types::AtlasData;

/// Cost of one pair fragment in units of one single-piece fragment, for the pairing rule:
/// estimated from the measured per-fragment costs on lavapipe (`docs/render.md`: the blend
/// ~3.5 ns, each `textureLoad` ~2.5 ns of CPU).
pub const PAIR_FRAGMENT_COST: f64 = 1.3;

/// Widest pair page in texels (narrower when the device limit is smaller).
pub const PAGE_WIDTH_MAX: u32 = 2048;

/// One pair as the GPU sees it. 64 bytes (a multiple of 16).
/// Must match the instance attributes (locations 0–7) of `shaders/transfer_pair.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct PairInstance {
    /// Top-left texel of the pair's rectangle in its page.
    pub src: [u32; 2],
    /// Top-left lightmap texel of the bounding box of both destination rectangles.
    pub dst: [u32; 2],
    /// Bounding-box width and height in texels.
    pub size: [u32; 2],
    /// Piece A's `Δt` in texels (`+y` down).
    pub offset_a: [i32; 2],
    /// Piece B's `Δt` in texels.
    pub offset_b: [i32; 2],
    /// `[2^−k_A, 2^−k_B]`: multiply the decoded binary16 values by these.
    pub scale: [f32; 2],
    /// Pyramid level `ℓ` of both pieces (only pieces of equal level are paired).
    pub level: u32,
    /// Padding (0).
    pub _pad: u32,
    /// Origin of level `ℓ` in the packed pyramid texture (`(0, 0)` at level 0).
    pub origin: [u32; 2],
}

/// One RGBA32Uint texture of pair texels and the pairs drawn from it.
#[derive(Clone, Debug, PartialEq)]
pub struct PairPage {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width·height` texels, row-major (layout in the module docs; 0 where no pair lies).
    /// Empty in a prepared `TransferScene` (uploaded, then dropped).
    pub texels: Vec<[u32; 4]>,
    /// The pairs stored in this page.
    pub instances: Vec<PairInstance>,
}

/// The frame's transfer work with pairs.
#[derive(Clone, Debug, PartialEq)]
pub struct PairedSchedule {
    /// Lightmap `[width, height]`.
    pub lightmap_size: [u32; 2],
    /// Instances left unpaired, per atlas (drawn by the ordinary blend path).
    pub singles: FrameSchedule,
    /// Pair pages.
    pub pages: Vec<PairPage>,
    /// Number of pairs.
    pub pairs: usize,
}

impl PairedSchedule {
    /// Fragments shaded per frame by the pieces (pair bounding boxes + unpaired pieces):
    /// the number of blends into the accumulation target.
    pub fn fragments(&self) -> u64 {
        self.singles.texel_blends()
            + self
                .pages
                .iter()
                .flat_map(|p| &p.instances)
                .map(|i| i.size[0] as u64 * i.size[1] as u64)
                .sum::<u64>()
    }
}

/// Round-to-nearest-even f32 → IEEE binary16 bits (subnormals, ±∞, NaN handled).
pub fn f32_to_f16(x: f32) -> u16 {
    let sign = ((x.to_bits() >> 16) & 0x8000) as u16;
    let a = x.abs();
    if a.is_nan() {
        return sign | 0x7e00;
    }
    if a >= 65520.0 {
        return sign | 0x7c00; // rounds to infinity
    }
    if a < 2f32.powi(-14) {
        // Subnormal (or zero): a = m·2^−24; m = 1024 is the smallest normal, encoded alike.
        let m = (a as f64 * 2f64.powi(24)).round_ties_even() as u16;
        return sign | m;
    }
    let bits = a.to_bits();
    let e = (bits >> 23) as i32 - 127; // −14 ..= 15
    let mant = bits & 0x7f_ffff;
    let mut h = (((e + 15) as u32) << 10) | (mant >> 13);
    let rem = mant & 0x1fff;
    if rem > 0x1000 || (rem == 0x1000 && h & 1 == 1) {
        h += 1; // a carry into the exponent is the correct rounding
    }
    sign | h as u16
}

/// [`f32_to_f16`] without subnormal results: magnitudes below `2^−14` (the smallest normal)
/// become 0 or `±2^−14`, whichever is nearer (ties to `2^−14`).
pub fn f32_to_f16_normal(x: f32) -> u16 {
    if x.abs() < 2f32.powi(-14) {
        let sign = ((x.to_bits() >> 16) & 0x8000) as u16;
        return sign | if x.abs() >= 2f32.powi(-15) { 0x0400 } else { 0 };
    }
    f32_to_f16(x)
}

/// The power of two `k` with `m·2^k ∈ [2^14, 2^15)` for `m > 0` finite, clamped to
/// `[−126, 126]` so `2^k` and `2^−k` are normal f32; 0 for `m = 0`.
pub fn scale_exponent(m: f32) -> i32 {
    if m <= 0.0 || !m.is_finite() {
        return 0;
    }
    let e = (m as f64).log2().floor() as i32;
    // Correct a floor off by one from log2 rounding.
    let e = if 2f64.powi(e) > m as f64 {
        e - 1
    } else if 2f64.powi(e + 1) <= m as f64 {
        e + 1
    } else {
        e
    };
    (14 - e).clamp(-126, 126)
}

/// Pairs the instances of `schedule` (see the module docs) and packs the pairs into pages
/// at most `max_side` texels high (the device's 2D limit).
pub fn pair_schedule(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    max_side: u32,
) -> Result<PairedSchedule, PassError> {
    let items: Vec<(u32, PieceInstance)> = schedule
        .batches
        .iter()
        .flat_map(|b| b.instances.iter().map(move |i| (b.atlas, *i)))
        .collect();
    let max_abs = items
        .iter()
        .enumerate()
        .map(|(k, (a, inst))| piece_max_abs(k, *a, inst, atlases))
        .collect::<Result<Vec<f32>, PassError>>()?;
    let pairs = greedy_pairs(&items, &max_abs);
    let mut used = vec![false; items.len()];
    for &(i, j) in &pairs {
        used[i] = true;
        used[j] = true;
    }
    let singles = singles(schedule, &items, &used);
    let page_w = PAGE_WIDTH_MAX.min(max_side);
    let boxes: Vec<([u32; 2], [u32; 2])> = pairs
        .iter()
        .map(|&(i, j)| bbox(&items[i].1, &items[j].1))
        .collect();
    let (order, place, page_heights) = shelf_pack(&boxes, page_w, max_side)?;
    let mut pages: Vec<PairPage> = page_heights
        .iter()
        .map(|&h| PairPage {
            width: page_w,
            height: h,
            texels: vec![[0; 4]; page_w as usize * h as usize],
            instances: Vec::new(),
        })
        .collect();
    for &p in &order {
        let (i, j) = pairs[p];
        let (page, px, py) = place[p];
        let a = (&items[i], scale_exponent(max_abs[i]));
        let b = (&items[j], scale_exponent(max_abs[j]));
        write_pair(&mut pages[page], [px, py], boxes[p], a, b, atlases);
    }
    Ok(PairedSchedule {
        lightmap_size: schedule.lightmap_size,
        singles,
        pages,
        pairs: pairs.len(),
    })
}

/// The largest `|value|` of instance `k` (reading `atlas`; ∞ when one is not finite),
/// after checking that its source rectangle lies inside the atlas.
fn piece_max_abs(
    k: usize,
    a: u32,
    inst: &PieceInstance,
    atlases: &[AtlasData],
) -> Result<f32, PassError> {
    let atlas = atlases
        .get(a as usize)
        .ok_or_else(|| PassError::InvalidInput {
            what: format!("schedule instance {k}"),
            problem: format!("names atlas {a} but only {} were given", atlases.len()),
        })?;
    let inside = atlas.rgb.len() == atlas.width as usize * atlas.height as usize
        && inst.src[0] as u64 + inst.size[0] as u64 <= atlas.width as u64
        && inst.src[1] as u64 + inst.size[1] as u64 <= atlas.height as u64;
    if !inside {
        return Err(PassError::InvalidInput {
            what: format!("schedule instance {k}"),
            problem: format!(
                "its source rectangle ({}, {}) + {}×{} is not inside atlas {a} ({}×{}, {} \
                 values); build the schedule from these atlases",
                inst.src[0],
                inst.src[1],
                inst.size[0],
                inst.size[1],
                atlas.width,
                atlas.height,
                atlas.rgb.len()
            ),
        });
    }
    let mut m = 0f32;
    for j in 0..inst.size[1] {
        let row = ((inst.src[1] + j) * atlas.width + inst.src[0]) as usize;
        for v in &atlas.rgb[row..row + inst.size[0] as usize] {
            for c in v {
                m = m.max(if c.is_finite() {
                    c.abs()
                } else {
                    f32::INFINITY
                });
            }
        }
    }
    Ok(m)
}

/// `(origin, size)` of the bounding box of two instances' destination rectangles.
fn bbox(p: &PieceInstance, q: &PieceInstance) -> ([u32; 2], [u32; 2]) {
    let x0 = p.dst[0].min(q.dst[0]);
    let y0 = p.dst[1].min(q.dst[1]);
    let x1 = (p.dst[0] + p.size[0]).max(q.dst[0] + q.size[0]);
    let y1 = (p.dst[1] + p.size[1]).max(q.dst[1] + q.size[1]);
    ([x0, y0], [x1 - x0, y1 - y0])
}

/// The pairing rule of the module docs: every pair of finite instances with a positive
/// saving, taken greedily by saving (ties by index); returns `(i, j)` index pairs.
fn greedy_pairs(items: &[(u32, PieceInstance)], max_abs: &[f32]) -> Vec<(usize, usize)> {
    let area = |i: &PieceInstance| i.size[0] as f64 * i.size[1] as f64;
    let mut candidates: Vec<(f64, u32, u32)> = Vec::new();
    for i in 0..items.len() {
        if !max_abs[i].is_finite() {
            continue;
        }
        for j in i + 1..items.len() {
            if !max_abs[j].is_finite() {
                continue;
            }
            let (p, q) = (&items[i].1, &items[j].1);
            // Pairs share one read formula per level; receiver-block pieces stay single.
            if p.level != q.level || p.receiver_level != 0 || q.receiver_level != 0 {
                continue;
            }
            let (_, s) = bbox(p, q);
            let saving = area(p) + area(q) - PAIR_FRAGMENT_COST * s[0] as f64 * s[1] as f64;
            if saving > 0.0 {
                candidates.push((saving, i as u32, j as u32));
            }
        }
    }
    candidates.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(&b.1)).then(a.2.cmp(&b.2)));
    let mut used = vec![false; items.len()];
    let mut pairs: Vec<(usize, usize)> = Vec::new();
    for (_, i, j) in candidates {
        let (i, j) = (i as usize, j as usize);
        if !used[i] && !used[j] {
            used[i] = true;
            used[j] = true;
            pairs.push((i, j));
        }
    }
    pairs
}

/// The unpaired instances (`!used`) per atlas, in input order.
fn singles(
    schedule: &FrameSchedule,
    items: &[(u32, PieceInstance)],
    used: &[bool],
) -> FrameSchedule {
    let mut singles = FrameSchedule {
        lightmap_size: schedule.lightmap_size,
        batches: Vec::new(),
        receiver_levels: schedule.receiver_levels,
    };
    for (k, (a, inst)) in items.iter().enumerate() {
        if used[k] {
            continue;
        }
        match singles.batches.last_mut() {
            Some(b) if b.atlas == *a => b.instances.push(*inst),
            _ => singles.batches.push(AtlasBatch {
                atlas: *a,
                instances: vec![*inst],
            }),
        }
    }
    singles
}

/// Shelf packing of the pairs' bounding `boxes` into pages `page_w` wide and at most
/// `max_side` high, tallest first. Returns the packing order, `(page, x, y)` per pair and
/// each page's height.
#[allow(
    clippy::type_complexity,
    reason = "three parallel results of one packing"
)]
fn shelf_pack(
    boxes: &[([u32; 2], [u32; 2])],
    page_w: u32,
    max_side: u32,
) -> Result<(Vec<usize>, Vec<(usize, u32, u32)>, Vec<u32>), PassError> {
    let mut order: Vec<usize> = (0..boxes.len()).collect();
    order.sort_by(|&a, &b| boxes[b].1[1].cmp(&boxes[a].1[1]).then(a.cmp(&b)));
    let mut place = vec![(0usize, 0u32, 0u32); boxes.len()];
    let mut page_heights: Vec<u32> = Vec::new();
    let (mut x, mut y, mut shelf_h) = (0u32, 0u32, 0u32);
    for &p in &order {
        let [w, h] = boxes[p].1;
        if w > page_w || h > max_side {
            return Err(PassError::TooLarge {
                what: format!("pair bounding box ({w}×{h})"),
                size: w.max(h) as u64,
                limit: page_w.min(max_side) as u64,
            });
        }
        if page_heights.is_empty() {
            page_heights.push(0);
        }
        if x + w > page_w {
            y += shelf_h;
            x = 0;
            shelf_h = 0;
        }
        if y + h > max_side {
            page_heights.push(0);
            x = 0;
            y = 0;
            shelf_h = 0;
        }
        let page = page_heights.len() - 1;
        place[p] = (page, x, y);
        x += w;
        shelf_h = shelf_h.max(h);
        page_heights[page] = page_heights[page].max(y + h);
    }
    Ok((order, place, page_heights))
}

/// Writes one pair's texels (layout in the module docs) at `origin` of `page` and appends
/// its instance. `(dst, size)` is the pair's bounding box; `a` and `b` are the two
/// `((atlas, instance), scale exponent)`.
fn write_pair(
    page: &mut PairPage,
    origin: [u32; 2],
    (dst, size): ([u32; 2], [u32; 2]),
    a: (&(u32, PieceInstance), i32),
    b: (&(u32, PieceInstance), i32),
    atlases: &[AtlasData],
) {
    let (((ai, ia), ka), ((bi, ib), kb)) = (a, b);
    let value = |atlas: u32, inst: &PieceInstance, k: i32, t: [u32; 2]| -> [u16; 3] {
        let inside = t[0] >= inst.dst[0]
            && t[1] >= inst.dst[1]
            && t[0] < inst.dst[0] + inst.size[0]
            && t[1] < inst.dst[1] + inst.size[1];
        if !inside {
            return [0; 3];
        }
        let at = &atlases[atlas as usize];
        let s = (inst.src[1] + t[1] - inst.dst[1]) * at.width + inst.src[0] + t[0] - inst.dst[0];
        let s2 = 2f32.powi(k);
        at.rgb[s as usize].map(|c| f32_to_f16_normal(c * s2))
    };
    let [px, py] = origin;
    for jj in 0..size[1] {
        for ii in 0..size[0] {
            let t = [dst[0] + ii, dst[1] + jj];
            let va = value(*ai, ia, ka, t);
            let vb = value(*bi, ib, kb, t);
            let lo_hi = |l: u16, h: u16| l as u32 | (h as u32) << 16;
            page.texels[((py + jj) * page.width + px + ii) as usize] = [
                lo_hi(va[0], va[1]),
                lo_hi(va[2], vb[0]),
                lo_hi(vb[1], vb[2]),
                0,
            ];
        }
    }
    page.instances.push(PairInstance {
        src: origin,
        dst,
        size,
        offset_a: ia.offset,
        offset_b: ib.offset,
        scale: [2f32.powi(-ka), 2f32.powi(-kb)],
        level: ia.level,
        _pad: 0,
        origin: ia.origin,
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::f16_to_f32;

    #[test]
    fn pair_instance_size() {
        assert_eq!(std::mem::size_of::<PairInstance>(), 64);
    }

    #[test]
    fn f16_encoding_round_trips_and_rounds_to_nearest() {
        for h in 0u16..=0xffff {
            let v = f16_to_f32(h);
            if v.is_nan() {
                continue;
            }
            assert_eq!(f32_to_f16(v), h, "round trip of {h:#06x}");
        }
        // Between consecutive finite positive binary16 values: below the midpoint → lower,
        // above → upper, at it → the even one.
        for h in 0u16..0x7bff {
            let (lo, hi) = (f16_to_f32(h) as f64, f16_to_f32(h + 1) as f64);
            let mid = (lo + hi) / 2.0;
            let below = ((mid + lo) / 2.0) as f32;
            let above = ((mid + hi) / 2.0) as f32;
            assert_eq!(f32_to_f16(below), h);
            assert_eq!(f32_to_f16(above), h + 1);
            let even = if h % 2 == 0 { h } else { h + 1 };
            assert_eq!(f32_to_f16(mid as f32), even, "midpoint after {h:#06x}");
        }
        assert_eq!(f32_to_f16(1e6), 0x7c00);
        assert_eq!(f32_to_f16(-1e6), 0xfc00);
        // No subnormals from the pair encoder: nearest of 0 and ±2^−14 below 2^−14.
        let min_normal = 2f32.powi(-14);
        assert_eq!(f32_to_f16_normal(0.49 * min_normal), 0);
        assert_eq!(f32_to_f16_normal(0.5 * min_normal), 0x0400);
        assert_eq!(f32_to_f16_normal(-0.9 * min_normal), 0x8400);
        assert_eq!(f32_to_f16_normal(1.5), f32_to_f16(1.5));
        for h in 1u16..0x0400 {
            let v = f16_to_f32(h);
            let e = f16_to_f32(f32_to_f16_normal(v));
            assert!((e - v).abs() <= 2f32.powi(-15), "{h:#06x}");
        }
    }

    #[test]
    fn scale_exponent_puts_the_maximum_in_range() {
        for m in [
            1e-30f32, 3e-9, 0.1, 0.5, 1.0, 1.5, 16383.9, 16384.0, 32767.0, 1e20,
        ] {
            let k = scale_exponent(m);
            let s = m as f64 * 2f64.powi(k);
            assert!(
                (16384.0..32768.0).contains(&s),
                "m = {m}: k = {k}, m·2^k = {s}"
            );
        }
        assert_eq!(scale_exponent(0.0), 0);
    }

    fn inst(dst: [u32; 2], size: [u32; 2], src: [u32; 2]) -> PieceInstance {
        PieceInstance {
            src,
            dst,
            size,
            offset: [0, 0],
            ..Default::default()
        }
    }

    /// Pieces of different levels are never paired; equal levels pair and carry the level.
    #[test]
    fn pairs_only_equal_levels() {
        let atlas = AtlasData {
            width: 32,
            height: 32,
            rgb: vec![[0.5; 3]; 32 * 32],
        };
        let mut a = inst([0, 0], [8, 8], [0, 0]);
        let mut b = inst([1, 0], [8, 8], [8, 0]);
        a.level = 2;
        a.origin = [5, 7];
        b.level = 1;
        let mut s = FrameSchedule {
            lightmap_size: [16, 16],
            batches: vec![AtlasBatch {
                atlas: 0,
                instances: vec![a, b],
            }],
            receiver_levels: 0,
        };
        let p = pair_schedule(&s, std::slice::from_ref(&atlas), 64).unwrap();
        assert_eq!(p.pairs, 0);
        b.level = 2;
        b.origin = [5, 7];
        s.batches[0].instances[1] = b;
        let p = pair_schedule(&s, &[atlas], 64).unwrap();
        assert_eq!(p.pairs, 1);
        let pi = p.pages[0].instances[0];
        assert_eq!((pi.level, pi.origin), (2, [5, 7]));
    }

    #[test]
    fn pairs_overlapping_pieces_and_leaves_disjoint_ones() {
        // Two 8×8 pieces overlapping in 6×8 (bbox 10×8: saves 128 − 1.3·80 > 0), and one far
        // away 2×2 piece (pairing it with either would shade a big empty box).
        let atlas = AtlasData {
            width: 32,
            height: 32,
            rgb: (0..32 * 32).map(|i| [i as f32, 1.0, 0.5]).collect(),
        };
        let s = FrameSchedule {
            lightmap_size: [64, 64],
            batches: vec![AtlasBatch {
                atlas: 0,
                instances: vec![
                    inst([0, 0], [8, 8], [0, 0]),
                    inst([40, 40], [2, 2], [20, 20]),
                    inst([2, 0], [8, 8], [8, 0]),
                ],
            }],
            receiver_levels: 0,
        };
        let p = pair_schedule(&s, std::slice::from_ref(&atlas), 8192).unwrap();
        assert_eq!(p.pairs, 1);
        assert_eq!(
            p.singles.batches[0].instances,
            vec![s.batches[0].instances[1]]
        );
        assert_eq!(p.fragments(), 80 + 4);
        let page = &p.pages[0];
        let pi = page.instances[0];
        assert_eq!((pi.dst, pi.size), ([0, 0], [10, 8]));
        // Decode every texel of the pair and compare with the atlas values (exactly
        // representable here after the power-of-two scale, except the largest which round).
        for j in 0..8u32 {
            for i in 0..10u32 {
                let tx = page.texels[((pi.src[1] + j) * page.width + pi.src[0] + i) as usize];
                let h = |w: u32, hi: bool| f16_to_f32(if hi { (w >> 16) as u16 } else { w as u16 });
                let a = [h(tx[0], false), h(tx[0], true), h(tx[1], false)].map(|v| v * pi.scale[0]);
                let b = [h(tx[1], true), h(tx[2], false), h(tx[2], true)].map(|v| v * pi.scale[1]);
                let want = |x0: u32, sx: u32| -> [f32; 3] {
                    if i < x0 || i >= x0 + 8 {
                        [0.0; 3]
                    } else {
                        atlas.rgb[(j * 32 + sx + i - x0) as usize]
                    }
                };
                let (wa, wb) = (want(0, 0), want(2, 8));
                for c in 0..3 {
                    assert!(
                        (a[c] - wa[c]).abs() <= wa[c].abs() * 2f32.powi(-11),
                        "a {i},{j}"
                    );
                    assert!(
                        (b[c] - wb[c]).abs() <= wb[c].abs() * 2f32.powi(-11),
                        "b {i},{j}"
                    );
                }
            }
        }
    }

    #[test]
    fn instances_outside_their_atlas_are_an_error() {
        let atlas = AtlasData {
            width: 4,
            height: 4,
            rgb: vec![[1.0; 3]; 16],
        };
        let s = FrameSchedule {
            lightmap_size: [8, 8],
            batches: vec![AtlasBatch {
                atlas: 0,
                instances: vec![inst([0, 0], [3, 3], [2, 0])],
            }],
            receiver_levels: 0,
        };
        assert!(pair_schedule(&s, std::slice::from_ref(&atlas), 64).is_err());
        let mut one = s.clone();
        one.batches[0].instances[0].src = [1, 1];
        assert!(pair_schedule(&one, &[atlas], 64).is_ok());
        assert!(pair_schedule(&one, &[], 64).is_err());
    }

    #[test]
    fn shelf_packing_keeps_pairs_apart_and_inside_pages() {
        let atlas = AtlasData {
            width: 64,
            height: 64,
            rgb: vec![[1.0; 3]; 64 * 64],
        };
        let mut instances = Vec::new();
        for k in 0..20u32 {
            let w = 5 + k % 7;
            let h = 3 + k % 5;
            instances.push(inst([k, k], [w, h], [0, 0]));
            instances.push(inst([k + 1, k], [w, h], [0, 0]));
        }
        let s = FrameSchedule {
            lightmap_size: [64, 64],
            batches: vec![AtlasBatch {
                atlas: 0,
                instances,
            }],
            receiver_levels: 0,
        };
        // A tiny device limit forces several shelves and pages.
        let p = pair_schedule(&s, &[atlas], 24).unwrap();
        assert!(p.pages.len() > 1);
        for page in &p.pages {
            assert!(page.width <= 24 && page.height <= 24);
            let mut owner = vec![usize::MAX; (page.width * page.height) as usize];
            for (n, i) in page.instances.iter().enumerate() {
                assert!(i.src[0] + i.size[0] <= page.width && i.src[1] + i.size[1] <= page.height);
                for y in i.src[1]..i.src[1] + i.size[1] {
                    for x in i.src[0]..i.src[0] + i.size[0] {
                        let o = &mut owner[(y * page.width + x) as usize];
                        assert_eq!(*o, usize::MAX, "pairs overlap in a page");
                        *o = n;
                    }
                }
            }
        }
        let drawn: usize = p.pages.iter().map(|pg| pg.instances.len()).sum();
        assert_eq!(drawn, p.pairs);
        let singles: usize = p.singles.batches.iter().map(|b| b.instances.len()).sum();
        assert_eq!(2 * p.pairs + singles, 40);
    }
}
