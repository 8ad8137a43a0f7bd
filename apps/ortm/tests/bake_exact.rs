//! The bake against the exact dense solve: energy balance of the exact solve on the Cornell box
//! (and its loss through the open side against the geometry's form factors), Eq. 9 being exact
//! when every integer offset is selected, and the convergence of the importance-sampled offsets
//! on the head (and the jittered grid's error beside it) and on the Cornell box, with README's
//! figures ("Offset maps (bake, part 2)") bounded at their measured values + 25 %.

mod common;

use std::sync::Arc;

use ortm::bake::eval::{Reference, random_light_setups};
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, Transport, texel_patches};
use ortm::bake::{self, BakeSettings, Selector};
use ortm::maps;
use ortm::scene::Scene;

/// The built-in head (radiosity + skin subsurface) with a `size`² lightmap.
fn head(size: u32) -> Scene {
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (size, size);
    scene
}

/// Each covered texel's form factor to the Cornell box's open side (the square z = L,
/// 0 ≤ x, y ≤ L), with occlusion: the fraction of `n × n` stratified cosine-weighted rays from the
/// texel that cross that square without hitting the mesh (jittered with a fixed seed). Independent
/// of the texel-to-texel form factors: only the box's geometry and the ray caster.
fn open_side_form_factors(grid: &TexelGrid, vis: &Visibility, n: u32) -> Vec<f64> {
    use rand::{RngExt, SeedableRng};
    let l = ortm::scene::cornell::BOX_SIZE_M;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(5);
    grid.texels
        .iter()
        .map(|t| {
            let nrm = t.face_normal;
            let (t1, t2) = ortm::bake::transport::form_factor::tangent_frame(nrm);
            let p = t.position_m + nrm * 1e-4;
            let mut hits = 0u32;
            for a in 0..n {
                for b in 0..n {
                    let u1 = (a as f32 + rng.random::<f32>()) / n as f32;
                    let u2 = (b as f32 + rng.random::<f32>()) / n as f32;
                    let (r, phi) = (u1.sqrt(), std::f32::consts::TAU * u2);
                    let d = t1 * (r * phi.cos()) + t2 * (r * phi.sin()) + nrm * (1.0 - u1).sqrt();
                    if d.z <= 0.0 {
                        continue;
                    }
                    let q = p + d * ((l - p.z) / d.z);
                    if (0.0..=l).contains(&q.x)
                        && (0.0..=l).contains(&q.y)
                        && vis.visible(p, q, 1e-5)
                    {
                        hits += 1;
                    }
                }
            }
            hits as f64 / (n * n) as f64
        })
        .collect()
}

#[test]
fn cornell_exact_solve_conserves_energy() {
    // Energy balance of the exact solve (emitted = absorbed + escaped through the open side, to
    // 1e-4), and the escaped power against what the geometry alone predicts: each texel's
    // radiosity × area × form factor to the open side (`open_side_form_factors`, 1,024 rays per
    // texel). Measured: the escaped power within 0.28 % (32²) and 0.18 % (64²) of the geometry's
    // (worst channel; 19.5 % / 20.3 % of the red channel's emitted power escapes). The bound, 1 %,
    // is what separates the collocated form factors from the earlier reciprocal near field,
    // whose rows fell short of 1 − F_open so that 4.14 % (32²) and 1.82 % (64²) more escaped.
    for (size, bound) in [(32, 0.01), (64, 0.01)] {
        let scene = ortm::scene::cornell::cornell_box(size);
        let grid = TexelGrid::build(&scene).unwrap();
        let vis = Arc::new(Visibility::new(&scene.mesh));
        let kernels = Kernels::new(&scene, Effects::default(), vis.clone());
        let patches = texel_patches(&grid);
        let dense = DenseTransport::new(&patches, &kernels);
        let e_d = lighting::irradiance(&grid, &scene.lights, &vis);
        let b_o = common::exitance(&grid, &e_d);
        let b = dense.solve(&b_o);
        // The power texel j receives from texel i is A_j F_ji B_i, so what i's radiosity sends
        // out of the box is B_i (A_i − Σ_j A_j F_ji): the column sums, not the rows (the
        // collocated form factors are not reciprocal between near texels).
        let reached = dense.form_factor_column_sums(&patches);
        let open = open_side_form_factors(&grid, &vis, 32);
        for ch in 0..3 {
            let (mut emitted, mut absorbed, mut escaped) = (0.0f64, 0.0f64, 0.0f64);
            for i in 0..dense.n {
                let a = patches[i].area_m2 as f64;
                let e_ind: f64 = (0..dense.n)
                    .map(|j| dense.form_factors[(i, j)] * b[j][ch] as f64)
                    .sum();
                let e_tot = e_d[i][ch] as f64 + e_ind;
                emitted += e_d[i][ch] as f64 * a;
                absorbed += (1.0 - patches[i].rho[ch] as f64) * e_tot * a;
                escaped += b[i][ch] as f64 * a * (1.0 - reached[i]);
            }
            let balance = (absorbed + escaped - emitted).abs() / emitted;
            assert!(
                balance < 1e-4,
                "{size}²: channel {ch}: emitted {emitted} W, absorbed {absorbed} W, escaped {escaped} W"
            );
            // What leaves through the open side, from the geometry alone: each texel's radiosity
            // times its area times its form factor to the opening, estimated by ray casting.
            let expected: f64 = (0..dense.n)
                .map(|i| b[i][ch] as f64 * patches[i].area_m2 as f64 * open[i])
                .sum();
            eprintln!(
                "{size}²: channel {ch}: escaped {:.4} of the emitted power (from the opening's form \
                 factors {:.4}); ratio {:.4}",
                escaped / emitted,
                expected / emitted,
                escaped / expected
            );
            assert!(
                (escaped / expected - 1.0).abs() < bound,
                "{size}²: channel {ch}: escaped {escaped} W, the open side's form factors give \
                 {expected} W"
            );
        }
    }
}

