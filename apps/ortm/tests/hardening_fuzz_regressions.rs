//! Regression inputs of the fuzz targets (`fuzz/`, docs/fuzzing.md): every file in
//! `tests/data/fuzz/<target>/` is fed to the same reader as the fuzz target `<target>` and must
//! fail cleanly for its recorded reason — no panic, no unbounded allocation, no hang, an error
//! that names the file and contains the distinctive words of that reason ([`REASONS`], the
//! reasons in `tests/data/fuzz/README.md`). An input that starts being accepted, or refused for
//! another reason (say a limit check moved behind a decoder that now rejects it first), fails.
//! Files named `crash-*`, `oom-*`, `slow-unit-*` or `timeout-*` were found by libFuzzer; the
//! others were written by hand for a limit the fuzzer would take long to reach.

mod common;

use std::fs;
use std::path::Path;

/// The reason each regression input must be refused for, as `(target, file, reason)`: every
/// string of `reason` must appear in the error message. `map_exr` inputs are read twice
/// (`decode_map` without an expected size, then expecting the fixture's 32×32); the second
/// read's reasons are under the target `map_exr 32x32`.
const REASONS: &[(&str, &str, &[&str])] = &[
    // Limits on the declared pixels, checked from the headers before decoding.
    (
        "map_exr",
        "huge_data_window.exr",
        &[
            "(sum of the parts' data windows): 805306368 texels",
            "MAX_TEXELS",
        ],
    ),
    (
        "map_exr",
        "expansion_bomb.exr",
        &[
            "(sum of the parts' data windows): 201331392 bytes of pixels declared by a 7491-byte file",
            "MAX_EXR_EXPANSION",
        ],
    ),
    // The exr crate's header validation, before ortm's own checks.
    (
        "map_exr",
        "stale_chunk_count.exr",
        &["chunk count not matching data size"],
    ),
    (
        "map_exr 32x32",
        "huge_data_window.exr",
        &["size mismatch, expected 32×32 but found 16384×16384"],
    ),
    (
        "map_exr 32x32",
        "expansion_bomb.exr",
        &["size mismatch, expected 32×32 but found 16384×16384"],
    ),
    (
        "map_exr 32x32",
        "stale_chunk_count.exr",
        &["chunk count not matching data size"],
    ),
    (
        "atlas_exr",
        "huge_window.exr",
        &["16384", "expected 64×64 at (0, 0) (the index's atlas size)"],
    ),
    (
        "atlas_exr",
        "stale_chunk_count.exr",
        &["chunk count not matching data size"],
    ),
    (
        "atlas_index",
        "huge_atlas_size.json",
        &[
            "atlas size in",
            "3221225472 bytes of pixels declared by a 17555-byte file",
            "MAX_EXR_EXPANSION",
        ],
    ),
    (
        "atlas_index",
        "huge_lightmap.json",
        &["(lightmap size)", "the atlases are stale"],
    ),
    (
        "atlas_index",
        "overlapping_full_pieces.json",
        &["the pieces cover 5120 texels but 1 atlases of 64×64 hold only 4096"],
    ),
    (
        "atlas_index",
        "piece_outside_lightmap.json",
        &["piece 0 (64×64 at lightmap (0, 0)) lies outside the 32×32 lightmap"],
    ),
    (
        "bake_index",
        "bytes_over_limit.json",
        &["maps[0]: bytes 5368709120", "MAX_EXR_BYTES"],
    ),
    (
        "bake_index",
        "device_file.json",
        &["map file name \"/dev/zero\" is not allowed"],
    ),
    (
        "obj",
        "fork-abort-87ff478f.obj",
        &["mesh.obj:14", "a face (`f`) without corners"],
    ),
    (
        "obj",
        "huge_index.obj",
        &["mesh.obj:7", "refers to position 4294967295"],
    ),
    (
        "scene_file",
        "device_mesh.toml",
        &[
            "scene.toml:1",
            "/dev/zero, which is a device, not a regular file",
        ],
    ),
    (
        "scene_file",
        "huge_lightmap.toml",
        &[
            "scene.toml:3",
            "`lightmap.width` is 4294967295, outside 1..=8192",
        ],
    ),
];

