//! Subsurface scattering of skin against independent references (issue 7):
//!
//! - a flat square slab under a point light: ortm's subsurface transfer against a direct
//!   numerical convolution `B(x) = ∫ R_d(|x − x'|) E(x') dA'` of Jensen's dipole with the
//!   analytic irradiance, done here by polar quadrature (within 2%);
//! - a UV seam: a slab cut in two charts whose seam edges lie far apart in the lightmap; light
//!   on one chart only reaches texels across the seam through the baked offset maps (the
//!   paper's argument for offsets over image-space blurs), with the amount the convolution
//!   predicts, while texels next to the lit chart *in the lightmap* (but 20 mm away on the
//!   surface) stay dark.
//!
//! The dipole is written out here again from Jensen et al. 2001 (not taken from ortm), and the
//! quadrature knows nothing of texels.

mod common;

use std::f64::consts::PI;

use common::{final_at, luminance, senders};
use glam::{Vec2, Vec3};
use ortm::bake::lighting;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::footprint::gauss_legendre;
use ortm::bake::transport::{Effects, Transport};
use ortm::bake::{self, BakeSettings};
use ortm::scene::{Albedo, Light, Material, Mesh, MeshTriangle, Scene, Subsurface};

/// Skin1 of Jensen et al. 2001 (mm⁻¹), dipole, from the `faces` crate.
fn skin1() -> Subsurface {
    ortm::scene::subsurface_preset(faces::HEAD_SKIN).expect("skin1 preset")
}

/// Jensen et al. 2001 dipole `R_d(r)` in m⁻² for one channel, coefficients in mm⁻¹.
struct Dipole {
    alpha_p: f64,
    sigma_tr: f64,
    z_r: f64,
    z_v: f64,
}

impl Dipole {
    fn new(sigma_a_mm: f64, sigma_s_p_mm: f64, eta: f64) -> Self {
        let (sa, ss) = (sigma_a_mm * 1e3, sigma_s_p_mm * 1e3);
        let st = sa + ss;
        let f_dr = -1.44 / (eta * eta) + 0.71 / eta + 0.668 + 0.0636 * eta;
        let a = (1.0 + f_dr) / (1.0 - f_dr);
        let z_r = 1.0 / st;
        Self {
            alpha_p: ss / st,
            sigma_tr: (3.0 * sa * st).sqrt(),
            z_r,
            z_v: z_r * (1.0 + 4.0 * a / 3.0),
        }
    }
    fn rd(&self, r: f64) -> f64 {
        let term = |z: f64| {
            let d = (r * r + z * z).sqrt();
            z * (self.sigma_tr * d + 1.0) * (-self.sigma_tr * d).exp() / (d * d * d)
        };
        self.alpha_p / (4.0 * PI) * (term(self.z_r) + term(self.z_v))
    }
}

fn dipoles(s: &Subsurface) -> [Dipole; 3] {
    std::array::from_fn(|c| {
        Dipole::new(
            s.sigma_a_per_mm[c] as f64,
            s.sigma_s_prime_per_mm[c] as f64,
            s.eta as f64,
        )
    })
}

