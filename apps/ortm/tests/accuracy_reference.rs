//! The path-traced reference (`ortm::accuracy::reference`) against the exact dense solve of the
//! same scene: two independent computations of the transport's model (Monte Carlo paths through
//! the BVH and the profile by probe rays, vs form factors and the profile's texel quadrature
//! solved by LU). Plus determinism (seed, thread count), and a measurement of the subsurface
//! weights' row sums against the continuous surface (`*_subsurface_rows_*`, ignored).

mod common;

use std::sync::atomic::AtomicBool;

use glam::Vec3;
use ortm::accuracy::compare::{near_first_order_edges, relative_rmse};
use ortm::accuracy::reference::{self, ReferenceMaps, Settings};
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, texel_patches};
use ortm::scene::{Light, Scene};
use std::sync::Arc;

/// The exact dense solve's final radiosity of `grid` under `lights`.
fn exact(scene: &Scene, grid: &TexelGrid, lights: &[Light], effects: Effects) -> Vec<Vec3> {
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let b_o = lighting::first_order(grid, lights, &vis);
    let kernels = Kernels::new(scene, effects, vis);
    DenseTransport::new(&texel_patches(grid), &kernels).solve(&b_o)
}

fn run(scene: &Scene, grid: &TexelGrid, lights: &[Light], settings: &Settings) -> ReferenceMaps {
    let (maps, stats) = reference::trace_with_stats(
        scene,
        grid,
        lights,
        settings,
        &|_, _| {},
        &AtomicBool::new(false),
    )
    .expect("not cancelled");
    println!(
        "{} texels × {} spp: {:.1} s, {:.2} Mrays/s",
        grid.texels.len(),
        settings.samples_per_texel,
        stats.seconds,
        stats.rays_per_second() / 1e6
    );
    maps
}

/// Figures of the reference against the exact solve over the texels of `mask`: fraction of
/// texels within `k` standard errors in every channel, relative RMSE, and the worst texels by
/// z-score.
struct Agreement {
    within: f64,
    rmse: f64,
    indirect_power_ratio: f64,
    /// The reference's noise over the mask as a relative RMSE, `sqrt(Σ σ² / Σ B²)`: what the
    /// relative RMSE would be if the exact solve were the reference's expectation.
    noise: f64,
}

fn agreement(
    grid: &TexelGrid,
    maps: &ReferenceMaps,
    exact: &[Vec3],
    k: f32,
    mask: &[bool],
) -> Agreement {
    // An absolute floor of 10⁻³ × the mean exact value: texels in deep shadow, where both are
    // ~0 and the reference's samples are all 0 (σ = 0).
    let floor =
        1e-3 * exact.iter().map(|e| e.element_sum() / 3.0).sum::<f32>() / exact.len() as f32;
    let mut within = 0usize;
    let mut z: Vec<(f32, usize)> = Vec::new();
    for (i, (b, e)) in maps.final_b.iter().zip(exact).enumerate() {
        if !mask[i] {
            continue;
        }
        let se = maps.std_error[i];
        let zi = (0..3)
            .map(|c| ((b[c] - e[c]).abs() - floor).max(0.0) / se[c].max(1e-12))
            .fold(0.0f32, f32::max);
        within += usize::from(zi <= k);
        z.push((zi, i));
    }
    let mut by_abs: Vec<(f32, usize)> = z
        .iter()
        .map(|&(_, i)| ((maps.final_b[i] - exact[i]).length(), i))
        .collect();
    by_abs.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(d, i) in by_abs.iter().take(6) {
        let t = &grid.texels[i];
        println!(
            "  largest |Δ| {d:.4} at ({}, {}): reference {:.4} ± {:.4}, exact {:.4}, first {:.4}",
            t.x, t.y, maps.final_b[i], maps.std_error[i], exact[i], maps.first_order[i]
        );
    }
    z.sort_by(|a, b| b.0.total_cmp(&a.0));
    for &(zi, i) in z.iter().take(4) {
        let t = &grid.texels[i];
        println!(
            "  texel ({}, {}) chart {} at {:?} n {:?} z = {zi:.1}: reference {:?} ± {:?}, exact {:?}, first {:?}",
            t.x,
            t.y,
            t.chart,
            t.position_m,
            t.normal,
            maps.final_b[i],
            maps.std_error[i],
            exact[i],
            maps.first_order[i]
        );
    }
    let (mut pr, mut pe) = (0.0f64, 0.0f64);
    for i in (0..exact.len()).filter(|&i| mask[i]) {
        let a = grid.texels[i].area_m2 as f64;
        pr += a * (maps.final_b[i] - maps.first_order[i]).element_sum() as f64;
        pe += a * (exact[i] - maps.first_order[i]).element_sum() as f64;
    }
    println!("indirect power reference / exact: {:.4}", pr / pe);
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for i in (0..exact.len()).filter(|&i| mask[i]) {
        num += maps.std_error[i].as_dvec3().length_squared();
        den += maps.final_b[i].as_dvec3().length_squared();
    }
    let a = Agreement {
        within: within as f64 / z.len() as f64,
        rmse: relative_rmse(&maps.final_b, exact, Some(mask)),
        indirect_power_ratio: pr / pe,
        noise: (num / den).sqrt(),
    };
    println!(
        "{} texels: within {k} σ: {:.4}; relative RMSE {:.5}, of which noise {:.5}; mean relative \
         standard error {:.5}",
        z.len(),
        a.within,
        a.rmse,
        a.noise,
        maps.mean_relative_std_error(&maps.final_b)
    );
    a
}

/// Texels within two texel sizes of a texel of another chart facing another way (creases,
/// corners, where the blocks stand on the floor): where the exact solve's piecewise-constant
/// senders approximate the continuous surface most coarsely.
fn near_creases(grid: &TexelGrid) -> Vec<bool> {
    let t = &grid.texels;
    t.iter()
        .map(|a| {
            t.iter().any(|b| {
                b.chart != a.chart
                    && a.normal.dot(b.normal) < 0.99
                    && (a.position_m - b.position_m).length()
                        < 2.0 * a.area_m2.max(b.area_m2).sqrt()
            })
        })
        .collect()
}

