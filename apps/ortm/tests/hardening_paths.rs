//! Untrusted bake and atlas directories (issue 8): every file an index names must resolve to a
//! regular file inside the directory — absolute paths, `..` and symbolic links that escape are
//! refused, one test per attempt — and an atlas index that does not match its bake is refused.
//! Also: resource limits refused up front with the number they would need.
//!
//! The fixture `tests/data/fuzz/fixture_bake` is a tiny Cornell bake (`ortm bake cornell --size
//! 32 --offsets 8`) binned with `ortm bin --atlas 64`.

mod common;

use std::fs;
use std::path::Path;

use ortm::atlas::{AtlasError, read_atlas_set};
use ortm::bake_dir::BakeIndex;
use ortm::io::FileError;
use ortm::maps::MapsError;

use common::{edit_json, fails, fixture_bake};

#[test]
fn fixture_reads_cleanly() {
    let dir = fixture_bake();
    let index = BakeIndex::read(dir.path()).unwrap();
    assert_eq!(index.load_maps(dir.path()).unwrap().len(), 8);
    let set = read_atlas_set(dir.path()).unwrap();
    assert_eq!(set.atlases.len(), 1);
}

#[test]
fn bake_index_absolute_path_is_refused() {
    let dir = fixture_bake();
    let abs = dir.path().join("map_00000_+0_+0.exr");
    edit_json(&dir.path().join("index.json"), |v| {
        v["maps"][0]["file"] = abs.to_string_lossy().into_owned().into();
    });
    let e = BakeIndex::read(dir.path()).unwrap_err();
    assert!(
        matches!(e, MapsError::File(FileError::BadFileName { .. })),
        "{e}"
    );
}

#[test]
fn bake_index_dotdot_is_refused() {
    let dir = fixture_bake();
    edit_json(&dir.path().join("index.json"), |v| {
        v["maps"][0]["file"] = "../map_00000_+0_+0.exr".into();
    });
    let e = BakeIndex::read(dir.path()).unwrap_err();
    assert!(
        matches!(e, MapsError::File(FileError::BadFileName { .. })),
        "{e}"
    );
}

