//! Skin on the scanned head (issue 7): energy balance of the combined radiosity + subsurface
//! transfer, and the glow of a back-lit ear.
//!
//! The head is read from `../shared/faces/head.obj` (or `$ORTM_HEAD_OBJ`) by
//! [`ortm::scene::head::head_scene`]; lights are the paper's figure set-ups from the `faces` crate.

mod common;

use common::{LUMA, exitance, final_all, final_at, senders};
use glam::Vec3;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Transport, texel_patches};
use ortm::bake::{self, BakeSettings, lighting};
use ortm::scene::{Light, Scene};
use rayon::prelude::*;

fn head(size: u32) -> Scene {
    let mut s = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    s.lightmap_size = (size, size);
    s
}

/// `Q̂_j` per texel: what the continuous surface re-emits per unit of power entering at the
/// texel's centre ([`ortm::bake::transport::surface`]), 0 for opaque texels.
fn surface_reemission(tr: &Transport, grid: &TexelGrid) -> Vec<Vec3> {
    let k = &tr.kernels;
    let surface = k.surface.as_ref().expect("a translucent head");
    grid.texels
        .par_iter()
        .map(|t| {
            let m = t.material as usize;
            match &k.tables[m] {
                Some(table) => {
                    let q = surface.at(table, t.material, t.position_m, k.support_m[m]);
                    Vec3::new(q[0] as f32, q[1] as f32, q[2] as f32)
                }
                None => Vec3::ZERO,
            }
        })
        .collect()
}

/// `Σ Q̂_j E_j A_j / Σ E_j A_j`: the continuous surface's re-emission under irradiance `e`.
fn continuous_ratio(q: &[Vec3], e: &[Vec3], area: &[f32]) -> Vec3 {
    let (mut num, mut den) = (Vec3::ZERO, Vec3::ZERO);
    for ((q, e), a) in q.iter().zip(e).zip(area) {
        num += *q * *e * *a;
        den += *e * *a;
    }
    num / den
}

fn figure_lights(id: &str) -> Vec<Light> {
    ortm::scene::head::figure_lights(faces::figures::figure(id).expect("figure"))
}