/// The regression inputs of `target` with the reason each must be refused for (from
/// [`REASONS`] under `reasons_of`). Every input file needs a reason and every reason an input.
fn cases(target: &str, reasons_of: &str) -> Vec<(String, Vec<u8>, &'static [&'static str])> {
    let dir = common::data("fuzz").join(target);
    assert!(dir.is_dir(), "tests/data/fuzz/{target}: not a folder");
    let files: Vec<(String, Vec<u8>)> = common::dir_files(&dir)
        .into_iter()
        .filter(|(name, _)| name != "README.md")
        .collect();
    assert!(!files.is_empty(), "no regression inputs for {target}");
    let mut listed: Vec<&str> = REASONS
        .iter()
        .filter(|(t, _, _)| *t == reasons_of)
        .map(|(_, f, _)| *f)
        .collect();
    listed.sort_unstable();
    let present: Vec<&str> = files.iter().map(|(n, _)| n.as_str()).collect();
    assert_eq!(
        present, listed,
        "tests/data/fuzz/{target}: the inputs and the reasons listed for `{reasons_of}` differ"
    );
    files
        .into_iter()
        .map(|(name, bytes)| {
            let reason = REASONS
                .iter()
                .find(|(t, f, _)| *t == reasons_of && *f == name)
                .unwrap()
                .2;
            (name, bytes, reason)
        })
        .collect()
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

/// `r` is an error that names `file` and contains every string of `reason`.
fn expect_refused<T, E: std::fmt::Display>(
    case: &str,
    file: &str,
    reason: &[&str],
    r: Result<T, E>,
) {
    let msg = match r {
        Ok(_) => panic!("{case}: accepted"),
        Err(e) => e.to_string(),
    };
    assert!(
        msg.contains(file),
        "{case}: error does not name {file}: {msg}"
    );
    for part in reason {
        assert!(
            msg.contains(part),
            "{case}: refused, but not for its recorded reason ({part:?} missing): {msg}"
        );
    }
}

#[test]
fn map_exr_regressions() {
    let path = Path::new("regression.exr");
    for (name, bytes, reason) in cases("map_exr", "map_exr") {
        let r = ortm::bake_dir::decode_map(path, &bytes, None);
        expect_refused(&name, "regression.exr", reason, r);
    }
    for (name, bytes, reason) in cases("map_exr", "map_exr 32x32") {
        let r = ortm::bake_dir::decode_map(path, &bytes, Some((32, 32)));
        expect_refused(
            &format!("{name}, expecting 32×32"),
            "regression.exr",
            reason,
            r,
        );
    }
}

#[test]
fn atlas_exr_regressions() {
    for (name, bytes, reason) in cases("atlas_exr", "atlas_exr") {
        let dir = scratch();
        let digest = ortm::io::sha256_hex(&bytes);
        common::edit_json(&dir.path().join("atlases.json"), |v| {
            v["atlases"][0]["bytes"] = bytes.len().into();
            v["atlases"][0]["sha256"] = digest.into();
        });
        fs::write(dir.path().join("atlas_000.exr"), &bytes).unwrap();
        let r = ortm::atlas::read_atlas_set(dir.path());
        expect_refused(&name, "atlas_000.exr", reason, r);
    }
}

#[test]
fn bake_index_regressions() {
    for (name, bytes, reason) in cases("bake_index", "bake_index") {
        let dir = scratch();
        fs::write(dir.path().join("index.json"), &bytes).unwrap();
        let r = ortm::bake_dir::BakeIndex::read(dir.path()).and_then(|i| i.load_maps(dir.path()));
        expect_refused(&name, "index.json", reason, r);
        // The atlas reader checks the same index.json against atlases.json: it must not panic
        // (it may accept an index whose key, size and offsets agree).
        let _ = ortm::atlas::read_atlas_index(dir.path());
    }
}

#[test]
fn atlas_index_regressions() {
    for (name, bytes, reason) in cases("atlas_index", "atlas_index") {
        let dir = scratch();
        fs::write(dir.path().join("atlases.json"), &bytes).unwrap();
        let r = ortm::atlas::read_atlas_set(dir.path());
        expect_refused(&name, "atlases.json", reason, r);
    }
}

#[test]
fn obj_regressions() {
    for (name, bytes, reason) in cases("obj", "obj") {
        let dir = scratch();
        let path = dir.path().join("mesh.obj");
        fs::write(&path, &bytes).unwrap();
        for skip in [false, true] {
            let options = ortm::scene::obj::ObjOptions {
                skip_degenerate_faces: skip,
            };
            let r = ortm::scene::obj::load_obj_with(&path, 0.01, &options);
            let case = format!("{name}, skip_degenerate_faces {skip}");
            expect_refused(&case, "mesh.obj", reason, r);
        }
    }
}

#[test]
fn scene_file_regressions() {
    for (name, bytes, reason) in cases("scene_file", "scene_file") {
        let dir = scratch();
        let path = dir.path().join("scene.toml");
        fs::write(&path, &bytes).unwrap();
        let r = ortm::scene::load_scene_with_warnings(&path);
        expect_refused(&name, "scene.toml", reason, r);
    }
}
