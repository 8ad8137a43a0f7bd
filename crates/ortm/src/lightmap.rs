//! Texture-space images shared by every stage: the [`Lightmap`] (RGB, linear, W/m²) and the
//! texel-centre convention.
//!
//! # Conventions
//! - A `W×H` lightmap is stored row-major, row 0 first. Texel `(x, y)` has its centre at
//!   `u = (x + 0.5) / W`, `v = 1 − (y + 0.5) / H`: row 0 is `v = 1`, as in image files
//!   (PNG, OpenEXR) and as wgpu's framebuffer rows.
//! - Values are radiosity `B = π·L_out` in W/m², linear RGB. First-order `B_o = ρ·E`.
//! - A texel is *covered* when its centre lies inside a UV triangle (the GPU rasterizer's rule;
//!   the bake's texel grid applies it with the top-left tie-break).

use glam::{IVec2, Vec2};

/// A linear RGB image in texture space. Units depend on the use: W/m² for lightmaps,
/// dimensionless for transfer maps.
#[derive(Clone, Debug, PartialEq)]
pub struct Lightmap {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width * height` RGB values, row-major, row 0 is `v = 1`.
    pub data: Vec<[f32; 3]>,
}

impl Lightmap {
    /// A black (all-zero) map.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            data: vec![[0.0; 3]; width as usize * height as usize],
        }
    }

    /// Linear index of texel `(x, y)`.
    #[inline]
    pub fn index(&self, x: u32, y: u32) -> usize {
        y as usize * self.width as usize + x as usize
    }

    /// Value at texel `(x, y)`.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> [f32; 3] {
        self.data[self.index(x, y)]
    }

    /// Value at `p`, or `None` outside the map.
    #[inline]
    pub fn get_checked(&self, p: IVec2) -> Option<[f32; 3]> {
        if p.x < 0 || p.y < 0 || p.x >= self.width as i32 || p.y >= self.height as i32 {
            None
        } else {
            Some(self.get(p.x as u32, p.y as u32))
        }
    }

    /// Sets texel `(x, y)`.
    #[inline]
    pub fn set(&mut self, x: u32, y: u32, v: [f32; 3]) {
        let i = self.index(x, y);
        self.data[i] = v;
    }
}

/// UV coordinate of the centre of texel `(x, y)` in a `width×height` map
/// (`u = (x+0.5)/W`, `v = 1 − (y+0.5)/H`); the tests' reference for [`uv_to_texel_space`].
#[cfg(test)]
pub fn texel_center_uv(x: u32, y: u32, width: u32, height: u32) -> Vec2 {
    Vec2::new(
        (x as f32 + 0.5) / width as f32,
        1.0 - (y as f32 + 0.5) / height as f32,
    )
}

/// Continuous texel-space coordinate of a UV point: `(u·W, (1−v)·H)`; texel `(x, y)` covers
/// `[x, x+1) × [y, y+1)` and its centre is `(x+0.5, y+0.5)`.
#[inline]
pub fn uv_to_texel_space(uv: Vec2, width: u32, height: u32) -> Vec2 {
    Vec2::new(uv.x * width as f32, (1.0 - uv.y) * height as f32)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texel_centre_round_trip() {
        let (w, h) = (8, 4);
        for y in 0..h {
            for x in 0..w {
                let uv = texel_center_uv(x, y, w, h);
                let p = uv_to_texel_space(uv, w, h);
                assert!((p.x - (x as f32 + 0.5)).abs() < 1e-5);
                assert!((p.y - (y as f32 + 0.5)).abs() < 1e-5);
            }
        }
        // Row 0 is v = 1 (top of the UV square).
        assert!(texel_center_uv(0, 0, w, h).y > 0.5);
    }
}
