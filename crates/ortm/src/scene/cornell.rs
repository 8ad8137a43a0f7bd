//! The built-in Cornell box, made in code, with its lightmap charts packed in code.
//!
//! # Geometry (metres, right-handed, y up)
//! The box is the cube `[0, 0.555]³`. The **open side faces +z** (the plane z = 0.555 has no
//! wall): a camera at z > 0.555 looking towards −z sees the back wall (z = 0), the red wall
//! on its left (x = 0), the green wall on its right (x = 0.555), the floor (y = 0) and the
//! ceiling (y = 0.555). The two white blocks follow the classic scene (coordinates of the
//! Cornell data rotated 180° about the vertical axis so that the open side faces +z): a
//! short block (0.165 m cube, rotated ≈ 17°) front right and a tall block (0.165 × 0.33 ×
//! 0.165 m, rotated ≈ −17°) back left. Their bottom faces (on the floor) are omitted.
//!
//! Every face is a separate planar rectangle with its own four vertices (flat normals; no
//! vertex is shared between faces) and its normal points into the air: walls inward, block
//! faces outward. Each rectangle is two triangles `(0,1,2)`, `(0,2,3)`, counter-clockwise
//! seen from the air side.
//!
//! # Materials and light
//! `white` ρ = 0.73 (floor, ceiling, back wall, blocks), `red` ρ = (0.63, 0.065, 0.05),
//! `green` ρ = (0.14, 0.45, 0.09). One white point light of [`LIGHT_INTENSITY_W_SR`] W/sr
//! 2 cm under the centre of the ceiling: the floor gets ≈ 28 W/m² directly below it and
//! ≈ 15 W/m² in the corners (before shadowing).
//!
//! # Lightmap charts
//! Every face is one axis-aligned rectangular chart whose texel size is proportional to the
//! face's world size (one texel density for all charts; each side rounded *up* to whole
//! texels, at least [`MIN_CHART_TEXELS`]). Charts are packed by a skyline bottom-left packer
//! (largest first; a chart may be turned by 90° but is never mirrored: the UV frame (u, v)
//! maps to a frame (e_u, e_v) on the face with e_u × e_v along the normal, for every chart)
//! with [`GUTTER_TEXELS`] empty texels between charts and to the border; the texel density
//! is the largest that fits (bisection). Chart corners lie on texel edges, so a chart of
//! w × h texels covers exactly w × h texel centres.
//!
//! # Limits
//! Only square lightmaps; sizes are clamped to [[`MIN_LIGHTMAP_SIZE`], 8192] (below 32
//! texels the charts and gutters do not fit; the returned scene states the size used).

use glam::{Vec2, Vec3};

use super::{Albedo, Light, Material, Mesh, MeshTriangle, Scene};

/// Edge length of the box, metres.
pub const BOX_SIZE_M: f32 = 0.555;
/// Empty texels between charts and between a chart and the lightmap border.
pub const GUTTER_TEXELS: u32 = 2;
/// Smallest chart side, texels.
pub const MIN_CHART_TEXELS: u32 = 3;
/// Smallest lightmap size [`cornell_box`] builds.
pub const MIN_LIGHTMAP_SIZE: u32 = 32;
/// Intensity of the default point light, W/sr.
pub const LIGHT_INTENSITY_W_SR: f32 = 8.0;

/// A block of the Cornell box: an upright box standing on the floor.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CornellBlock {
    /// Centre of the footprint (x, z), metres.
    pub centre_xz: Vec2,
    /// Half the footprint's side, metres.
    pub half_side_m: f32,
    /// Height, metres.
    pub height_m: f32,
    /// Rotation about +y, radians (counter-clockwise seen from above).
    pub angle_rad: f32,
}

impl CornellBlock {
    /// Footprint corners (x, z), counter-clockwise seen from above (+y).
    pub fn footprint(&self) -> [Vec2; 4] {
        // Rotation about +y by θ maps (x, z) to (x cosθ + z sinθ, −x sinθ + z cosθ);
        // counter-clockwise seen from +y means increasing angle from +z towards +x.
        let (s, c) = self.angle_rad.sin_cos();
        let rot = |p: Vec2| Vec2::new(p.x * c + p.y * s, -p.x * s + p.y * c);
        let h = self.half_side_m;
        [
            Vec2::new(-h, -h),
            Vec2::new(-h, h),
            Vec2::new(h, h),
            Vec2::new(h, -h),
        ]
        .map(|p| self.centre_xz + rot(p))
    }

