//! Resuming a bake: an interrupted or damaged bake directory is completed by rerunning the same
//! bake, keeping the valid finished maps, and the result is byte-identical (every map file, the
//! index and the selection) to an uninterrupted bake with the same seed.

mod common;

use std::path::Path;
use std::sync::atomic::AtomicBool;

use ortm::bake::{BakeError, BakeSettings, bake};

fn settings() -> BakeSettings {
    BakeSettings {
        size: (32, 32),
        offsets: 20,
        refinement_iterations: 100,
        seed: 5,
        ..BakeSettings::default()
    }
}

/// The bake's maps as decoded from its index, and the bytes of every output file (maps, index,
/// selection), sorted by name.
type Content = (Vec<ortm::maps::TransferMap>, Vec<(String, Vec<u8>)>);

fn content(dir: &Path) -> Content {
    let index = ortm::bake_dir::BakeIndex::read(dir).unwrap();
    let files: Vec<(String, Vec<u8>)> = common::dir_files(dir)
        .into_iter()
        .filter(|(n, _)| n.ends_with(".exr") || n.ends_with(".json"))
        .collect();
    (index.load_maps(dir).unwrap(), files)
}

#[test]
fn interrupted_and_damaged_bakes_resume_to_identical_output() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let s = settings();
    let no = AtomicBool::new(false);
    let reference = tempfile::tempdir().unwrap();
    let first = bake(&scene, &s, reference.path(), &|_| {}, &no).unwrap();
    assert_eq!(first.reused, 0);
    let expected = content(reference.path());

    // Interrupted before any map: a clean error, no index.
    let dir = tempfile::tempdir().unwrap();
    let stop = AtomicBool::new(true);
    let err = bake(&scene, &s, dir.path(), &|_| {}, &stop).unwrap_err();
    assert!(
        matches!(err, BakeError::Interrupted { done: 0, .. }),
        "{err}"
    );
    assert!(!dir.path().join("index.json").exists());
    let resumed = bake(&scene, &s, dir.path(), &|_| {}, &no).unwrap();
    assert!(
        content(dir.path()) == expected,
        "byte-identical to the uninterrupted bake"
    );
    assert_eq!(resumed.maps, 20);

    // Damage: index gone, three maps deleted, one truncated, a stale temporary file left.
    std::fs::remove_file(dir.path().join("index.json")).unwrap();
    let mut maps: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "exr"))
        .collect();
    maps.sort();
    for p in &maps[..3] {
        std::fs::remove_file(p).unwrap();
    }
    let bytes = std::fs::read(&maps[5]).unwrap();
    std::fs::write(&maps[5], &bytes[..bytes.len() / 2]).unwrap();
    std::fs::write(dir.path().join(".map_99999_+0_+0.exr.tmp"), b"half").unwrap();
    let again = bake(&scene, &s, dir.path(), &|_| {}, &no).unwrap();
    assert_eq!(again.reused, 20 - 4, "valid finished maps are kept");
    assert_eq!(
        content(dir.path()),
        expected,
        "identical to the uninterrupted bake"
    );
    assert!(!dir.path().join(".map_99999_+0_+0.exr.tmp").exists());

    // A different seed is a different bake: nothing is reused.
    let other = BakeSettings {
        seed: 6,
        ..settings()
    };
    let third = bake(&scene, &other, dir.path(), &|_| {}, &no).unwrap();
    assert_eq!(third.reused, 0);
}
