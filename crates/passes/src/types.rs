//! Plain input and output types of the passes: meshes, albedo, lights, transfer atlases and
//! pieces, texel weights of the first-order pyramid, and read-back texel images. No GPU
//! objects here; the `ortm` CLI converts its own types into these (the `passes` crate does
//! not depend on `ortm`).
//!
//! # Conventions
//! - Units: metres for positions, W/sr for point/spot intensities, W/m² for directional
//!   irradiance (measured perpendicular to the light's travel direction) and for lightmaps
//!   (radiosity `B = π·L_out`, linear RGB). Albedo and transfer values are dimensionless.
//! - Images are row-major, row 0 first; a `W×H` map's texel `(x, y)` has its centre at
//!   `u = (x + 0.5)/W`, `v = 1 − (y + 0.5)/H`, so row 0 is `v = 1` (as in image files and in
//!   wgpu framebuffers).
//! - Offsets `Δt = (dx, dy)` are in texels (in level-`ℓ` blocks of `2^ℓ × 2^ℓ` texels for a
//!   piece of pyramid level `ℓ`, [`TransferPiece::level`]), `+dy` goes *down* the image.
//! - Texel weights ([`TexelWeights`]) are texel areas in m² (0 on uncovered texels).
//! - A texel is *covered* when its centre lies inside a UV triangle of the mesh; passes store
//!   coverage in alpha (1 covered, 0.5 filled by gutter dilation, 0 empty).

use crate::error::PassError;

/// A triangle mesh with one lightmap UV set.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct MeshData {
    /// Vertex positions in metres (world space).
    pub positions_m: Vec<[f32; 3]>,
    /// Vertex normals (unit length, world space); interpolated and renormalised per texel.
    pub normals: Vec<[f32; 3]>,
    /// Lightmap UVs in `[0, 1]²`, `v = 1` is row 0 of the lightmap.
    pub lightmap_uvs: Vec<[f32; 2]>,
    /// Triangle list, three indices per triangle, counter-clockwise seen from the front.
    pub indices: Vec<u32>,
}

impl MeshData {
    /// Checks array lengths, index ranges and finiteness.
    pub fn validate(&self) -> Result<(), PassError> {
        let n = self.positions_m.len();
        if self.normals.len() != n {
            return Err(PassError::BadLength {
                what: "MeshData.normals".into(),
                expected: n,
                got: self.normals.len(),
                hint: "one normal per position".into(),
            });
        }
        if self.lightmap_uvs.len() != n {
            return Err(PassError::BadLength {
                what: "MeshData.lightmap_uvs".into(),
                expected: n,
                got: self.lightmap_uvs.len(),
                hint: "one lightmap UV per position".into(),
            });
        }
        if self.indices.is_empty() || !self.indices.len().is_multiple_of(3) {
            return Err(PassError::InvalidInput {
                what: "MeshData.indices".into(),
                problem: format!(
                    "has {} entries; it must be a non-empty triangle list (a multiple of 3)",
                    self.indices.len()
                ),
            });
        }
        if let Some((i, &ix)) = self
            .indices
            .iter()
            .enumerate()
            .find(|&(_, &ix)| ix as usize >= n)
        {
            return Err(PassError::InvalidInput {
                what: format!("MeshData.indices[{i}]"),
                problem: format!("is {ix} but there are only {n} vertices"),
            });
        }
        let bad = self
            .positions_m
            .iter()
            .chain(&self.normals)
            .flatten()
            .chain(self.lightmap_uvs.iter().flatten())
            .any(|v| !v.is_finite());
        if bad {
            return Err(PassError::InvalidInput {
                what: "MeshData".into(),
                problem: "contains a NaN or infinite position, normal or UV".into(),
            });
        }
        Ok(())
    }
}

