//! [`TransferMap`]: one offset transfer map `TR(t, t+Δt)·TVA(t, Δt)` (paper Eq. 10), stored
//! cropped.
//!
//! # Data
//! - `offset` `Δt` in texels (`+y` goes down the image), `voronoi_area` `|V(Δt, O)|` in the
//!   offset sampler's normalised units (informational: it is already folded into the values via
//!   `TVA`), `importance` (the sampler's weight for this offset, informational).
//! - Values are dimensionless RGB over the map's *receiver grid*: the `W×H` lightmap itself, or
//!   for a map of receiver level `r > 0` ([`TransferMap::receiver_level`]) the grid of
//!   `2^r × 2^r` receiver blocks, `⌈W/2^r⌉ × ⌈H/2^r⌉`, one value per block shared by the
//!   block's covered texels ([`crate::maps::levels`]). [`TransferMap::width`] and
//!   [`TransferMap::height`] are that grid, [`TransferMap::lightmap_size`] is `W×H`. Only the
//!   [`Crop`]s are stored: disjoint rectangles inside the grid, each with its values row-major
//!   (row 0 of the crop is its top row `rect.y`). Grid cells outside every crop are zero.
//!
//! # Invariants (checked by every constructor)
//! Lightmap size `1 ≤ width·height ≤` [`MAX_TEXELS`]; every rectangle non-empty, inside the
//! receiver grid, disjoint from the others, with `w·h` data values; all values, the area and the
//! importance finite; the area ≥ 0; receiver level `r ≤` the pyramid level `ℓ ≤`
//! [`MAX_MAP_LEVEL`].

use glam::IVec2;

use super::crop::{CropOptions, CropRect, crop_rects};
use super::{MAX_TEXELS, MapsError};
use crate::Lightmap;

/// One cropped rectangle of a transfer map and its values.
#[derive(Clone, Debug, PartialEq)]
pub struct Crop {
    /// Where the rectangle lies in the lightmap.
    pub rect: CropRect,
    /// `rect.w · rect.h` RGB values, row-major, first row is lightmap row `rect.y`.
    pub data: Vec<[f32; 3]>,
}

/// One offset transfer map, stored as disjoint crops of a `width×height` lightmap.
#[derive(Clone, Debug, PartialEq)]
pub struct TransferMap {
    /// The offset `Δt = (dx, dy)` in texels; the value at `t` multiplies `B_o(t + Δt)`.
    pub offset: IVec2,
    /// Voronoi area `|V(Δt, O)|` of the offset (normalised units, informational).
    pub voronoi_area: f64,
    /// Importance (sampling weight) of the offset (informational).
    pub importance: f64,
    /// Lightmap width `W`, texels.
    width: u32,
    /// Lightmap height `H`, texels.
    height: u32,
    crops: Vec<Crop>,
    /// Pyramid level of the senders ([`crate::maps::levels`]): 0 for the paper's maps.
    level: u32,
    /// Receiver level `r ≤ level`: 0 for one value per texel, `r` for one value per `2^r × 2^r`
    /// receiver block.
    receiver_level: u32,
}

/// Largest pyramid level a map may have (blocks of `2^15` texels: beyond any lightmap side
/// [`crate::io::limits::MAX_LIGHTMAP_SIDE`]).
pub const MAX_MAP_LEVEL: u32 = 15;

/// Checks a lightmap's size and data length; `what` names it in errors.
pub(crate) fn check_lightmap(what: &str, map: &Lightmap) -> Result<(), MapsError> {
    check_size(what, map.width, map.height)?;
    if map.data.len() as u64 != map.width as u64 * map.height as u64 {
        return Err(MapsError::LightmapDataLength {
            what: what.to_owned(),
            width: map.width,
            height: map.height,
            len: map.data.len(),
        });
    }
    Ok(())
}