/// `∫_rect R_d(|p − x'|) E(x') dA'` per channel over the axis-aligned rectangle
/// `[lo, hi]` (metres, in the plane), by polar quadrature around `p`: angles split at the
/// corners (64-point Gauss–Legendre per piece), radii on geometric panels from where the ray
/// enters the rectangle to where it leaves (8-point Gauss–Legendre per panel).
fn convolve_rect(
    p: [f64; 2],
    lo: [f64; 2],
    hi: [f64; 2],
    e: &dyn Fn([f64; 2]) -> [f64; 3],
    d: &[Dipole; 3],
) -> [f64; 3] {
    let gl64 = gauss_legendre(64);
    let gl8 = gauss_legendre(8);
    let mut cuts: Vec<f64> = [lo, [hi[0], lo[1]], hi, [lo[0], hi[1]]]
        .iter()
        .map(|c| (c[1] - p[1]).atan2(c[0] - p[0]).rem_euclid(2.0 * PI))
        .collect();
    cuts.push(0.0);
    cuts.push(2.0 * PI);
    cuts.sort_by(f64::total_cmp);
    let mut out = [0.0f64; 3];
    for w in cuts.windows(2) {
        let (a0, a1) = (w[0], w[1]);
        if a1 - a0 < 1e-12 {
            continue;
        }
        for &(xa, wa) in &gl64 {
            let th = 0.5 * (a0 + a1) + 0.5 * (a1 - a0) * xa;
            let (c, s) = (th.cos(), th.sin());
            // Ray p + t (c, s) against the rectangle (slab method).
            let (mut t0, mut t1) = (0.0f64, f64::INFINITY);
            for (k, dir) in [c, s].into_iter().enumerate() {
                if dir.abs() < 1e-300 {
                    if p[k] < lo[k] || p[k] > hi[k] {
                        t1 = -1.0;
                    }
                    continue;
                }
                let (ta, tb) = ((lo[k] - p[k]) / dir, (hi[k] - p[k]) / dir);
                t0 = t0.max(ta.min(tb));
                t1 = t1.min(ta.max(tb));
            }
            if t1 <= t0 {
                continue;
            }
            // Geometric panels in t − t0.
            let mut edges = vec![t0];
            let mut step = 1e-6;
            while edges.last().unwrap() + step < t1 {
                edges.push(edges.last().unwrap() + step);
                step *= 1.4;
            }
            edges.push(t1);
            let mut ray = [0.0f64; 3];
            for pw in edges.windows(2) {
                let (r0, r1) = (pw[0], pw[1]);
                for &(xr, wr) in &gl8 {
                    let r = 0.5 * (r0 + r1) + 0.5 * (r1 - r0) * xr;
                    let ev = e([p[0] + r * c, p[1] + r * s]);
                    for ch in 0..3 {
                        ray[ch] += wr * 0.5 * (r1 - r0) * d[ch].rd(r) * ev[ch] * r;
                    }
                }
            }
            for ch in 0..3 {
                out[ch] += wa * 0.5 * (a1 - a0) * ray[ch];
            }
        }
    }
    out
}

/// A flat rectangle in the z = 0 plane facing +z, with planar lightmap UVs: the quad
/// `[x0, x1] × [y0, y1]` (metres) mapped to `[u0, u1] × [v0, v1]`.
fn add_quad(mesh: &mut Mesh, xy: [f32; 4], uv: [f32; 4]) {
    let [x0, x1, y0, y1] = xy;
    let [u0, u1, v0, v1] = uv;
    let base = mesh.positions_m.len() as u32;
    for (x, y, u, v) in [
        (x0, y0, u0, v0),
        (x1, y0, u1, v0),
        (x1, y1, u1, v1),
        (x0, y1, u0, v1),
    ] {
        mesh.positions_m.push(Vec3::new(x, y, 0.0));
        mesh.uvs.push(Vec2::new(u, v));
        mesh.normals.push(Vec3::Z);
    }
    for t in [[0, 1, 2], [0, 2, 3]] {
        let idx = t.map(|k| base + k);
        mesh.triangles.push(MeshTriangle {
            position: idx,
            uv: idx,
            normal: idx,
            material: 0,
        });
    }
}

fn skin_scene(name: &str, mesh: Mesh, size: (u32, u32), lights: Vec<Light>) -> Scene {
    Scene {
        name: name.into(),
        mesh,
        materials: vec![Material {
            name: "skin".into(),
            albedo: Albedo::Constant(Vec3::from_array(faces::HEAD_ALBEDO)),
            subsurface: Some(skin1()),
        }],
        lights,
        lightmap_size: size,
        allow_uv_overlap: false,
    }
}

const SSS_ONLY: Effects = Effects {
    radiosity: false,
    subsurface: true,
};

#[test]
fn independent_dipole_matches_ortms_profile() {
    let p = ortm::scene::subsurface::Profile::new(&skin1());
    let d = dipoles(&skin1());
    for r in [0.0, 1e-4, 1e-3, 5e-3, 2e-2] {
        let o = p.rd(r);
        for c in 0..3 {
            assert!((o[c] - d[c].rd(r)).abs() <= 1e-9 * d[c].rd(r).abs().max(1e-300));
        }
    }
}

