//! Lightmap charts for scenes built in code from planar rectangles (`cornell`, `maze`).
//!
//! A built-in scene lists its faces as [`Face`]s (a corner and two edges, metres, the air on
//! the side of `e1 × e2`); [`charted_mesh`] gives every face its own axis-aligned rectangular
//! chart and returns the mesh.
//!
//! # Layout
//! Every chart's texel size is proportional to its face's world size (one texel density for
//! all charts; each side rounded *up* to whole texels, at least [`MIN_CHART_TEXELS`]). Charts
//! are packed by a skyline bottom-left packer (largest first; a chart may be turned by 90° but
//! is never mirrored: the UV frame (u, v) maps to a frame (e_u, e_v) on the face with
//! e_u × e_v along the normal, for every chart) with [`GUTTER_TEXELS`] empty texels between
//! charts and to the border; the texel density is the largest that fits (bisection). Chart
//! corners lie on texel edges, so a chart of w × h texels covers exactly w × h texel centres.
//!
//! # Mesh
//! Every face becomes four vertices of its own (flat normal, no vertex shared between faces)
//! and two triangles `(0,1,2)`, `(0,2,3)`, counter-clockwise seen from the air side, in the
//! order of the faces.

use glam::{Vec2, Vec3};

use super::{Mesh, MeshTriangle};

/// Empty texels between charts and between a chart and the lightmap border.
pub const GUTTER_TEXELS: u32 = 2;
/// Smallest chart side, texels.
pub const MIN_CHART_TEXELS: u32 = 3;

/// A planar rectangle `origin + s·e1 + t·e2`, s, t ∈ [0, 1] (metres); the air is on the side
/// of `e1 × e2`.
#[derive(Clone, Copy, Debug)]
pub struct Face {
    /// One corner, metres.
    pub origin: Vec3,
    /// First edge from `origin`, metres.
    pub e1: Vec3,
    /// Second edge from `origin`, metres.
    pub e2: Vec3,
    /// Index into the scene's materials.
    pub material: u32,
}

impl Face {
    /// A face with the given corner and edges, oriented so that `e1 × e2` has a positive
    /// component along `towards_air`.
    pub fn oriented(origin: Vec3, e1: Vec3, e2: Vec3, towards_air: Vec3, material: u32) -> Self {
        if e1.cross(e2).dot(towards_air) >= 0.0 {
            Face {
                origin,
                e1,
                e2,
                material,
            }
        } else {
            Face {
                origin,
                e1: e2,
                e2: e1,
                material,
            }
        }
    }
}

/// A placed chart: the texel rectangle `[x, x+w) × [y, y+h)` (y down, row 0 is v = 1); the
/// default is the empty chart at the origin.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ChartRect {
    /// Left texel column.
    pub x: u32,
    /// Top texel row.
    pub y: u32,
    /// Width in texels.
    pub w: u32,
    /// Height in texels.
    pub h: u32,
}

/// Chart sizes in texels at `texels_per_m`: each side rounded up, at least
/// [`MIN_CHART_TEXELS`]. `(e1 side, e2 side)` → `(width, height)` before any turning.
pub(crate) fn chart_sizes(sides_m: &[(f32, f32)], texels_per_m: f64) -> Vec<(u32, u32)> {
    let texels = |len: f32| {
        let t = (len as f64 * texels_per_m - 1e-6).ceil().max(0.0) as u32;
        t.max(MIN_CHART_TEXELS)
    };
    sides_m
        .iter()
        .map(|&(a, b)| (texels(a), texels(b)))
        .collect()
}

/// Skyline bottom-left packing (y down, so "bottom" is the smallest y) of the charts,
/// tallest first, into `size × size` with [`GUTTER_TEXELS`] between charts and to the
/// border. Each chart may be turned by 90° (the returned flag says so) when that places it
/// lower. `None` if some chart does not fit.
///
/// Gutters: every chart is inflated by the gutter on its right and bottom and the inflated
/// rectangles are packed without overlap into `[g, size)²`; then two charts are at least `g`
/// apart and every chart is at least `g` from each border.
pub(crate) fn skyline_pack(sizes: &[(u32, u32)], size: u32) -> Option<Vec<(ChartRect, bool)>> {
    let g = GUTTER_TEXELS;
    let extent = size.checked_sub(g)?; // packing area [g, size) has extent size − g
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| {
        let (w, h) = sizes[i];
        (std::cmp::Reverse(w.max(h)), std::cmp::Reverse(w.min(h)), i)
    });
    let mut sky: Skyline = vec![(0, extent, 0)];
    let mut out = vec![(ChartRect::default(), false); sizes.len()];
    for i in order {
        let (y, x, w, h, turned) = lowest_placement(&sky, sizes[i], extent)?;
        out[i] = (
            ChartRect {
                x: x + g,
                y: y + g,
                w,
                h,
            },
            turned,
        );
        raise_skyline(&mut sky, x, w + g, y + h + g);
    }
    Some(out)
}

