//! Paths that are not regular files (issue 19): a FIFO in the place of the scene, the mesh, the
//! scene an index records, `selection.json`, a map or an atlas gives a clean error naming what
//! the path is, at once — opening a FIFO for reading would wait forever for a writer, so each
//! run has a deadline (a hang is infinite; the runs measured 0.01–0.3 s here, the deadline is
//! 2 s for the runs that open the FIFO before any work and 20 s for the bake, which builds the
//! transport (0.5 s measured) before it reads `selection.json`).

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output, Stdio};
use std::time::{Duration, Instant};

use common::{edit_json, fixture_bake, ortm_command};

/// Makes a FIFO at `path` with the system's `mkfifo`.
fn mkfifo(path: &Path) {
    let st = Command::new("mkfifo")
        .arg(path)
        .status()
        .expect("mkfifo runs");
    assert!(st.success(), "mkfifo {}", path.display());
}

/// Runs `cmd` and returns its output; fails the test (killing the child) if it has not ended
/// within `limit`.
fn run_within(mut cmd: Command, limit: Duration) -> Output {
    let mut child = cmd
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("ortm runs");
    let start = Instant::now();
    loop {
        if child.try_wait().expect("wait").is_some() {
            return child.wait_with_output().expect("output");
        }
        if start.elapsed() > limit {
            let _ = child.kill();
            let _ = child.wait();
            panic!("{cmd:?} did not end within {limit:?} (blocked on a FIFO?)");
        }
        std::thread::sleep(Duration::from_millis(5));
    }
}

/// Runs `ortm <args>` in `cwd` within `secs` seconds; asserts that it failed with exit 1 and
/// returns its stderr.
fn fails_within(args: &[&str], cwd: &Path, secs: u64) -> String {
    let mut cmd = ortm_command();
    cmd.args(args).current_dir(cwd);
    let out = run_within(cmd, Duration::from_secs(secs));
    let err = String::from_utf8_lossy(&out.stderr).into_owned();
    assert_eq!(out.status.code(), Some(1), "{args:?} should fail: {err}");
    assert!(!err.contains("panicked"), "{err}");
    err
}

#[test]
fn fifo_as_scene_is_refused_at_once() {
    let dir = tempfile::tempdir().unwrap();
    mkfifo(&dir.path().join("scene.toml"));
    for args in [
        &["inspect", "scene.toml"][..],
        &["bake", "scene.toml", "-o", "out"][..],
    ] {
        let err = fails_within(args, dir.path(), 2);
        assert!(err.contains("is a FIFO (named pipe)"), "{err}");
    }
}

/// A copy of `tests/data/scene/two_quads.toml` in `dir` whose mesh is `mesh`.
fn scene_with_mesh(dir: &Path, mesh: &str) -> PathBuf {
    let text = fs::read_to_string(common::data("scene/two_quads.toml")).unwrap();
    let text = text.replace("mesh = \"two_quads.obj\"", &format!("mesh = \"{mesh}\""));
    assert!(text.contains(mesh));
    let p = dir.join("scene.toml");
    fs::write(&p, text).unwrap();
    p
}

#[test]
fn fifo_directory_and_link_loop_as_mesh_say_what_they_are() {
    let dir = tempfile::tempdir().unwrap();
    let d = dir.path();
    mkfifo(&d.join("fifo.obj"));
    fs::create_dir(d.join("dir.obj")).unwrap();
    std::os::unix::fs::symlink(d.join("b.obj"), d.join("a.obj")).unwrap();
    std::os::unix::fs::symlink(d.join("a.obj"), d.join("b.obj")).unwrap();
    for (mesh, says) in [
        ("fifo.obj", "is a FIFO (named pipe)"),
        ("dir.obj", "is a directory"),
        ("a.obj", "symbolic link loop"),
        ("none.obj", "does not exist"),
    ] {
        scene_with_mesh(d, mesh);
        let err = fails_within(&["inspect", "scene.toml"], d, 2);
        assert!(err.contains(says), "{mesh}: {err}");
        assert!(
            err.contains("scene.toml:3:"),
            "{mesh}: the mesh field's line: {err}"
        );
    }
}

#[test]
fn fifo_named_by_an_index_settings_scene_is_never_opened() {
    let root = tempfile::tempdir().unwrap();
    let bake = fixture_bake();
    // The edits below change index.json, which the atlases record: render from the maps.
    fs::remove_file(bake.path().join("atlases.json")).unwrap();
    // Outside the bake directory: refused without looking at what it is.
    let outside = root.path().join("scene.toml");
    mkfifo(&outside);
    edit_json(&bake.path().join("index.json"), |v| {
        v["settings"]["scene"] = outside.to_string_lossy().into_owned().into();
    });
    let b = bake.path().to_str().unwrap();
    let err = fails_within(&["render", b], root.path(), 2);
    assert!(err.contains("outside the bake directory"), "{err}");
    assert!(err.contains("--scene"), "{err}");
    // Inside it: opened by the non-blocking opener, which refuses the FIFO.
    let inside = bake.path().join("scene.toml");
    mkfifo(&inside);
    edit_json(&bake.path().join("index.json"), |v| {
        v["settings"]["scene"] = inside.to_string_lossy().into_owned().into();
    });
    let err = fails_within(&["render", b], root.path(), 2);
    assert!(err.contains("is a FIFO (named pipe)"), "{err}");
}

#[test]
fn fifo_as_selection_json_is_an_error() {
    let dir = tempfile::tempdir().unwrap();
    fs::create_dir(dir.path().join("out")).unwrap();
    mkfifo(&dir.path().join("out/selection.json"));
    let args = [
        "bake",
        "cornell",
        "--size",
        "32",
        "--offsets",
        "4",
        "--iterations",
        "50",
        "-o",
        "out",
    ];
    let err = fails_within(&args, dir.path(), 20);
    assert!(
        err.contains("selection.json") && err.contains("is a FIFO (named pipe)"),
        "{err}"
    );
}

#[test]
fn fifo_as_map_or_atlas_is_an_error() {
    let root = tempfile::tempdir().unwrap();
    let out = root.path().join("atlases");
    let out = out.to_str().unwrap();
    // A map: `ortm bin` refuses it when loading the maps.
    let bake = fixture_bake();
    let map = bake.path().join("map_00003_-20_+12.exr");
    fs::remove_file(&map).unwrap();
    mkfifo(&map);
    let b = bake.path().to_str().unwrap();
    let err = fails_within(&["bin", b, "--atlas", "64", "-o", out], root.path(), 2);
    assert!(err.contains("is a FIFO (named pipe)"), "{err}");
    // An atlas, and the atlas index itself: `ortm render` refuses them before any GPU work.
    for name in ["atlas_000.exr", "atlases.json", "index.json"] {
        let bake = fixture_bake();
        let p = bake.path().join(name);
        fs::remove_file(&p).unwrap();
        mkfifo(&p);
        let b = bake.path().to_str().unwrap();
        let err = fails_within(&["render", b, "--scene", "cornell"], root.path(), 2);
        assert!(err.contains("is a FIFO (named pipe)"), "{name}: {err}");
    }
}
