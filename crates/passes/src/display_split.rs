//! Which triangles need the per-pixel light loop in this frame: the display pass's split of
//! the mesh into triangles whose every pixel keeps the lightmap's diffused light (subsurface
//! surfaces), triangles no light reaches, and the others ([`Class`]).
//!
//! # Why
//! On subsurface surfaces the per-pixel display takes the share `w = clamp(1 − ℓ/f, 0, 1)` of
//! its direct light per pixel (`ℓ` the diffusion length, `f` the larger side of the pixel's
//! footprint on the surface; [`crate::display`]). Where `ℓ ≥ f` — skin at any usual zoom —
//! `w = 0`: the pixel is `B_o/π + T/π`, and the light loop, shadow lookups and derivatives
//! are multiplied by zero. SIMD software rasterisers (lavapipe) run a divergent branch's
//! body under a mask, so skipping the loop per pixel saves nothing; choosing the pipeline
//! per draw does. So per frame [`DisplaySplit::diffused_only`] marks the triangles whose every
//! pixel provably has `f ≤ ℓ`, and [`DisplaySplit::unlit`] those that face away from every
//! light (the shader's cosine test fails at each of their points, so `E = 0`). The display
//! draws the first with the lightmap display's shader (`fs_filtered` / `fs_manual` in
//! `shaders/display.wgsl`: `B/π`, the final light, which is what the per-pixel shader
//! computes at `w = 0`), the second without the light loop (the override `LIGHTS` off; on
//! scenes without subsurface texels the lightmap display's shader on `T`, the same), then
//! the rest with the full shader: up to three draws from an index buffer rewritten when the
//! classes change. The image is the same byte for byte
//! (`apps/ortm/tests/display_direct.rs`, the `split_display_*` tests).
//!
//! # The footprint bound
//! A pixel's view ray `D = F + x·s·X + y·s·Y` (unit forward, right and up vectors, `s` the
//! pixel pitch on the image plane at unit distance, `2·tan(fov_y/2)/height`, `|D| ≥ 1`)
//! meets the triangle's plane (unit normal `m` towards the eye, at distance `h` from it) at
//! `p = e + h·D/(m·D)` (up to the sign convention of `m`), the perspective-correct
//! interpolated world position. So `∂p/∂x = h·s·m × (X × D)/(m·D)²` (a vector triple
//! product), of length at most `h·s·|D|/(m·D)² ≤ h·s/cos²φ`, `φ` the angle between the ray
//! and the normal; the same for `y`. The shader's `dpdx`, `dpdy` are differences across the
//! pixel's 2×2 quad, along which the ray stays within an angle `√2·s` of the pixel's own, so
//! `cos φ ≥ cos φ_P − 2s` there. Over the triangle `cos φ_P = h/|e − p|` is smallest at its
//! farthest vertex: with `c = h/d_max`, `f ≤ h·s/(c − 2s)²`. A triangle is drawn without the
//! light loop when that bound, plus 1 % and a few float ulps of the coordinates, is at
//! most the smallest `ℓ` its bilinear lookups can read; one that faces away or is grazed
//! (`c ≤ 4s`), or can read a texel with `ℓ = 0`, never is.
//!
//! # Data flow and units
//! [`DisplaySplit::build`] at upload (planes of the triangles, vertex normals, UV boxes);
//! [`DisplaySplit::min_lengths`] when the diffusion lengths are set (per triangle, from the
//! dilated surface texels); per frame [`DisplaySplit::diffused_only`],
//! [`DisplaySplit::unlit`], [`DisplaySplit::classes`] and [`DisplaySplit::indices`]
//! (`O(triangles × lights)` on the CPU). Metres, radians; UVs as in
//! [`crate::types::MeshData`].

use glam::Vec3;

use crate::cpu::display::texel_coords;
use crate::display::Camera;
use crate::types::{LightDesc, MeshData};