/// Skyline: `(x, width, y)` segments covering `[0, extent)`, in packing-area coordinates,
/// sorted by `x`.
type Skyline = Vec<(u32, u32, u32)>;

/// The lowest (then leftmost) place on `sky` for a `(w0, h0)` chart inflated by the gutter,
/// as is or turned: `(y, x, w, h, turned)`; `None` if it fits nowhere within `extent`.
fn lowest_placement(
    sky: &[(u32, u32, u32)],
    (w0, h0): (u32, u32),
    extent: u32,
) -> Option<(u32, u32, u32, u32, bool)> {
    let g = GUTTER_TEXELS;
    // Best placement: (y, x, w, h, turned).
    let mut best: Option<(u32, u32, u32, u32, bool)> = None;
    for (w, h, turned) in [(w0, h0, false), (h0, w0, true)] {
        let (wi, hi) = (w + g, h + g);
        for start in 0..sky.len() {
            let x = sky[start].0;
            if x + wi > extent {
                break;
            }
            // Highest skyline under [x, x + wi).
            let y = sky[start..]
                .iter()
                .take_while(|seg| seg.0 < x + wi)
                .map(|seg| seg.2)
                .max()
                .unwrap_or(0);
            if y + hi > extent {
                continue;
            }
            if best.is_none_or(|b| (y, x) < (b.0, b.1)) {
                best = Some((y, x, w, h, turned));
            }
        }
    }
    best
}

/// Raises the skyline over `[x, x + width)` to `top`, merging neighbours at the same height.
fn raise_skyline(sky: &mut Skyline, x: u32, width: u32, top: u32) {
    let x_end = x + width;
    let mut next: Vec<(u32, u32, u32)> = Vec::with_capacity(sky.len() + 2);
    for &(sx, sw, sy) in sky.iter() {
        let s_end = sx + sw;
        if s_end <= x || sx >= x_end {
            next.push((sx, sw, sy));
            continue;
        }
        if sx < x {
            next.push((sx, x - sx, sy));
        }
        if s_end > x_end {
            next.push((x_end, s_end - x_end, sy));
        }
    }
    next.push((x, width, top));
    next.sort_by_key(|seg| seg.0);
    sky.clear();
    for seg in next {
        match sky.last_mut() {
            Some(last) if last.2 == seg.2 && last.0 + last.1 == seg.0 => last.1 += seg.1,
            _ => sky.push(seg),
        }
    }
}