impl MeshData {
    /// Whether the mesh is a closed surface with consistent, outward-facing
    /// counter-clockwise winding: every directed edge (vertices compared by position, so
    /// UV seams do not break it) is matched by exactly one opposite edge, and the signed
    /// volume is positive. Then, for a viewer or light *outside* the mesh, back faces are
    /// always hidden behind front faces and can be culled without changing any visible
    /// pixel or shadow-map depth. `false` for open, non-manifold or inside-out meshes.
    pub fn is_closed_outward(&self) -> bool {
        use std::collections::HashMap;
        let key = |i: u32| -> Option<[u32; 3]> {
            self.positions_m
                .get(i as usize)
                .map(|p| [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()])
        };
        let mut ids: HashMap<[u32; 3], u32> = HashMap::new();
        let mut id = |i: u32| -> Option<u32> {
            let k = key(i)?;
            let n = ids.len() as u32;
            Some(*ids.entry(k).or_insert(n))
        };
        let mut edges: HashMap<(u32, u32), u32> = HashMap::new();
        let mut volume6 = 0.0f64;
        for t in self.indices.chunks_exact(3) {
            let (Some(a), Some(b), Some(c)) = (id(t[0]), id(t[1]), id(t[2])) else {
                return false;
            };
            if a == b || b == c || c == a {
                continue; // degenerate: no area, no edges of its own
            }
            for e in [(a, b), (b, c), (c, a)] {
                *edges.entry(e).or_insert(0) += 1;
            }
            let p = |i: u32| self.positions_m[i as usize].map(f64::from);
            let (p0, p1, p2) = (p(t[0]), p(t[1]), p(t[2]));
            // p0 · (p1 × p2): six times the signed volume of the tetrahedron with the origin.
            volume6 += p0[0] * (p1[1] * p2[2] - p1[2] * p2[1])
                + p0[1] * (p1[2] * p2[0] - p1[0] * p2[2])
                + p0[2] * (p1[0] * p2[1] - p1[1] * p2[0]);
        }
        !edges.is_empty()
            && edges
                .iter()
                .all(|(&(u, v), &n)| n == 1 && edges.get(&(v, u)) == Some(&1))
            && volume6 > 0.0
    }
}

/// Diffuse reflectance ρ per lightmap texel (`B_o = ρ·E`); for subsurface materials the
/// profile's total diffuse reflectance. Same layout as the lightmap.
#[derive(Clone, Debug, PartialEq)]
pub struct AlbedoMap {
    /// Width in texels (= lightmap width).
    pub width: u32,
    /// Height in texels (= lightmap height).
    pub height: u32,
    /// `width·height` linear RGB reflectances in `[0, 1]`, row 0 is `v = 1`.
    pub rgb: Vec<[f32; 3]>,
}

impl AlbedoMap {
    /// A map with the same reflectance everywhere.
    pub fn uniform(width: u32, height: u32, rho: [f32; 3]) -> Self {
        Self {
            width,
            height,
            rgb: vec![rho; width as usize * height as usize],
        }
    }
}

/// A light of the first-order pass. `color` is a linear RGB tint (usually in `[0, 1]`) that
/// multiplies the scalar strength.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum LightDesc {
    /// Isotropic point light: `E = I·cosθ/d²`.
    Point {
        /// Position in metres.
        position_m: [f32; 3],
        /// RGB tint.
        color: [f32; 3],
        /// Radiant intensity in W/sr.
        intensity_w_sr: f32,
    },
    /// Spot light: a point light times `smoothstep(cos outer, cos inner, cos α)`, α the angle
    /// from the axis.
    Spot {
        /// Position in metres.
        position_m: [f32; 3],
        /// Axis (direction the light points to); need not be normalised.
        direction: [f32; 3],
        /// RGB tint.
        color: [f32; 3],
        /// Radiant intensity on the axis in W/sr.
        intensity_w_sr: f32,
        /// Full-intensity half-angle in degrees.
        inner_deg: f32,
        /// Cut-off half-angle in degrees (`> inner_deg`, `< 90`).
        outer_deg: f32,
    },
    /// Directional light: `E = E⊥·cosθ`.
    Directional {
        /// Travel direction of the light (from the light towards the scene).
        direction: [f32; 3],
        /// RGB tint.
        color: [f32; 3],
        /// Irradiance on a surface perpendicular to the light, W/m².
        irradiance_w_m2: f32,
    },
}

impl LightDesc {
    /// Checks finiteness and ranges; `index` names the light in messages.
    pub fn validate(&self, index: usize) -> Result<(), PassError> {
        let what = format!("lights[{index}]");
        let (vals, strength): (Vec<f32>, f32) = match *self {
            LightDesc::Point {
                position_m,
                color,
                intensity_w_sr,
            } => (
                position_m.into_iter().chain(color).collect(),
                intensity_w_sr,
            ),
            LightDesc::Spot {
                position_m,
                direction,
                color,
                intensity_w_sr,
                inner_deg,
                outer_deg,
            } => {
                if !(0.0..90.0).contains(&outer_deg) || !(0.0..=outer_deg).contains(&inner_deg) {
                    return Err(PassError::InvalidInput {
                        what,
                        problem: format!(
                            "spot angles inner {inner_deg}°, outer {outer_deg}° must satisfy \
                             0 ≤ inner ≤ outer < 90"
                        ),
                    });
                }
                (
                    position_m
                        .into_iter()
                        .chain(direction)
                        .chain(color)
                        .collect(),
                    intensity_w_sr,
                )
            }
            LightDesc::Directional {
                direction,
                color,
                irradiance_w_m2,
            } => (
                direction.into_iter().chain(color).collect(),
                irradiance_w_m2,
            ),
        };
        if vals.iter().any(|v| !v.is_finite()) || !strength.is_finite() || strength < 0.0 {
            return Err(PassError::InvalidInput {
                what,
                problem: "has a NaN/infinite field or a negative strength".into(),
            });
        }
        if let LightDesc::Spot { direction, .. } | LightDesc::Directional { direction, .. } = *self
            && direction.iter().map(|d| d * d).sum::<f32>() < 1e-12
        {
            return Err(PassError::InvalidInput {
                what,
                problem: "direction is the zero vector; give the direction the light travels"
                    .into(),
            });
        }
        Ok(())
    }
}

