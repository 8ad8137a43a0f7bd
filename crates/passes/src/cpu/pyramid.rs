//! CPU mirror of the pyramid pass (`shaders/pyramid.wgsl`, [`crate::pyramid`]).
//!
//! Same 2×2 reductions as the shader: level 1 sums `(w·B_o, w)` over each block's in-map
//! texels, level `ℓ ≥ 2` sums level `ℓ − 1`'s in-level blocks; a block's mean is
//! `Σ w·B / Σ w` (0 where `Σ w = 0`). The sums are `f64` (as `ortm::maps::levels`), rounded
//! once to `f32`; the GPU's `f32` sums are compared with a derived bound (`tests/pyramid.rs`).

use crate::pyramid::level_size;
use crate::types::{TexelImage, TexelWeights};

/// Levels `1..=max_level` of the pyramid of `first_order` (RGB) with texel `weights`: index
/// `ℓ − 1` holds level `ℓ`, `⌈W/2^ℓ⌉ × ⌈H/2^ℓ⌉` blocks, RGB = mean (W/m²), alpha = `Σ w` (m²).
/// Level 0 is `first_order` itself (not repeated). `weights` must match `first_order`'s size.
pub fn pyramid(
    first_order: &TexelImage,
    weights: &TexelWeights,
    max_level: u32,
) -> Vec<TexelImage> {
    let size = [first_order.width, first_order.height];
    assert_eq!(
        [weights.width, weights.height],
        size,
        "weights must match the lightmap"
    );
    // Level 0 sums: (w·B, w) per texel.
    let mut sums: Vec<[f64; 4]> = first_order
        .rgba
        .iter()
        .zip(&weights.weights)
        .map(|(b, &w)| {
            let w = w as f64;
            [w * b[0] as f64, w * b[1] as f64, w * b[2] as f64, w]
        })
        .collect();
    let mut out = Vec::new();
    for l in 1..=max_level {
        // cs_reduce: each block sums its in-level children of level l − 1.
        let [sw, sh] = level_size(size, l - 1);
        let [dw, dh] = level_size(size, l);
        let mut next = vec![[0.0f64; 4]; (dw * dh) as usize];
        for by in 0..dh {
            for bx in 0..dw {
                let s = &mut next[(by * dw + bx) as usize];
                for dy in 0..2 {
                    for dx in 0..2 {
                        let (cx, cy) = (2 * bx + dx, 2 * by + dy);
                        if cx >= sw || cy >= sh {
                            continue;
                        }
                        let c = sums[(cy * sw + cx) as usize];
                        for k in 0..4 {
                            s[k] += c[k];
                        }
                    }
                }
            }
        }
        let mut img = TexelImage::new(dw, dh);
        for (px, s) in img.rgba.iter_mut().zip(&next) {
            let mean = if s[3] > 0.0 {
                [s[0] / s[3], s[1] / s[3], s[2] / s[3]]
            } else {
                [0.0; 3]
            };
            *px = [mean[0] as f32, mean[1] as f32, mean[2] as f32, s[3] as f32];
        }
        out.push(img);
        sums = next;
    }
    out
}

/// `P_level` at signed block `(x, y)` (RGBA; 0 outside the level): `first_order` for level 0,
/// `levels[level − 1]` (as returned by [`pyramid`] or read back from the GPU) above.
///
/// Panics when `level > levels.len()` (a piece of a level the pyramid does not hold).
#[inline]
pub fn read(
    first_order: &TexelImage,
    levels: &[TexelImage],
    level: u32,
    x: i32,
    y: i32,
) -> [f32; 4] {
    if level == 0 {
        first_order.get_or_zero(x, y)
    } else {
        let img = levels.get(level as usize - 1).unwrap_or_else(|| {
            panic!(
                "a piece of level {level} but the pyramid holds levels 1..={}",
                levels.len()
            )
        });
        img.get_or_zero(x, y)
    }
}