/// The head scene with a `size`² lightmap and its texels.
fn head_at(size: u32) -> (Scene, TexelGrid) {
    let Ok(mut scene) = ortm::scene::head::head_scene() else {
        panic!("head scene (../shared/faces/head.obj)");
    };
    scene.lightmap_size = (size, size);
    let grid = TexelGrid::build(&scene).unwrap();
    (scene, grid)
}

/// [`agreement`] near the reference's first-order edges and away from them
/// ([`near_first_order_edges`]), each printed under a heading that starts with `label`.
fn by_first_order_edges(
    grid: &TexelGrid,
    maps: &ReferenceMaps,
    exact: &[Vec3],
    label: &str,
) -> (Agreement, Agreement) {
    let edges = near_first_order_edges(grid, &maps.first_order);
    let calm: Vec<bool> = edges.iter().map(|e| !e).collect();
    println!("{label}near first-order edges:");
    let near = agreement(grid, maps, exact, 3.0, &edges);
    println!("{label}away from first-order edges:");
    let away = agreement(grid, maps, exact, 3.0, &calm);
    (near, away)
}

/// The reference's settings: `spp` paths per texel in replicates of 8 stratified paths, so that
/// a texel's standard error has `spp/8 − 1` degrees of freedom (255 at 2,048 spp) and "within
/// 3σ" means what it does for a known σ (the default 32 replicates put 0.53 % of the texels
/// beyond 3σ per channel by the Student t's tails alone).
fn settings(spp: u32, seed: u64, effects: Effects) -> Settings {
    Settings {
        samples_per_texel: spp,
        replicates: (spp / 4).max(2),
        seed,
        effects,
    }
}

const RADIOSITY: Effects = Effects {
    radiosity: true,
    subsurface: false,
};

/// Cornell 64², radiosity. The scene's own light hangs 2 cm under the ceiling, so the ceiling's
/// first order peaks as h/(r²+h²)^{3/2} (20,000 W/m² above the lamp): paths that land there are
/// rare and carry most of the indirect light (with cosine-sampled bounces alone, mean relative
/// standard error 0.24 of the final at 64 spp, against 0.09 with this lamp). The test moves the
/// lamp to (0.4, 0.45, 0.2) m, ≥ 0.1 m from every surface.
#[test]
fn cornell_64_agrees_with_the_exact_solve() {
    let scene = ortm::scene::cornell::cornell_box(64);
    let grid = TexelGrid::build(&scene).unwrap();
    let spp = 2048;
    let lights = vec![Light::Point {
        position_m: Vec3::new(0.4, 0.45, 0.2),
        color: Vec3::ONE,
        intensity_w_sr: 1.0,
    }];
    let maps = run(&scene, &grid, &lights, &settings(spp, 1, RADIOSITY));
    let exact = exact(&scene, &grid, &lights, RADIOSITY);
    let creases = near_creases(&grid);
    let all = vec![true; grid.texels.len()];
    let away: Vec<bool> = creases.iter().map(|c| !c).collect();
    println!("all texels:");
    let a_all = agreement(&grid, &maps, &exact, 3.0, &all);
    println!("near creases:");
    let _ = agreement(&grid, &maps, &exact, 3.0, &creases);
    println!("away from creases:");
    let a_away = agreement(&grid, &maps, &exact, 3.0, &away);
    // Measured (2,048 spp in 512 replicates of 4 stratified paths, seed 1, the first-order light
    // at every vertex): all 2,100 texels 0.9914 within 3σ, relative RMSE 0.0068 (of which noise
    // 0.0059), indirect power 1.0015 × the exact solve's; the 1,068 texels near creases 0.9860 /
    // 0.0100; the 1,032 away from them 0.9971 / 0.0050 (noise 0.0051). Issue 15's check: ≥ 99 %
    // within 3σ and ≤ 1 % relative RMSE over all covered texels. The misses left are
    // systematic, at the bottom rows of the rotated blocks' faces, where axis-aligned floor
    // texels whose centres lie under a block stay dark although part of their square is in the
    // open (the reference's floor is continuous); with less noise they show more: 4,096
    // independent paths read 0.9876 / 0.0063, and 2,048 paths in replicates of 8 (noise 0.0055)
    // 0.9867 / 0.0068 — so the check holds at this noise, not for every reference. With 2,048
    // independent paths (noise 0.0069) seeds 1–4 read 0.9905–0.9933.
    assert!(a_all.within >= 0.99, "all: {:.4} within 3σ", a_all.within);
    assert!(
        a_away.within >= 0.99,
        "away from creases: {:.4} within 3σ",
        a_away.within
    );
    assert!(a_all.rmse < 0.01, "all: relative RMSE {:.4}", a_all.rmse);
    assert!(
        a_away.rmse < 1.25 * 0.0058,
        "away: relative RMSE {:.4}",
        a_away.rmse
    );
    assert!(
        (a_all.indirect_power_ratio - 1.0).abs() < 0.0025,
        "indirect power ratio {:.4}",
        a_all.indirect_power_ratio
    );
}