/// Checks `1 ≤ width, height` and `width·height ≤ MAX_TEXELS`.
pub(crate) fn check_size(what: &str, width: u32, height: u32) -> Result<(), MapsError> {
    if width == 0 || height == 0 || width as u64 * height as u64 > MAX_TEXELS {
        return Err(MapsError::LightmapSize {
            what: what.to_owned(),
            width,
            height,
        });
    }
    Ok(())
}

impl TransferMap {
    /// Crops a full `W×H` map (zero = nothing stored) with the default [`CropOptions`].
    ///
    /// # Errors
    /// [`MapsError::LightmapSize`] / [`MapsError::LightmapDataLength`] for a malformed `full`,
    /// [`MapsError::InvalidValue`] for a non-finite value, area or importance.
    pub fn from_full(
        offset: IVec2,
        voronoi_area: f64,
        importance: f64,
        full: &Lightmap,
    ) -> Result<Self, MapsError> {
        Self::from_full_with(
            offset,
            voronoi_area,
            importance,
            full,
            &CropOptions::default(),
        )
    }

    /// [`TransferMap::from_full`] with explicit cropping options.
    ///
    /// # Errors
    /// As [`TransferMap::from_full`].
    pub fn from_full_with(
        offset: IVec2,
        voronoi_area: f64,
        importance: f64,
        full: &Lightmap,
        options: &CropOptions,
    ) -> Result<Self, MapsError> {
        check_lightmap("full transfer map", full)?;
        check_scalars(offset, voronoi_area, importance)?;
        if let Some(i) = full
            .data
            .iter()
            .position(|v| v.iter().any(|c| !c.is_finite()))
        {
            let (x, y) = (i as u32 % full.width, i as u32 / full.width);
            return Err(MapsError::InvalidValue {
                offset: (offset.x, offset.y),
                what: format!("texel ({x}, {y}) is {:?}", full.data[i]),
            });
        }
        let crops = crop_rects(full, options)
            .into_iter()
            .map(|rect| {
                let mut data = Vec::with_capacity(rect.area() as usize);
                for y in rect.y..rect.y + rect.h {
                    let row = full.index(rect.x, y);
                    data.extend_from_slice(&full.data[row..row + rect.w as usize]);
                }
                Crop { rect, data }
            })
            .collect();
        Ok(Self {
            offset,
            voronoi_area,
            importance,
            width: full.width,
            height: full.height,
            crops,
            level: 0,
            receiver_level: 0,
        })
    }

    /// Builds a map from explicit crops (e.g. read from a file), validating every invariant
    /// listed in the module doc. `what` names the source in errors.
    ///
    /// # Errors
    /// [`MapsError::LightmapSize`], [`MapsError::InvalidCrop`] (bounds, overlap, data length) or
    /// [`MapsError::InvalidValue`].
    pub fn from_crops(
        what: &str,
        offset: IVec2,
        voronoi_area: f64,
        importance: f64,
        width: u32,
        height: u32,
        crops: Vec<Crop>,
    ) -> Result<Self, MapsError> {
        check_size(what, width, height)?;
        check_scalars(offset, voronoi_area, importance)?;
        let rects: Vec<CropRect> = crops.iter().map(|c| c.rect).collect();
        check_rects(what, &rects, width, height)?;
        for c in &crops {
            if c.data.len() as u64 != c.rect.area() {
                return Err(MapsError::InvalidCrop {
                    what: what.to_owned(),
                    reason: format!(
                        "rectangle {:?} has {} values, expected {}",
                        c.rect,
                        c.data.len(),
                        c.rect.area()
                    ),
                });
            }
            if let Some(i) = c.data.iter().position(|v| v.iter().any(|x| !x.is_finite())) {
                let (x, y) = (
                    c.rect.x + i as u32 % c.rect.w,
                    c.rect.y + i as u32 / c.rect.w,
                );
                return Err(MapsError::InvalidValue {
                    offset: (offset.x, offset.y),
                    what: format!("texel ({x}, {y}) is {:?}", c.data[i]),
                });
            }
        }
        Ok(Self {
            offset,
            voronoi_area,
            importance,
            width,
            height,
            crops,
            level: 0,
            receiver_level: 0,
        })
    }

