//! The lightmap's texels as surface patches: for a `W×H` lightmap, every *covered* texel with
//! its world position (metres), normal, area (m²), albedo, material and chart.
//!
//! # Coverage rule
//! A texel is covered when its centre lies inside a UV triangle — the rule of the GPU
//! rasterizer, which the first-order pass uses to render the same lightmap. Texel `(x, y)`'s
//! centre is at texel-space point `(x + 0.5, y + 0.5)` where texel space is `(u·W, (1 − v)·H)`
//! (row 0 is `v = 1`, as in image files). A centre exactly on an edge shared by two triangles
//! belongs to one of them by the top-left rule (as in Direct3D and Vulkan rasterizers), so
//! adjacent triangles never both cover a texel.
//!
//! # Patch attributes
//! Position and shading normal are interpolated barycentrically at the texel centre. The area is
//! the surface area the texel stands for: the world area per texel-space area (the UV→3D
//! Jacobian) averaged over the part of the texel's square that its chart covers — each of the
//! chart's triangles weighted by the texel-space area it clips from the square, so a texel
//! counts one texel of its chart's surface however its triangles are stretched. The footprint
//! vectors are the mean `∂P/∂x`, `∂P/∂y` over the same part (the secants across the square),
//! scaled so their parallelogram has that area. Where every triangle clipped shares the covering
//! triangle's Jacobian within 10⁻⁵ (planar charts mapped affinely: the Cornell box, the maze),
//! the covering triangle's own values are kept. On a scan whose triangles are smaller than a
//! texel and unevenly stretched (the head), the covering triangle's Jacobian alone jumps 2–3×
//! between neighbouring texels; the average does not. Albedo is the material's (a texture is sampled at the texel's UV); for
//! subsurface materials it is the profile's total diffuse reflectance (the effective albedo that
//! first-order lighting `B_o = ρ·E` uses).
//!
//! # Validation
//! Overlapping UVs (a texel centre inside two triangles) are an error naming the overlapping area,
//! unless the scene opts out (`allow_uv_overlap`); then the triangle drawn last wins, as on the
//! GPU. A small number of overlapping texels (≤ 0.1% of covered texels, typical of seams in
//! scanned meshes) is tolerated with a warning.

use std::collections::HashMap;

use glam::{DVec2, DVec3, Vec2, Vec3};
use thiserror::Error;

use crate::lightmap::uv_to_texel_space;
use crate::scene::{Scene, SurfaceAlbedo};

/// Marker for an uncovered lightmap slot.
pub const NO_TEXEL: u32 = u32::MAX;

/// Fraction of covered texels that may overlap without an error.
pub const OVERLAP_TOLERANCE: f64 = 0.001;

/// One covered texel as a surface patch.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Texel {
    /// Column.
    pub x: u32,
    /// Row (row 0 is v = 1).
    pub y: u32,
    /// Surface point at the texel centre, metres.
    pub position_m: Vec3,
    /// Unit shading normal (interpolated).
    pub normal: Vec3,
    /// Unit geometric normal of the covering triangle.
    pub face_normal: Vec3,
    /// Surface area the texel represents, m² (the Jacobian averaged over the texel's square:
    /// module docs, "Patch attributes").
    pub area_m2: f32,
    /// The texel's footprint: the 3D steps (metres) of one texel in x and in y (`∂P/∂x`,
    /// `∂P/∂y` in texel units, averaged over the texel's square), so the footprint is the
    /// parallelogram `position_m + s·f[0] + t·f[1]`, `s, t ∈ [−½, ½]`, of area
    /// `|f[0] × f[1]| = area_m2`.
    pub footprint_m: [Vec3; 2],
    /// Effective diffuse albedo ρ (RGB).
    pub albedo: Vec3,
    /// Material index.
    pub material: u32,
    /// Chart (connected UV island) index.
    pub chart: u32,
    /// Covering triangle index.
    pub triangle: u32,
}