/// The head at 64², radiosity + subsurface, with the scene's light (the paper's Fig. 5 lamp):
/// the measured distance between the reference and the exact solve (see the comment below).
#[test]
fn head_64_agrees_with_the_exact_solve() {
    let (scene, grid) = head_at(64);
    let spp = 256;
    let effects = Effects::default();
    let lights = scene.lights.clone();
    let maps = run(&scene, &grid, &lights, &settings(spp, 1, effects));
    let exact = exact(&scene, &grid, &lights, effects);
    let creases = near_creases(&grid);
    let all = vec![true; grid.texels.len()];
    let away: Vec<bool> = creases.iter().map(|c| !c).collect();
    println!("all texels:");
    let a_all = agreement(&grid, &maps, &exact, 3.0, &all);
    println!("near seams:");
    let _ = agreement(&grid, &maps, &exact, 3.0, &creases);
    println!("away from seams:");
    let _ = agreement(&grid, &maps, &exact, 3.0, &away);
    let _ = by_first_order_edges(&grid, &maps, &exact, "");
    let noise = maps.rms_relative_std_error(&maps.final_b);
    println!("the reference's noise as a relative RMSE: {noise:.4}");
    // Measured (256 spp in 64 replicates of 4, seed 1): 0.9307 of the 3,782 texels within 3σ,
    // relative RMSE 0.0921, of which the reference's noise is 0.0416 (sqrt Σσ² / sqrt ΣB²); the
    // reference's indirect power is 1.50 × the exact solve's. Split by the first-order light's
    // edges: the 1,673 texels near them 0.8715 / 0.1027 / 1.54, the 2,109 away from them
    // 0.9777 / 0.0311 (noise 0.0313) / 1.14 — away from the edges the two agree to the
    // reference's noise, and
    // [`head_64_agrees_away_from_first_order_edges_for_each_effect`] shows it for each effect
    // alone. The gap is the 64² texel (4–9 mm, against a subsurface profile of 1–3 mm mean
    // free path) holding the first-order light constant across shadow edges and terminators,
    // where the reference's exit points and bounces gather the light beside the centre. With
    // the first order sampled as a light on opaque surfaces only (cosine bounces alone on
    // skin) the figures were 0.815 / 0.1199 / 1.75: rare paths from dark skin to lit skin left
    // many texels at 0 ± 0. Independent paths with the profile's normal probe at probability ½
    // and a uniform choice among a probe's hits (the reference before its stratified paths)
    // read 0.9368 / 0.1148 with noise 0.0842. Bounds: measured + 25 % of the error.
    assert!(a_all.within >= 0.913, "{:.4} within 3σ", a_all.within);
    assert!(a_all.rmse < 0.115, "relative RMSE {:.4}", a_all.rmse);
    assert!(noise < 0.052, "noise {noise:.4}");
}

/// The head at 64² with the scene's light, each effect alone: away from the first-order light's
/// edges (`ortm::accuracy::compare::near_first_order_edges`) the reference and the exact solve
/// must agree to the reference's noise — within 3 standard errors on ≥ 99 % of the texels, and
/// a relative RMSE no larger than the reference's own noise (+ 25 %) — so whatever separates
/// them there is the discretisation of the first-order light at those edges, not the radiosity
/// or the subsurface model of either.
#[test]
fn head_64_agrees_away_from_first_order_edges_for_each_effect() {
    let (scene, grid) = head_at(64);
    let lights = scene.lights.clone();
    let only_sss = Effects {
        radiosity: false,
        subsurface: true,
    };
    for (name, effects) in [("radiosity", RADIOSITY), ("subsurface", only_sss)] {
        let maps = run(&scene, &grid, &lights, &settings(256, 1, effects));
        let exact = exact(&scene, &grid, &lights, effects);
        let (near, away) = by_first_order_edges(&grid, &maps, &exact, &format!("{name}, "));
        // Measured (256 spp in 64 replicates of 4, seed 1; 1,673 texels near edges, 2,109
        // away): radiosity near 0.9438 within 3σ / RMSE 0.0162 (noise 0.0046), away 0.9896 /
        // 0.0035 (noise 0.0036); subsurface near 0.8362 / 0.0902 (noise 0.0393), away 0.9957 /
        // 0.0330 (noise 0.0305). Away from the edges the RMSE is the noise; the radiosity's
        // misses there are texels whose small indirect term the stratified paths pin to ~0.06 %
        // while the exact solve's texel discretisation differs by more (the independent paths'
        // reference, noise 0.0040, read 0.9948: the fraction within 3σ falls as the noise does,
        // the RMSE does not rise). Independent paths with the profile's normal probe at ½ and a
        // uniform choice of hit read subsurface near 0.8793 / 0.1134 (noise 0.0837), away
        // 0.9986 / 0.0743 (noise 0.0726).
        assert!(away.within >= 0.97, "{name}: {:.4} within 3σ", away.within);
        assert!(
            away.rmse < 1.25 * away.noise,
            "{name}: relative RMSE {:.4} against noise {:.4}",
            away.rmse,
            away.noise
        );
        assert!(
            near.within < away.within,
            "{name}: the edges are where they differ"
        );
    }
}

fn bits(m: &ReferenceMaps) -> Vec<[u32; 3]> {
    m.final_b
        .iter()
        .chain(&m.std_error)
        .map(|v| v.to_array().map(f32::to_bits))
        .collect()
}

/// Same seed → bit-identical maps, with 1 and 2 worker threads; another seed → other noise.
/// Cornell 32² with radiosity and the head at 48² with subsurface (the probe rays).
#[test]
fn reference_is_deterministic_for_a_seed_whatever_the_thread_count() {
    let cornell = ortm::scene::cornell::cornell_box(32);
    let mut head = ortm::scene::head::head_scene().expect("head scene");
    head.lightmap_size = (48, 48);
    for scene in [&cornell, &head] {
        let grid = TexelGrid::build(scene).unwrap();
        let trace = |threads: usize, seed: u64| {
            let pool = rayon::ThreadPoolBuilder::new()
                .num_threads(threads)
                .build()
                .unwrap();
            pool.install(|| {
                reference::trace(
                    scene,
                    &grid,
                    &scene.lights,
                    &settings(8, seed, Effects::default()),
                    &|_, _| {},
                    &AtomicBool::new(false),
                )
                .unwrap()
            })
        };
        let one = bits(&trace(1, 5));
        assert_eq!(one, bits(&trace(2, 5)), "{}: 1 vs 2 threads", scene.name);
        assert_eq!(one, bits(&trace(2, 5)), "{}: same seed", scene.name);
        assert_ne!(one, bits(&trace(2, 6)), "{}: another seed", scene.name);
    }
}