/// Power balance of the whole head at 48² (Figs. 4, 5, 6b lights; radiosity + subsurface, and
/// subsurface alone; pair evaluator and exact solve). Every watt that enters the skin at `x`
/// leaves it through the profile at most `Q̂(x)` times — what the continuous surface re-emits,
/// ρ̄ on a plane (0.436 / 0.227 / 0.131 per channel), more in folds, as the model's Euclidean
/// distances make it ([`ortm::bake::transport::surface`]) — and interreflection only returns
/// some of the escaping light to the skin, where it again leaves at most `Q̂ < 1` times; so the
/// power escaping the head is at most `Σ Q̂ E A` over the entering `Σ E A`, per channel
/// (tolerance 1e-3 for f32 sums). Measured escaping/entering: with radiosity 0.4215–0.4268 (R),
/// 0.2173–0.2221 (G), 0.1244–0.1276 (B); subsurface alone 0.4344–0.4388, 0.2274–0.2280,
/// 0.1310–0.1312 (the bound: 0.4372–0.4424, 0.2277–0.2286, 0.1311–0.1314); with each texel's
/// area its covering triangle's Jacobian, not its average over the texel's square: 0.4184–0.4248,
/// 0.2161–0.2216, 0.1239–0.1274. The lower bounds are the smallest measured ratio less 25%.
#[test]
fn head_outgoing_power_never_exceeds_incoming_per_channel() {
    let scene = head(48);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let lowest_measured = Vec3::new(0.4215, 0.2173, 0.1244);
    let area: Vec<f32> = grid.texels.iter().map(|t| t.area_m2).collect();
    let sum_a = |v: &[Vec3]| -> Vec3 { v.iter().zip(&area).map(|(b, a)| *b * *a).sum() };
    for effects in [
        Effects::default(),
        Effects {
            radiosity: false,
            subsurface: true,
        },
    ] {
        let tr = Transport::new(&scene, &grid, effects, 8);
        let dense = DenseTransport::new(&texel_patches(&grid), &tr.kernels);
        let q = surface_reemission(&tr, &grid);
        // Fraction of each texel's radiosity that reaches no other texel (escapes the head).
        let escape: Vec<f32> = dense
            .form_factor_row_sums()
            .iter()
            .map(|f| (1.0 - f) as f32)
            .collect();
        for fig in [
            "fig5_point_light",
            "fig4_first_order_vs_global",
            "fig6b_backlit_ear",
        ] {
            let lights = figure_lights(fig);
            let e = lighting::irradiance(&grid, &lights, &vis);
            let b_o = exitance(&grid, &e);
            let p_in = sum_a(&e);
            let bound = continuous_ratio(&q, &e, &area);
            for (label, b) in [
                ("evaluator", final_all(&tr, &b_o)),
                ("exact", dense.solve(&b_o)),
            ] {
                // Power leaving the head: radiosity times the fraction that escapes.
                let p_out: Vec3 = b
                    .iter()
                    .zip(&area)
                    .zip(&escape)
                    .map(|((b, a), f)| *b * *a * *f)
                    .sum();
                let ratio = p_out / p_in;
                println!(
                    "{effects:?} {fig} {label}: in {p_in} W, out {p_out} W, out/in {ratio}, \
                     bound ΣQ̂EA/ΣEA {bound}"
                );
                assert!(
                    ratio.cmple(bound * (1.0 + 1e-3)).all()
                        && ratio.cmpgt(lowest_measured * 0.75).all(),
                    "{effects:?} {fig} {label}: outgoing/incoming power {ratio}, bound {bound}"
                );
                if !effects.radiosity {
                    // No surface-to-surface exchange: all exitance leaves the head.
                    let r = sum_a(&b) / p_in;
                    assert!(
                        r.cmple(bound * (1.0 + 1e-3)).all(),
                        "{fig} {label}: ΣB·A / ΣE·A = {r}, bound {bound}"
                    );
                }
            }
        }
    }
}

/// Stricter: subsurface scattering alone only *redistributes* the first-order light, so the
/// power it re-emits, `Σ B·A`, cannot exceed what the continuous surface re-emits of the
/// entering light, `Σ Q̂·E·A` (see `head_outgoing_power_never_exceeds_incoming_per_channel`;
/// ρ̄·E·A on a plane, the first order's `Σ B_o·A`), in the pair evaluator nor in the exact
/// solve. Before the subsurface weights were normalised per sender (`ortm::bake::transport`,
/// "Subsurface weights") the head at 48² re-emitted 1.016 / 1.033 / 1.080 × the first order
/// under the Fig. 4 light (overlapping texel footprints: stretched texels, and texel centres of
/// two charts nearly coinciding on seams). Now (both solvers agree to 1e-6), as a fraction of
/// the first order: Fig. 5 1.0066 / 1.0028 / 1.0012 against the bound 1.0149 / 1.0054 /
/// 1.0029, Fig. 4 1.0049 / 1.0029 / 1.0011 against 1.0129 / 1.0056 / 1.0030 (with each
/// texel's area its covering triangle's Jacobian: Fig. 5 1.0017 / 1.00003 / 1.00018 against
/// 1.0171 / 1.0049 / 1.0021, Fig. 4 0.9991 / 1.0004 / 1.0003 against 1.0137 / 1.0049 /
/// 1.0023, whose shortfalls set the lower bound below): the fold excess
/// of the Euclidean profile, less what the discrete profile loses where the 8 mm texels'
/// footprints do not tile the curved surface and at the neck's edge. The lower bound allows
/// 25 % more than the largest measured shortfall below the bound per channel.
#[test]
fn subsurface_alone_reemits_no_more_than_the_first_order() {
    let scene = head(48);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let effects = Effects {
        radiosity: false,
        subsurface: true,
    };
    let tr = Transport::new(&scene, &grid, effects, 8);
    let dense = DenseTransport::new(&texel_patches(&grid), &tr.kernels);
    let area: Vec<f32> = grid.texels.iter().map(|t| t.area_m2).collect();
    let sum_a = |v: &[Vec3]| -> Vec3 { v.iter().zip(&area).map(|(b, a)| *b * *a).sum() };
    let q = surface_reemission(&tr, &grid);
    for fig in ["fig5_point_light", "fig4_first_order_vs_global"] {
        let lights = figure_lights(fig);
        let e = lighting::irradiance(&grid, &lights, &vis);
        let b_o = exitance(&grid, &e);
        // The continuous surface's re-emission over the first order's.
        let bound = continuous_ratio(&q, &e, &area) * sum_a(&e) / sum_a(&b_o);
        for (label, b) in [
            ("evaluator", final_all(&tr, &b_o)),
            ("exact", dense.solve(&b_o)),
        ] {
            let ratio = sum_a(&b) / sum_a(&b_o);
            println!("{fig} {label}: ΣB·A / ΣB_o·A = {ratio}, bound ΣQ̂EA/ΣB_oA {bound}");
            assert!(
                ratio.cmple(bound * (1.0 + 1e-3)).all(),
                "{fig} {label}: subsurface re-emits {ratio} of the first order, bound {bound}"
            );
            let largest_shortfall = Vec3::new(0.0154, 0.0049, 0.00203);
            assert!(
                ratio.cmpgt(bound - largest_shortfall * 1.25).all(),
                "{fig} {label}: subsurface re-emits only {ratio} of the first order"
            );
        }
    }
}

