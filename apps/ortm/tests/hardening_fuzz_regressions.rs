//! Regression inputs of the fuzz targets (`fuzz/`, docs/fuzzing.md): every file in
//! `tests/data/fuzz/<target>/` is fed to the same reader as the fuzz target `<target>` and must
//! give a clean error naming the file — no panic, no unbounded allocation, no hang. Files named
//! `crash-*`, `oom-*`, `slow-unit-*` or `timeout-*` were found by libFuzzer; the others were
//! written by hand for a limit the fuzzer would take long to reach (each says which in
//! `tests/data/fuzz/README.md`).

use std::fs;
use std::path::{Path, PathBuf};

use sha2::{Digest, Sha256};

fn data() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/fuzz")
}

/// The regression inputs of `target` (at least one).
fn cases(target: &str) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = fs::read_dir(data().join(target))
        .unwrap_or_else(|e| panic!("tests/data/fuzz/{target}: {e}"))
        .map(|e| e.unwrap())
        .filter(|e| e.file_name() != "README.md")
        .map(|e| {
            (
                e.file_name().into_string().unwrap(),
                fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    assert!(!v.is_empty(), "no regression inputs for {target}");
    v
}

/// A scratch copy of the fixture bake (and `two_quads.obj`), as the fuzz targets use.
fn scratch() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for e in fs::read_dir(data().join("fixture_bake")).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    let obj = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/scene/two_quads.obj");
    fs::copy(obj, dir.path().join("two_quads.obj")).unwrap();
    dir
}

fn expect_clean<T, E: std::fmt::Display>(case: &str, file: &str, r: Result<T, E>) {
    match r {
        Ok(_) => panic!("{case}: accepted"),
        Err(e) => {
            let msg = e.to_string();
            assert!(
                msg.contains(file),
                "{case}: error does not name {file}: {msg}"
            );
        }
    }
}

#[test]
fn map_exr_regressions() {
    for (name, bytes) in cases("map_exr") {
        let path = Path::new("regression.exr");
        expect_clean(
            &name,
            "regression.exr",
            ortm::bake_dir::decode_map(path, &bytes, None),
        );
        expect_clean(
            &name,
            "regression.exr",
            ortm::bake_dir::decode_map(path, &bytes, Some((32, 32))),
        );
    }
}

#[test]
fn atlas_exr_regressions() {
    for (name, bytes) in cases("atlas_exr") {
        let dir = scratch();
        let mut v: serde_json::Value =
            serde_json::from_slice(&fs::read(dir.path().join("atlases.json")).unwrap()).unwrap();
        v["atlases"][0]["bytes"] = bytes.len().into();
        let digest: String = Sha256::digest(&bytes)
            .iter()
            .map(|b| format!("{b:02x}"))
            .collect();
        v["atlases"][0]["sha256"] = digest.into();
        fs::write(
            dir.path().join("atlases.json"),
            serde_json::to_vec_pretty(&v).unwrap(),
        )
        .unwrap();
        fs::write(dir.path().join("atlas_000.exr"), &bytes).unwrap();
        expect_clean(
            &name,
            "atlas_000.exr",
            ortm::atlas::read_atlas_set(dir.path()),
        );
    }
}

#[test]
fn bake_index_regressions() {
    for (name, bytes) in cases("bake_index") {
        let dir = scratch();
        fs::write(dir.path().join("index.json"), &bytes).unwrap();
        let r = ortm::bake_dir::BakeIndex::read(dir.path()).and_then(|i| i.load_maps(dir.path()));
        expect_clean(&name, "index.json", r);
        // The atlas reader checks the same index.json against atlases.json: it must not panic
        // (it may accept an index whose key, size and offsets agree).
        let _ = ortm::atlas::read_atlas_index(dir.path());
    }
}

#[test]
fn atlas_index_regressions() {
    for (name, bytes) in cases("atlas_index") {
        let dir = scratch();
        fs::write(dir.path().join("atlases.json"), &bytes).unwrap();
        let r = ortm::atlas::read_atlas_set(dir.path());
        expect_clean(&name, "", r);
    }
}

#[test]
fn obj_regressions() {
    for (name, bytes) in cases("obj") {
        let dir = scratch();
        let path = dir.path().join("mesh.obj");
        fs::write(&path, &bytes).unwrap();
        for skip in [false, true] {
            let options = ortm::scene::obj::ObjOptions {
                skip_degenerate_faces: skip,
            };
            let r = ortm::scene::obj::load_obj_with(&path, 0.01, &options);
            expect_clean(&name, "mesh.obj", r);
        }
    }
}

#[test]
fn scene_file_regressions() {
    for (name, bytes) in cases("scene_file") {
        let dir = scratch();
        let path = dir.path().join("scene.toml");
        fs::write(&path, &bytes).unwrap();
        let r = ortm::scene::load_scene_with_warnings(&path);
        expect_clean(&name, "", r);
    }
}