/// Problems found while rasterizing the UV layout.
#[derive(Debug, Error)]
pub enum TexelError {
    /// Two or more triangles cover the same texel centres.
    #[error(
        "scene '{scene}': lightmap UVs overlap: {texels} texel(s) at {width}x{height} \
         ({fraction:.3}% of the covered texels, e.g. triangles {tri_a} and {tri_b} both cover \
         texel ({x}, {y})). Lightmap UVs must not overlap: give every face its own UV area \
         (e.g. re-unwrap with a lightmap UV tool), or set `allow_uv_overlap = true` in the scene \
         file to accept it (the last triangle wins)"
    )]
    Overlap {
        /// Scene name.
        scene: String,
        /// Overlapping texels.
        texels: usize,
        /// Percentage of covered texels.
        fraction: f64,
        /// Lightmap width.
        width: u32,
        /// Lightmap height.
        height: u32,
        /// A triangle involved.
        tri_a: u32,
        /// Another triangle involved.
        tri_b: u32,
        /// Example texel column.
        x: u32,
        /// Example texel row.
        y: u32,
    },
    /// No texel is covered.
    #[error(
        "scene '{scene}': no lightmap texel centre lies inside any UV triangle at {width}x{height}; \
         use a larger lightmap size or check the UVs"
    )]
    Empty {
        /// Scene name.
        scene: String,
        /// Lightmap width.
        width: u32,
        /// Lightmap height.
        height: u32,
    },
}

/// Statistics of the rasterization.
#[derive(Clone, Debug, Default)]
pub struct CoverageStats {
    /// Covered texels.
    pub covered: usize,
    /// Texels inside two or more triangles.
    pub overlapping: usize,
    /// Number of charts (UV islands).
    pub charts: usize,
    /// Triangles that cover no texel centre (too small at this resolution).
    pub triangles_without_texels: usize,
    /// Total surface area, m² (sum of texel areas).
    pub area_m2: f64,
    /// Warnings (e.g. tolerated overlaps).
    pub warnings: Vec<String>,
}

/// All covered texels of a `width × height` lightmap.
#[derive(Clone, Debug)]
pub struct TexelGrid {
    /// Lightmap width.
    pub width: u32,
    /// Lightmap height.
    pub height: u32,
    /// Covered texels in row-major order.
    pub texels: Vec<Texel>,
    /// For each lightmap slot (`y*width + x`), the index into `texels` or [`NO_TEXEL`].
    pub slot: Vec<u32>,
    /// Chart index of every triangle.
    pub triangle_chart: Vec<u32>,
    /// Statistics.
    pub stats: CoverageStats,
}

/// Top-left rule for an edge `a → b` of a triangle with positive (counter-clockwise in a
/// y-down frame ⇒ we normalise orientation first) orientation.
#[inline]
fn is_top_left(a: (f64, f64), b: (f64, f64)) -> bool {
    let (dx, dy) = (b.0 - a.0, b.1 - a.1);
    // With edge functions E = (b−a)×(p−a) > 0 inside (clockwise on screen, y down):
    // a "top" edge is horizontal with the interior below it, a "left" edge goes upwards.
    (dy == 0.0 && dx > 0.0) || dy < 0.0
}

/// Connected UV islands: triangles sharing an edge with the same positions and UVs.
fn charts(scene: &Scene) -> (Vec<u32>, usize) {
    let tris = &scene.mesh.triangles;
    let mut parent: Vec<u32> = (0..tris.len() as u32).collect();
    fn find(p: &mut [u32], mut i: u32) -> u32 {
        while p[i as usize] != i {
            p[i as usize] = p[p[i as usize] as usize];
            i = p[i as usize];
        }
        i
    }
    let key = |t: usize, k: usize| {
        let tri = &tris[t];
        let uv = scene.mesh.uvs[tri.uv[k] as usize];
        (tri.position[k], uv.x.to_bits(), uv.y.to_bits())
    };
    // An edge end point: (position index, UV bits); an edge: its two sorted end points.
    type EdgeEnd = (u32, u32, u32);
    let mut edges: HashMap<(EdgeEnd, EdgeEnd), u32> = HashMap::new();
    for t in 0..tris.len() {
        for k in 0..3 {
            let (a, b) = (key(t, k), key(t, (k + 1) % 3));
            let e = if a < b { (a, b) } else { (b, a) };
            if let Some(&other) = edges.get(&e) {
                let (ra, rb) = (find(&mut parent, t as u32), find(&mut parent, other));
                if ra != rb {
                    parent[ra as usize] = rb;
                }
            } else {
                edges.insert(e, t as u32);
            }
        }
    }
    let mut ids = HashMap::new();
    let mut out = vec![0u32; tris.len()];
    for (t, o) in out.iter_mut().enumerate() {
        let r = find(&mut parent, t as u32);
        let n = ids.len() as u32;
        *o = *ids.entry(r).or_insert(n);
    }
    (out, ids.len())
}