#[test]
fn slab_under_point_light_matches_direct_convolution() {
    // 40 mm square slab of skin, 160² lightmap (0.25 mm texels, below the 0.67 mm
    // mean free path 1/σ_t' of skin1's blue channel), point light 8 mm above (10 mm off-centre).
    let half = 0.02f32;
    let n = 160u32;
    let mut mesh = Mesh::default();
    add_quad(&mut mesh, [-half, half, -half, half], [0.0, 1.0, 0.0, 1.0]);
    let (lx, ly, lh, intensity) = (0.003f64, 0.0f64, 0.008f64, 0.5f64);
    let light = Light::Point {
        position_m: Vec3::new(lx as f32, ly as f32, lh as f32),
        color: Vec3::ONE,
        intensity_w_sr: intensity as f32,
    };
    let scene = skin_scene("slab", mesh, (n, n), vec![light]);
    let grid = TexelGrid::build(&scene).unwrap();
    assert_eq!(grid.texels.len(), (n * n) as usize);
    let tr = Transport::new(&scene, &grid, SSS_ONLY, 8);
    let vis = ortm::bake::raycast::Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    let senders = senders(&b_o);

    // Analytic irradiance of the point light on the plane (W/m²).
    let e = |q: [f64; 2]| {
        let (dx, dy) = (q[0] - lx, q[1] - ly);
        let d2 = dx * dx + dy * dy + lh * lh;
        [intensity * lh / (d2 * d2.sqrt()); 3]
    };
    let d = dipoles(&skin1());
    let h = 2.0 * half as f64;
    let mut worst = 0.0f64;
    // Receivers at least 12 mm inside the edges, under and away from the light.
    for (x, y) in [
        (80, 80),
        (92, 80),
        (80, 60),
        (100, 100),
        (68, 96),
        (110, 70),
    ] {
        let i = grid.at(x, y).unwrap();
        let t = &grid.texels[i as usize];
        let p = [t.position_m.x as f64, t.position_m.y as f64];
        assert!(p[0].abs() < 0.008 + 1e-9 && p[1].abs() < 0.008 + 1e-9);
        let got = final_at(&tr, &b_o, &senders, i);
        let want = convolve_rect(p, [-h / 2.0; 2], [h / 2.0; 2], &e, &d);
        for c in 0..3 {
            let rel = (got[c] as f64 - want[c]) / want[c];
            println!(
                "texel ({x},{y}) at ({:.4},{:.4}) m, channel {c}: ortm {:.5e}, convolution {:.5e} W/m², {:+.3}%",
                p[0],
                p[1],
                got[c],
                want[c],
                100.0 * rel
            );
            worst = worst.max(rel.abs());
        }
    }
    // Measured: worst −0.161% (blue; −0.02% red, −0.03% green), the transfer's quadrature of the
    // profile on 0.25 mm texels against the convolution; bound 25% above.
    assert!(worst < 0.002, "worst relative difference {worst}");
}

/// A 20 mm × 10 mm slab of skin cut at x = 0 into two charts. In the 72×32 lightmap the right
/// half (x ∈ [0, 10] mm) sits at texel columns 2..34 and the left half (x ∈ [−10, 0] mm) at
/// columns 38..70: the seam joins columns 2 and 69 (67 texels apart), while columns 33 and
/// 38, neighbours across the gutter in the lightmap, are 20 mm apart on the surface.
fn seam_scene() -> Scene {
    let (w, h) = (72u32, 32u32);
    let col = |c: u32| c as f32 / w as f32;
    let mut mesh = Mesh::default();
    add_quad(
        &mut mesh,
        [0.0, 0.01, 0.0, 0.01],
        [col(2), col(34), 0.0, 1.0],
    );
    add_quad(
        &mut mesh,
        [-0.01, 0.0, 0.0, 0.01],
        [col(38), col(70), 0.0, 1.0],
    );
    skin_scene("seam", mesh, (w, h), vec![])
}

