//! CPU mirror of the gutter-dilation pass (`shaders/dilate.wgsl`): per iteration, every
//! empty texel (alpha 0) with non-empty 8-neighbours becomes their mean with alpha
//! [`FILLED_ALPHA`]; non-empty texels are copied unchanged.

use crate::dilate::FILLED_ALPHA;
use crate::types::TexelImage;

/// `iterations` rounds of dilation.
pub fn dilate(src: &TexelImage, iterations: u32) -> TexelImage {
    let mut cur = src.clone();
    for _ in 0..iterations {
        let mut next = cur.clone();
        for y in 0..cur.height as i32 {
            for x in 0..cur.width as i32 {
                let c = cur.get(x as u32, y as u32);
                if c[3] > 0.0 {
                    continue; // copied unchanged
                }
                let mut sum = [0.0f32; 3];
                let mut n = 0.0f32;
                for dy in -1..=1 {
                    for dx in -1..=1 {
                        let (qx, qy) = (x + dx, y + dy);
                        if (dx == 0 && dy == 0)
                            || qx < 0
                            || qy < 0
                            || qx >= cur.width as i32
                            || qy >= cur.height as i32
                        {
                            continue;
                        }
                        let v = cur.get(qx as u32, qy as u32);
                        if v[3] > 0.0 {
                            for k in 0..3 {
                                sum[k] += v[k];
                            }
                            n += 1.0;
                        }
                    }
                }
                *next.at_mut(x as u32, y as u32) = if n > 0.0 {
                    [sum[0] / n, sum[1] / n, sum[2] / n, FILLED_ALPHA]
                } else {
                    [0.0; 4]
                };
            }
        }
        cur = next;
    }
    cur
}