    /// The map with its senders read from pyramid level `level` ([`crate::maps::levels`]): its
    /// offset is then in level-`level` blocks.
    ///
    /// # Errors
    /// [`MapsError::InvalidValue`] when `level` exceeds [`MAX_MAP_LEVEL`] or is below the
    /// receiver level.
    pub fn with_level(mut self, level: u32) -> Result<Self, MapsError> {
        if level > MAX_MAP_LEVEL || level < self.receiver_level {
            return Err(MapsError::InvalidValue {
                offset: (self.offset.x, self.offset.y),
                what: format!(
                    "pyramid level {level} (at most {MAX_MAP_LEVEL}, at least the receiver level {})",
                    self.receiver_level
                ),
            });
        }
        self.level = level;
        Ok(self)
    }

    /// Pyramid level of the senders: 0 for the paper's maps (the value at `t` multiplies
    /// `B_o(t + Δt)`), `ℓ` for a multi-resolution map (it multiplies `P_ℓ(⌊t/2^ℓ⌋ + Δ)`,
    /// [`crate::maps::levels`]).
    pub fn level(&self) -> u32 {
        self.level
    }

    /// The map with one value per `2^r × 2^r` receiver block (`r` = `receiver_level`): its
    /// crops, built over the `W×H` lightmap, are then read in the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of
    /// receiver blocks, and its value at block `c` multiplies `P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)` for every
    /// covered texel of the block ([`crate::maps::levels`]). Set the pyramid level first
    /// ([`Self::with_level`]).
    ///
    /// # Errors
    /// [`MapsError::InvalidValue`] when `r` exceeds the map's level or [`MAX_MAP_LEVEL`],
    /// [`MapsError::InvalidCrop`] when a crop lies outside the level-`r` grid.
    pub fn with_receiver_level(mut self, r: u32) -> Result<Self, MapsError> {
        if r > MAX_MAP_LEVEL || r > self.level {
            return Err(MapsError::InvalidValue {
                offset: (self.offset.x, self.offset.y),
                what: format!(
                    "receiver level {r} (at most the pyramid level {} and {MAX_MAP_LEVEL})",
                    self.level
                ),
            });
        }
        let (gw, gh) = receiver_grid((self.width, self.height), r);
        check_rects(
            &format!(
                "level-{r} receiver blocks of the map of offset {:?}",
                self.offset.to_array()
            ),
            &self.rects(),
            gw,
            gh,
        )?;
        self.receiver_level = r;
        Ok(self)
    }

    /// Receiver level `r`: 0 for one value per texel, `r > 0` for one value per `2^r × 2^r`
    /// block of receivers ([`Self::with_receiver_level`]).
    pub fn receiver_level(&self) -> u32 {
        self.receiver_level
    }

    /// Width of the receiver grid: the lightmap width `W` at receiver level 0, else `⌈W/2^r⌉`.
    pub fn width(&self) -> u32 {
        receiver_grid((self.width, self.height), self.receiver_level).0
    }

    /// Height of the receiver grid: the lightmap height `H` at receiver level 0, else
    /// `⌈H/2^r⌉`.
    pub fn height(&self) -> u32 {
        receiver_grid((self.width, self.height), self.receiver_level).1
    }

    /// The lightmap size `(W, H)` in texels, whatever the receiver level.
    pub fn lightmap_size(&self) -> (u32, u32) {
        (self.width, self.height)
    }

    /// The stored crops (disjoint, in cropping order).
    pub fn crops(&self) -> &[Crop] {
        &self.crops
    }

    /// The crop rectangles, in order.
    pub fn rects(&self) -> Vec<CropRect> {
        self.crops.iter().map(|c| c.rect).collect()
    }