fn check_all_offsets_exact(scene: &Scene, lights: &[ortm::scene::Light]) {
    let grid = TexelGrid::build(scene).unwrap();
    // block = 1: the coarse level is the texel level, so R(t, t') is the exact transfer.
    let transport = Transport::new(scene, &grid, Effects::default(), 1);
    let offsets = common::all_offsets(grid.width, grid.height);
    let maps = bake::bake_maps(
        &transport,
        &grid,
        &offsets,
        bake::CellRule::Integrated,
        &|_| {},
    )
    .unwrap();
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, lights, &vis);
    let dense = DenseTransport::new(&texel_patches(&grid), &transport.kernels);
    let exact = dense.solve(&b_o);
    let out = maps::apply(&maps, &lighting::to_lightmap(&grid, &b_o)).unwrap();
    let got = lighting::from_lightmap(&grid, &out);
    let scale = exact.iter().map(|v| v.max_element()).fold(0.0f32, f32::max);
    let mut worst = 0.0f32;
    for (g, e) in got.iter().zip(&exact) {
        for c in 0..3 {
            let rel = (g[c] - e[c]).abs() / e[c].abs().max(1e-3 * scale);
            worst = worst.max(rel);
        }
    }
    assert!(worst < 1e-5, "{}: worst relative error {worst}", scene.name);
}

#[test]
fn all_offsets_reproduce_the_exact_solve_cornell() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let lights = scene.lights.clone();
    check_all_offsets_exact(&scene, &lights);
}

#[test]
fn all_offsets_reproduce_the_exact_solve_head_with_subsurface() {
    let scene = head(24);
    let lights = random_light_setups(&scene, 1, 7).remove(0);
    check_all_offsets_exact(&scene, &lights);
}

/// Selects `k` offsets with `selector` and `seed` (the grid's size, the transport's effects), bakes
/// them with `rule` and returns the relative RMSE of the indirect term against `reference`.
fn indirect_error(
    transport: &Transport,
    grid: &TexelGrid,
    reference: &Reference,
    k: usize,
    selector: Selector,
    rule: bake::CellRule,
    seed: u64,
) -> f64 {
    let settings = BakeSettings {
        size: (grid.width, grid.height),
        offsets: k,
        effects: transport.kernels.effects,
        selector,
        seed,
        ..BakeSettings::default()
    };
    let (offsets, _) = bake::select_offsets(transport, grid, &settings, &|_| {}).unwrap();
    let maps = bake::bake_maps(transport, grid, &offsets, rule, &|_| {}).unwrap();
    reference.indirect_error(grid, &maps)
}