/// How a triangle is drawn this frame ([`DisplaySplit::classes`]); the index buffer holds
/// the classes in this order.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub enum Class {
    /// Every pixel takes `w = 0`: the lightmap display's shader (`B/π`).
    Diffused,
    /// No light reaches it by the shader's cosine test: the per-pixel shader without the
    /// light loop (on scenes without subsurface texels, the lightmap display's shader on
    /// `T`, which is the same).
    Unlit,
    /// The full per-pixel shader.
    Full,
}

/// The mesh's triangles as the split needs them.
#[derive(Clone, Debug, PartialEq)]
pub struct DisplaySplit {
    positions: Vec<Vec3>,
    /// Vertex normals, as given (the shader interpolates and normalises them).
    normals: Vec<Vec3>,
    /// Three vertex indices per triangle (the mesh's order).
    indices: Vec<u32>,
    /// Per triangle: unit normal by the winding (counter-clockwise seen from the front)
    /// and `n·v₀`; a zero normal for a degenerate triangle.
    planes: Vec<(Vec3, f32)>,
    /// UV bounding box `[u_min, v_min, u_max, v_max]` of each triangle.
    triangle_uv: Vec<[f32; 4]>,
}

impl DisplaySplit {
    /// The planes and UV boxes of a validated mesh's triangles ([`MeshData::validate`]).
    pub fn build(mesh: &MeshData) -> Self {
        let positions: Vec<Vec3> = mesh.positions_m.iter().map(|&p| p.into()).collect();
        let mut planes = Vec::with_capacity(mesh.indices.len() / 3);
        let mut triangle_uv = Vec::with_capacity(mesh.indices.len() / 3);
        for t in mesh.indices.chunks_exact(3) {
            let v = [0, 1, 2].map(|k| positions[t[k] as usize]);
            let n = (v[1] - v[0]).cross(v[2] - v[0]).normalize_or_zero();
            planes.push((n, n.dot(v[0])));
            let uv = [0, 1, 2].map(|k| mesh.lightmap_uvs[t[k] as usize]);
            triangle_uv.push([
                uv[0][0].min(uv[1][0]).min(uv[2][0]),
                uv[0][1].min(uv[1][1]).min(uv[2][1]),
                uv[0][0].max(uv[1][0]).max(uv[2][0]),
                uv[0][1].max(uv[1][1]).max(uv[2][1]),
            ]);
        }
        Self {
            positions,
            normals: mesh.normals.iter().map(|&n| n.into()).collect(),
            indices: mesh.indices[..planes.len() * 3].to_vec(),
            planes,
            triangle_uv,
        }
    }

    /// Number of triangles.
    pub fn triangles(&self) -> usize {
        self.planes.len()
    }

    /// Per triangle, the smallest diffusion length (alpha of `surface`, the dilated surface
    /// texels of [`crate::display::surface_texels`], row-major `size[0] × size[1]`) that a
    /// bilinear lookup inside it can read: the texels under its UV box, one more on every
    /// side for the filter and one for rounding. 0 for a triangle that can see a diffuse
    /// (or empty) texel.
    pub fn min_lengths(&self, surface: &[[f32; 4]], size: [u32; 2]) -> Vec<f32> {
        let (w, h) = (i64::from(size[0]), i64::from(size[1]));
        let texel = |x: f32| x.floor() as i64;
        self.triangle_uv
            .iter()
            .map(|uv| {
                // The box's corners in texel space (v grows upwards, rows downwards); a
                // bilinear lookup reads floor(st) and floor(st) + 1.
                let [s0, t0] = texel_coords([uv[0], uv[3]], size[0], size[1]);
                let [s1, t1] = texel_coords([uv[2], uv[1]], size[0], size[1]);
                let x0 = (texel(s0) - 1).clamp(0, w - 1);
                let x1 = (texel(s1) + 2).clamp(0, w - 1);
                let y0 = (texel(t0) - 1).clamp(0, h - 1);
                let y1 = (texel(t1) + 2).clamp(0, h - 1);
                let mut min = f32::INFINITY;
                for y in y0..=y1 {
                    let row = &surface[(y * w) as usize..][..w as usize];
                    for t in &row[x0 as usize..=x1 as usize] {
                        min = min.min(t[3]);
                    }
                    if min <= 0.0 {
                        return 0.0;
                    }
                }
                if min.is_finite() { min } else { 0.0 }
            })
            .collect()
    }