    /// Total number of stored texels (Σ crop areas).
    pub fn stored_texels(&self) -> u64 {
        self.crops.iter().map(|c| c.rect.area()).sum()
    }

    /// Value at texel `(x, y)`: the stored value, or zero outside every crop (and outside the
    /// map).
    pub fn value_at(&self, x: u32, y: u32) -> [f32; 3] {
        self.crops
            .iter()
            .find(|c| c.rect.contains(x, y))
            .map_or([0.0; 3], |c| {
                c.data[(y - c.rect.y) as usize * c.rect.w as usize + (x - c.rect.x) as usize]
            })
    }

    /// Expands the crops back into a full `width()×height()` map of the receiver grid (zero
    /// outside the crops).
    pub fn to_full(&self) -> Lightmap {
        let mut full = Lightmap::new(self.width(), self.height());
        for c in &self.crops {
            for (row, y) in (c.rect.y..c.rect.y + c.rect.h).enumerate() {
                let dst = full.index(c.rect.x, y);
                let src = row * c.rect.w as usize;
                full.data[dst..dst + c.rect.w as usize]
                    .copy_from_slice(&c.data[src..src + c.rect.w as usize]);
            }
        }
        full
    }
}

/// The `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of receiver blocks of level `r` of a `W×H` lightmap.
pub fn receiver_grid((w, h): (u32, u32), r: u32) -> (u32, u32) {
    let r = r.min(31);
    (
        ((u64::from(w) + (1u64 << r) - 1) >> r) as u32,
        ((u64::from(h) + (1u64 << r) - 1) >> r) as u32,
    )
}

/// Checks that the area and importance are finite and the area ≥ 0.
fn check_scalars(offset: IVec2, voronoi_area: f64, importance: f64) -> Result<(), MapsError> {
    let bad = |what: String| MapsError::InvalidValue {
        offset: (offset.x, offset.y),
        what,
    };
    if !voronoi_area.is_finite() || voronoi_area < 0.0 {
        return Err(bad(format!("Voronoi area is {voronoi_area}")));
    }
    if !importance.is_finite() {
        return Err(bad(format!("importance is {importance}")));
    }
    Ok(())
}

