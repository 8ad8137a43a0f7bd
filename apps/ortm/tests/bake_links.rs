//! The bake's cell integration with the hierarchical first bounce (`ortm bake --tolerance ε`,
//! `ortm::bake::cells`, "With the hierarchical operator") against the exact dense solve.
//!
//! With every integer offset selected each cell is one offset, so the maps hold `R(t, t + Δt)`
//! itself; with single-texel clusters the higher-order remainder is exact, so what is left is
//! the first bounce from the links. Its error must fall as `ε` falls, towards the exact solve.

mod common;

use glam::Vec3;
use ortm::accuracy::compare::{interior_mask, relative_rmse};
use ortm::bake::eval::random_light_setups;
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, SetupProgress, Transport, hier, texel_patches};
use ortm::bake::{self, CellRule};
use ortm::maps;
use ortm::scene::{Light, Scene};

/// Relative RMSE (interior texels) of the indirect term of all-offset maps baked with the
/// hierarchical first bounce at each of `tolerances`, against the exact solve for `lights`.
fn all_offset_errors(scene: &Scene, lights: &[Light], tolerances: &[f32]) -> Vec<f64> {
    let grid = TexelGrid::build(scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, lights, &vis);
    let offsets = common::all_offsets(grid.width, grid.height);
    let mask = interior_mask(&grid);
    let mut exact_ind = None;
    tolerances
        .iter()
        .map(|&tolerance| {
            let settings = hier::Settings {
                tolerance,
                ..hier::Settings::default()
            };
            let tr = Transport::build_hierarchical(
                scene,
                &grid,
                Effects::default(),
                1,
                &settings,
                &SetupProgress::none(),
            )
            .unwrap();
            let exact_ind: &Vec<Vec3> = exact_ind.get_or_insert_with(|| {
                let dense = DenseTransport::new(&texel_patches(&grid), &tr.kernels);
                let exact = dense.solve(&b_o);
                exact.iter().zip(&b_o).map(|(b, o)| *b - *o).collect()
            });
            let maps =
                bake::bake_maps(&tr, &grid, &offsets, CellRule::Integrated, &|_| {}).unwrap();
            let out = maps::apply(&maps, &lighting::to_lightmap(&grid, &b_o)).unwrap();
            let got = lighting::from_lightmap(&grid, &out);
            let ind: Vec<Vec3> = got.iter().zip(&b_o).map(|(b, o)| *b - *o).collect();
            let err = relative_rmse(&ind, exact_ind, Some(&mask));
            eprintln!(
                "{} {}² ({} texels), all offsets, links at ε = {tolerance:e} ({} links): indirect \
                 relative RMSE {err:.4}",
                scene.name,
                grid.width,
                grid.texels.len(),
                tr.links.as_ref().unwrap().link_count()
            );
            err
        })
        .collect()
}

/// Asserts that the errors `e` fall as ε falls and that each is below its bound.
fn check_falls(name: &str, e: &[f64], bounds: &[f64]) {
    for w in e.windows(2) {
        assert!(w[1] < w[0], "{name}: {e:?} does not fall with ε");
    }
    for (x, b) in e.iter().zip(bounds) {
        assert!(x < b, "{name}: errors {e:?}, bounds {bounds:?}");
    }
}

const TOLERANCES: [f32; 3] = [1e-2, 1e-3, 1e-4];

/// Cornell 32², the box's light. Measured: 0.0729 (15.5 k links), 0.0142 (49.6 k), 0.00090
/// (77.9 k). Bounds: measured + 25 % (+ 33 % at 10⁻⁴). Counting only the receivers' own links
/// (not their ancestors') gives 0.39 / 0.107 / 0.0012.
#[test]
fn cornell_all_offsets_converge_to_the_exact_solve_as_the_tolerance_falls() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let lights = scene.lights.clone();
    let e = all_offset_errors(&scene, &lights, &TOLERANCES);
    check_falls("cornell 32²", &e, &[0.0911, 0.0178, 0.0012]);
}