#[test]
fn bake_index_symlink_escape_is_refused() {
    let dir = fixture_bake();
    // The map file is replaced by a link to an identical file outside the bake directory:
    // same bytes and checksum, but it is not in the directory.
    let outside = tempfile::tempdir().unwrap();
    let name = "map_00001_+10_-2.exr";
    let target = outside.path().join(name);
    fs::rename(dir.path().join(name), &target).unwrap();
    std::os::unix::fs::symlink(&target, dir.path().join(name)).unwrap();
    let e = BakeIndex::read(dir.path()).unwrap_err();
    assert!(
        matches!(e, MapsError::File(FileError::PathEscape { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("outside the bake directory"), "{e}");
    // A link that stays inside the directory is fine.
    fs::remove_file(dir.path().join(name)).unwrap();
    fs::rename(&target, dir.path().join("real.exr")).unwrap();
    std::os::unix::fs::symlink("real.exr", dir.path().join(name)).unwrap();
    let index = BakeIndex::read(dir.path()).unwrap();
    index.load_maps(dir.path()).unwrap();
    // A resumed bake never reuses a linked map file.
    let key = ortm::bake_dir::BakeKey::new(&index.scene_hash, &index.settings);
    let scan = ortm::bake_dir::scan_finished_maps(dir.path(), &key, 32, 32).unwrap();
    assert!(!scan.finished.contains_key(&1));
    assert!(scan.rejected.iter().any(|(p, _)| p.ends_with(name)));
}

#[test]
fn bake_index_naming_a_directory_or_device_is_refused() {
    let dir = fixture_bake();
    fs::create_dir(dir.path().join("sub.exr")).unwrap();
    edit_json(&dir.path().join("index.json"), |v| {
        v["maps"][0]["file"] = "sub.exr".into();
    });
    let e = BakeIndex::read(dir.path()).unwrap_err();
    assert!(
        matches!(e, MapsError::File(FileError::PathEscape { .. })),
        "{e}"
    );
    assert!(
        e.to_string().contains("is a directory, not a regular file"),
        "{e}"
    );
}

#[test]
fn atlas_index_absolute_path_is_refused() {
    let dir = fixture_bake();
    let abs = dir.path().join("atlas_000.exr");
    edit_json(&dir.path().join("atlases.json"), |v| {
        v["atlases"][0]["file"] = abs.to_string_lossy().into_owned().into();
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(
        matches!(e, AtlasError::File(FileError::BadFileName { .. })),
        "{e}"
    );
}

#[test]
fn atlas_index_dotdot_is_refused() {
    let dir = fixture_bake();
    edit_json(&dir.path().join("atlases.json"), |v| {
        v["atlases"][0]["file"] = "../atlas_000.exr".into();
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(
        matches!(e, AtlasError::File(FileError::BadFileName { .. })),
        "{e}"
    );
}

#[test]
fn atlas_index_symlink_escape_is_refused() {
    let dir = fixture_bake();
    let outside = tempfile::tempdir().unwrap();
    let target = outside.path().join("atlas_000.exr");
    fs::rename(dir.path().join("atlas_000.exr"), &target).unwrap();
    std::os::unix::fs::symlink(&target, dir.path().join("atlas_000.exr")).unwrap();
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(
        matches!(e, AtlasError::File(FileError::PathEscape { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("outside the atlas directory"), "{e}");
}

#[test]
fn atlas_index_that_does_not_match_the_bake_is_refused() {
    // A map whose pieces all have an offset other than the map's in index.json (changing one
    // piece only would be refused earlier, as pieces of one map that disagree).
    let dir = fixture_bake();
    edit_json(&dir.path().join("atlases.json"), |v| {
        let map = v["pieces"][0]["map_index"].clone();
        for p in v["pieces"].as_array_mut().unwrap() {
            if p["map_index"] == map {
                p["offset"] = serde_json::json!([5, 5]);
            }
        }
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(matches!(e, AtlasError::BadIndex { .. }), "{e}");
    assert!(
        e.to_string()
            .contains("with offset [5, 5], but the bake index"),
        "{e}"
    );
    // A piece naming a map the bake does not have (with a consistent offset in its own index).
    let dir = fixture_bake();
    edit_json(&dir.path().join("index.json"), |v| {
        v["maps"].as_array_mut().unwrap().truncate(1);
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(e.to_string().contains("1 maps"), "{e}");
    // An atlas index claiming a far larger atlas than its 17 kB file can hold is refused before
    // any geometry check allocates for it.
    let dir = fixture_bake();
    edit_json(&dir.path().join("atlases.json"), |v| {
        v["atlas_size"] = serde_json::json!({"width": 65536, "height": 4096});
    });
    let e = read_atlas_set(dir.path()).unwrap_err();
    assert!(e.to_string().contains("MAX_EXR_EXPANSION"), "{e}");
}

#[test]
fn oversized_json_is_refused_before_reading() {
    let dir = fixture_bake();
    let f = fs::File::create(dir.path().join("index.json")).unwrap();
    f.set_len(ortm::io::limits::MAX_JSON_BYTES + 1).unwrap(); // sparse: no disk used
    let e = BakeIndex::read(dir.path()).unwrap_err();
    assert!(e.to_string().contains("MAX_JSON_BYTES"), "{e}");
}

#[test]
fn scene_naming_a_device_as_mesh_is_refused() {
    if !Path::new("/dev/zero").exists() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("s.toml");
    fs::write(&scene, "mesh = \"/dev/zero\"\nmetres_per_unit = 1.0\n[[material]]\nname = \"a\"\nalbedo = [0.5, 0.5, 0.5]\n").unwrap();
    let e = ortm::scene::load_scene_with_warnings(&scene).unwrap_err();
    assert!(
        e.to_string()
            .contains("/dev/zero, which is a device, not a regular file"),
        "{e}"
    );
    // The OBJ loader itself refuses it before reading (it would never reach end of file).
    let e = ortm::scene::load_obj(Path::new("/dev/zero"), 1.0).unwrap_err();
    assert!(
        e.to_string().contains("is a device, not a regular file"),
        "{e}"
    );
}

#[test]
fn bake_over_the_memory_limit_is_refused_with_the_bytes_needed() {
    let dir = tempfile::tempdir().unwrap();
    let out = common::ortm_command()
        .args(["bake", "cornell", "--size", "64", "--offsets", "4", "-o"])
        .arg(dir.path())
        .env(ortm::io::limits::MEMORY_LIMIT_ENV, "100000")
        .output()
        .unwrap();
    let err = fails(out);
    assert!(err.contains("bytes") && err.contains("needed"), "{err}");
    assert!(err.contains("100000 bytes"), "{err}");
    // Nothing was baked.
    assert!(!dir.path().join("index.json").exists());
    assert!(!dir.path().join("selection.json").exists());
}

#[test]
fn impossible_offset_counts_and_sizes_are_refused_up_front() {
    let dir = tempfile::tempdir().unwrap();
    let run = |args: &[&str]| {
        let out = common::ortm_command()
            .args(args)
            .arg("-o")
            .arg(dir.path())
            .output()
            .unwrap();
        fails(out)
    };
    // A 32×32 lightmap has 63·63 = 3969 distinct offsets.
    let err = run(&["bake", "cornell", "--size", "32", "--offsets", "4000"]);
    assert!(err.contains("3969 for 32×32"), "{err}");
    let err = run(&["bake", "cornell", "--size", "32", "--offsets", "70000"]);
    assert!(err.contains("MAX_OFFSETS"), "{err}");
}

#[test]
fn bin_over_the_memory_limit_is_refused_with_the_bytes_needed() {
    let dir = fixture_bake();
    fs::remove_file(dir.path().join("atlases.json")).unwrap();
    let out = common::ortm_command()
        .arg("bin")
        .arg(dir.path())
        .args(["--atlas", "4096"])
        .env(ortm::io::limits::MEMORY_LIMIT_ENV, "100000000")
        .output()
        .unwrap();
    let err = fails(out);
    // One 4096² atlas of RGB f32 plus the fixture's 2130 stored texels.
    let need = (4096 * 4096 + 2130) * 12;
    assert!(err.contains(&format!("{need} bytes")), "{err}");
    assert!(!dir.path().join("atlases.json").exists());
}

#[test]
fn implausible_saved_selection_is_ignored_and_selected_again() {
    let dir = tempfile::tempdir().unwrap();
    let bake = || {
        let out = common::ortm_command()
            .args(["bake", "cornell", "--size", "32", "--offsets", "4"])
            .args(["--iterations", "50", "-o"])
            .arg(dir.path())
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "{}",
            String::from_utf8_lossy(&out.stderr)
        );
    };
    bake();
    let sel = dir.path().join("selection.json");
    let original = fs::read(&sel).unwrap();
    let index = fs::read(dir.path().join("index.json")).unwrap();
    // Same bake key (so it would be reused) but offsets far outside the 32×32 lightmap and
    // repeated: a corrupt or hostile file. The bake must not trust it.
    edit_json(&sel, |v| {
        v["offsets"] = serde_json::json!([[100000, 0], [100000, 0], [0, -7], [3, 3]]);
    });
    for e in fs::read_dir(dir.path()).unwrap() {
        let p = e.unwrap().path();
        if p.extension().is_some_and(|x| x == "exr") || p.ends_with("index.json") {
            fs::remove_file(p).unwrap();
        }
    }
    bake();
    assert_eq!(fs::read(&sel).unwrap(), original);
    assert_eq!(fs::read(dir.path().join("index.json")).unwrap(), index);
}