/// Checks that every rectangle is non-empty, inside `width×height`, and disjoint from the
/// others. O(n²) in the number of rectangles (a handful per map).
pub(crate) fn check_rects(
    what: &str,
    rects: &[CropRect],
    width: u32,
    height: u32,
) -> Result<(), MapsError> {
    let bad = |reason: String| MapsError::InvalidCrop {
        what: what.to_owned(),
        reason,
    };
    for (i, r) in rects.iter().enumerate() {
        if !r.fits_in(width, height) {
            return Err(bad(format!(
                "rectangle {i} {r:?} is empty or outside the {width}×{height} lightmap"
            )));
        }
        if let Some(j) = rects[..i].iter().position(|o| o.intersects(r)) {
            return Err(bad(format!(
                "rectangles {j} and {i} overlap ({:?}, {r:?})",
                rects[j]
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::{RngExt, SeedableRng};
    use rand_chacha::ChaCha8Rng;

    /// Random sparse map: a few blobs of random values plus scattered texels.
    pub(crate) fn random_sparse(rng: &mut ChaCha8Rng, w: u32, h: u32) -> Lightmap {
        let mut m = Lightmap::new(w, h);
        for _ in 0..rng.random_range(0..5) {
            let bx = rng.random_range(0..w);
            let by = rng.random_range(0..h);
            let bw = rng.random_range(1..=(w - bx).min(6));
            let bh = rng.random_range(1..=(h - by).min(6));
            for y in by..by + bh {
                for x in bx..bx + bw {
                    m.set(x, y, [rng.random(), rng.random::<f32>() * 1e-6, 0.0]);
                }
            }
        }
        for _ in 0..rng.random_range(0..4) {
            let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
            m.set(x, y, [0.0, 0.0, rng.random_range(1e-7..1.0)]);
        }
        m
    }

    fn bits(m: &Lightmap) -> Vec<[u32; 3]> {
        m.data.iter().map(|v| v.map(f32::to_bits)).collect()
    }

    #[test]
    fn from_full_round_trip_is_bit_exact() {
        let mut rng = ChaCha8Rng::seed_from_u64(11);
        for _ in 0..100 {
            let (w, h) = (rng.random_range(1..30), rng.random_range(1..30));
            let full = random_sparse(&mut rng, w, h);
            for k in [0, 64] {
                let opts = CropOptions {
                    rect_overhead_texels: k,
                };
                let tm =
                    TransferMap::from_full_with(IVec2::new(3, -2), 0.5, 2.0, &full, &opts).unwrap();
                assert_eq!(bits(&tm.to_full()), bits(&full));
                // value_at agrees with the full map everywhere.
                for y in 0..h {
                    for x in 0..w {
                        assert_eq!(tm.value_at(x, y), full.get(x, y));
                    }
                }
                // Every non-zero texel is in exactly one rect; rects are disjoint.
                let rects = tm.rects();
                check_rects("test", &rects, w, h).unwrap();
                for y in 0..h {
                    for x in 0..w {
                        let n = rects.iter().filter(|r| r.contains(x, y)).count();
                        if full.get(x, y) != [0.0; 3] {
                            assert_eq!(n, 1);
                        }
                    }
                }
            }
        }
    }

    #[test]
    fn all_zero_gives_no_crops() {
        let tm = TransferMap::from_full(IVec2::ZERO, 1.0, 1.0, &Lightmap::new(5, 3)).unwrap();
        assert!(tm.crops().is_empty());
        assert_eq!(tm.stored_texels(), 0);
        assert_eq!(tm.to_full(), Lightmap::new(5, 3));
    }

    #[test]
    fn rejects_bad_input() {
        let mut m = Lightmap::new(4, 4);
        m.set(2, 1, [0.0, f32::NAN, 0.0]);
        let e = TransferMap::from_full(IVec2::ONE, 1.0, 1.0, &m).unwrap_err();
        assert!(e.to_string().contains("texel (2, 1)"), "{e}");
        let m = Lightmap::new(4, 4);
        assert!(TransferMap::from_full(IVec2::ONE, -1.0, 1.0, &m).is_err());
        assert!(TransferMap::from_full(IVec2::ONE, 1.0, f64::INFINITY, &m).is_err());
        let short = Lightmap {
            width: 4,
            height: 4,
            data: vec![[0.0; 3]; 15],
        };
        assert!(matches!(
            TransferMap::from_full(IVec2::ONE, 1.0, 1.0, &short),
            Err(MapsError::LightmapDataLength { .. })
        ));
        assert!(matches!(
            TransferMap::from_full(IVec2::ONE, 1.0, 1.0, &Lightmap::new(0, 3)),
            Err(MapsError::LightmapSize { .. })
        ));
        let crop = |x, y, w, h| Crop {
            rect: CropRect { x, y, w, h },
            data: vec![[1.0; 3]; (w * h) as usize],
        };
        let make = |crops| TransferMap::from_crops("t", IVec2::ZERO, 0.0, 0.0, 8, 8, crops);
        assert!(make(vec![crop(0, 0, 2, 2), crop(2, 0, 2, 2)]).is_ok());
        assert!(make(vec![crop(0, 0, 2, 2), crop(1, 1, 2, 2)]).is_err());
        assert!(make(vec![crop(7, 0, 2, 2)]).is_err());
        assert!(make(vec![crop(0, 0, 0, 2)]).is_err());
        let mut short_crop = crop(0, 0, 2, 2);
        short_crop.data.pop();
        assert!(make(vec![short_crop]).is_err());
    }
}