/// `scene` traced by `estimator` at `spp` paths per texel (radiosity), with the wall time.
fn trace_estimator(
    scene: &Scene,
    grid: &TexelGrid,
    lights: &[Light],
    estimator: reference::Estimator,
    (spp, seed, effects): (u32, u64, Effects),
) -> (ReferenceMaps, f64) {
    let (maps, stats) = reference::trace_with_estimator(
        scene,
        grid,
        lights,
        &settings(spp, seed, effects),
        estimator,
        &|_, _| {},
        &AtomicBool::new(false),
    )
    .expect("not cancelled");
    (maps, stats.seconds)
}

/// The first order sampled as a light (multiple importance sampling with the cosine-sampled
/// bounce, at every path vertex) estimates the same `B` as cosine-sampled bounces alone:
/// Cornell 32², the lamp moved ≥ 0.1 m from every surface (so the cosine estimator's standard
/// error is trustworthy, see [`cornell_64_agrees_with_the_exact_solve`]), independent seeds;
/// per texel within 3 combined standard errors, and the total power within 4.
#[test]
fn first_order_light_agrees_with_cosine_bounces() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let grid = TexelGrid::build(&scene).unwrap();
    let lights = vec![Light::Point {
        position_m: Vec3::new(0.4, 0.45, 0.2),
        color: Vec3::ONE,
        intensity_w_sr: 1.0,
    }];
    let (within, z_power) = estimators_agree(&scene, &grid, &lights, RADIOSITY, (1024, 512));
    // Measured (cosine 1,024 spp seed 7, light 512 spp seed 8, replicates of 4): 0.9931 within
    // 3σ, total power z −1.86 (noise 0.0143 and 0.0120); with independent paths 0.9954, z −0.54
    // (noise 0.0162 and 0.0139). Independent Gaussian errors put the largest of 3 channels
    // within 3σ for ~0.992 of the texels.
    assert!(within >= 0.99, "{within:.4} of the texels within 3σ");
    assert!(z_power.abs() < 4.0, "total power differs by {z_power:.2}σ");
}

/// The same on translucent skin: the head at 64² with radiosity and subsurface, where the first
/// order of the translucent surface is sampled as a light and its exit steps subtract the
/// light sample's share (`reference::path`).
#[test]
fn first_order_light_agrees_with_cosine_bounces_on_skin() {
    let (scene, grid) = head_at(64);
    let lights = scene.lights.clone();
    let (within, z_power) =
        estimators_agree(&scene, &grid, &lights, Effects::default(), (512, 256));
    // Measured (cosine 512 spp seed 7, light 256 spp seed 8, replicates of 4): 0.9910 within
    // 3σ, total power z +0.10 (noise 0.0300 and 0.0426: at equal paths the two are about as
    // noisy on lit skin, whose exit points carry the variance); in replicates of 8, 0.9868.
    // Independent paths with the normal probe at ½ and a uniform choice of hit: 0.9942, z +1.51
    // (noise 0.0602 and 0.0845).
    assert!(within >= 0.99, "{within:.4} of the texels within 3σ");
    assert!(z_power.abs() < 4.0, "total power differs by {z_power:.2}σ");
}

/// Cosine-sampled bounces (`spp.0` paths per texel, seed 7) against the first-order light
/// (`spp.1`, seed 8): the fraction of texels whose difference is within 3 combined standard errors in
/// every channel, and the difference of the total power in combined standard errors.
fn estimators_agree(
    scene: &Scene,
    grid: &TexelGrid,
    lights: &[Light],
    effects: Effects,
    spp: (u32, u32),
) -> (f64, f64) {
    let (cosine, _) = trace_estimator(
        scene,
        grid,
        lights,
        reference::Estimator::Cosine,
        (spp.0, 7, effects),
    );
    let (light, _) = trace_estimator(
        scene,
        grid,
        lights,
        reference::Estimator::FirstOrderLight,
        (spp.1, 8, effects),
    );
    let mut within = 0usize;
    let (mut dp, mut var_p) = (0.0f64, 0.0f64);
    for (i, t) in grid.texels.iter().enumerate() {
        let (a, b) = (cosine.final_b[i], light.final_b[i]);
        let (sa, sb) = (cosine.std_error[i], light.std_error[i]);
        let sigma = (sa * sa + sb * sb).powf(0.5);
        let z = (0..3)
            .map(|c| (a[c] - b[c]).abs() / sigma[c].max(1e-12))
            .fold(0.0f32, f32::max);
        within += usize::from(z <= 3.0);
        let area = t.area_m2 as f64;
        dp += area * (b - a).element_sum() as f64;
        var_p += area * area * (sigma * sigma).element_sum() as f64;
    }
    let within = within as f64 / grid.texels.len() as f64;
    let z_power = dp / var_p.sqrt();
    println!(
        "{} texels: within 3σ {within:.4}; total power z {z_power:.2}; noise cosine {:.4}, \
         first-order light {:.4}",
        grid.texels.len(),
        cosine.rms_relative_std_error(&cosine.final_b),
        light.rms_relative_std_error(&light.final_b)
    );
    (within, z_power)
}

/// The case the first-order light is for: Cornell 32² with its own lamp 2 cm under the ceiling
/// (a small, very bright spot that cosine-sampled bounces rarely find). At equal paths per
/// texel the RMS relative standard error of the final falls several times.
#[test]
fn first_order_light_lowers_the_noise_under_a_lamp_near_the_ceiling() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let grid = TexelGrid::build(&scene).unwrap();
    let spp = 256;
    let noise = |estimator| {
        let (m, seconds) =
            trace_estimator(&scene, &grid, &scene.lights, estimator, (spp, 1, RADIOSITY));
        let noise = m.rms_relative_std_error(&m.final_b);
        println!("{estimator:?}: noise {noise:.4} at {spp} spp in {seconds:.1} s");
        noise
    };
    let cosine = noise(reference::Estimator::Cosine);
    let light = noise(reference::Estimator::FirstOrderLight);
    // Measured (256 spp, seed 1): cosine 0.1124, first-order light 0.0188 (6.0×).
    assert!(
        cosine > 4.0 * light,
        "cosine {cosine:.4}, first-order light {light:.4}"
    );
}