/// The face bake's energy, through the library's bake pipeline in the README's configuration
/// (`ortm demo face`: the built-in head, 256² lightmap, 100 importance-sampled offsets,
/// radiosity + subsurface, integrated cells, default seed), for the dipole and the exponential
/// falloff: under each of the five face figures' lights, the final lightmap (`maps::apply` to
/// the CPU first order) summed over texels (mean of R, G, B per texel, as the `energy:` line
/// of `ortm render` sums it) against the first order's sum.
///
/// Measured (figures 3, 4, 5, 6a, 6b): dipole 1.0130 / 1.0194 / 1.0216 / 1.0102 / 1.0047,
/// exponential 1.0287 / 1.0442 / 1.0519 / 1.0202 / 1.0108 (with each texel's area its covering
/// triangle's Jacobian: 1.0095 / 1.0128 / 1.0147 / 1.0048 / 1.0021 and 1.0259 / 1.0419 /
/// 1.0507 / 1.0162 / 1.0105, which set the band below) — the interreflected light (a few
/// tenths of a percent on a convex head) and the folds, where the Euclidean profile re-emits
/// more than ρ̄ (`ortm::bake::transport::surface`; the exponential falloff reaches furthest, so
/// it gains most), outweigh what the discrete profile loses where the texels' footprints do not
/// tile the curved surface. The band: no figure may lose more than 0.2 % (the measured least
/// is 1.0021), nor gain more than 1.25 × the largest measured gain (5.07 %). With the senders
/// capped at ρ̄ instead of the surface's re-emission: 1.000–1.005 (dipole), 1.002–1.006
/// (exponential); with the midpoint rule before the weights were integrated over each texel's
/// footprint: 0.964–0.973 and 0.987–0.996; before they were normalised the seams created
/// light: 0.98–0.99 (dipole) and 1.00–1.04 (exponential) in the GPU render's `energy:` lines.
#[test]
fn face_bake_final_energy_stays_near_the_first_order() {
    let t0 = std::time::Instant::now();
    let sum = |m: &ortm::Lightmap| -> f64 {
        m.data
            .iter()
            .map(|p| (p[0] + p[1] + p[2]) as f64 / 3.0)
            .sum()
    };
    for falloff in [faces::Falloff::Dipole, faces::Falloff::Exponential] {
        let scene = ortm::scene::head::head_scene_with(falloff).expect("head scene");
        let settings = BakeSettings {
            size: scene.lightmap_size,
            ..BakeSettings::default()
        };
        assert_eq!((settings.size, settings.offsets), ((256, 256), 100));
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = Visibility::new(&scene.mesh);
        let tr = Transport::new(&scene, &grid, settings.effects, settings.coarse_block);
        let (offsets, _) = bake::select_offsets(&tr, &grid, &settings, &|_| {}).unwrap();
        let maps = bake::bake_maps(&tr, &grid, &offsets, settings.cell_rule, &|_| {}).unwrap();
        let ratios: Vec<f64> = faces::FIGURES
            .iter()
            .map(|f| {
                let lights = ortm::scene::head::figure_lights(f);
                let first =
                    lighting::to_lightmap(&grid, &lighting::first_order(&grid, &lights, &vis));
                let out = ortm::maps::apply(&maps, &first).unwrap();
                sum(&out) / sum(&first)
            })
            .collect();
        println!(
            "{falloff:?}: final / first order summed over texels, figures {:?}: {ratios:.4?} \
             ({:.0} s so far)",
            faces::FIGURES.iter().map(|f| f.id).collect::<Vec<_>>(),
            t0.elapsed().as_secs_f64()
        );
        let (lo, hi) = (1.0 - 0.002, 1.0 + 1.25 * 0.0507);
        for (f, r) in faces::FIGURES.iter().zip(&ratios) {
            assert!(
                (lo..=hi).contains(r),
                "{falloff:?} {}: final / first order {r:.4}, expected {lo:.4}..{hi:.4}",
                f.id
            );
        }
    }
}

