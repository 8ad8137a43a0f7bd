//! Memory before allocation (issue 19, item 5): a 300-byte scene asking for an 8192² lightmap
//! made `ortm inspect` peak at 6.1 GB and `ortm bake` at 6.9 GB before any memory check. Now
//! the rasterizer's memory (`limits::LIGHTMAP_BYTES_PER_TEXEL` per texel, measured) is checked
//! against `ORTM_MEMORY_LIMIT_BYTES` before rasterizing, so under a 1 GB limit both are refused
//! with the bytes needed, and their peak resident memory (`VmHWM`, which the binary prints at
//! exit under the test hook `ORTM_TEST_REPORT_PEAK`) stays under the limit + 10 %; measured
//! here: 8–10 MB (`ORTM_TEST_REPORT_PEAK=1 ortm inspect scene.toml`: 9494528 bytes).

mod common;

use std::fs;

use common::ortm_command;

/// Peak bytes the run reported (`ORTM_TEST_PEAK_BYTES: N` on stderr).
fn peak(stderr: &str) -> u64 {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("ORTM_TEST_PEAK_BYTES: "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no peak reported: {stderr}"))
}

#[test]
fn huge_lightmap_is_refused_before_rasterizing_under_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let text = fs::read_to_string(common::data("scene/two_quads.toml")).unwrap();
    let text = text
        .replace("width = 64", "width = 8192")
        .replace("height = 32", "height = 8192");
    assert!(text.contains("width = 8192") && text.contains("height = 8192"));
    fs::write(dir.path().join("scene.toml"), text).unwrap();
    fs::copy(
        common::data("scene/two_quads.obj"),
        dir.path().join("two_quads.obj"),
    )
    .unwrap();
    let limit: u64 = 1_000_000_000;
    for args in [
        &["inspect", "scene.toml"][..],
        &["bake", "scene.toml", "-o", "out"][..],
        &["bake", "cornell", "--size", "8192", "-o", "out"][..],
    ] {
        let out = ortm_command()
            .args(args)
            .current_dir(dir.path())
            .env(ortm::io::limits::MEMORY_LIMIT_ENV, limit.to_string())
            .env("ORTM_TEST_REPORT_PEAK", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        // 8192² texels × 104 bytes.
        let need = 8192u64 * 8192 * ortm::io::limits::LIGHTMAP_BYTES_PER_TEXEL;
        assert!(
            err.contains(&format!("{need} bytes")) && err.contains("1000000000 bytes"),
            "{args:?}: {err}"
        );
        let p = peak(&err);
        assert!(p < limit + limit / 10, "{args:?}: peak {p} bytes");
        assert!(!dir.path().join("out").exists(), "{args:?} wrote output");
    }
}