/// A raised cancel flag stops the trace with `Cancelled`.
#[test]
fn a_raised_cancel_flag_stops_the_reference() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let grid = TexelGrid::build(&scene).unwrap();
    let r = reference::trace(
        &scene,
        &grid,
        &scene.lights,
        &settings(64, 1, RADIOSITY),
        &|_, _| {},
        &AtomicBool::new(true),
    );
    assert!(matches!(r, Err(reference::ReferenceError::Cancelled)));
}

/// `ortm reference` writes the four EXRs (the covered texels' values; uncovered texels 0) and
/// PNGs; a missing scene file is a clear error naming it.
#[test]
fn cli_writes_the_four_exrs_and_names_a_bad_scene() {
    let dir = tempfile::tempdir().unwrap();
    let text = common::ok(common::ortm(
        &[
            "reference",
            "cornell",
            "--size",
            "32",
            "--spp",
            "4",
            "--effects",
            "radiosity",
            "-o",
            "out",
        ],
        dir.path(),
    ));
    assert!(text.contains("4 paths per texel"), "{text}");
    let scene = ortm::scene::cornell::cornell_box(32);
    let grid = TexelGrid::build(&scene).unwrap();
    let read = |name: &str| {
        ortm::render::lightmap_exr::read_lightmap_exr(&dir.path().join("out").join(name))
            .unwrap_or_else(|e| panic!("{name}: {e}"))
    };
    let (fin, first, ind, se) = (
        read("final.exr"),
        read("first_order.exr"),
        read("indirect.exr"),
        read("std_error.exr"),
    );
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    for (i, t) in grid.texels.iter().enumerate() {
        let (f, o, d) = (fin.get(t.x, t.y), first.get(t.x, t.y), ind.get(t.x, t.y));
        assert_eq!(o, b_o[i].to_array(), "first order at texel {i}");
        for c in 0..3 {
            assert!((f[c] - o[c] - d[c]).abs() <= 1e-4 * f[c].abs().max(1.0));
            assert!(se.get(t.x, t.y)[c] >= 0.0);
        }
    }
    let uncovered = (0..32u32).flat_map(|y| (0..32u32).map(move |x| (x, y)));
    for (x, y) in uncovered.filter(|&(x, y)| grid.at(x as i32, y as i32).is_none()) {
        assert_eq!(fin.get(x, y), [0.0; 3]);
    }
    for png in ["final.png", "first_order.png", "indirect.png"] {
        assert!(dir.path().join("out").join(png).is_file(), "{png}");
    }
    let text = common::fails(common::ortm(
        &["reference", "no_such_scene.toml", "-o", "out2"],
        dir.path(),
    ));
    assert!(
        text.contains("no_such_scene.toml") && text.contains("not found"),
        "{text}"
    );
}

/// A flat translucent square (0.2 m, skin1 of Jensen et al. 2001) under a uniform directional
/// light of 1 W/m² along its normal, subsurface only: away from the edges (farther than the
/// profile's support `R`) the convolution gives exactly `B = E·∫₀^R R_d(r) 2πr dr` per channel
/// (the profile's disk integral), an analytic check of the subsurface path (probe rays, the
/// multiple-importance density, the weights). Dipole and exponential profiles.
#[test]
fn flat_translucent_square_reemits_the_profile_integral() {
    use glam::Vec2;
    use ortm::scene::subsurface::Profile;
    use ortm::scene::{Albedo, Material, Mesh, MeshTriangle, Subsurface, SubsurfaceModel};
    for model in [SubsurfaceModel::Dipole, SubsurfaceModel::Exponential] {
        let sss = Subsurface {
            sigma_a_per_mm: Vec3::new(0.032, 0.17, 0.48),
            sigma_s_prime_per_mm: Vec3::new(0.74, 0.88, 1.01),
            eta: 1.3,
            model,
        };
        let h = 0.1f32;
        let scene = Scene {
            name: "square".into(),
            mesh: Mesh {
                positions_m: vec![
                    Vec3::new(-h, -h, 0.0),
                    Vec3::new(h, -h, 0.0),
                    Vec3::new(h, h, 0.0),
                    Vec3::new(-h, h, 0.0),
                ],
                uvs: vec![
                    Vec2::new(0.0, 0.0),
                    Vec2::new(1.0, 0.0),
                    Vec2::new(1.0, 1.0),
                    Vec2::new(0.0, 1.0),
                ],
                normals: vec![Vec3::Z],
                triangles: [[0, 1, 2], [0, 2, 3]]
                    .map(|p| MeshTriangle {
                        position: p,
                        uv: p,
                        normal: [0; 3],
                        material: 0,
                    })
                    .to_vec(),
            },
            materials: vec![Material {
                name: "skin".into(),
                albedo: Albedo::Constant(Vec3::ONE),
                subsurface: Some(sss),
            }],
            lights: vec![Light::Directional {
                direction: -Vec3::Z,
                color: Vec3::ONE,
                irradiance_w_m2: 1.0,
            }],
            lightmap_size: (16, 16),
            allow_uv_overlap: false,
        };
        let grid = TexelGrid::build(&scene).unwrap();
        let effects = Effects {
            radiosity: false,
            subsurface: true,
        };
        let maps = run(&scene, &grid, &scene.lights, &settings(512, 2, effects));
        let profile = Profile::new(&sss);
        let support = profile.support_radius(1e-4);
        let d = profile.disk_integral(support);
        let expected = Vec3::new(d[0] as f32, d[1] as f32, d[2] as f32);
        let (mut n, mut sum, mut var, mut worst_z) = (0usize, Vec3::ZERO, Vec3::ZERO, 0.0f32);
        for (i, t) in grid.texels.iter().enumerate() {
            let p = t.position_m;
            if p.x.abs().max(p.y.abs()) > h - support as f32 {
                continue;
            }
            n += 1;
            sum += maps.final_b[i];
            var += maps.std_error[i] * maps.std_error[i];
            worst_z =
                worst_z.max(((maps.final_b[i] - expected).abs() / maps.std_error[i]).max_element());
        }
        let mean = sum / n as f32;
        let se = Vec3::new(var.x.sqrt(), var.y.sqrt(), var.z.sqrt()) / n as f32;
        let z = (mean - expected).abs() / se;
        println!(
            "{model:?}: {n} interior texels, mean B {mean:.5} ± {se:.5} vs ∫R_d {expected:.5} \
             ({z:.2} σ); worst texel {worst_z:.2} σ"
        );
        assert!(n >= 16);
        assert!(
            z.max_element() < 3.0,
            "{model:?}: mean {mean} vs {expected} ({z} σ)"
        );
        assert!(worst_z < 4.5, "{model:?}: a texel {worst_z} σ off");
    }
}

