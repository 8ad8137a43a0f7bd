//! Crash safety of `ortm bake` and `ortm bin` (issue 8): the real binary is killed with SIGKILL
//! in the middle of each of its file writes in turn and rerun. The contract
//! (docs/bake-format.md, "Writing and resuming a bake"; docs/atlas-format.md) is that every file
//! is written to a temporary name, synced and renamed, and that the index (`index.json`,
//! `atlases.json`) is written after the files it lists. So after every kill no reader accepts a
//! half-written file (every map file with a final name decodes, the index is absent, the atlas
//! set is absent or complete), and after a rerun every output file is byte-identical to an
//! uninterrupted run with the same seed, with no temporary file left.
//!
//! Where the kills land: a write of these small files takes well under a millisecond of the
//! run, so kills at timed moments would almost never interrupt one, and no timing makes them
//! do so reliably on a loaded machine. The binary's crash-test hook does:
//! `ORTM_TEST_STOP_IN_WRITE=N` makes its `N`-th atomic write stop after half of the bytes reached
//! the temporary file and announce it on stderr (`ortm::io::write_atomic`,
//! docs/bake-format.md, "Crash tests"); the test kills the process at that moment. Each kill is
//! proven to have interrupted a write: at kill time the announced temporary file holds exactly
//! the first half of the bytes that the uninterrupted run wrote under the final name, and the
//! final name does not exist yet. Nothing depends on timing.

mod common;

use std::fs;
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Instant;

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

/// The crash-test hook's environment variable and the start of its stderr line
/// (`crates/ortm/src/io/atomic.rs`).
const STOP_VAR: &str = "ORTM_TEST_STOP_IN_WRITE";
const STOP_LINE: &str = "ORTM_TEST_STOP_IN_WRITE: stopped in write ";

fn bake_cmd(dir: &Path) -> Command {
    let mut c = ortm_command();
    c.args(BAKE_ARGS)
        .arg("-o")
        .arg(dir)
        .env("RAYON_NUM_THREADS", "2")
        .env_remove(STOP_VAR)
        .stdout(Stdio::null())
        .stderr(Stdio::piped());
    c
}