#[test]
fn backlit_ear_glows_with_subsurface_scattering() {
    let scene = head(128);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    // Fig. 6b: a point light behind the head.
    let lights = figure_lights("fig6b_backlit_ear");
    let e = lighting::irradiance(&grid, &lights, &vis);
    let b_o = exitance(&grid, &e);
    // Ear-rim texels the light does not reach directly.
    let ear = ortm::bake::eval::ear_texels(&grid);
    let dark: Vec<u32> = ear
        .iter()
        .copied()
        .filter(|&i| e[i as usize] == Vec3::ZERO)
        .collect();
    println!(
        "{} ear texels, {} of them not directly lit",
        ear.len(),
        dark.len()
    );
    assert!(dark.len() >= 20, "too few unlit ear texels: {}", dark.len());
    let senders = senders(&b_o);
    let lum = |effects: Effects| -> (f32, Vec3) {
        let tr = Transport::new(&scene, &grid, effects, 8);
        let b: Vec3 = dark
            .par_iter()
            .map(|&i| final_at(&tr, &b_o, &senders, i))
            .sum();
        (b.dot(LUMA), b)
    };
    let (with_sss, rgb_sss) = lum(Effects::default());
    let (without, rgb_rad) = lum(Effects {
        radiosity: true,
        subsurface: false,
    });
    let factor = with_sss / without;
    println!(
        "unlit ear texels, summed radiosity: with SSS {rgb_sss} (luminance {with_sss:.4e}), \
         radiosity only {rgb_rad} (luminance {without:.4e}); factor {factor:.2}"
    );
    assert!(without > 0.0, "interreflection alone reaches the ear");
    // Measured: 131.5 (128.8 with each texel's area its covering triangle's Jacobian rather
    // than its average over the texel's square; 56 unlit ear-rim texels at 128², 0.88 m per
    // model unit; 152.7 before the
    // subsurface weights were normalised per sender, which scales down the senders of the thin
    // ear, whose profile reaches both of its sides; 120.4 with the midpoint rule, 114.7 with
    // footprints and the senders capped at ρ̄ rather than the surface's re-emission). Bounds:
    // ±25%.
    assert!(
        (96.6..=161.0).contains(&factor),
        "SSS / no SSS luminance factor {factor}"
    );
    // The glow is warm: skin carries red furthest.
    assert!(rgb_sss.x > rgb_sss.y && rgb_sss.y > rgb_sss.z, "{rgb_sss}");
}