    /// Per triangle, whether every pixel it covers in a viewport `height_px` pixels high
    /// (square pixels) seen by `camera` has a footprint at most its `min_lengths` (module
    /// docs), i.e. takes `w = 0`.
    pub fn diffused_only(&self, camera: &Camera, height_px: u32, min_lengths: &[f32]) -> Vec<bool> {
        let eye = Vec3::from(camera.eye);
        let s = 2.0 * (0.5 * camera.fov_y_deg.to_radians()).tan() / height_px.max(1) as f32;
        self.planes
            .iter()
            .zip(self.indices.chunks_exact(3))
            .zip(min_lengths)
            .map(|(((n, k), t), &ell)| {
                let h = n.dot(eye) - k;
                if !(ell > 0.0 && h > 0.0) {
                    return false;
                }
                let d_max = t
                    .iter()
                    .map(|&i| self.positions[i as usize].distance(eye))
                    .fold(0.0f32, f32::max);
                // d_max ≥ h > 0: c is finite, in (0, 1].
                let c = h / d_max;
                if c <= 4.0 * s {
                    return false;
                }
                let bound = h * s / ((c - 2.0 * s) * (c - 2.0 * s));
                let ulps = 64.0 * f32::EPSILON * (eye.abs().max_element() + d_max);
                bound * 1.01 + ulps <= ell
            })
            .collect()
    }

    /// Per triangle, whether no light of `lights` reaches any point of it by the per-pixel
    /// shader's test `n·(L − p) > 0` (`lights.wgsl`; `n` the interpolated vertex normal, `p`
    /// the point; for a directional light `n·(−direction) > 0`), or the light is black.
    /// Both `n` and `L − p` are convex combinations of the vertices' (the same barycentric
    /// weights, normalisation keeps the sign), so `n·(L − p)` is a convex combination of
    /// `n_i·(L − v_j)`: all of those below `−10⁻⁴·|n_i|·|L − v_j|` (a margin for the shader's
    /// rounding) mean no light there.
    pub fn unlit(&self, lights: &[LightDesc]) -> Vec<bool> {
        // d < −m·|n|·|to|, squared (no square roots per pair).
        let below = |n: Vec3, to: Vec3| {
            let d = n.dot(to);
            d < 0.0 && d * d > 1e-8 * n.length_squared() * to.length_squared()
        };
        self.indices
            .chunks_exact(3)
            .map(|t| {
                let n = [0, 1, 2].map(|k| self.normals[t[k] as usize]);
                let v = [0, 1, 2].map(|k| self.positions[t[k] as usize]);
                lights.iter().all(|light| match *light {
                    LightDesc::Directional {
                        direction,
                        color,
                        irradiance_w_m2,
                    } => {
                        let to = -Vec3::from(direction);
                        black(color, irradiance_w_m2) || n.iter().all(|n| below(*n, to))
                    }
                    LightDesc::Point {
                        position_m,
                        color,
                        intensity_w_sr,
                    }
                    | LightDesc::Spot {
                        position_m,
                        color,
                        intensity_w_sr,
                        ..
                    } => {
                        let l = Vec3::from(position_m);
                        black(color, intensity_w_sr)
                            || n.iter().all(|n| v.iter().all(|v| below(*n, l - *v)))
                    }
                })
            })
            .collect()
    }