/// Which triangle covers each lightmap slot (the coverage rule of the module docs).
struct Coverage {
    /// Per slot (`y·W + x`): the last covering triangle ([`NO_TEXEL`] if none) and the texel
    /// centre's barycentrics in it.
    cover: Vec<(u32, [f32; 3])>,
    /// Per slot, how many triangles cover it (saturating).
    count: Vec<u8>,
    /// The first overlap found: (earlier triangle, later triangle, x, y).
    first_overlap: Option<(u32, u32, u32, u32)>,
    /// Triangles that cover no texel centre (or have no UV area).
    triangles_without_texels: usize,
}

/// Rasterizes every triangle's UVs at `width × height` texel centres, top-left rule on shared
/// edges; a later triangle overwrites an earlier one.
fn rasterize(scene: &Scene, width: u32, height: u32) -> Coverage {
    let mesh = &scene.mesh;
    let n_slots = width as usize * height as usize;
    let mut cov = Coverage {
        cover: vec![(NO_TEXEL, [0.0; 3]); n_slots],
        count: vec![0u8; n_slots],
        first_overlap: None,
        triangles_without_texels: 0,
    };
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let p: [(f64, f64); 3] = std::array::from_fn(|k| {
            let q = uv_to_texel_space(mesh.uvs[tri.uv[k] as usize], width, height);
            (q.x as f64, q.y as f64)
        });
        // Orientation: make E = (b−a)×(p−a) positive inside.
        let area2 = (p[1].0 - p[0].0) * (p[2].1 - p[0].1) - (p[1].1 - p[0].1) * (p[2].0 - p[0].0);
        if area2 == 0.0 || !area2.is_finite() {
            cov.triangles_without_texels += 1;
            continue;
        }
        let order = if area2 > 0.0 { [0, 1, 2] } else { [0, 2, 1] };
        let v = [p[order[0]], p[order[1]], p[order[2]]];
        if !rasterize_triangle(&mut cov, ti as u32, v, order, area2.abs(), width, height) {
            cov.triangles_without_texels += 1;
        }
    }
    cov
}