    /// Whether point `p` lies strictly inside the block.
    pub fn contains(&self, p: Vec3) -> bool {
        let (s, c) = self.angle_rad.sin_cos();
        let d = Vec2::new(p.x, p.z) - self.centre_xz;
        // Inverse rotation.
        let local = Vec2::new(d.x * c - d.y * s, d.x * s + d.y * c);
        local.abs().max_element() < self.half_side_m && p.y > 0.0 && p.y < self.height_m
    }
}

/// The two blocks: short (front right) and tall (back left).
pub fn cornell_blocks() -> [CornellBlock; 2] {
    // Classic Cornell data (mm, open side at z = 0, red wall at x ≈ 555):
    // short block footprint centre (185.5, 169), tall (368.5, 351.25); sides 165 mm,
    // edges rotated ≈ ±17°. Rotated 180° about y: (x, z) → (555 − x, 555 − z).
    let l = BOX_SIZE_M;
    [
        CornellBlock {
            centre_xz: Vec2::new(l - 0.1855, l - 0.169),
            half_side_m: 0.0825,
            height_m: 0.165,
            angle_rad: (-17.0f32).to_radians(),
        },
        CornellBlock {
            centre_xz: Vec2::new(l - 0.3685, l - 0.35125),
            half_side_m: 0.0825,
            height_m: 0.33,
            angle_rad: 17.0f32.to_radians(),
        },
    ]
}

/// A planar rectangle `origin + s·e1 + t·e2`, s, t ∈ [0, 1]; the air is on the side of
/// `e1 × e2`.
#[derive(Clone, Copy, Debug)]
struct Face {
    origin: Vec3,
    e1: Vec3,
    e2: Vec3,
    material: u32,
}