fn bin_cmd(dir: &Path) -> Command {
    let mut c = ortm_command();
    c.arg("bin")
        .arg(dir)
        .args(["--atlas", "64"])
        .env("RAYON_NUM_THREADS", "2")
        .env_remove(STOP_VAR)
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

/// The final name a temporary file of `write_atomic` stands for (`.<name>.<pid>-<n>.tmp`).
fn final_name(tmp: &Path) -> String {
    let n = tmp.file_name().unwrap().to_str().unwrap();
    let inner = n
        .strip_prefix('.')
        .and_then(|n| n.strip_suffix(".tmp"))
        .unwrap_or_else(|| panic!("{n} is not a temporary name"));
    let (name, _pid_n) = inner.rsplit_once('.').unwrap();
    name.to_owned()
}

/// Runs `cmd` with the hook stopping its `n`-th write, SIGKILLs it there and returns the final
/// name of the file whose write was interrupted. Asserts that the kill interrupted that write:
/// when the process was killed, the temporary file held exactly the first half of the bytes
/// `expected` has under the final name, and the final name did not exist (or, with
/// `replacing`, held the complete file of an earlier run).
fn kill_in_write(
    mut cmd: Command,
    n: usize,
    dir: &Path,
    expected: &[(String, Vec<u8>)],
    replacing: bool,
) -> String {
    let mut child = cmd.env(STOP_VAR, n.to_string()).spawn().unwrap();
    let mut stderr = BufReader::new(child.stderr.take().unwrap());
    let mut seen = String::new();
    let tmp = loop {
        let mut line = String::new();
        if stderr.read_line(&mut line).unwrap() == 0 {
            let status = child.wait().unwrap();
            panic!("the run ended ({status}) before its write {n}; stderr:\n{seen}");
        }
        if let Some(i) = line.find(STOP_LINE) {
            let rest = line[i + STOP_LINE.len()..].trim_end();
            let (k, path) = rest.split_once(": ").expect("hook line: N: PATH");
            assert_eq!(k, n.to_string(), "stopped in the wrong write");
            break PathBuf::from(path);
        }
        seen.push_str(&line);
    };
    // The process is now inside write `n`, between its half write and the rest; the temporary
    // file cannot change until the kill (the other worker thread writes other files).
    let name = final_name(&tmp);
    assert_eq!(tmp.parent(), Some(dir), "temporary file outside {dir:?}");
    let at_kill = fs::read(&tmp).unwrap_or_else(|e| panic!("{tmp:?} at the kill: {e}"));
    let final_before = fs::read(dir.join(&name)).ok();
    // std's Child::kill sends SIGKILL on Unix.
    child.kill().unwrap();
    let status = child.wait().unwrap();
    assert!(
        status.code().is_none(),
        "write {n} ({name}): the process was not ended by the signal: {status}"
    );
    let full = &expected
        .iter()
        .find(|(f, _)| *f == name)
        .unwrap_or_else(|| panic!("write {n} is of {name}, not a file of the uninterrupted run"))
        .1;
    assert_eq!(
        at_kill,
        full[..full.len() / 2],
        "write {n} ({name}): the temporary file is not the first half of the final file"
    );
    match final_before {
        None => {}
        Some(b) if replacing && b == *full => {}
        Some(_) => panic!("write {n} ({name}): the final name existed (replacing: {replacing})"),
    }
    // After the kill the interrupted write is still visible as its temporary file.
    assert!(tmp.is_file(), "write {n} ({name}): temporary file gone");
    name
}

/// What a reader sees in a bake directory after a kill: every final-named map file decodes,
/// and `index.json`, written last, is absent (every kill here is inside a write, so before the
/// index's rename).
fn check_bake_readers(dir: &Path) {
    for p in map_files(dir) {
        ortm::bake_dir::read_map_file(&p, Some((32, 32)))
            .unwrap_or_else(|e| panic!("half-written map file accepted as final: {e}"));
    }
    assert!(
        !dir.join("index.json").exists(),
        "index.json exists after a kill inside a write"
    );
    assert!(
        ortm::bake_dir::BakeIndex::read(dir).is_err(),
        "a killed bake reads as complete"
    );
}

/// What a reader sees in an atlas directory after a kill: no atlas index, or (once
/// `atlases.json` has been renamed into place) a complete set.
fn check_atlas_readers(dir: &Path, index_written: bool) {
    match ortm::atlas::read_atlas_set(dir) {
        Ok(_) if index_written => {}
        Err(ortm::atlas::AtlasError::MissingIndex { .. }) if !index_written => {}
        Ok(_) => panic!("an atlas set reads as complete before atlases.json was written"),
        Err(e) => panic!("an interrupted `ortm bin` left a directory that reads as {e}"),
    }
}

/// Whether a file name is a temporary file of an interrupted write.
fn is_temp(name: &str) -> bool {
    ortm::io::is_temp_name(name)
}

#[test]
fn killed_bake_and_bin_resume_to_byte_identical_output() {
    // Uninterrupted reference run (bake, then bin).
    let t0 = Instant::now();
    let reference = tempfile::tempdir().unwrap();
    run_ok(bake_cmd(reference.path()));
    let expected_bake = dir_files(reference.path());
    run_ok(bin_cmd(reference.path()));
    let expected = dir_files(reference.path());
    assert!(!expected.iter().any(|(n, _)| is_temp(n)));
    let bin_files: Vec<String> = expected
        .iter()
        .filter(|(n, _)| n.starts_with("atlas"))
        .map(|(n, _)| n.clone())
        .collect();
    assert_eq!(expected.len(), expected_bake.len() + bin_files.len());
    let maps = map_files(reference.path()).len();
    assert_eq!(maps, 12);
    eprintln!("reference bake + bin: {:?}", t0.elapsed());

    // Bake: every file of the bake is written once, so a fresh bake makes exactly
    // `expected_bake.len()` atomic writes: selection.json, the 12 maps (two worker threads, in
    // either order), the two report pictures, index.json. Kill in each of them; rerun in the
    // same directory, killed again in the resumed run's second write (that run rewrites the
    // interrupted files, the reports and the index, so it has at least 3 writes); then complete.
    let writes = expected_bake.len();
    let mut order = Vec::new();
    for n in 1..=writes {
        let dir = tempfile::tempdir().unwrap();
        let name = kill_in_write(bake_cmd(dir.path()), n, dir.path(), &expected_bake, false);
        check_bake_readers(dir.path());
        let again = kill_in_write(bake_cmd(dir.path()), 2, dir.path(), &expected_bake, true);
        check_bake_readers(dir.path());
        eprintln!(
            "bake killed in write {n} ({name}), resumed and killed in its write 2 ({again}): \
             {} map files",
            map_files(dir.path()).len()
        );
        run_ok(bake_cmd(dir.path()));
        assert_eq!(
            dir_files(dir.path()),
            expected_bake,
            "bake killed in write {n} ({name}) and resumed differs"
        );
        order.push(name);
    }
    // The write order the contract promises: the selection, the maps, the reports, the index
    // last.
    assert_eq!(order[0], "selection.json");
    assert!(
        order[1..=maps]
            .iter()
            .all(|n| n.starts_with("map_") && n.ends_with(".exr")),
        "{order:?}"
    );
    assert_eq!(
        order[maps + 1..],
        ["report_offsets.png", "report_density.png", "index.json"],
        "{order:?}"
    );

    // Bin over a complete bake: one write per file it adds (the atlases, two worker threads;
    // atlases.json; the pictures). Kill in each of them, then rerun.
    let bake_only = |dir: &Path| {
        for (name, bytes) in &expected_bake {
            fs::write(dir.join(name), bytes).unwrap();
        }
    };
    let mut order = Vec::new();
    for n in 1..=bin_files.len() {
        let dir = tempfile::tempdir().unwrap();
        bake_only(dir.path());
        let name = kill_in_write(bin_cmd(dir.path()), n, dir.path(), &expected, false);
        let index_written = order.contains(&"atlases.json".to_owned());
        check_atlas_readers(dir.path(), index_written);
        eprintln!("bin killed in write {n} ({name})");
        run_ok(bin_cmd(dir.path()));
        assert_eq!(
            dir_files(dir.path()),
            expected,
            "bin killed in write {n} ({name}) differs"
        );
        order.push(name);
    }
    let atlases = bin_files.iter().filter(|n| n.ends_with(".exr")).count();
    assert!(
        order[..atlases]
            .iter()
            .all(|n| n.starts_with("atlas_") && n.ends_with(".exr")),
        "{order:?}"
    );
    assert_eq!(order[atlases], "atlases.json", "{order:?}");
    assert!(
        order[atlases + 1..].iter().all(|n| n.ends_with(".png")),
        "{order:?}"
    );

    // Bin over a directory holding a complete earlier set: the old atlases.json is removed
    // before the first atlas file is replaced, so a kill in that write leaves no index that
    // could point at half-replaced atlases.
    let dir = tempfile::tempdir().unwrap();
    for (name, bytes) in &expected {
        fs::write(dir.path().join(name), bytes).unwrap();
    }
    let name = kill_in_write(bin_cmd(dir.path()), 1, dir.path(), &expected, true);
    check_atlas_readers(dir.path(), false);
    run_ok(bin_cmd(dir.path()));
    assert_eq!(
        dir_files(dir.path()),
        expected,
        "re-bin killed in write 1 ({name}) differs"
    );
    eprintln!("total: {:?}", t0.elapsed());
}
