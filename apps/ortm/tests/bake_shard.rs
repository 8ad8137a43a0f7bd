//! The sharded bake (`ortm bake --plan --shards N`, `--shard I/N`, `--merge`;
//! `ortm::bake::shard`), every step a separate `ortm` process as a scheduler would run it:
//! the merged directory is byte-identical to a single-process bake with the same settings
//! (every file: maps, index, selection, report) for N = 1, 2, 3, 5, for offset maps with and
//! without the hierarchical transport and for multi-resolution maps; a shard killed with
//! `kill -9` and rerun gives the same bytes; the merge refuses a missing shard or a damaged
//! chunk, naming the shard; the shard index comes from Slurm's or Kubernetes' variables.

mod common;

use std::path::Path;
use std::process::Stdio;

use common::{dir_files, fails, ok, ortm, ortm_command};

/// `ortm bake <bake> -o <out>` in `cwd` (one process).
fn single(cwd: &Path, bake: &str, out: &str) {
    let mut args: Vec<&str> = vec!["bake"];
    args.extend(bake.split(' '));
    args.extend(["-o", out]);
    ok(ortm(&args, cwd));
}

/// One step of a sharded bake: `ortm bake <bake> -o <out> <step...>`.
fn step(cwd: &Path, bake: &str, out: &str, step: &[&str]) -> std::process::Output {
    let mut args: Vec<&str> = vec!["bake"];
    args.extend(bake.split(' '));
    args.extend(["-o", out]);
    args.extend(step);
    ortm(&args, cwd)
}

/// Plan, every shard (in reverse order, to show the order does not matter), merge.
fn sharded(cwd: &Path, bake: &str, out: &str, n: u32) -> String {
    let mut log = ok(step(
        cwd,
        bake,
        out,
        &["--plan", "--shards", &n.to_string()],
    ));
    for i in (0..n).rev() {
        log += &ok(step(cwd, bake, out, &["--shard", &format!("{i}/{n}")]));
    }
    log + &ok(ortm(&["bake", out, "--merge"], cwd))
}

fn assert_same_files(a: &Path, b: &Path, what: &str) {
    let (fa, fb) = (dir_files(a), dir_files(b));
    let names = |f: &[(String, Vec<u8>)]| f.iter().map(|(n, _)| n.clone()).collect::<Vec<_>>();
    assert_eq!(names(&fa), names(&fb), "{what}: file lists differ");
    for ((name, x), (_, y)) in fa.iter().zip(&fb) {
        assert!(x == y, "{what}: {name} differs");
    }
    assert!(
        fa.iter().any(|(n, _)| n == "index.json"),
        "{what}: no index"
    );
}

#[test]
fn sharded_bakes_are_byte_identical_to_one_process() {
    let tmp = tempfile::tempdir().unwrap();
    let cwd = tmp.path();
    let cases: [(&str, &[u32]); 6] = [
        // Offset maps, integrated cells over the coarse clusters.
        ("maze --size 128 --offsets 40", &[1, 2, 3, 5]),
        // The hierarchical transport: its links travel in transport.bin.
        ("maze --size 96 --offsets 30 --tolerance 1e-3", &[2, 3]),
        // The head (../shared): the subsurface term, its kept near weights and, with
        // --tolerance, the subsurface walk.
        ("head --size 64 --offsets 30", &[2]),
        ("head --size 96 --offsets 30 --tolerance 1e-3", &[3]),
        // Multi-resolution maps with receiver blocks: rows by receiver (from the pair
        // evaluator on 8×8 clusters; the hierarchical rows are the last case's).
        (
            "cornell --size 48 --levels 1e-2 --coarse-block 8 --receiver-blocks on",
            &[3, 5],
        ),
        // With the gathered near field: each shard gathers its own receivers' rows.
        (
            "head --size 48 --effects radiosity --levels 1e-2 --tolerance 1e-3 --near-gather 4",
            &[3],
        ),
    ];
    for (c, (bake, counts)) in cases.iter().enumerate() {
        let reference = format!("ref{c}");
        single(cwd, bake, &reference);
        for &n in *counts {
            let out = format!("sharded{c}_{n}");
            let log = sharded(cwd, bake, &out, n);
            assert!(log.contains(&format!("merged {n} shards")), "{log}");
            assert_same_files(
                &cwd.join(&reference),
                &cwd.join(&out),
                &format!("{bake}, N = {n}"),
            );
        }
    }
}