#[test]
fn head_scene_file_equals_the_built_in_head() {
    let path = concat!(env!("CARGO_MANIFEST_DIR"), "/../../crates/faces/head.toml");
    let file = ortm::scene::load_scene(std::path::Path::new(path)).expect("faces/head.toml");
    let built = ortm::scene::head::head_scene().unwrap();
    assert_eq!(file.lightmap_size, built.lightmap_size);
    assert_eq!(file.mesh.positions_m.len(), built.mesh.positions_m.len());
    for (a, b) in file.mesh.positions_m.iter().zip(&built.mesh.positions_m) {
        assert!((*a - *b).length() < 1e-6, "{a} vs {b}");
    }
    assert_eq!(file.materials.len(), 1);
    assert_eq!(file.materials[0].subsurface, built.materials[0].subsurface);
    assert_eq!(file.lights, built.lights);
}

/// Measurement (ignored; `cargo test --release --test faces_head -- --ignored --nocapture
/// seam`): where a sender's raw subsurface weights go. A receiver's weight is the sender's
/// footprint integral seen from the receiver's centre, times the receiver's area; across a UV
/// seam a large texel of the other chart whose centre lies a millimetre from the sender counts
/// its whole area at the profile's near-singular peak: it takes most of the sender's light,
/// the normalisation (`min(1, Q̂/Q)`) then scales the sender down, and the receiver is a bright
/// texel beside darker ones (the brightest of the faint lines in the face figures). Prints, at
/// 64² and 256², the senders whose largest raw share `A_i·S_ij / A_j` goes to a texel of
/// another chart and exceeds the sender's own self share, and the worst cases.
#[test]
#[ignore = "measurement: cargo test --release --test faces_head -- --ignored --nocapture seam"]
fn seam_senders_give_their_light_to_the_other_charts_border() {
    for size in [64u32, 256] {
        let scene = head(size);
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = std::sync::Arc::new(Visibility::new(&scene.mesh));
        let k = ortm::bake::transport::Kernels::new(&scene, Effects::default(), vis);
        let patches = texel_patches(&grid);
        let near = ortm::bake::transport::SupportGrid::new(&patches, &k);
        let worst: Vec<(f64, f64, usize, usize)> = (0..patches.len())
            .into_par_iter()
            .filter_map(|j| {
                let b = &patches[j];
                let (mut own, mut best) = (0.0f64, (0.0f64, j));
                near.for_each_near(b.position_m, |i| {
                    let (i, a) = (i as usize, &patches[i as usize]);
                    let Some(s) = k.subsurface_raw(a, b, i == j) else {
                        return;
                    };
                    let share = s[0] * a.area_m2 as f64 / b.area_m2 as f64;
                    if i == j {
                        own = share;
                    } else if share > best.0 {
                        best = (share, i);
                    }
                });
                let other = grid.texels[best.1].chart != grid.texels[j].chart;
                (other && best.0 > own).then_some((best.0, own, j, best.1))
            })
            .collect();
        let mut worst = worst;
        worst.sort_by(|p, q| q.0.total_cmp(&p.0));
        println!(
            "head {size}²: {} of {} senders give their largest share (red) to a texel of another \
             chart, more than to themselves",
            worst.len(),
            patches.len()
        );
        for &(share, own, j, i) in worst.iter().take(5) {
            let (s, r) = (&grid.texels[j], &grid.texels[i]);
            println!(
                "  sender ({}, {}) chart {} → ({}, {}) chart {}: {share:.3} against {own:.3} to \
                 itself, {:.2} mm apart",
                s.x,
                s.y,
                s.chart,
                r.x,
                r.y,
                r.chart,
                (s.position_m - r.position_m).length() * 1e3
            );
        }
    }
}
