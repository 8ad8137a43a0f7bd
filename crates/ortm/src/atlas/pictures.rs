//! Pictures of an atlas for people: the packing ([`packing_image`], each piece in its map's
//! colour with its map index) and the values ([`atlas_values_image`], tone-mapped).

use image::{Rgb, RgbImage};

use super::AtlasSet;
use crate::Lightmap;

/// Colour of map `map_index` in [`packing_image`]: a hash of the index, mid-bright.
pub fn map_color(map_index: u32) -> Rgb<u8> {
    // SplitMix64 finaliser: neighbouring indices get unrelated colours.
    let mut z = u64::from(map_index).wrapping_add(0x9e37_79b9_7f4a_7c15);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    let c = |k: u32| 70 + ((z >> (8 * k)) & 0xff) as u8 % 170;
    Rgb([c(0), c(1), c(2)])
}

/// Background of [`packing_image`] (atlas texels outside every piece).
pub const PACKING_BACKGROUND: Rgb<u8> = Rgb([24, 24, 24]);

/// 3×5 digit glyphs, one row per `u8` (bit 2 = left column).
const DIGITS: [[u8; 5]; 10] = [
    [0b111, 0b101, 0b101, 0b101, 0b111],
    [0b010, 0b110, 0b010, 0b010, 0b111],
    [0b111, 0b001, 0b111, 0b100, 0b111],
    [0b111, 0b001, 0b111, 0b001, 0b111],
    [0b101, 0b101, 0b111, 0b001, 0b001],
    [0b111, 0b100, 0b111, 0b001, 0b111],
    [0b111, 0b100, 0b111, 0b101, 0b111],
    [0b111, 0b001, 0b001, 0b001, 0b001],
    [0b111, 0b101, 0b111, 0b101, 0b111],
    [0b111, 0b101, 0b111, 0b001, 0b111],
];

/// Pixels per atlas texel in [`packing_image`]: small atlases are enlarged to about 512 pixels
/// (at most 16×), large ones drawn 1:1.
pub fn packing_scale(atlas_size: (u32, u32)) -> u32 {
    (512 / atlas_size.0.max(atlas_size.1).max(1)).clamp(1, 16)
}

/// A picture of atlas `atlas`'s packing for people: each piece filled with its map's
/// [`map_color`], outlined one pixel darker, and labelled with its map index (3×5 digits,
/// scaled up to 8×) where the piece is big enough; free texels are [`PACKING_BACKGROUND`].
/// Each atlas texel is [`packing_scale`] pixels square. `None` if the atlas does not exist.
pub fn packing_image(set: &AtlasSet, atlas: u32) -> Option<RgbImage> {
    if atlas as usize >= set.atlases.len() {
        return None;
    }
    let k = packing_scale(set.atlas_size);
    let (iw, ih) = (set.atlas_size.0 * k, set.atlas_size.1 * k);
    let mut img = RgbImage::from_pixel(iw, ih, PACKING_BACKGROUND);
    for p in set.pieces.iter().filter(|p| p.atlas == atlas) {
        let fill = map_color(p.map_index);
        let edge = Rgb(fill.0.map(|c| (u16::from(c) * 9 / 20) as u8));
        let (x0, y0, pw, ph) = (p.src_x * k, p.src_y * k, p.w * k, p.h * k);
        for y in y0..(y0 + ph).min(ih) {
            for x in x0..(x0 + pw).min(iw) {
                let border = x == x0 || y == y0 || x + 1 == x0 + pw || y + 1 == y0 + ph;
                img.put_pixel(x, y, if border { edge } else { fill });
            }
        }
        let label = p.map_index.to_string();
        let n = label.len() as u32;
        let (tw, th) = (4 * n - 1, 5);
        let s = ((pw.saturating_sub(4)) / tw)
            .min(ph.saturating_sub(4) / th)
            .min(8);
        if s == 0 {
            continue;
        }
        let luma = 299 * u32::from(fill[0]) + 587 * u32::from(fill[1]) + 114 * u32::from(fill[2]);
        let ink = if luma > 128_000 {
            Rgb([0, 0, 0])
        } else {
            Rgb([255, 255, 255])
        };
        let lx = x0 + (pw - tw * s) / 2;
        let ly = y0 + (ph - th * s) / 2;
        for (d, ch) in label.bytes().enumerate() {
            let glyph = DIGITS[usize::from(ch - b'0')];
            for (row, bits) in glyph.iter().enumerate() {
                for col in 0..3u32 {
                    if bits >> (2 - col) & 1 == 0 {
                        continue;
                    }
                    let gx = lx + (d as u32 * 4 + col) * s;
                    let gy = ly + row as u32 * s;
                    for yy in gy..gy + s {
                        for xx in gx..gx + s {
                            img.put_pixel(xx, yy, ink);
                        }
                    }
                }
            }
        }
    }
    Some(img)
}

/// A tone-mapped picture of atlas `atlas`'s values (linear RGB scaled so the 99th percentile of
/// the non-zero texels is white, sRGB-encoded), each texel [`packing_scale`] pixels square like
/// [`packing_image`]. `None` if the atlas does not exist.
pub fn atlas_values_image(set: &AtlasSet, atlas: u32) -> Option<RgbImage> {
    let data = set.atlases.get(atlas as usize)?;
    let map = Lightmap {
        width: set.atlas_size.0,
        height: set.atlas_size.1,
        data: data.clone(),
    };
    let white = crate::bake::report::percentile_99(&map);
    let texels = crate::bake::report::lightmap_image(&map, white);
    let k = packing_scale(set.atlas_size);
    Some(RgbImage::from_fn(map.width * k, map.height * k, |x, y| {
        *texels.get_pixel(x / k, y / k)
    }))
}
