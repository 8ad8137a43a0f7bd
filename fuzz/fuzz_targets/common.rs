//! Shared set-up of the fuzz targets: a private scratch directory per process, seeded with a
//! copy of the fixture bake `tests/data/fuzz/fixture_bake` (a tiny Cornell bake and its atlas).

#![allow(dead_code, reason = "each target uses a subset")]

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

/// The repository's fixture bake directory.
pub fn fixture_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../apps/ortm/tests/data/fuzz/fixture_bake")
}

/// The repository's small scene data (`tests/data/scene`).
pub fn scene_data_dir() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../apps/ortm/tests/data/scene")
}

/// A fresh scratch directory for this process (`$TMPDIR/ortm-fuzz-<name>-<pid>`), holding a
/// copy of the fixture bake. Created once per process.
pub fn scratch(name: &str) -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| {
        let dir = std::env::temp_dir().join(format!("ortm-fuzz-{name}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).expect("create scratch dir");
        for e in fs::read_dir(fixture_dir()).expect("fixture bake (tests/data/fuzz/fixture_bake)") {
            let e = e.expect("list fixture");
            fs::copy(e.path(), dir.join(e.file_name())).expect("copy fixture");
        }
        fs::copy(
            scene_data_dir().join("two_quads.obj"),
            dir.join("two_quads.obj"),
        )
        .expect("copy two_quads.obj");
        dir
    })
}

/// Restores `name` in the scratch directory from the fixture.
pub fn restore(dir: &Path, name: &str) {
    fs::copy(fixture_dir().join(name), dir.join(name)).expect("restore fixture file");
}