/// The head at 64² (scene light): the exact dense solve and the bake's cluster evaluator
/// (`Transport::new` with 4×4 and 8×8 clusters, every pair) against the path-traced reference
/// at 1,024 spp, relative RMSE of the indirect term over all covered texels, radiosity alone
/// and with subsurface scattering. Prints the figures (about 2 min in release); the evaluator's
/// distance to the exact solve is asserted in `bake_evaluator.rs`.
#[test]
#[ignore]
fn head_64_cluster_evaluator_against_the_reference() {
    let (scene, grid) = head_at(64);
    let lights = scene.lights.clone();
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let b_o = lighting::first_order(&grid, &lights, &vis);
    let indirect = |b: &[Vec3]| -> Vec<Vec3> { b.iter().zip(&b_o).map(|(x, o)| *x - *o).collect() };
    for (name, effects) in [("radiosity", RADIOSITY), ("both", Effects::default())] {
        let maps = run(&scene, &grid, &lights, &settings(1024, 1, effects));
        let reference = indirect(&maps.final_b);
        let exact = indirect(&exact(&scene, &grid, &lights, effects));
        println!(
            "{name}: exact solve against the reference (indirect) {:.4}",
            relative_rmse(&exact, &reference, None)
        );
        for block in [4u32, 8] {
            let tr = ortm::bake::transport::Transport::new(&scene, &grid, effects, block);
            let ev = indirect(&ortm::bake::eval::evaluator_final(&tr, &b_o));
            println!(
                "{name}: {block}×{block} cluster evaluator against the reference {:.4}, against \
                 the exact solve {:.4}",
                relative_rmse(&ev, &reference, None),
                relative_rmse(&ev, &exact, None)
            );
        }
    }
}

/// Eight point lights of 1/8 W/sr each on a Fibonacci sphere at four bounding radii from the
/// head's centre: light from every side, so that most texels lie away from a shadow's edge.
fn dome_lights(scene: &Scene) -> Vec<Light> {
    let (centre, r) = scene.mesh.bounding_sphere().expect("a mesh");
    let n = 8;
    (0..n)
        .map(|k| {
            let z = 1.0 - 2.0 * (k as f32 + 0.5) / n as f32;
            let phi = k as f32 * 2.399_963;
            let s = (1.0 - z * z).sqrt();
            Light::Point {
                position_m: centre + 4.0 * r * Vec3::new(s * phi.cos(), z, s * phi.sin()),
                color: Vec3::ONE,
                intensity_w_sr: 1.0 / n as f32,
            }
        })
        .collect()
}

/// RMS over patches and channels of `sum_i / q̂_i − 1`.
fn rms_deviation(sums: &[[f64; 3]], q_hat: &[[f64; 3]]) -> f64 {
    let squares: f64 = (0..3).map(|c| rms_in_channel(sums, q_hat, c).powi(2)).sum();
    (squares / 3.0).sqrt()
}

/// Figures of [`subsurface_rows_at`]: RMS deviation of the weights' row sums from `Q̂`, capped
/// and balanced, and their agreement with the reference under `lights` over the texels away
/// from the first order's edges.
struct RowsFigures {
    capped_rows: f64,
    balanced_rows: f64,
    balanced_columns: f64,
    capped_away: Agreement,
    balanced_away: Agreement,
    balanced_all: Agreement,
    capped_all: Agreement,
}