/// Marks the texel centres inside the positively oriented texel-space triangle `v` (vertex `k`
/// of `v` is vertex `order[k]` of triangle `ti`, whose doubled area is `area2`); whether any
/// was.
fn rasterize_triangle(
    cov: &mut Coverage,
    ti: u32,
    v: [(f64, f64); 3],
    order: [usize; 3],
    area2: f64,
    width: u32,
    height: u32,
) -> bool {
    let min_x = v.iter().map(|q| q.0).fold(f64::INFINITY, f64::min);
    let max_x = v.iter().map(|q| q.0).fold(f64::NEG_INFINITY, f64::max);
    let min_y = v.iter().map(|q| q.1).fold(f64::INFINITY, f64::min);
    let max_y = v.iter().map(|q| q.1).fold(f64::NEG_INFINITY, f64::max);
    let x0 = ((min_x - 0.5).ceil().max(0.0)) as i64;
    let x1 = ((max_x - 0.5).floor().min(width as f64 - 1.0)) as i64;
    let y0 = ((min_y - 0.5).ceil().max(0.0)) as i64;
    let y1 = ((max_y - 0.5).floor().min(height as f64 - 1.0)) as i64;
    let tl = [
        is_top_left(v[0], v[1]),
        is_top_left(v[1], v[2]),
        is_top_left(v[2], v[0]),
    ];
    let mut any = false;
    for y in y0..=y1 {
        for x in x0..=x1 {
            let c = (x as f64 + 0.5, y as f64 + 0.5);
            let e = |a: (f64, f64), b: (f64, f64)| {
                (b.0 - a.0) * (c.1 - a.1) - (b.1 - a.1) * (c.0 - a.0)
            };
            let e0 = e(v[0], v[1]); // opposite v2
            let e1 = e(v[1], v[2]); // opposite v0
            let e2 = e(v[2], v[0]); // opposite v1
            let inside = |ev: f64, top_left: bool| ev > 0.0 || (ev == 0.0 && top_left);
            if !(inside(e0, tl[0]) && inside(e1, tl[1]) && inside(e2, tl[2])) {
                continue;
            }
            any = true;
            // Barycentrics in the original vertex order.
            let mut b = [0.0f32; 3];
            b[order[0]] = (e1 / area2) as f32;
            b[order[1]] = (e2 / area2) as f32;
            b[order[2]] = (e0 / area2) as f32;
            let s = y as usize * width as usize + x as usize;
            if cov.count[s] > 0 && cov.first_overlap.is_none() {
                cov.first_overlap = Some((cov.cover[s].0, ti, x as u32, y as u32));
            }
            cov.count[s] = cov.count[s].saturating_add(1);
            cov.cover[s] = (ti, b);
        }
    }
    any
}

/// Per lightmap slot (`y·width + x`), whether the UVs of two or more triangles cover its
/// texel centre: the overlaps [`TexelGrid::build_with_size`] counts, for pictures
/// (`ortm inspect` draws them red).
pub fn overlapping_slots(scene: &Scene, width: u32, height: u32) -> Vec<bool> {
    rasterize(scene, width, height)
        .count
        .iter()
        .map(|&c| c > 1)
        .collect()
}