/// The head at 48², radiosity and subsurface, a random light. Measured: 0.0424 (21.3 k links),
/// 0.0174 (42.9 k), 0.0060 (127 k); 0.0359 / 0.0139 / 0.0043 with each texel's area its
/// covering triangle's Jacobian instead of its average over the texel's square. Bounds:
/// measured + 25 %.
#[test]
fn head_all_offsets_converge_to_the_exact_solve_as_the_tolerance_falls() {
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (48, 48);
    let lights = random_light_setups(&scene, 1, 7).remove(0);
    let e = all_offset_errors(&scene, &lights, &TOLERANCES);
    check_falls("head 48²", &e, &[0.053, 0.0218, 0.0075]);
}

/// The 64² figures (evaluator vs exact, indirect, all offsets; ~800 MB of cell values
/// per scene, so not in the default run: `cargo test --release --test bake_links -- --ignored
/// --nocapture`, 4 min). Measured at ε = 10⁻³ / 3·10⁻⁴ / 10⁻⁴: Cornell 0.0440 / 0.0231 /
/// 0.0090, maze 0.0121 / 0.0051 / 0.0021, head (radiosity + subsurface, a random light)
/// 0.0195 / 0.0089 / 0.0053. Bounds: measured + 25 %.
#[test]
#[ignore = "~800 MB of cell values per scene; run with --ignored"]
fn all_offsets_at_64_fall_below_two_percent() {
    let t = [1e-3f32, 3e-4, 1e-4];
    let scene = ortm::scene::cornell::cornell_box(64);
    let l = scene.lights.clone();
    check_falls(
        "cornell 64²",
        &all_offset_errors(&scene, &l, &t),
        &[0.055, 0.0289, 0.0113],
    );
    let scene = ortm::scene::maze::maze(64);
    let l = scene.lights.clone();
    check_falls(
        "maze 64²",
        &all_offset_errors(&scene, &l, &t),
        &[0.0151, 0.0064, 0.0027],
    );
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (64, 64);
    let l = random_light_setups(&scene, 1, 7).remove(0);
    check_falls(
        "head 64²",
        &all_offset_errors(&scene, &l, &t),
        &[0.0244, 0.0111, 0.0066],
    );
}

/// `ortm bake --tolerance ε`: bakes with the links and automatic clusters (recorded in the
/// index), refuses a tolerance that is not positive, and stops with an error naming
/// `--tolerance` (and writes no index) when the links do not fit what the memory limit leaves.
#[test]
fn bake_tolerance_option_bakes_refuses_and_names_itself_when_memory_runs_out() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str], limit: Option<u64>| {
        let mut c = common::ortm_command();
        c.args(args).current_dir(dir.path());
        if let Some(l) = limit {
            c.env("ORTM_MEMORY_LIMIT_BYTES", l.to_string());
        }
        c.output().unwrap()
    };
    let args = |o: &'static str, t: &'static str| {
        [
            "bake",
            "maze",
            "--size",
            "48",
            "--offsets",
            "20",
            "--tolerance",
            t,
            "-o",
            o,
        ]
    };
    let out = run(&args("b", "1e-3"), None);
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{err}");
    assert!(
        err.contains("hierarchical first bounce at tolerance 1e-3"),
        "{err}"
    );
    let index: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("b/index.json")).unwrap()).unwrap();
    let settings = &index["settings"];
    assert_eq!(
        settings["tolerance"].as_f64().map(|t| t as f32),
        Some(1e-3),
        "{settings}"
    );
    assert_eq!(settings["coarse_block"], 0, "{settings}");
    let e = common::fails(run(&args("z", "0"), None));
    assert!(e.contains("--tolerance 0: give a positive number"), "{e}");
    // What the rest of this bake plans (single-texel clusters: 48² maze has < 4,096 texels),
    // plus 64 kB: far less than its links at 10⁻⁴.
    let grid = TexelGrid::build(&ortm::scene::maze::maze(48)).unwrap();
    let n = grid.texels.len() as u64;
    let rest = ortm::io::limits::bake_memory_bytes(n, n, n * 20);
    let e = common::fails(run(&args("m", "1e-4"), Some(rest + 65_536)));
    assert!(
        e.contains("the hierarchical operator needs more than 65536 bytes")
            && e.contains("--tolerance 1e-4"),
        "{e}"
    );
    assert!(!dir.path().join("m/index.json").exists());
}