/// The packed layout for a `size × size` lightmap: texel density (texels per metre), and per
/// face its chart and whether it is turned (the face's `e2` runs along the chart's width).
///
/// The density is bisected in `[0, 2·size / longest side]` (the upper end never fits: the
/// longest side alone would be twice the map). At the smallest map a scene supports,
/// minimum-size charts must fit (density 0); otherwise every chart is empty, so nothing can
/// overlap.
pub fn layout(faces: &[Face], size: u32) -> (f64, Vec<(ChartRect, bool)>) {
    let sides: Vec<(f32, f32)> = faces
        .iter()
        .map(|f| (f.e1.length(), f.e2.length()))
        .collect();
    let longest = sides
        .iter()
        .fold(0.0f32, |m, &(a, b)| m.max(a).max(b))
        .max(f32::MIN_POSITIVE);
    let fits = |s: f64| skyline_pack(&chart_sizes(&sides, s), size);
    let (mut lo, mut hi) = (0.0f64, 2.0 * size as f64 / longest as f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if fits(mid).is_some() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let rects = fits(lo).unwrap_or_else(|| vec![(ChartRect::default(), false); faces.len()]);
    (lo, rects)
}

/// The mesh of `faces`, each with its own chart of the [`layout`] for a `size × size` lightmap
/// (see the module docs).
pub fn charted_mesh(faces: &[Face], size: u32) -> Mesh {
    let (_, charts) = layout(faces, size);
    let mut mesh = Mesh::default();
    let texel_to_uv =
        |x: u32, y: u32| Vec2::new(x as f32 / size as f32, 1.0 - y as f32 / size as f32);
    for (face, (r, rotated)) in faces.iter().zip(charts) {
        let base = mesh.positions_m.len() as u32;
        // Chart frame: origin at the chart's bottom-left, e_u along +u, e_v along +v.
        let (origin, e_u, e_v) = if rotated {
            (face.origin + face.e1, face.e2, -face.e1)
        } else {
            (face.origin, face.e1, face.e2)
        };
        let corners = [origin, origin + e_u, origin + e_u + e_v, origin + e_v];
        let uvs = [
            texel_to_uv(r.x, r.y + r.h),
            texel_to_uv(r.x + r.w, r.y + r.h),
            texel_to_uv(r.x + r.w, r.y),
            texel_to_uv(r.x, r.y),
        ];
        let n = e_u.cross(e_v).normalize();
        let normal_index = mesh.normals.len() as u32;
        mesh.normals.push(n);
        mesh.positions_m.extend(corners);
        mesh.uvs.extend(uvs);
        for [a, b, c] in [[0, 1, 2], [0, 2, 3]] {
            let idx = [base + a, base + b, base + c];
            mesh.triangles.push(MeshTriangle {
                position: idx,
                uv: idx,
                normal: [normal_index; 3],
                material: face.material,
            });
        }
    }
    mesh
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Whether the placed charts keep the gutter from each other and from the border.
    fn valid(rects: &[(ChartRect, bool)], size: u32) -> bool {
        let g = GUTTER_TEXELS;
        let inside = rects
            .iter()
            .all(|(r, _)| r.x >= g && r.y >= g && r.x + r.w + g <= size && r.y + r.h + g <= size);
        let apart = rects.iter().enumerate().all(|(i, (a, _))| {
            rects[i + 1..].iter().all(|(b, _)| {
                a.x + a.w + g <= b.x
                    || b.x + b.w + g <= a.x
                    || a.y + a.h + g <= b.y
                    || b.y + b.h + g <= a.y
            })
        });
        inside && apart
    }

    #[test]
    fn skyline_pack_respects_gutters_bounds_and_sizes() {
        let sizes = [(10, 4), (10, 4), (5, 5), (3, 12), (7, 3), (4, 4)];
        let r = skyline_pack(&sizes, 32).expect("fits");
        assert!(valid(&r, 32));
        for ((rect, turned), (w, h)) in r.iter().zip(sizes) {
            let want = if *turned { (h, w) } else { (w, h) };
            assert_eq!((rect.w, rect.h), want);
        }
        // The first chart placed (the longest side) sits in the corner.
        assert_eq!((r[3].0.x, r[3].0.y), (GUTTER_TEXELS, GUTTER_TEXELS));
        // A chart exactly as large as the map minus both gutters fits; one texel more fails.
        assert!(skyline_pack(&[(28, 3)], 32).is_some());
        assert!(skyline_pack(&[(29, 3)], 32).is_none());
        // Many small charts: brute-force check of every pair.
        let many: Vec<(u32, u32)> = (0..40).map(|i| (3 + i % 5, 3 + (i * 7) % 6)).collect();
        let r = skyline_pack(&many, 96).expect("fits");
        assert!(valid(&r, 96));
        // Too many charts for the area: refused, not overlapped.
        assert!(skyline_pack(&vec![(10, 10); 30], 48).is_none());
    }

    #[test]
    fn chart_sizes_round_up_with_a_minimum() {
        let s = chart_sizes(&[(0.5, 1.0), (0.01, 0.01), (0.25, 0.3)], 10.0);
        assert_eq!(
            s,
            vec![(5, 10), (MIN_CHART_TEXELS, MIN_CHART_TEXELS), (3, 3)]
        );
    }

    #[test]
    fn layout_is_valid_and_densest_within_one_step() {
        // Two 1 × 0.5 m faces and a 0.2 m square at 64²: valid, and 1 % denser does not fit.
        let f = |a: f32, b: f32| Face {
            origin: Vec3::ZERO,
            e1: Vec3::X * a,
            e2: Vec3::Y * b,
            material: 0,
        };
        let faces = [f(1.0, 0.5), f(1.0, 0.5), f(0.2, 0.2)];
        let (density, rects) = layout(&faces, 64);
        assert!(valid(&rects, 64));
        assert!(density > 0.0);
        let sides: Vec<_> = faces
            .iter()
            .map(|f| (f.e1.length(), f.e2.length()))
            .collect();
        assert!(skyline_pack(&chart_sizes(&sides, density * 1.01), 64).is_none());
    }
}
