//! Tampered `atlases.json` (issue 19): deleting a piece, shifting one piece by a texel, editing
//! an atlas checksum or the recorded bake-index checksum, and an `atlases.json` of the previous
//! format version each give a clean error naming the file and the fix (re-run `ortm bin`), where
//! they used to render a different lightmap with exit 0. The reference is the untouched fixture
//! (`tests/data/fuzz/fixture_bake`, binned with `ortm bin --atlas 64`), which reads cleanly.

mod common;

use ortm::atlas::{AtlasError, read_atlas_set};

use common::{edit_json, fixture_bake};

/// Edits the fixture's `atlases.json` and returns the error of reading the set.
fn tampered(edit: impl FnOnce(&mut serde_json::Value)) -> String {
    let dir = fixture_bake();
    edit_json(&dir.path().join("atlases.json"), edit);
    let e = read_atlas_set(dir.path()).expect_err("a tampered atlas set was accepted");
    let text = e.to_string();
    assert!(
        text.contains("atlases.json") || text.contains("atlas_000.exr"),
        "{text}"
    );
    text
}

#[test]
fn untouched_fixture_reads_and_records_its_bake_index() {
    let dir = fixture_bake();
    let set = read_atlas_set(dir.path()).unwrap();
    assert!(!set.pieces.is_empty());
    let index = ortm::atlas::read_atlas_index(dir.path()).unwrap();
    let bytes = std::fs::read(dir.path().join("index.json")).unwrap();
    assert_eq!(
        index.bake_index_sha256.as_deref(),
        Some(ortm::bake_dir::index_digest(&bytes).unwrap().as_str())
    );
}

#[test]
fn removed_piece_is_refused() {
    let e = tampered(|v| {
        v["pieces"].as_array_mut().unwrap().remove(3);
    });
    assert!(
        e.contains("a piece is missing or extra") && e.contains("re-run `ortm bin`"),
        "{e}"
    );
}

#[test]
fn piece_shifted_by_one_texel_is_refused() {
    for field in ["dst_x", "dst_y"] {
        let e = tampered(|v| {
            // Move a piece away from the lightmap's edge so it stays inside the lightmap and
            // the bounds check cannot be what catches it.
            let pieces = v["pieces"].as_array_mut().unwrap();
            let p = pieces
                .iter_mut()
                .find(|p| p[field].as_u64().unwrap() > 0)
                .unwrap();
            p[field] = (p[field].as_u64().unwrap() - 1).into();
        });
        assert!(
            e.contains("do not cover its crop rectangles exactly") || e.contains("overlaps"),
            "{field}: {e}"
        );
    }
}

#[test]
fn edited_checksums_are_refused() {
    let e = tampered(|v| {
        v["atlases"][0]["sha256"] = "0".repeat(64).into();
    });
    assert!(e.contains("SHA-256") || e.contains("checksum"), "{e}");
    let e = tampered(|v| {
        v["bake_index_sha256"] = "0".repeat(64).into();
    });
    assert!(e.contains("not made from this bake index"), "{e}");
    let e = tampered(|v| {
        v["bake_index_sha256"] = serde_json::Value::Null;
    });
    assert!(e.contains("not made from this bake index"), "{e}");
}

#[test]
fn previous_format_version_asks_to_rerun_bin() {
    let dir = fixture_bake();
    edit_json(&dir.path().join("atlases.json"), |v| {
        v["version"] = 1.into();
        v.as_object_mut().unwrap().remove("bake_index_sha256");
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(matches!(e, AtlasError::Version { .. }), "{e}");
    assert!(e.to_string().contains("re-run `ortm bin`"), "{e}");
}