/// One transfer atlas (paper Sec. 5.2): many transfer-map pieces packed in one texture.
/// Values are dimensionless transfer coefficients, linear RGB.
#[derive(Clone, Debug, PartialEq)]
pub struct AtlasData {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width·height` RGB values, row-major, row 0 first.
    pub rgb: Vec<[f32; 3]>,
}

/// A rectangle of an atlas and where it applies (paper Eq. 9, with multi-resolution senders):
/// for every texel `t = dst + (i,j)`, `0 ≤ i < w`, `0 ≤ j < h`,
///
/// ```text
/// final[t] += atlas[src + (i,j)] · P_ℓ(⌊t / 2^ℓ⌋ + Δ)
/// ```
///
/// where `ℓ = level`, `⌊t / 2^ℓ⌋` is taken per component (a shift right; `t ≥ 0`), `Δ =
/// offset` is in level-`ℓ` blocks, and `P_ℓ` is level `ℓ` of the area-weighted pyramid of the
/// first-order lightmap ([`crate::pyramid`]): `P_0` is the first-order map itself (so level 0
/// is `final[t] += atlas[src + (i,j)] · first_order[t + Δt]`, Δt in texels), and `P_ℓ` is 0
/// outside level `ℓ`'s size `⌈W/2^ℓ⌉ × ⌈H/2^ℓ⌉` (W×H = the lightmap). Level 0 pieces are
/// exactly the original single-resolution form. `level ≤` [`MAX_PIECE_LEVEL`]; pieces of
/// level > 0 need [`TexelWeights`] to build the pyramid.
///
/// # Receiver blocks (`receiver_level = r > 0`)
/// The rectangle then lies in the grid of `2^r × 2^r` receiver blocks (`⌈W/2^r⌉ × ⌈H/2^r⌉`):
/// `dst`, `w`, `h` count blocks, and its value at block `c = dst + (i,j)` multiplies
/// `P_ℓ(⌊c / 2^(ℓ−r)⌋ + Δ)` and adds into *every covered texel* `t` with `⌊t / 2^r⌋ = c`
/// (covered: first-order alpha > 0). `r ≤ ℓ`. One block value stands for up to `4^r` texels:
/// the frame cost is the block count, not the texel count. `r = 0` is the form above.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TransferPiece {
    /// Index into the atlas list.
    pub atlas: u32,
    /// Left column of the rectangle in the atlas.
    pub src_x: u32,
    /// Top row of the rectangle in the atlas.
    pub src_y: u32,
    /// Width of the rectangle in texels.
    pub w: u32,
    /// Height of the rectangle in texels.
    pub h: u32,
    /// Lightmap column receiving the rectangle's left column.
    pub dst_x: u32,
    /// Lightmap row receiving the rectangle's top row.
    pub dst_y: u32,
    /// Offset `Δ = (dx, dy)` in level-`level` blocks (texels at level 0; `+dy` down): where
    /// first-order light is read.
    pub offset: [i32; 2],
    /// Pyramid level `ℓ` of the first-order light read (0 = the first-order map itself);
    /// at most [`MAX_PIECE_LEVEL`].
    pub level: u32,
    /// Receiver level `r ≤ level` (0: one value per texel; see the type's docs).
    pub receiver_level: u32,
}

/// The largest [`TransferPiece::level`] (blocks of `2^15 × 2^15` texels: one block covers
/// any lightmap the device can hold).
pub const MAX_PIECE_LEVEL: u32 = 15;

/// Per-texel weights of the first-order pyramid ([`crate::pyramid`]): each texel's surface
/// area in m², 0 on texels no triangle covers (so gutters never darken a block). Static per
/// scene; same layout as the lightmap.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelWeights {
    /// Width in texels (= lightmap width).
    pub width: u32,
    /// Height in texels (= lightmap height).
    pub height: u32,
    /// `width·height` non-negative finite weights (m²), row-major, row 0 first.
    pub weights: Vec<f32>,
}