#[test]
fn importance_sampled_offsets_converge_on_the_head_and_beat_the_jittered_grid() {
    // Radiosity and subsurface scattering (the bake's default). Convergence in K is measured over
    // the exact transport (1×1 clusters), so the error is that of the offset approximation alone;
    // the importance-vs-grid comparison is repeated with 2×2 clusters, the same physical cluster
    // size as the default 8×8 at 256², whose far field sets an error floor of its own.
    let scene = head(64);
    let grid = TexelGrid::build(&scene).unwrap();
    let effects = Effects::default();
    let exact_transport = Transport::new(&scene, &grid, effects, 1);
    let clustered = Transport::new(&scene, &grid, effects, 2);
    let vis = Visibility::new(&scene.mesh);
    let dense = DenseTransport::new(&texel_patches(&grid), &exact_transport.kernels);
    let setups = random_light_setups(&scene, 8, 11);
    let reference = Reference::new(&grid, &vis, &dense, &setups);
    let error =
        |transport: &Transport, k: usize, selector: Selector, rule: bake::CellRule, seed| {
            indirect_error(transport, &grid, &reference, k, selector, rule, seed)
        };
    // One offset set is one random draw: average three seeds so that "falls as K grows" is a
    // statement about the estimator, not about one draw.
    let seeds = [3u64, 4, 5];
    let mean = |transport: &Transport, k: usize, selector: Selector| {
        let e: Vec<f64> = seeds
            .iter()
            .map(|&s| error(transport, k, selector, bake::CellRule::Integrated, s))
            .collect();
        (e.iter().sum::<f64>() / e.len() as f64, e)
    };
    let per_k: Vec<(f64, Vec<f64>)> = [25, 50, 100, 200]
        .iter()
        .map(|&k| mean(&exact_transport, k, Selector::Importance))
        .collect();
    let errs: Vec<f64> = per_k.iter().map(|(m, _)| *m).collect();
    let draws: Vec<&Vec<f64>> = per_k.iter().map(|(_, e)| e).collect();
    let (jittered, jittered_draws) = mean(&exact_transport, 100, Selector::JitteredGrid);
    let sampled = error(
        &exact_transport,
        100,
        Selector::Importance,
        bake::CellRule::Sampled,
        seeds[0],
    );
    let sampled_jittered = error(
        &exact_transport,
        100,
        Selector::JitteredGrid,
        bake::CellRule::Sampled,
        seeds[0],
    );
    let (c_imp, c_imp_draws) = mean(&clustered, 100, Selector::Importance);
    let (c_imp200, _) = mean(&clustered, 200, Selector::Importance);
    let (c_jit, c_jit_draws) = mean(&clustered, 100, Selector::JitteredGrid);
    eprintln!(
        "head 64², radiosity + subsurface, relative RMSE of the indirect term vs the exact solve, \
         mean of seeds {seeds:?}. Exact transport (1×1 clusters): importance K = 25/50/100/200: \
         {errs:.4?} (per seed {draws:.4?}); jittered grid K = 100: {jittered:.4} (per seed \
         {jittered_draws:.4?}); the paper's Eq. 10 rule at K = 100, seed {}: importance \
         {sampled:.4}, jittered grid {sampled_jittered:.4}. 2×2 clusters: importance K = 100: \
         {c_imp:.4} (per seed {c_imp_draws:.4?}), K = 200: {c_imp200:.4}; jittered grid K = 100: \
         {c_jit:.4} (per seed {c_jit_draws:.4?})",
        seeds[0]
    );
    for w in errs.windows(2) {
        assert!(w[1] < w[0], "error must fall as K grows: {errs:?}");
    }
    // README's table and the cluster floor, each bounded at its measured value + 25 %
    // (measured: importance K = 25/50/100/200 0.4175 / 0.2513 / 0.1850 / 0.1364, jittered grid
    // 0.9186, Eq. 10 importance / jittered grid 8.9156 / 1.4365; 2×2 clusters importance
    // K = 100/200 0.3329 / 0.3295, jittered grid 0.8751. Before the texels' form factors were
    // collocated at their centres: 0.5067 / 0.2931 / 0.1955 / 0.1384, 0.9106, 3.8421 / 1.4467;
    // 0.3172 / 0.3160, 0.8804 — Eq. 10's single sample per cell now lands on a larger
    // near-singular first bounce where a cell's site is a neighbour across a fold, while the
    // integrated cells improved at every K. With each texel's area its covering
    // triangle's Jacobian, not its average over the texel's square: 0.3782 / 0.2657 / 0.2286 /
    // 0.2060, 0.7214, 1.0136 / 1.1965; 0.3067 / 0.3146, 0.7256 — the exact solve these are
    // measured against moved, its indirect power ~65 % up, closer to the path-traced
    // reference).
    let bounded = [
        ("importance, K = 25", errs[0], 0.522),
        ("importance, K = 50", errs[1], 0.314),
        ("importance, K = 100", errs[2], 0.231),
        ("importance, K = 200", errs[3], 0.171),
        ("jittered grid, K = 100", jittered, 1.15),
        ("importance, Eq. 10, K = 100", sampled, 11.1),
        ("jittered grid, Eq. 10, K = 100", sampled_jittered, 1.80),
        ("2×2 clusters, importance, K = 100", c_imp, 0.416),
        ("2×2 clusters, importance, K = 200", c_imp200, 0.412),
        ("2×2 clusters, jittered grid, K = 100", c_jit, 1.09),
    ];
    for (what, e, bound) in bounded {
        assert!(e < bound, "{what}: error {e}, bound {bound}");
    }
    // The paper's claim: at K = 100 importance sampling beats the jittered grid, by 4.97× over
    // the exact transport and 2.63× with 2×2 clusters (means over the seeds), and for every
    // seed (per-seed ratios 5.35 / 4.36 / 5.22 and 2.78 / 2.43 / 2.68; 4.66× / 2.78× before the
    // texels' form factors were collocated, 3.16× / 2.37× before the texel areas were averaged
    // over their squares). Each ratio must reach the earliest measured value / 1.25: the
    // means, and the smallest per-seed ratio for every seed.
    let ratios = [
        ("exact transport", jittered / errs[2], 2.52),
        ("2×2 clusters", c_jit / c_imp, 1.89),
    ];
    for (what, ratio, least) in ratios {
        assert!(
            ratio > least,
            "{what}: jittered grid / importance at K = 100 is {ratio}, must exceed {least}"
        );
    }
    for (what, imp, jit, least) in [
        ("exact transport", draws[2], &jittered_draws, 2.14),
        ("2×2 clusters", &c_imp_draws, &c_jit_draws, 1.74),
    ] {
        for ((seed, i), j) in seeds.iter().zip(imp).zip(jit) {
            assert!(
                j / i > least,
                "{what}, seed {seed}: jittered grid {j} / importance {i} must exceed {least}"
            );
        }
    }
    // The integrated cell rule against the paper's Eq. 10 at K = 100, seed 3 (importance):
    // 0.1826 vs 8.9156 (48.8×; 0.2189 vs 3.8421, 17.6×, before the texels' form factors were
    // collocated; 0.2296 vs 1.0136, 4.41×, before the texel areas were averaged over their
    // squares); the ratio must reach 4.41 / 1.25.
    let eq10_ratio = sampled / draws[2][0];
    assert!(
        eq10_ratio > 3.53,
        "Eq. 10 {sampled} / integrated {} = {eq10_ratio}, must exceed 3.53",
        draws[2][0]
    );
}