/// The head at `size`², subsurface alone: the transport's weights (normalised per sender,
/// columns capped at `Q̂_j`) and the same raw weights balanced in rows and columns
/// (`Kernels::balance_rounds`, 50 rounds), each applied to the first order of `lights` (`B_i = Σ_j S_ij E_j`, the exact
/// solve without interreflection) and compared with the reference at `spp` paths per texel.
fn subsurface_rows_at(size: u32, spp: u32, lights: impl Fn(&Scene) -> Vec<Light>) -> RowsFigures {
    use rayon::prelude::*;
    let (scene, grid) = head_at(size);
    let effects = Effects {
        radiosity: false,
        subsurface: true,
    };
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let mut kernels = Kernels::new(&scene, effects, vis.clone());
    let patches = texel_patches(&grid);
    let n = patches.len();
    let q_hat: Vec<[f64; 3]> = (patches.iter())
        .map(|p| kernels.continuous_reemission(p).expect("skin"))
        .collect();
    let area: Vec<f64> = patches.iter().map(|p| p.area_m2 as f64).collect();
    // The raw weights within the profile's support, row by row.
    let support = kernels.support_m[0] as f32;
    let rows: Vec<Vec<(usize, [f64; 3])>> = (0..n)
        .into_par_iter()
        .map(|i| {
            (0..n)
                .filter(|&j| {
                    i == j || (patches[i].position_m - patches[j].position_m).length() <= support
                })
                .filter_map(|j| {
                    let w = kernels.subsurface_raw(&patches[i], &patches[j], i == j)?;
                    (w != [0.0; 3]).then_some((j, w))
                })
                .collect()
        })
        .collect();
    let mut capped = patches.clone();
    kernels.normalise_subsurface(&mut capped);
    let beta_cap: Vec<[f64; 3]> = (capped.iter())
        .map(|p| p.subsurface_scale.to_array().map(f64::from))
        .collect();
    let ones = vec![[1.0f64; 3]; n];
    kernels.balance_rounds = 50;
    let mut balanced = patches.clone();
    kernels.normalise_subsurface(&mut balanced);
    let factors = |f: fn(&ortm::bake::transport::Patch) -> Vec3| -> Vec<[f64; 3]> {
        balanced
            .iter()
            .map(|p| f(p).to_array().map(f64::from))
            .collect()
    };
    let alpha = factors(|p| p.subsurface_gather);
    let beta = factors(|p| p.subsurface_scale);
    let sums = |alpha: &[[f64; 3]], beta: &[[f64; 3]]| {
        let mut row = vec![[0.0f64; 3]; n];
        let mut col = vec![[0.0f64; 3]; n];
        for (i, r) in rows.iter().enumerate() {
            for &(j, w) in r {
                for c in 0..3 {
                    let s = alpha[i][c] * w[c] * beta[j][c];
                    row[i][c] += s;
                    col[j][c] += area[i] * s / area[j];
                }
            }
        }
        (rms_deviation(&row, &q_hat), rms_deviation(&col, &q_hat))
    };
    let (capped_rows, capped_columns) = sums(&ones, &beta_cap);
    let (balanced_rows, balanced_columns) = sums(&alpha, &beta);
    println!(
        "{size}²: row / column sums against Q̂, RMS deviation: capped {capped_rows:.4} / \
         {capped_columns:.4}, balanced {balanced_rows:.4} / {balanced_columns:.4}"
    );
    let apply = |alpha: &[[f64; 3]], beta: &[[f64; 3]], b_o: &[Vec3]| -> Vec<Vec3> {
        (rows.iter().enumerate())
            .map(|(i, row)| {
                let mut s = [0.0f64; 3];
                for &(j, w) in row {
                    for c in 0..3 {
                        let rho = patches[j].rho[c] as f64;
                        if rho > 0.0 {
                            s[c] += alpha[i][c] * w[c] * beta[j][c] * b_o[j][c] as f64 / rho;
                        }
                    }
                }
                Vec3::new(s[0] as f32, s[1] as f32, s[2] as f32)
            })
            .collect()
    };
    let lights = lights(&scene);
    let maps = run(&scene, &grid, &lights, &settings(spp, 1, effects));
    let b_o = lighting::first_order(&grid, &lights, &vis);
    let capped_b = apply(&ones, &beta_cap, &b_o);
    let balanced_b = apply(&alpha, &beta, &b_o);
    if n <= 6000 {
        let same = relative_rmse(&capped_b, &exact(&scene, &grid, &lights, effects), None);
        assert!(
            same < 1e-5,
            "the capped weights are the exact solve's: {same}"
        );
        let solve = DenseTransport::new(&patches, &kernels).solve(&b_o);
        let same = relative_rmse(&balanced_b, &solve, None);
        assert!(
            same < 1e-5,
            "the balanced weights are the balanced solve's: {same}"
        );
    }
    let all = vec![true; n];
    println!("capped, all texels:");
    let capped_all = agreement(&grid, &maps, &capped_b, 3.0, &all);
    println!("balanced, all texels:");
    let balanced_all = agreement(&grid, &maps, &balanced_b, 3.0, &all);
    let (_, capped_away) = by_first_order_edges(&grid, &maps, &capped_b, "capped, ");
    let (_, balanced_away) = by_first_order_edges(&grid, &maps, &balanced_b, "balanced, ");
    println!(
        "{size}²: all texels capped {:.4} ({:.4} within 3σ), balanced {:.4} ({:.4}); away from \
         the first order's edges capped {:.4} ({:.4}), balanced {:.4} ({:.4}); the reference's \
         noise {:.4} / {:.4}",
        capped_all.rmse,
        capped_all.within,
        balanced_all.rmse,
        balanced_all.within,
        capped_away.rmse,
        capped_away.within,
        balanced_away.rmse,
        balanced_away.within,
        capped_all.noise,
        capped_away.noise
    );
    RowsFigures {
        capped_rows,
        balanced_rows,
        balanced_columns,
        capped_away,
        balanced_away,
        balanced_all,
        capped_all,
    }
}

/// The subsurface weights' row sums against the continuous surface (head at 64², subsurface
/// alone). Under a uniform irradiance texel `i` re-emits `Σ_j S_ij` in the transport and `Q̂_i`
/// (`Kernels::continuous_reemission`) in the continuous model the reference samples. The
/// weights are normalised per sender (columns capped at `Q̂_j`), so nothing holds the rows,
/// and they are off by a few percent: under lights from every side ([`dome_lights`]), away
/// from the first order's edges, that is most of the exact solve's distance to the
/// reference. The same weights balanced in rows and columns (`Kernels::balance_rounds`,
/// `ortm solve --balance-subsurface`) agree with the reference there to its noise:
/// `cargo test --release --test accuracy_reference
/// subsurface_rows -- --ignored --nocapture` (10 s on 2 cores; the 256² one, with the paper's
/// light as well, 2.6 minutes).
#[test]
#[ignore]
fn head_64_subsurface_rows_against_the_continuous_surface() {
    let f = subsurface_rows_at(64, 1024, dome_lights);
    // Measured (1,024 spp in 256 replicates of 4, seed 1; 2,558 of 3,782 texels away from
    // the edges): rows 0.0404 / columns 0.0168 capped, 0.0015 / 0.0000 balanced; all texels
    // capped 0.0467 (0.820 within 3σ), balanced 0.0366 (0.936); away from the edges capped
    // 0.0343 (0.862), balanced 0.0167 (0.979), noise 0.0152.
    assert!(f.capped_rows > 0.02, "capped rows {:.4}", f.capped_rows);
    assert!(f.balanced_rows < 0.005 && f.balanced_columns < 0.005);
    let away = (&f.capped_away, &f.balanced_away);
    assert!(
        away.0.rmse > 1.8 * away.0.noise,
        "capped {:.4}",
        away.0.rmse
    );
    assert!(
        away.1.rmse < 1.25 * away.1.noise,
        "balanced {:.4}",
        away.1.rmse
    );
    assert!(f.balanced_all.rmse < f.capped_all.rmse);
}

