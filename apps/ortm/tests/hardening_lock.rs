//! One writer per directory (issue 19): while one `ortm bake` or `ortm bin` writes a folder, a
//! second writer into it fails at once with exit 1 and "'DIR' is being written by process N";
//! the first finishes and the folder is exactly its result. The overlap is made certain, not
//! timed: the first writer is paused inside its first write by the test hook
//! `ORTM_TEST_PAUSE_IN_WRITE=1:PATH` (docs/bake-format.md, "Crash tests") until the second
//! has failed. Also: a saved `selection.json` edited by hand is selected again, never reused.

mod common;

use std::fs;
use std::io::{BufRead, BufReader};
use std::path::Path;
use std::process::{Child, Command, Stdio};

use common::{dir_files, edit_json, fixture_bake, ortm_command};

/// Starts `cmd` paused in its first atomic write until `go` exists; returns once it has
/// printed that it paused (so it holds its directory's lock).
#[allow(
    clippy::zombie_processes,
    reason = "the child is returned to the caller, which waits for it in `finish`"
)]
fn start_paused(mut cmd: Command, go: &Path) -> (Child, BufReader<std::process::ChildStderr>) {
    let mut child = cmd
        .env("ORTM_TEST_PAUSE_IN_WRITE", format!("1:{}", go.display()))
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .unwrap();
    let mut err = BufReader::new(child.stderr.take().unwrap());
    let mut line = String::new();
    loop {
        line.clear();
        if err.read_line(&mut line).unwrap() == 0 {
            let status = child.wait().unwrap();
            panic!("the first writer ended ({status}) before pausing");
        }
        if line.contains("ORTM_TEST_PAUSE_IN_WRITE: paused in write 1") {
            return (child, err);
        }
    }
}

/// Lets the paused writer go on and asserts that it succeeds.
fn finish(mut child: Child, mut err: BufReader<std::process::ChildStderr>, go: &Path) {
    fs::write(go, b"").unwrap();
    let mut rest = String::new();
    std::io::Read::read_to_string(&mut err, &mut rest).unwrap();
    assert!(child.wait().unwrap().success(), "first writer: {rest}");
}

/// Runs a second writer and asserts that it fails with the lock message naming `pid`.
fn second_fails(cmd: &mut Command, dir: &Path, pid: u32) {
    let out = cmd.output().unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "second writer: {err}");
    let expected = format!("'{}' is being written by process {pid}", dir.display());
    assert!(err.contains(&expected), "{err}");
}

fn bake_cmd(out: &Path, seed: &str) -> Command {
    let mut c = ortm_command();
    c.args(["bake", "cornell", "--size", "32", "--offsets", "6"])
        .args(["--iterations", "50", "--seed", seed, "-o"])
        .arg(out);
    c
}

#[test]
fn two_bakes_into_one_folder_one_fails_with_the_lock_message() {
    let tmp = tempfile::tempdir().unwrap();
    let (out, go) = (tmp.path().join("bake"), tmp.path().join("go"));
    let (first, err) = start_paused(bake_cmd(&out, "1"), &go);
    second_fails(&mut bake_cmd(&out, "2"), &out, first.id());
    finish(first, err, &go);
    // The folder is the first bake's, whole: the same files as that bake run alone.
    let alone = tmp.path().join("alone");
    assert!(bake_cmd(&alone, "1").output().unwrap().status.success());
    assert_eq!(dir_files(&out), dir_files(&alone));
    let index = ortm::bake_dir::BakeIndex::read(&out).unwrap();
    assert_eq!(index.settings["seed"], 1);
    assert_eq!(index.load_maps(&out).unwrap().len(), 6);
}

fn bin_cmd(bake: &Path, out: &Path, atlas: &str) -> Command {
    let mut c = ortm_command();
    c.arg("bin")
        .arg(bake)
        .args(["--atlas", atlas, "-o"])
        .arg(out);
    c
}

#[test]
fn two_bins_into_one_folder_one_fails_with_the_lock_message() {
    let bake = fixture_bake();
    let tmp = tempfile::tempdir().unwrap();
    let (out, go) = (tmp.path().join("atlases"), tmp.path().join("go"));
    let (first, err) = start_paused(bin_cmd(bake.path(), &out, "64"), &go);
    second_fails(&mut bin_cmd(bake.path(), &out, "128"), &out, first.id());
    finish(first, err, &go);
    let alone = tmp.path().join("alone");
    assert!(
        bin_cmd(bake.path(), &alone, "64")
            .output()
            .unwrap()
            .status
            .success()
    );
    assert_eq!(dir_files(&out), dir_files(&alone));
    let index = ortm::atlas::read_atlas_index(&out).unwrap();
    assert_eq!(index.atlas_size.width, 64);
}

#[test]
fn edited_selection_is_selected_again_not_reused() {
    let dir = tempfile::tempdir().unwrap();
    let bake = || {
        let out = bake_cmd(dir.path(), "1").output().unwrap();
        let err = String::from_utf8_lossy(&out.stderr).into_owned();
        assert!(out.status.success(), "{err}");
        err
    };
    bake();
    let sel = dir.path().join("selection.json");
    let original = fs::read(&sel).unwrap();
    let index = fs::read(dir.path().join("index.json")).unwrap();
    // One offset moved by one texel: still plausible (distinct, inside the lightmap), same bake
    // key — only the checksum tells.
    let mut moved = None;
    edit_json(&sel, |v| {
        let o = &mut v["offsets"][0];
        let dx = o[0].as_i64().unwrap();
        let new = if dx > 0 { dx - 1 } else { dx + 1 };
        o[0] = new.into();
        moved = Some(v["offsets"].clone());
    });
    let offsets: Vec<[i64; 2]> = serde_json::from_value(moved.unwrap()).unwrap();
    let distinct: std::collections::HashSet<_> = offsets.iter().collect();
    assert_eq!(
        distinct.len(),
        offsets.len(),
        "the edit must stay plausible"
    );
    let err = bake();
    assert!(
        err.contains("does not match its checksum") && err.contains("selecting the offsets again"),
        "{err}"
    );
    // Selected again from the seed: the original file and index, byte for byte.
    assert_eq!(fs::read(&sel).unwrap(), original);
    assert_eq!(fs::read(dir.path().join("index.json")).unwrap(), index);
}
