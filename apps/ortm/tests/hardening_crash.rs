//! Crash safety of `ortm bake` and `ortm bin` (issue 8): the real binary is killed with SIGKILL
//! at several moments — after a given number of maps appeared, and at pseudo-random delays
//! within the length of an uninterrupted run — and rerun. After every kill no reader accepts a
//! half-written file (every map file with a final name decodes, the index is absent or
//! complete, the atlas set is absent or complete), and after the final rerun every output file
//! is byte-identical to an uninterrupted run with the same seed.

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::time::{Duration, Instant};

use common::{dir_files, ortm_command};

const BAKE_ARGS: [&str; 10] = [
    "bake",
    "cornell",
    "--size",
    "32",
    "--offsets",
    "12",
    "--seed",
    "7",
    "--iterations",
    "100",
];

fn bake_cmd(dir: &Path) -> Command {
    let mut c = ortm_command();
    c.args(BAKE_ARGS)
        .arg("-o")
        .arg(dir)
        .env("RAYON_NUM_THREADS", "2")
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

fn bin_cmd(dir: &Path) -> Command {
    let mut c = ortm_command();
    c.arg("bin")
        .arg(dir)
        .args(["--atlas", "64"])
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

fn run_ok(mut c: Command) {
    let out = c.output().expect("run ortm");
    assert!(
        out.status.success(),
        "ortm failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
}

fn map_files(dir: &Path) -> Vec<PathBuf> {
    fs::read_dir(dir)
        .map(|r| {
            r.map(|e| e.unwrap().path())
                .filter(|p| {
                    let n = p.file_name().unwrap().to_string_lossy();
                    n.starts_with("map_") && n.ends_with(".exr")
                })
                .collect()
        })
        .unwrap_or_default()
}

/// Kills `child` with SIGKILL once `ready()` holds or `deadline` passes (whichever is first);
/// returns whether it was still running when killed.
fn kill_when(mut child: Child, deadline: Duration, ready: &dyn Fn() -> bool) -> bool {
    let t0 = Instant::now();
    loop {
        if let Some(_status) = child.try_wait().unwrap() {
            return false;
        }
        if ready() || t0.elapsed() >= deadline {
            // std's Child::kill sends SIGKILL on Unix.
            let _ = child.kill();
            let _ = child.wait();
            return true;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// What a reader sees in a bake directory after a kill: every final-named map file decodes
/// and the index is either absent or fully loadable.
fn check_bake_readers(dir: &Path) {
    for p in map_files(dir) {
        ortm::bake_dir::read_map_file(&p, Some((32, 32)))
            .unwrap_or_else(|e| panic!("half-written map file accepted as final: {e}"));
    }
    if dir.join("index.json").exists() {
        let index = ortm::bake_dir::BakeIndex::read(dir).expect("index readable");
        index.load_maps(dir).expect("maps of a written index load");
    }
}

/// What a reader sees in an atlas directory after a kill: no atlas index, or a complete set.
fn check_atlas_readers(dir: &Path) {
    match ortm::atlas::read_atlas_set(dir) {
        Ok(_) => {}
        Err(ortm::atlas::AtlasError::MissingIndex { .. }) => {}
        Err(e) => panic!("an interrupted `ortm bin` left a directory that reads as {e}"),
    }
}

/// Small deterministic pseudo-random numbers (SplitMix64) for the kill moments.
fn splitmix(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9e37_79b9_7f4a_7c15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^ (z >> 31)
}

/// One scenario: the uninterrupted run's timing and files set the kill moments and the expected
/// bytes of every killed run after it.
#[test]
fn killed_bake_and_bin_resume_to_byte_identical_output() {
    // Uninterrupted reference run (bake, then bin), timed.
    let reference = tempfile::tempdir().unwrap();
    let t0 = Instant::now();
    run_ok(bake_cmd(reference.path()));
    let bake_time = t0.elapsed();
    let t1 = Instant::now();
    run_ok(bin_cmd(reference.path()));
    let bin_time = t1.elapsed();
    let expected = dir_files(reference.path());
    assert!(expected.iter().any(|(n, _)| n == "atlases.json"));
    let expected_bake: Vec<_> = expected
        .iter()
        .filter(|(n, _)| !n.starts_with("atlas"))
        .cloned()
        .collect();

    // Bake: killed after 1, 4 and 9 maps appeared (successive resumes of one directory), then
    // at pseudo-random moments of fresh runs; each directory is then completed by a rerun.
    let dir = tempfile::tempdir().unwrap();
    let mut killed = 0;
    for n in [1usize, 4, 9] {
        let child = bake_cmd(dir.path()).spawn().unwrap();
        let d = dir.path().to_owned();
        killed += usize::from(kill_when(child, bake_time * 4, &|| {
            map_files(&d).len() >= n
        }));
        eprintln!(
            "bake killed after {n} maps: {} map files on disk",
            map_files(dir.path()).len()
        );
        check_bake_readers(dir.path());
    }
    run_ok(bake_cmd(dir.path()));
    assert_eq!(dir_files(dir.path()), expected_bake, "resumed bake differs");
    assert!(
        killed >= 2,
        "only {killed} of 3 bake runs were still running when killed"
    );

    let mut rng = 0x0f0e_0d0c_u64;
    for _ in 0..3 {
        let dir = tempfile::tempdir().unwrap();
        let at = bake_time.mul_f64((splitmix(&mut rng) % 1000) as f64 / 1000.0);
        let child = bake_cmd(dir.path()).spawn().unwrap();
        let was_running = kill_when(child, at, &|| false);
        eprintln!(
            "bake killed at {at:?} of {bake_time:?} (running: {was_running}): {} map files, \
             selection {}",
            map_files(dir.path()).len(),
            dir.path().join("selection.json").exists()
        );
        check_bake_readers(dir.path());
        run_ok(bake_cmd(dir.path()));
        assert_eq!(
            dir_files(dir.path()),
            expected_bake,
            "bake killed at {at:?} differs"
        );
    }

    // Bin: killed at pseudo-random moments of its run over a complete bake, then rerun.
    for _ in 0..4 {
        let dir = tempfile::tempdir().unwrap();
        for (name, bytes) in &expected_bake {
            fs::write(dir.path().join(name), bytes).unwrap();
        }
        let at = bin_time.mul_f64((splitmix(&mut rng) % 1000) as f64 / 1000.0);
        let child = bin_cmd(dir.path()).spawn().unwrap();
        let was_running = kill_when(child, at, &|| false);
        eprintln!(
            "bin killed at {at:?} of {bin_time:?} (running: {was_running}): atlas {}, index {}",
            dir.path().join("atlas_000.exr").exists(),
            dir.path().join("atlases.json").exists()
        );
        check_atlas_readers(dir.path());
        run_ok(bin_cmd(dir.path()));
        assert_eq!(
            dir_files(dir.path()),
            expected,
            "bin killed at {at:?} differs"
        );
    }
}