#[test]
fn a_killed_shard_rerun_gives_the_same_bytes() {
    let tmp = tempfile::tempdir().unwrap();
    let cwd = tmp.path();
    // Big enough that a shard takes a while, small enough for CI.
    let bake = "maze --size 256 --offsets 60";
    single(cwd, bake, "ref");
    ok(step(cwd, bake, "out", &["--plan", "--shards", "2"]));
    let folder = cwd.join("out/shard_0_of_2");
    let mut args: Vec<&str> = vec!["bake"];
    args.extend(bake.split(' '));
    args.extend(["-o", "out", "--shard", "0/2"]);
    let mut child = ortm_command()
        .args(&args)
        .current_dir(cwd)
        .stdout(Stdio::null())
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Kill it as soon as its first chunk is on disk (or give up waiting after a minute).
    let t0 = std::time::Instant::now();
    while !folder.join("chunk_00000.bin").exists() && t0.elapsed().as_secs() < 60 {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let killed = kill_9(child.id());
    let status = child.wait().unwrap();
    assert!(
        killed && !status.success(),
        "the shard was not killed: {status}"
    );
    assert!(
        !folder.join("done.json").exists(),
        "the shard finished before it was killed; nothing was tested"
    );
    // The merge refuses the unfinished shard by name.
    ok(step(cwd, bake, "out", &["--shard", "1/2"]));
    let e = fails(ortm(&["bake", "out", "--merge"], cwd));
    assert!(e.contains("shard 0/2 has not finished"), "{e}");
    // The scheduler reruns it: it keeps its finished chunks.
    let log = ok(step(cwd, bake, "out", &["--shard", "0/2"]));
    let kept: usize = log
        .split(" chunks written, ")
        .nth(1)
        .and_then(|s| s.split(' ').next())
        .and_then(|s| s.parse().ok())
        .unwrap_or_else(|| panic!("{log}"));
    assert!(kept >= 1, "no chunk kept: {log}");
    // Rerunning a finished shard does nothing.
    let again = ok(step(cwd, bake, "out", &["--shard", "0/2"]));
    assert!(again.contains("already finished"), "{again}");
    ok(ortm(&["bake", "out", "--merge"], cwd));
    assert_same_files(
        &cwd.join("ref"),
        &cwd.join("out"),
        "after kill -9 and rerun",
    );
}

/// `kill -9 pid` through the `kill` command (no `unsafe` libc call in tests).
fn kill_9(pid: u32) -> bool {
    std::process::Command::new("kill")
        .args(["-9", &pid.to_string()])
        .status()
        .is_ok_and(|s| s.success())
}

#[test]
fn the_merge_refuses_missing_shards_and_damaged_chunks_naming_the_shard() {
    let tmp = tempfile::tempdir().unwrap();
    let cwd = tmp.path();
    let bake = "cornell --size 32 --offsets 12";
    // An earlier plan for 2 shards, one of them run: planning again for 3 replaces it, and
    // the merge removes its folder too.
    ok(step(cwd, bake, "out", &["--plan", "--shards", "2"]));
    ok(step(cwd, bake, "out", &["--shard", "0/2"]));
    let log = ok(step(cwd, bake, "out", &["--plan", "--shards", "3"]));
    assert!(!log.contains("kept the existing plan"), "{log}");
    ok(step(cwd, bake, "out", &["--shard", "0/3"]));
    ok(step(cwd, bake, "out", &["--shard", "1/3"]));
    let e = fails(ortm(&["bake", "out", "--merge"], cwd));
    assert!(e.contains("shard 2/3 has not finished"), "{e}");
    assert!(e.contains("--shard 2/3"), "the fix is named: {e}");
    ok(step(cwd, bake, "out", &["--shard", "2/3"]));
    // One bit of one chunk of shard 1 flipped.
    let chunk = cwd.join("out/shard_1_of_3/chunk_00000.bin");
    let mut bytes = std::fs::read(&chunk).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 0x10;
    std::fs::write(&chunk, &bytes).unwrap();
    let e = fails(ortm(&["bake", "out", "--merge"], cwd));
    assert!(e.contains("shard 1/3") && e.contains("SHA-256"), "{e}");
    assert!(
        !cwd.join("out/index.json").exists(),
        "no index after a refusal"
    );
    // The damaged chunk is not kept by a rerun of its shard; then the merge succeeds.
    bytes[mid] ^= 0x10;
    bytes[mid + 1] ^= 0x01;
    std::fs::write(&chunk, &bytes).unwrap();
    std::fs::remove_file(cwd.join("out/shard_1_of_3/done.json")).unwrap();
    let log = ok(step(cwd, bake, "out", &["--shard", "1/3"]));
    assert!(log.contains("1 chunks written"), "{log}");
    ok(ortm(&["bake", "out", "--merge"], cwd));
    single(cwd, bake, "ref");
    assert_same_files(&cwd.join("ref"), &cwd.join("out"), "after a repaired chunk");
    // A finished merge leaves only the single-process bake's files: a new merge finds no plan.
    let e = fails(ortm(&["bake", "out", "--merge"], cwd));
    assert!(e.contains("plan.json is missing"), "{e}");
}

#[test]
fn shards_refuse_other_settings_and_take_their_index_from_the_scheduler() {
    let tmp = tempfile::tempdir().unwrap();
    let cwd = tmp.path();
    let bake = "cornell --size 32 --offsets 12";
    let e = fails(step(cwd, bake, "out", &["--shard", "0/2"]));
    assert!(
        e.contains("--plan --shards N") && e.contains("first"),
        "{e}"
    );
    ok(step(cwd, bake, "out", &["--plan", "--shards", "2"]));
    let e = fails(step(
        cwd,
        "cornell --size 32 --offsets 13",
        "out",
        &["--shard", "0/2"],
    ));
    assert!(
        e.contains("same options") || e.contains("exactly the scene and options"),
        "{e}"
    );
    let e = fails(step(cwd, bake, "out", &["--shard", "0/3"]));
    assert!(e.contains("for 2 shards"), "{e}");
    let e = fails(step(cwd, bake, "out", &["--shard", "2/2"]));
    assert!(
        e.contains("0 ≤ I < N") || e.contains("indices run from 0"),
        "{e}"
    );
    let e = fails(step(cwd, bake, "out", &["--shard"]));
    assert!(
        e.contains("SLURM_ARRAY_TASK_ID") && e.contains("JOB_COMPLETION_INDEX"),
        "{e}"
    );
    let mut args: Vec<&str> = vec!["bake"];
    args.extend(bake.split(' '));
    args.extend(["-o", "out", "--shard"]);
    // A Slurm array task resubmitted alone (`sbatch --array=1`, a one-task array): the task id
    // is the shard index, the count the plan's.
    let out = ortm_command()
        .args(&args)
        .current_dir(cwd)
        .env("SLURM_ARRAY_TASK_ID", "1")
        .env("SLURM_ARRAY_TASK_MIN", "1")
        .env("SLURM_ARRAY_TASK_COUNT", "1")
        .output()
        .unwrap();
    assert!(ok(out).contains("shard 1/2:"));
    // A Kubernetes Indexed Job pod: the count from the plan.
    let out = ortm_command()
        .args(&args)
        .current_dir(cwd)
        .env_remove("SLURM_ARRAY_TASK_ID")
        .env("JOB_COMPLETION_INDEX", "0")
        .output()
        .unwrap();
    assert!(ok(out).contains("shard 0/2:"));
    ok(ortm(&["bake", "out", "--merge"], cwd));
    single(cwd, bake, "ref");
    assert_same_files(&cwd.join("ref"), &cwd.join("out"), "scheduler indices");
}