/// The patch of texel `(x, y)` of a `width × height` lightmap whose centre lies in triangle
/// `ti` at barycentrics `b` (the attributes of the module docs); `surface_albedo` is the scene's
/// albedo rule, `chart` the triangle's chart.
fn texel_patch(
    scene: &Scene,
    surface_albedo: &SurfaceAlbedo<'_>,
    (x, y): (u32, u32),
    (width, height): (u32, u32),
    (ti, b): (u32, [f32; 3]),
    chart: u32,
) -> Texel {
    let mesh = &scene.mesh;
    let tri = &mesh.triangles[ti as usize];
    let pos: [Vec3; 3] = std::array::from_fn(|k| mesh.positions_m[tri.position[k] as usize]);
    let uvs: [Vec2; 3] = std::array::from_fn(|k| mesh.uvs[tri.uv[k] as usize]);
    let nrm: [Vec3; 3] = std::array::from_fn(|k| mesh.normals[tri.normal[k] as usize]);
    let position_m = pos[0] * b[0] + pos[1] * b[1] + pos[2] * b[2];
    let cross = (pos[1] - pos[0]).cross(pos[2] - pos[0]);
    let world_area = 0.5 * cross.length();
    let face_normal = cross.normalize_or_zero();
    let normal = (nrm[0] * b[0] + nrm[1] * b[1] + nrm[2] * b[2])
        .try_normalize()
        .unwrap_or(face_normal);
    let t: [Vec2; 3] = std::array::from_fn(|k| uv_to_texel_space(uvs[k], width, height));
    let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
    let det = d1.perp_dot(d2);
    let texel_area = 0.5 * det.abs();
    let area_m2 = world_area / texel_area;
    // P(t) = p0 + a(p1 − p0) + b(p2 − p0) with t − t0 = a·d1 + b·d2: the columns of ∂P/∂t.
    let (e1, e2) = (pos[1] - pos[0], pos[2] - pos[0]);
    let footprint_m = [(e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det];
    let uv = uvs[0] * b[0] + uvs[1] * b[1] + uvs[2] * b[2];
    let material = tri.material;
    let albedo = surface_albedo.at(material, uv);
    Texel {
        x,
        y,
        position_m,
        normal,
        face_normal,
        area_m2,
        footprint_m,
        albedo,
        material,
        chart,
        triangle: ti,
    }
}

/// Relative difference below which a clipped triangle's Jacobian counts as the covering
/// triangle's (module docs, "Patch attributes").
const SAME_JACOBIAN: f64 = 1e-5;

/// Area (texel² units) of the part of texel-space triangle `t` inside the square
/// `[x, x+1] × [y, y+1]` (Sutherland–Hodgman against the square's four sides).
fn clipped_area(t: [DVec2; 3], x: f64, y: f64) -> f64 {
    let (lo, hi) = (DVec2::new(x, y), DVec2::new(x + 1.0, y + 1.0));
    if t.iter().all(|p| p.cmpge(lo).all() && p.cmple(hi).all()) {
        return 0.5 * (t[1] - t[0]).perp_dot(t[2] - t[0]).abs();
    }
    // A triangle clipped by four half-planes has at most 7 corners.
    let mut poly = [DVec2::ZERO; 8];
    let mut next = [DVec2::ZERO; 8];
    poly[..3].copy_from_slice(&t);
    let mut n = 3;
    // Each side as (axis, bound, keep the side where the coordinate ≥ bound?).
    for (axis, bound, keep_above) in [
        (0, x, true),
        (0, x + 1.0, false),
        (1, y, true),
        (1, y + 1.0, false),
    ] {
        let inside = |p: DVec2| {
            let c = if axis == 0 { p.x } else { p.y };
            if keep_above { c >= bound } else { c <= bound }
        };
        let mut m = 0;
        for i in 0..n {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let (ia, ib) = (inside(a), inside(b));
            if ia {
                next[m] = a;
                m += 1;
            }
            if ia != ib {
                let (ca, cb) = if axis == 0 { (a.x, b.x) } else { (a.y, b.y) };
                next[m] = a + (b - a) * ((bound - ca) / (cb - ca));
                m += 1;
            }
        }
        std::mem::swap(&mut poly, &mut next);
        n = m;
        if n < 3 {
            return 0.0;
        }
    }
    let twice: f64 = (0..n).map(|i| poly[i].perp_dot(poly[(i + 1) % n])).sum();
    0.5 * twice.abs()
}

/// Replaces each covered texel's area and footprint by their averages over the part of its
/// square that its chart covers (module docs, "Patch attributes"); `slot` maps lightmap slots
/// to `texels`, `triangle_chart` gives every triangle's chart.
fn average_over_squares(
    scene: &Scene,
    (width, height): (u32, u32),
    texels: &mut [Texel],
    slot: &[u32],
    (triangle_chart, n_charts): (&[u32], usize),
) {
    /// Per texel, sums over the triangles clipped to its square (f32: at most a few hundred
    /// terms each).
    #[derive(Clone, Copy, Default)]
    struct Sums {
        /// Texel-space area clipped (texel²).
        uv: f32,
        /// World area clipped (m²).
        area: f32,
        /// Σ clipped area × `∂P/∂x`, `∂P/∂y` (m per texel).
        f: [Vec3; 2],
        /// Some clipped triangle's Jacobian differs from the covering triangle's.
        mixed: bool,
    }
    let mesh = &scene.mesh;
    let width_i = width as usize;
    // Each triangle's texel-space corners, Jacobian (m² per texel²) and ∂P/∂x, ∂P/∂y.
    let affine = |tri: &crate::scene::MeshTriangle| {
        let t: [DVec2; 3] = std::array::from_fn(|k| {
            uv_to_texel_space(mesh.uvs[tri.uv[k] as usize], width, height).as_dvec2()
        });
        let pos: [DVec3; 3] =
            std::array::from_fn(|k| mesh.positions_m[tri.position[k] as usize].as_dvec3());
        let (d1, d2) = (t[1] - t[0], t[2] - t[0]);
        let det = d1.perp_dot(d2);
        if det == 0.0 || !det.is_finite() {
            return None;
        }
        let (e1, e2) = (pos[1] - pos[0], pos[2] - pos[0]);
        let jacobian = e1.cross(e2).length() / det.abs();
        let f = [(e1 * d2.y - e2 * d1.y) / det, (e2 * d1.x - e1 * d2.x) / det];
        Some((t, jacobian, f))
    };
    let same = |(j, f): (f64, [DVec3; 2]), (j0, f0): (f64, [DVec3; 2])| {
        (j - j0).abs() <= SAME_JACOBIAN * j0
            && (0..2).all(|i| (f[i] - f0[i]).length() <= SAME_JACOBIAN * f0[i].length())
    };
    // Charts whose triangles all share one Jacobian keep their texels as they are: skip them
    // (no work, no memory, for the planar charts of rooms).
    let mut first: Vec<Option<(f64, [DVec3; 2])>> = vec![None; n_charts];
    let mut uneven = vec![false; n_charts];
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let Some((_, j, f)) = affine(tri) else {
            continue;
        };
        let c = triangle_chart[ti] as usize;
        match first[c] {
            None => first[c] = Some((j, f)),
            Some(j0) => uneven[c] |= !same((j, f), j0),
        }
    }
    if !uneven.iter().any(|&u| u) {
        return;
    }
    // `affine` again per triangle rather than a per-triangle table: cheap beside the clipping,
    // and no memory that grows with the mesh.
    let mut sums = vec![Sums::default(); texels.len()];
    for (ti, tri) in mesh.triangles.iter().enumerate() {
        let chart = triangle_chart[ti];
        if !uneven[chart as usize] {
            continue;
        }
        let Some((t, jacobian, f)) = affine(tri) else {
            continue;
        };
        let lo = t[0].min(t[1]).min(t[2]).floor().max(DVec2::ZERO);
        let hi = t[0].max(t[1]).max(t[2]).ceil();
        let (x1, y1) = (
            (hi.x as i64).min(width as i64),
            (hi.y as i64).min(height as i64),
        );
        for y in lo.y as i64..y1 {
            for x in lo.x as i64..x1 {
                let k = slot[y as usize * width_i + x as usize];
                if k == NO_TEXEL || texels[k as usize].chart != chart {
                    continue;
                }
                let a = clipped_area(t, x as f64, y as f64);
                if a <= 0.0 {
                    continue;
                }
                let texel = &texels[k as usize];
                let s = &mut sums[k as usize];
                s.uv += a as f32;
                s.area += (a * jacobian) as f32;
                s.f[0] += (f[0] * a).as_vec3();
                s.f[1] += (f[1] * a).as_vec3();
                if ti as u32 != texel.triangle && !s.mixed {
                    let own = (
                        texel.area_m2 as f64,
                        texel.footprint_m.map(|v| v.as_dvec3()),
                    );
                    s.mixed = !same((jacobian, f), own);
                }
            }
        }
    }
    for (texel, s) in texels.iter_mut().zip(&sums) {
        if !s.mixed || s.uv <= 0.0 {
            continue;
        }
        let area = s.area / s.uv;
        let f = [s.f[0] / s.uv, s.f[1] / s.uv];
        let parallelogram = f[0].cross(f[1]).length();
        texel.area_m2 = area;
        if parallelogram > 0.0 && parallelogram.is_finite() {
            let scale = (area / parallelogram).sqrt();
            texel.footprint_m = [f[0] * scale, f[1] * scale];
        }
    }
}