    /// Per triangle, its [`Class`]: [`Class::Diffused`] where `diffused` (from
    /// [`DisplaySplit::diffused_only`]; `None` on scenes without subsurface texels), else
    /// [`Class::Unlit`] where `unlit` ([`DisplaySplit::unlit`]), else [`Class::Full`].
    pub fn classes(&self, diffused: Option<&[bool]>, unlit: &[bool]) -> Vec<Class> {
        (0..self.triangles())
            .map(|t| {
                if diffused.is_some_and(|d| d[t]) {
                    Class::Diffused
                } else if unlit[t] {
                    Class::Unlit
                } else {
                    Class::Full
                }
            })
            .collect()
    }

    /// The index list ordered by class ([`Class`] order), each class in the mesh's order, and
    /// the index counts of the classes.
    pub fn indices(&self, classes: &[Class]) -> (Vec<u32>, [u32; 3]) {
        let mut out = Vec::with_capacity(self.indices.len());
        let mut counts = [0u32; 3];
        for (k, class) in [Class::Diffused, Class::Unlit, Class::Full]
            .into_iter()
            .enumerate()
        {
            for (t, _) in self
                .indices
                .chunks_exact(3)
                .zip(classes)
                .filter(|(_, c)| **c == class)
            {
                out.extend_from_slice(t);
                counts[k] += 3;
            }
        }
        (out, counts)
    }
}