/// [`head_64_subsurface_rows_against_the_continuous_surface`] at 256², the face bakes' size,
/// under the dome and under the paper's Fig. 5 lamp (the scene's light): 512 paths per texel.
#[test]
#[ignore]
fn head_256_subsurface_rows_against_the_continuous_surface() {
    let dome = subsurface_rows_at(256, 512, dome_lights);
    let fig5 = subsurface_rows_at(256, 512, |s: &Scene| s.lights.clone());
    // Measured (512 spp in 128 replicates of 4, seed 1): rows 0.0252 capped (per channel
    // 0.021 / 0.026 / 0.029), 0.0006 balanced. Dome: all texels capped 0.0316 (0.923 within
    // 3σ), balanced 0.0247 (0.976), noise 0.0229; away from the edges (53,435 texels) 0.0299
    // → 0.0220, noise 0.0218. Fig. 5: all 0.0330 (0.951) → 0.0316 (0.965), noise 0.0260; away
    // (50,877) 0.0250 → 0.0229, noise 0.0227.
    for f in [&dome, &fig5] {
        assert!(f.capped_rows > 0.015, "capped rows {:.4}", f.capped_rows);
        assert!(f.balanced_all.rmse < f.capped_all.rmse);
        assert!(f.balanced_away.rmse < 1.1 * f.balanced_away.noise);
        assert!(f.balanced_all.within > f.capped_all.within);
    }
}

/// RMS over texels of `rows_i / q̂_i − 1` in channel `c`.
fn rms_in_channel(rows: &[[f64; 3]], q_hat: &[[f64; 3]], c: usize) -> f64 {
    let v: f64 = (rows.iter().zip(q_hat))
        .map(|(r, q)| (r[c] / q[c] - 1.0).powi(2))
        .sum();
    (v / rows.len() as f64).sqrt()
}

/// The rows of the weights as the subsurface near field uses them (`ortm solve --near-field
/// N`, reach 2: the senders within 2 texels replaced by their `N × N` sub-texels' raw weights,
/// the others the capped weights) against `Q̂`, beside the capped weights' rows, head at
/// `size`², per channel. Measured (`cargo test --release --test accuracy_reference
/// near_field_rows -- --ignored --nocapture`, 43 s for both): 64², N = 5,
/// capped 0.0381 / 0.0405 / 0.0425, the near field's 0.0430 / 0.0567 / 0.0694; 256², N = 3,
/// capped 0.0208 / 0.0257 / 0.0285, the near field's 0.0207 / 0.0238 / 0.0269. The near field
/// does not hold the rows either: balancing it would mean balancing these weights.
fn near_field_rows_at(size: u32, n_sub: u32) -> ([f64; 3], [f64; 3]) {
    use rayon::prelude::*;
    let (scene, grid) = head_at(size);
    let effects = Effects {
        radiosity: false,
        subsurface: true,
    };
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let kernels = Kernels::new(&scene, effects, vis);
    let mut patches = texel_patches(&grid);
    kernels.normalise_subsurface(&mut patches);
    let q_hat: Vec<[f64; 3]> = (patches.iter())
        .map(|p| kernels.continuous_reemission(p).expect("skin"))
        .collect();
    let fine = TexelGrid::build_with_size(&scene, grid.width * n_sub, grid.height * n_sub).unwrap();
    let fine_patches = texel_patches(&fine);
    let children = ortm::bake::near_field::sub_texels(&grid, &fine, n_sub);
    let support = kernels.support_m[0] as f32;
    let middle = (n_sub / 2) as i32;
    let rows: Vec<([f64; 3], [f64; 3])> = (0..patches.len())
        .into_par_iter()
        .map(|i| {
            let (a, ti) = (&patches[i], &grid.texels[i]);
            let centre = fine.at(
                ti.x as i32 * n_sub as i32 + middle,
                ti.y as i32 * n_sub as i32 + middle,
            );
            let (mut capped, mut near) = ([0.0f64; 3], [0.0f64; 3]);
            let mut window = Vec::new();
            for dy in -2..=2 {
                for dx in -2..=2 {
                    let Some(j) = grid.at(ti.x as i32 + dx, ti.y as i32 + dy) else {
                        continue;
                    };
                    window.push(j as usize);
                    for &s in &children[j as usize] {
                        let b = &fine_patches[s as usize];
                        if let Some(w) = kernels.subsurface_raw(a, b, Some(s) == centre) {
                            (0..3).for_each(|c| near[c] += w[c]);
                        }
                    }
                }
            }
            for (j, b) in patches.iter().enumerate() {
                if i != j && (a.position_m - b.position_m).length() > support {
                    continue;
                }
                if let Some(w) = kernels.subsurface(a, b, i == j) {
                    (0..3).for_each(|c| capped[c] += w[c]);
                    if !window.contains(&j) {
                        (0..3).for_each(|c| near[c] += w[c]);
                    }
                }
            }
            (capped, near)
        })
        .collect();
    let capped: Vec<[f64; 3]> = rows.iter().map(|r| r.0).collect();
    let near: Vec<[f64; 3]> = rows.iter().map(|r| r.1).collect();
    let per_channel = |r: &[[f64; 3]]| [0, 1, 2].map(|c| rms_in_channel(r, &q_hat, c));
    let (capped, near) = (per_channel(&capped), per_channel(&near));
    println!(
        "{size}², N = {n_sub}: rows against Q̂, RMS deviation per channel: capped \
         {capped:.4?}, the near field's {near:.4?}"
    );
    (capped, near)
}

/// [`near_field_rows_at`] at 64² (N = 5) and 256² (N = 3): the near field's rows are off
/// `Q̂` at least as far as the texels' own (within 10 % of them, or further).
#[test]
#[ignore]
fn head_near_field_rows_against_the_continuous_surface() {
    for (size, n_sub) in [(64, 5), (256, 3)] {
        let (capped, near) = near_field_rows_at(size, n_sub);
        for c in 0..3 {
            assert!(capped[c] > 0.015, "{size}²: capped {capped:?}");
            assert!(
                near[c] > 0.9 * capped[c],
                "{size}²: {near:?} against {capped:?}"
            );
        }
    }
}