/// The overlap rule of the module docs: an error when more than [`OVERLAP_TOLERANCE`] of the
/// `covered` texels overlap and the scene does not allow it, else a warning for any overlap.
fn check_overlap(
    scene: &Scene,
    width: u32,
    height: u32,
    overlapping: usize,
    covered: usize,
    cov: &Coverage,
) -> Result<Vec<String>, TexelError> {
    let mut warnings = Vec::new();
    if overlapping > 0 {
        let fraction = overlapping as f64 / covered as f64;
        let (tri_a, tri_b, x, y) = cov.first_overlap.unwrap_or_default();
        if fraction > OVERLAP_TOLERANCE && !scene.allow_uv_overlap {
            return Err(TexelError::Overlap {
                scene: scene.name.clone(),
                texels: overlapping,
                fraction: fraction * 100.0,
                width,
                height,
                tri_a,
                tri_b,
                x,
                y,
            });
        }
        warnings.push(format!(
            "{overlapping} overlapping texel(s) ({:.3}% of covered) at {width}x{height}; \
             the last triangle wins",
            fraction * 100.0
        ));
    }
    Ok(warnings)
}

impl TexelGrid {
    /// Rasterizes `scene`'s UV layout at the scene's lightmap size.
    pub fn build(scene: &Scene) -> Result<Self, TexelError> {
        let (w, h) = scene.lightmap_size;
        Self::build_with_size(scene, w, h)
    }

