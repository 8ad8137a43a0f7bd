//! Regression inputs of the fuzz targets (`fuzz/`, docs/fuzzing.md): every file in
//! `tests/data/fuzz/<target>/` is fed to the same reader as the fuzz target `<target>` and must
//! give a clean error naming the file — no panic, no unbounded allocation, no hang. Files named
//! `crash-*`, `oom-*`, `slow-unit-*` or `timeout-*` were found by libFuzzer; the others were
//! written by hand for a limit the fuzzer would take long to reach (each says which in
//! `tests/data/fuzz/README.md`).

mod common;

use std::fs;
use std::path::Path;

/// The regression inputs of `target` (at least one).
fn cases(target: &str) -> Vec<(String, Vec<u8>)> {
    let dir = common::data("fuzz").join(target);
    assert!(dir.is_dir(), "tests/data/fuzz/{target}: not a folder");
    let v: Vec<(String, Vec<u8>)> = common::dir_files(&dir)
        .into_iter()
        .filter(|(name, _)| name != "README.md")
        .collect();
    assert!(!v.is_empty(), "no regression inputs for {target}");
    v
}

/// A scratch copy of the fixture bake (and `two_quads.obj`), as the fuzz targets use.
fn scratch() -> tempfile::TempDir {
    let dir = common::fixture_bake();
    fs::copy(
        common::data("scene/two_quads.obj"),
        dir.path().join("two_quads.obj"),
    )
    .unwrap();
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
        let digest = ortm::io::sha256_hex(&bytes);
        common::edit_json(&dir.path().join("atlases.json"), |v| {
            v["atlases"][0]["bytes"] = bytes.len().into();
            v["atlases"][0]["sha256"] = digest.into();
        });
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