impl Face {
    /// A face with the given corner and edges, oriented so that `e1 × e2` has a positive
    /// component along `towards_air`.
    fn oriented(origin: Vec3, e1: Vec3, e2: Vec3, towards_air: Vec3, material: u32) -> Self {
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

/// Material indices.
const WHITE: u32 = 0;
const RED: u32 = 1;
const GREEN: u32 = 2;

/// The 15 faces: 5 walls, then 5 faces per block.
fn faces() -> Vec<Face> {
    let l = BOX_SIZE_M;
    let (x, y, z) = (Vec3::X * l, Vec3::Y * l, Vec3::Z * l);
    let o = Vec3::ZERO;
    let centre = Vec3::splat(l / 2.0);
    let wall = |origin: Vec3, e1: Vec3, e2: Vec3, m: u32| {
        let mid = origin + 0.5 * (e1 + e2);
        Face::oriented(origin, e1, e2, centre - mid, m)
    };
    let mut out = vec![
        wall(o, x, z, WHITE), // floor, y = 0
        wall(y, x, z, WHITE), // ceiling, y = L
        wall(o, x, y, WHITE), // back, z = 0
        wall(o, y, z, RED),   // left, x = 0
        wall(x, y, z, GREEN), // right, x = L
    ];
    for b in cornell_blocks() {
        let fp = b.footprint();
        let c3 = Vec3::new(b.centre_xz.x, b.height_m / 2.0, b.centre_xz.y);
        let up = Vec3::Y * b.height_m;
        for k in 0..4 {
            let p = Vec3::new(fp[k].x, 0.0, fp[k].y);
            let q = Vec3::new(fp[(k + 1) % 4].x, 0.0, fp[(k + 1) % 4].y);
            let mid = 0.5 * (p + q) + 0.5 * up;
            out.push(Face::oriented(p, q - p, up, mid - c3, WHITE));
        }
        let top = Vec3::new(fp[0].x, b.height_m, fp[0].y);
        let e1 = Vec3::new(fp[1].x - fp[0].x, 0.0, fp[1].y - fp[0].y);
        let e2 = Vec3::new(fp[3].x - fp[0].x, 0.0, fp[3].y - fp[0].y);
        out.push(Face::oriented(top, e1, e2, Vec3::Y, WHITE));
    }
    out
}

/// A placed chart: the texel rectangle `[x, x+w) × [y, y+h)` (y down, row 0 is v = 1); the
/// default is the empty chart at the origin.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
struct ChartRect {
    /// Left texel column.
    x: u32,
    /// Top texel row.
    y: u32,
    /// Width in texels.
    w: u32,
    /// Height in texels.
    h: u32,
}

/// Chart sizes in texels at `texels_per_m`: each side rounded up, at least
/// [`MIN_CHART_TEXELS`]. `(e1 side, e2 side)` → `(width, height)` before any turning.
fn chart_sizes(sides_m: &[(f32, f32)], texels_per_m: f64) -> Vec<(u32, u32)> {
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
fn skyline_pack(sizes: &[(u32, u32)], size: u32) -> Option<Vec<(ChartRect, bool)>> {
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
fn layout(faces: &[Face], size: u32) -> (f64, Vec<(ChartRect, bool)>) {
    let sides: Vec<(f32, f32)> = faces
        .iter()
        .map(|f| (f.e1.length(), f.e2.length()))
        .collect();
    let fits = |s: f64| skyline_pack(&chart_sizes(&sides, s), size);
    let (mut lo, mut hi) = (0.0f64, 2.0 * size as f64 / BOX_SIZE_M as f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if fits(mid).is_some() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    // `lo` is feasible (s = 0 gives minimum-size charts, which fit at MIN_LIGHTMAP_SIZE);
    // fall back to empty charts otherwise so that nothing can overlap.
    let rects = fits(lo).unwrap_or_else(|| vec![(ChartRect::default(), false); faces.len()]);
    (lo, rects)
}

/// The Cornell box (see the module docs) with a `lightmap_size × lightmap_size` chart layout
/// (clamped to `[32, 8192]`).
pub fn cornell_box(lightmap_size: u32) -> Scene {
    let size = lightmap_size.clamp(MIN_LIGHTMAP_SIZE, super::file::MAX_LIGHTMAP_SIZE);
    let faces = faces();
    let (_, charts) = layout(&faces, size);
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
    let materials = vec![
        Material {
            name: "white".into(),
            albedo: Albedo::Constant(Vec3::splat(0.73)),
            subsurface: None,
        },
        Material {
            name: "red".into(),
            albedo: Albedo::Constant(Vec3::new(0.63, 0.065, 0.05)),
            subsurface: None,
        },
        Material {
            name: "green".into(),
            albedo: Albedo::Constant(Vec3::new(0.14, 0.45, 0.09)),
            subsurface: None,
        },
    ];
    let l = BOX_SIZE_M;
    Scene {
        name: "cornell".into(),
        mesh,
        materials,
        lights: vec![Light::Point {
            position_m: Vec3::new(l / 2.0, l - 0.02, l / 2.0),
            color: Vec3::ONE,
            intensity_w_sr: LIGHT_INTENSITY_W_SR,
        }],
        lightmap_size: (size, size),
        allow_uv_overlap: false,
    }
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
    fn block_footprints_are_counter_clockwise_squares() {
        for b in cornell_blocks() {
            let fp = b.footprint();
            for k in 0..4 {
                let e = fp[(k + 1) % 4] - fp[k];
                assert!((e.length() - 2.0 * b.half_side_m).abs() < 1e-5);
            }
            // Counter-clockwise seen from +y (z × x = y): the signed area in the (z, x)
            // plane, Σ (z_k x_{k+1} − x_k z_{k+1}) / 2, is +side².
            let area: f32 = (0..4)
                .map(|k| {
                    let (p, q) = (fp[k], fp[(k + 1) % 4]);
                    p.y * q.x - p.x * q.y
                })
                .sum::<f32>()
                / 2.0;
            assert!(
                (area - (2.0 * b.half_side_m).powi(2)).abs() < 1e-5,
                "area {area}"
            );
            assert!(b.contains(Vec3::new(b.centre_xz.x, 0.01, b.centre_xz.y)));
        }
    }
}