    /// Rasterizes `scene`'s UV layout at `width × height`.
    pub fn build_with_size(scene: &Scene, width: u32, height: u32) -> Result<Self, TexelError> {
        let n_slots = width as usize * height as usize;
        let cov = rasterize(scene, width, height);
        let (triangle_chart, n_charts) = charts(scene);
        let surface_albedo = scene.surface_albedo();

        let mut texels = Vec::new();
        let mut slot = vec![NO_TEXEL; n_slots];
        let mut overlapping = 0usize;
        for y in 0..height {
            for x in 0..width {
                let s = y as usize * width as usize + x as usize;
                let (ti, b) = cov.cover[s];
                if ti == NO_TEXEL {
                    continue;
                }
                if cov.count[s] > 1 {
                    overlapping += 1;
                }
                let texel = texel_patch(
                    scene,
                    &surface_albedo,
                    (x, y),
                    (width, height),
                    (ti, b),
                    triangle_chart[ti as usize],
                );
                slot[s] = texels.len() as u32;
                texels.push(texel);
            }
        }
        if texels.is_empty() {
            return Err(TexelError::Empty {
                scene: scene.name.clone(),
                width,
                height,
            });
        }
        let warnings = check_overlap(scene, width, height, overlapping, texels.len(), &cov)?;
        let triangles_without_texels = cov.triangles_without_texels;
        drop(cov);
        average_over_squares(
            scene,
            (width, height),
            &mut texels,
            &slot,
            (&triangle_chart, n_charts),
        );
        let area_total = texels.iter().map(|t| t.area_m2 as f64).sum::<f64>();
        Ok(Self {
            width,
            height,
            stats: CoverageStats {
                covered: texels.len(),
                overlapping,
                charts: n_charts,
                triangles_without_texels,
                area_m2: area_total,
                warnings,
            },
            texels,
            slot,
            triangle_chart,
        })
    }

    /// Index of the texel at `(x, y)`, if covered (coordinates may be out of range).
    #[inline]
    pub fn at(&self, x: i32, y: i32) -> Option<u32> {
        if x < 0 || y < 0 || x >= self.width as i32 || y >= self.height as i32 {
            return None;
        }
        let s = self.slot[y as usize * self.width as usize + x as usize];
        (s != NO_TEXEL).then_some(s)
    }

    /// Per-slot texel areas in m² (0 where uncovered), row-major `width × height`.
    pub fn area_map(&self) -> Vec<f32> {
        let mut a = vec![0.0; self.slot.len()];
        for t in &self.texels {
            a[(t.y * self.width + t.x) as usize] = t.area_m2;
        }
        a
    }

    /// Per-slot albedo (0 where uncovered).
    pub fn albedo_map(&self) -> crate::Lightmap {
        let mut m = crate::Lightmap::new(self.width, self.height);
        for t in &self.texels {
            m.set(t.x, t.y, t.albedo.to_array());
        }
        m
    }
}