/// Bakes the maze at 1024² with `args` after `--size 1024` into `DIR/b` under
/// `ORTM_MEMORY_LIMIT_BYTES` = 4 GiB; asserts success and a peak resident memory (`VmHWM`,
/// reported by the test hook `ORTM_TEST_REPORT_PEAK`) under the limit; returns the bake's
/// index, its peak (bytes) and wall time (s).
fn maze_1024_under_four_gib(dir: &std::path::Path, args: &[&str]) -> (serde_json::Value, u64, f64) {
    let limit: u64 = 4 << 30;
    let t0 = std::time::Instant::now();
    let out = common::ortm_command()
        .args(["bake", "maze", "--size", "1024"])
        .args(args)
        .args(["-o", "b"])
        .current_dir(dir)
        .env("ORTM_MEMORY_LIMIT_BYTES", limit.to_string())
        .env("ORTM_TEST_REPORT_PEAK", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert!(out.status.success(), "{err}");
    let peak = common::reported_peak(&err);
    assert!(peak < limit, "peak {peak} bytes over the 4 GiB limit");
    let index = serde_json::from_slice(&std::fs::read(dir.join("b/index.json")).unwrap()).unwrap();
    (index, peak, t0.elapsed().as_secs_f64())
}

/// Issue 16's memory bound: the maze at 1024² (844,546 covered texels) bakes with
/// `--tolerance 1e-3` under `ORTM_MEMORY_LIMIT_BYTES` = 4 GiB, and its peak resident memory
/// stays under it. 16 maps keep the cell values (12 bytes per covered texel and map) and the
/// run short (~1–2 min on 2 cores; measured peak 1.13 GB). The ignored test below bakes the
/// default tolerance with 100 maps.
#[test]
fn maze_1024_bakes_under_four_gib() {
    let dir = tempfile::tempdir().unwrap();
    let (index, peak, _) =
        maze_1024_under_four_gib(dir.path(), &["--offsets", "16", "--tolerance", "1e-3"]);
    println!("maze 1024², 16 maps, ε = 1e-3: peak {peak} bytes");
    assert_eq!(index["maps"].as_array().map(Vec::len), Some(16), "{index}");
    assert_eq!(index["lightmap"]["width"], 1024, "{}", index["lightmap"]);
}

/// Issue 16's scale goal at the default tolerance: the maze at 1024², 100 maps, `--tolerance`
/// (ε = 10⁻⁴) under `ORTM_MEMORY_LIMIT_BYTES` = 4 GiB, peak under it (~4.5 min on 2 cores, so
/// not in CI; measured peak 3.79 GB = 3.53 GiB, 258–262 s). Run with `cargo test --release --test
/// bake_links maze_1024_default -- --ignored --nocapture`.
#[test]
#[ignore = "4.5 minutes on 2 cores"]
fn maze_1024_default_tolerance_100_maps_under_four_gib() {
    let dir = tempfile::tempdir().unwrap();
    let (index, peak, seconds) =
        maze_1024_under_four_gib(dir.path(), &["--offsets", "100", "--tolerance"]);
    println!("maze 1024², 100 maps, default ε: peak {peak} bytes, {seconds:.1} s");
    assert_eq!(index["maps"].as_array().map(Vec::len), Some(100), "{index}");
}