impl TexelWeights {
    /// Checks that the weights are `width·height` finite non-negative values of a
    /// `lightmap_size` lightmap.
    pub fn validate(&self, lightmap_size: [u32; 2]) -> Result<(), PassError> {
        if [self.width, self.height] != lightmap_size {
            return Err(PassError::InvalidInput {
                what: "TexelWeights".into(),
                problem: format!(
                    "are {}×{} but the lightmap is {}×{}; give one weight per lightmap texel",
                    self.width, self.height, lightmap_size[0], lightmap_size[1]
                ),
            });
        }
        let n = self.width as usize * self.height as usize;
        if self.weights.len() != n {
            return Err(PassError::BadLength {
                what: "TexelWeights.weights".into(),
                expected: n,
                got: self.weights.len(),
                hint: "width·height texel areas (m², 0 where uncovered)".into(),
            });
        }
        if let Some((i, w)) = self
            .weights
            .iter()
            .enumerate()
            .find(|(_, w)| !w.is_finite() || **w < 0.0)
        {
            return Err(PassError::InvalidInput {
                what: format!("TexelWeights.weights[{i}]"),
                problem: format!("is {w}; weights are texel areas, finite and ≥ 0"),
            });
        }
        Ok(())
    }
}

/// An RGBA float image read back from the GPU (or produced by a CPU mirror). RGB in the
/// units of the map (W/m² for lightmaps), alpha = coverage.
#[derive(Clone, Debug, PartialEq)]
pub struct TexelImage {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
    /// `width·height` RGBA values, row-major, row 0 first.
    pub rgba: Vec<[f32; 4]>,
}

impl TexelImage {
    /// An all-zero image.
    pub fn new(width: u32, height: u32) -> Self {
        Self {
            width,
            height,
            rgba: vec![[0.0; 4]; width as usize * height as usize],
        }
    }

    /// Value at `(x, y)`.
    #[inline]
    pub fn get(&self, x: u32, y: u32) -> [f32; 4] {
        self.rgba[y as usize * self.width as usize + x as usize]
    }

    /// Value at signed `(x, y)`, or zero outside the image.
    #[inline]
    pub fn get_or_zero(&self, x: i32, y: i32) -> [f32; 4] {
        if x < 0 || y < 0 || x >= self.width as i32 || y >= self.height as i32 {
            [0.0; 4]
        } else {
            self.get(x as u32, y as u32)
        }
    }

    /// Mutable value at `(x, y)`.
    #[inline]
    pub fn at_mut(&mut self, x: u32, y: u32) -> &mut [f32; 4] {
        &mut self.rgba[y as usize * self.width as usize + x as usize]
    }
}

#[cfg(test)]
mod tests {
    use super::MeshData;

    /// Unit cube, 8 shared vertices, 12 triangles CCW seen from outside.
    fn cube() -> MeshData {
        let positions_m: Vec<[f32; 3]> = (0..8)
            .map(|i| [(i & 1) as f32, ((i >> 1) & 1) as f32, ((i >> 2) & 1) as f32])
            .collect();
        // Quads as (a, b, c, d) CCW from outside.
        let quads = [
            [0, 2, 3, 1], // z = 0, normal −z
            [4, 5, 7, 6], // z = 1, +z
            [0, 1, 5, 4], // y = 0, −y
            [2, 6, 7, 3], // y = 1, +y
            [0, 4, 6, 2], // x = 0, −x
            [1, 3, 7, 5], // x = 1, +x
        ];
        let indices = quads
            .iter()
            .flat_map(|q| [q[0], q[1], q[2], q[0], q[2], q[3]])
            .collect();
        MeshData {
            normals: vec![[0.0, 0.0, 1.0]; 8],
            lightmap_uvs: vec![[0.5, 0.5]; 8],
            positions_m,
            indices,
        }
    }

    #[test]
    fn closed_outward_cube_and_its_failures() {
        let c = cube();
        assert!(c.is_closed_outward());
        // Inside out: every triangle reversed.
        let mut inv = c.clone();
        for t in inv.indices.chunks_exact_mut(3) {
            t.swap(1, 2);
        }
        assert!(!inv.is_closed_outward());
        // Open: one face missing.
        let mut open = c.clone();
        open.indices.truncate(30);
        assert!(!open.is_closed_outward());
        // One triangle flipped: inconsistent winding.
        let mut flip = c.clone();
        flip.indices.swap(1, 2);
        assert!(!flip.is_closed_outward());
        // Split vertices (same positions, e.g. at UV seams) keep it closed.
        let mut split = c.clone();
        for i in 0..split.indices.len() {
            let v = split.indices[i] as usize;
            split.positions_m.push(split.positions_m[v]);
            split.normals.push(split.normals[v]);
            split.lightmap_uvs.push(split.lightmap_uvs[v]);
            split.indices[i] = (split.positions_m.len() - 1) as u32;
        }
        assert!(split.is_closed_outward());
    }
}