/// A light of this colour and strength adds nothing.
fn black(color: [f32; 3], strength: f32) -> bool {
    strength == 0.0 || color == [0.0; 3]
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A `n × n` grid of quads on the plane z = 0 (1 m square), normals +z, UVs = xy.
    fn grid(n: u32) -> MeshData {
        let mut m = MeshData {
            positions_m: vec![],
            normals: vec![],
            lightmap_uvs: vec![],
            indices: vec![],
        };
        for j in 0..=n {
            for i in 0..=n {
                let (x, y) = (i as f32 / n as f32, j as f32 / n as f32);
                m.positions_m.push([x, y, 0.0]);
                m.normals.push([0.0, 0.0, 1.0]);
                m.lightmap_uvs.push([x, y]);
            }
        }
        let v = |i: u32, j: u32| j * (n + 1) + i;
        for j in 0..n {
            for i in 0..n {
                m.indices.extend([v(i, j), v(i + 1, j), v(i + 1, j + 1)]);
                m.indices.extend([v(i, j), v(i + 1, j + 1), v(i, j + 1)]);
            }
        }
        m
    }

    /// The bound of the module docs against the exact difference of two ray–plane hits a
    /// pixel apart, for random planes, eyes and pixels (each pixel of each of its quads).
    #[test]
    fn footprint_bound_holds_for_random_planes_and_pixels() {
        let mut state = 0x9e37_79b9_7f4a_7c15u64;
        let mut rnd = move || {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state >> 11) as f64 / (1u64 << 53) as f64
        };
        type V = [f64; 3];
        let dot = |u: V, v: V| u[0] * v[0] + u[1] * v[1] + u[2] * v[2];
        let cross = |u: V, v: V| {
            [
                u[1] * v[2] - u[2] * v[1],
                u[2] * v[0] - u[0] * v[2],
                u[0] * v[1] - u[1] * v[0],
            ]
        };
        let unit = |u: V| u.map(|x| x / dot(u, u).sqrt());
        let mut worst = 0.0f64;
        let mut checked = 0;
        for _ in 0..20_000 {
            let s = 1e-3 * (0.2 + 4.0 * rnd());
            // Eye at the origin looking down −z; the pixel at (x, y) pixels from the centre.
            let (x, y) = ((rnd() - 0.5) * 1000.0, (rnd() - 0.5) * 1000.0);
            let ray = |dx: f64, dy: f64| -> V { [(x + dx) * s, (y + dy) * s, -1.0] };
            // A plane through the point at distance t along the pixel's ray, its normal
            // (towards the eye) at angle b < 88° from the direction back to the eye.
            let t = 0.1 + 5.0 * rnd();
            let back = unit(ray(0.0, 0.0).map(|v| -v));
            let (a, b) = (rnd() * std::f64::consts::TAU, rnd() * 88f64.to_radians());
            let helper = if back[0].abs() < 0.9 {
                [1.0, 0.0, 0.0]
            } else {
                [0.0, 1.0, 0.0]
            };
            let e1 = unit(cross(back, helper));
            let e2 = cross(back, e1);
            let m: V = std::array::from_fn(|i| {
                b.cos() * back[i] + b.sin() * (a.cos() * e1[i] + a.sin() * e2[i])
            });
            let h = t * b.cos(); // distance of the plane from the eye
            let hit = |d: V| d.map(|v| v * h / -dot(m, d));
            // The pixel's own point is the farthest vertex: c = h/d_max = cos b.
            let c = b.cos();
            if c <= 4.0 * s {
                continue;
            }
            let bound = h * s / ((c - 2.0 * s) * (c - 2.0 * s));
            for (ox, oy) in [(-1.0, -1.0), (0.0, -1.0), (-1.0, 0.0), (0.0, 0.0)] {
                for (dx, dy) in [(1.0, 0.0), (0.0, 1.0)] {
                    let (d0, d1) = (ray(ox, oy), ray(ox + dx, oy + dy));
                    assert!(dot(m, d0) < 0.0 && dot(m, d1) < 0.0, "ray misses the front");
                    let (p0, p1) = (hit(d0), hit(d1));
                    let f = dot(
                        [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]],
                        [p1[0] - p0[0], p1[1] - p0[1], p1[2] - p0[2]],
                    )
                    .sqrt();
                    assert!(
                        f <= bound,
                        "footprint {f} > bound {bound} (s {s}, angle {b})"
                    );
                    worst = worst.max(f / bound);
                    checked += 1;
                }
            }
        }
        assert!(checked > 100_000);
        // Not loose by orders of magnitude either.
        assert!(worst > 0.5, "worst footprint / bound {worst}");
    }

    #[test]
    fn min_lengths_see_a_diffuse_texel_within_reach() {
        let mesh = grid(8);
        let split = DisplaySplit::build(&mesh);
        let size = [32u32, 32];
        let mut surface = vec![[0.5, 0.5, 0.5, 0.004f32]; 32 * 32];
        assert!(
            split
                .min_lengths(&surface, size)
                .iter()
                .all(|&l| l == 0.004)
        );
        // A diffuse texel at (5, 5), centre uv (5.5/32, 1 − 5.5/32): a triangle sees it
        // when its UV box, grown by 2 texels, holds that centre, else keeps 0.004.
        surface[5 * 32 + 5][3] = 0.0;
        let lengths = split.min_lengths(&surface, size);
        let (x, y) = (5.5 / 32.0, 1.0 - 5.5 / 32.0);
        let g = 2.0 / 32.0;
        for (uv, &l) in split.triangle_uv.iter().zip(&lengths) {
            let near = uv[0] - g <= x && x <= uv[2] + g && uv[1] - g <= y && y <= uv[3] + g;
            // Every triangle whose bilinear footprint reaches the texel sees it; one more
            // texel of margin may catch a neighbour, nothing farther.
            let reach = uv[0] - 1.0 / 32.0 < x
                && x < uv[2] + 1.0 / 32.0
                && uv[1] - 1.0 / 32.0 < y
                && y < uv[3] + 1.0 / 32.0;
            if reach {
                assert_eq!(l, 0.0, "box {uv:?}");
            }
            if !near {
                assert_eq!(l, 0.004, "box {uv:?}");
            }
        }
        assert!(lengths.contains(&0.0) && lengths.contains(&0.004));
    }

    #[test]
    fn grazing_far_and_back_views_keep_the_light_loop() {
        let mesh = grid(16);
        let split = DisplaySplit::build(&mesh);
        let ell = vec![0.0037; split.triangles()];
        let cam = |eye: [f32; 3]| Camera {
            eye,
            target: [0.5, 0.5, 0.0],
            ..Camera::default()
        };
        let all = |v: Vec<bool>, want: bool| v.iter().all(|&d| d == want);
        // Head-on from 1 m at 720 px: ~0.8 mm pixels, every triangle diffused only.
        assert!(all(
            split.diffused_only(&cam([0.5, 0.5, 1.0]), 720, &ell),
            true
        ));
        // From behind (back faces): none.
        assert!(all(
            split.diffused_only(&cam([0.5, 0.5, -1.0]), 720, &ell),
            false
        ));
        // Grazing, 2° above the plane from 3 m: none.
        let g = 2f32.to_radians();
        let eye = [0.5 + 3.0 * g.cos(), 0.5, 3.0 * g.sin()];
        assert!(all(split.diffused_only(&cam(eye), 720, &ell), false));
        // 100 m away (8 cm pixels): none; with ℓ = 0: none.
        assert!(all(
            split.diffused_only(&cam([0.5, 0.5, 100.0]), 720, &ell),
            false
        ));
        let zero = vec![0.0; ell.len()];
        assert!(all(
            split.diffused_only(&cam([0.5, 0.5, 1.0]), 720, &zero),
            false
        ));
        // 1 m away at 40° from the normal, ℓ = 2.5 mm: the near triangles only.
        let eye = [
            0.5 + 40f32.to_radians().sin(),
            0.5,
            40f32.to_radians().cos(),
        ];
        let some = split.diffused_only(&cam(eye), 720, &vec![0.0025; ell.len()]);
        assert!(some.contains(&true) && some.contains(&false), "{some:?}");
    }

    #[test]
    fn indices_put_the_classes_in_order_each_in_mesh_order() {
        let mesh = grid(2);
        let split = DisplaySplit::build(&mesh);
        let (d, u, f) = (Class::Diffused, Class::Unlit, Class::Full);
        let classes = [f, d, u, f, d, f, d, u];
        let (idx, counts) = split.indices(&classes);
        assert_eq!(counts, [9, 6, 9]);
        let tri = |k: usize| mesh.indices[3 * k..3 * k + 3].to_vec();
        let want: Vec<u32> = [1, 4, 6, 2, 7, 0, 3, 5].into_iter().flat_map(tri).collect();
        assert_eq!(idx, want);
        let diffused = [false, true, false, false, true, false, true, false];
        let unlit = [false, true, true, false, false, false, false, true];
        assert_eq!(split.classes(Some(&diffused), &unlit), classes);
        assert_eq!(split.classes(None, &unlit)[1], u);
    }

    /// The plane z = 0 (normals +z) against lights above, below, beside and grazing it.
    #[test]
    fn unlit_triangles_face_away_from_every_light() {
        let mesh = grid(4);
        let split = DisplaySplit::build(&mesh);
        let point = |z: f32| LightDesc::Point {
            position_m: [0.5, 0.5, z],
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        let sun = |z: f32| LightDesc::Directional {
            direction: [0.3, 0.0, -z],
            color: [1.0; 3],
            irradiance_w_m2: 1.0,
        };
        let all = |lights: &[LightDesc], want: bool| split.unlit(lights).iter().all(|&u| u == want);
        assert!(all(&[point(-1.0)], true));
        assert!(all(&[point(1.0)], false));
        assert!(all(&[point(-1.0), point(1.0)], false));
        assert!(all(&[sun(-1.0)], true)); // travelling up: lights the back
        assert!(all(&[sun(1.0)], false));
        assert!(all(&[], true));
        // A black light above: nothing reaches.
        let black = LightDesc::Point {
            position_m: [0.5, 0.5, 1.0],
            color: [0.0; 3],
            intensity_w_sr: 5.0,
        };
        assert!(all(&[black, point(-1.0)], true));
        // A light in the plane (grazing, n·(L − p) = 0 everywhere): not provably unlit.
        assert!(all(&[point(0.0)], false));
        // Below the plane but beside it: the far triangles see it under the plane only.
        let beside = LightDesc::Point {
            position_m: [3.0, 0.5, -0.01],
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        assert!(all(&[beside], true));
    }
}