/// One scenario: the checks next to the seam, next to the lit chart in the lightmap and of the
/// power across the seam all read the same bake. The seam rule of the integrated cells (a
/// sender is counted at the physically nearest of its cell's site, the neighbouring sites and
/// the receiver; `ortm::bake::cells`, "Seams") matters here: counting every sender at its own
/// cell's site instead makes the baked maps 7.6% short next to the seam (bound 0.9%), up to 71%
/// 1–2 mm further, and carry 0.55 / 0.72 / 0.85 of the power across it.
#[test]
fn subsurface_light_crosses_a_uv_seam_through_offset_maps() {
    // The two charts of `seam_scene`.
    let scene = seam_scene();
    let (w, h) = scene.lightmap_size;
    let grid = TexelGrid::build(&scene).unwrap();
    assert_eq!(grid.texels.len(), (64 * h) as usize);
    // Light only the left half: uniform irradiance E0 on x < 0 (first order ρ̄·E0).
    let e0 = 1.0f32;
    let lit = |t: &ortm::bake::texels::Texel| t.position_m.x < 0.0;
    let b_o: Vec<Vec3> = grid
        .texels
        .iter()
        .map(|t| if lit(t) { t.albedo * e0 } else { Vec3::ZERO })
        .collect();
    let senders = senders(&b_o);
    let first = lighting::to_lightmap(&grid, &b_o);

    // Bake: importance-selected offsets, subsurface only.
    let settings = BakeSettings {
        size: (w, h),
        offsets: 100,
        effects: SSS_ONLY,
        ..BakeSettings::default()
    };
    let tr = Transport::new(&scene, &grid, SSS_ONLY, 4);
    let (offsets, _) = bake::select_offsets(&tr, &grid, &settings, &|_| {}).unwrap();
    let seam_offsets = offsets.iter().filter(|o| o.x.abs() >= 60).count();
    let maps = bake::bake_maps(&tr, &grid, &offsets, bake::CellRule::Integrated, &|_| {}).unwrap();
    let out = ortm::maps::apply(&maps, &first).unwrap();
    let baked = lighting::from_lightmap(&grid, &out);

    let d = dipoles(&skin1());
    let e_lit = |_: [f64; 2]| [e0 as f64; 3];
    println!(
        "{} offsets, {seam_offsets} of them jump the seam (|dx| ≥ 60)",
        offsets.len()
    );
    // Right-half texels next to the seam (column 2: x ≈ 0.16 mm), and 1 mm, 2 mm further.
    let mut worst_exact = 0.0f64;
    let mut worst_baked = [0.0f64; 3];
    for (n, c) in [2u32, 5, 8].into_iter().enumerate() {
        for y in [8u32, 16, 24] {
            let i = grid.at(c as i32, y as i32).unwrap();
            let t = &grid.texels[i as usize];
            assert!(!lit(t));
            let p = [t.position_m.x as f64, t.position_m.y as f64];
            let want = convolve_rect(p, [-0.01, 0.0], [0.0, 0.01], &e_lit, &d);
            let exact = final_at(&tr, &b_o, &senders, i);
            let got = baked[i as usize];
            for ch in 0..3 {
                let rel_exact = (exact[ch] as f64 - want[ch]) / want[ch];
                let rel_baked = (got[ch] as f64 - want[ch]) / want[ch];
                println!(
                    "column {c} row {y} (x = {:.2} mm) channel {ch}: convolution {:.4e}, \
                     transfer {:.4e} ({:+.1}%), baked maps {:.4e} ({:+.1}%)",
                    p[0] * 1e3,
                    want[ch],
                    exact[ch],
                    100.0 * rel_exact,
                    got[ch],
                    100.0 * rel_baked
                );
                worst_exact = worst_exact.max(rel_exact.abs());
                worst_baked[n] = worst_baked[n].max(rel_baked.abs());
            }
        }
    }
    // Next to the lit chart in the lightmap (column 33, x ≈ 9.84 mm), 10 mm from the lit half on
    // the surface: only the convolution's tail, where an image-space blur of the first-order
    // lightmap would carry the light of the lit chart's texels at columns 38+.
    let mut far_rel = (f64::INFINITY, 0.0f64);
    for y in [8, 16, 24] {
        let i = grid.at(33, y).unwrap();
        let t = &grid.texels[i as usize];
        let p = [t.position_m.x as f64, t.position_m.y as f64];
        let want = convolve_rect(p, [-0.01, 0.0], [0.0, 0.01], &e_lit, &d);
        let got = baked[i as usize];
        let rel =
            luminance(got) as f64 / luminance(Vec3::from_array(want.map(|v| v as f32))) as f64;
        println!(
            "column 33 row {y} (x = {:.2} mm): convolution {want:?}, baked maps {got}",
            p[0] * 1e3
        );
        far_rel = (far_rel.0.min(rel), far_rel.1.max(rel));
    }
    // Power that crosses the seam: Σ B·A over the unlit half, baked maps vs the transfer.
    let (mut p_baked, mut p_exact) = (Vec3::ZERO, Vec3::ZERO);
    for (i, t) in grid.texels.iter().enumerate() {
        if !lit(t) {
            p_baked += baked[i] * t.area_m2;
            p_exact += final_at(&tr, &b_o, &senders, i as u32) * t.area_m2;
        }
    }
    let p_rel = (p_baked - p_exact) / p_exact;
    println!(
        "power across the seam (W): baked {p_baked}, transfer {p_exact}, relative {p_rel}; \
         worst relative error of the transfer next to the seam {worst_exact:.4}, of the baked \
         maps per column (2, 5, 8) {worst_baked:.4?}; 10 mm away, baked / convolution \
         luminance {:.3}..{:.3}",
        far_rel.0, far_rel.1
    );
    // The importance sampling finds the seam: 38 of the 100 offsets jump it (25% margin).
    assert!(seam_offsets >= 29, "{seam_offsets} offsets jump the seam");
    // The transfer (the pair evaluator) against the convolution: measured 1.9% worst (blue,
    // 1 mm from the seam); bound 25% above.
    assert!(
        worst_exact < 0.024,
        "transfer across the seam: {worst_exact}"
    );
    // The baked maps, texel by texel: next to the seam they match the convolution (0.7% worst,
    // the transfer's own error), 1 and 2 mm further they fall short (37% and 27% worst, see the
    // power below); bounds 25% above.
    for (bound, (col, worst)) in [0.009, 0.47, 0.34]
        .into_iter()
        .zip([2, 5, 8].into_iter().zip(worst_baked))
    {
        assert!(
            worst < bound,
            "baked maps at column {col}: worst relative error {worst}"
        );
    }
    // The baked maps carry the light across the seam, though not all of it: 0.757 / 0.880 /
    // 0.956 (R/G/B) of the transfer's power, measured, with 100 importance-sampled offsets on this
    // 2,048-texel layout (the integrated cell rule counts a seam-crossing sender at the physically
    // nearest site, which here can be the receiver itself, dark because the seam is also the
    // lighting boundary; with Eq. 10 they overshot by 20–56%). Without seam-jumping offsets the
    // error would be −100%. The shortfall per channel is bounded 25% above its measured value.
    let shortfall = -p_rel;
    for (c, bound) in [0.304f32, 0.150, 0.055].into_iter().enumerate() {
        assert!(
            shortfall[c] > 0.0 && shortfall[c] < bound,
            "power across the seam, channel {c}: {p_rel}"
        );
    }
    // 10 mm away only the convolution's tail arrives (0.1% of the light next to the seam; an
    // image-space blur would carry there the light of the lit chart's texels 1.5 mm away in the
    // lightmap, ~60× more). Measured: the baked maps hold 0.984–0.987 × the tail (luminance);
    // bounds ±25%.
    assert!(
        far_rel.0 > 0.74 && far_rel.1 < 1.234,
        "10 mm from the lit half: baked / convolution {far_rel:?}"
    );
}