#[test]
fn cornell_offsets_converge() {
    // The Cornell box (radiosity only, six charts): cells of offset space span several charts,
    // so the first-order light at a cell's site is a poor sample of its senders' light; the error
    // is large at small K, and falls as K grows.
    let scene = ortm::scene::cornell::cornell_box(48);
    let grid = TexelGrid::build(&scene).unwrap();
    let effects = Effects::default();
    let transport = Transport::new(&scene, &grid, effects, 2);
    let vis = Visibility::new(&scene.mesh);
    let dense = DenseTransport::new(&texel_patches(&grid), &transport.kernels);
    let mut setups = random_light_setups(&scene, 6, 11);
    setups.push(scene.lights.clone());
    let reference = Reference::new(&grid, &vis, &dense, &setups);
    let errs: Vec<f64> = [50usize, 100, 200]
        .iter()
        .map(|&k| {
            let e: f64 = [3u64, 4]
                .iter()
                .map(|&seed| {
                    indirect_error(
                        &transport,
                        &grid,
                        &reference,
                        k,
                        Selector::Importance,
                        bake::CellRule::Integrated,
                        seed,
                    )
                })
                .sum();
            e / 2.0
        })
        .collect();
    eprintln!(
        "Cornell box 48², 2×2 clusters, 7 light set-ups, relative RMSE of the indirect term, \
         mean of seeds 3, 4: K = 50/100/200: {errs:.4?}"
    );
    for w in errs.windows(2) {
        assert!(w[1] < w[0], "error must fall as K grows: {errs:?}");
    }
    // README's figures (measured 1.2396 / 0.9717 / 0.7186), each bounded at + 25 %.
    for (e, bound) in errs.iter().zip([1.55, 1.21, 0.90]) {
        assert!(
            e < &bound,
            "K = 50/100/200: {errs:?}, bounds 1.55 / 1.21 / 0.90"
        );
    }
}
