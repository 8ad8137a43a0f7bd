//! `ortm bin` end to end on a synthetic bake directory: atlases, index and pictures written and
//! readable; clear errors for a missing index and a corrupt map file.

mod common;

use std::ffi::OsStr;
use std::fs;
use std::path::Path;

use common::{fails, ortm};
use glam::IVec2;
use ortm::Lightmap;
use ortm::atlas::{apply_atlas_set, read_atlas_set};
use ortm::bake_dir::BakeIndex;
use ortm::maps::{self, TransferMap};

/// A bake of `n` maps of a 40×24 lightmap, each a few rectangles of distinct values.
fn write_bake(dir: &Path, n: u32) -> Vec<TransferMap> {
    let (w, h) = (40, 24);
    let maps: Vec<TransferMap> = (0..n)
        .map(|i| {
            let mut full = Lightmap::new(w, h);
            for (x0, y0, bw, bh) in [(i % 7, i % 5, 9, 6), (25, 10 + i % 9, 13, 4)] {
                for y in y0..y0 + bh {
                    for x in x0..x0 + bw {
                        full.set(x, y, [0.01 * (i + 1) as f32, (x * y) as f32 * 1e-4, 0.5]);
                    }
                }
            }
            TransferMap::from_full(IVec2::new(i as i32 % 5 - 2, 1), 0.1, 1.0, &full).unwrap()
        })
        .collect();
    common::write_bake(dir, &maps, (w, h), "cli-scene", serde_json::json!({}));
    maps
}

#[test]
fn bin_writes_readable_atlases_and_pictures() {
    let bake = tempfile::tempdir().unwrap();
    let maps = write_bake(bake.path(), 9);
    let out = bake.path().join("atlases");
    let o = ortm(
        &[
            "bin".as_ref(),
            bake.path().as_os_str(),
            "--atlas".as_ref(),
            "32x64".as_ref(),
            "-o".as_ref(),
            out.as_os_str(),
        ],
        bake.path(),
    );
    let stdout = String::from_utf8_lossy(&o.stdout);
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let set = read_atlas_set(&out).unwrap();
    assert_eq!(set.atlas_size, (32, 64));
    let stored: u64 = maps.iter().map(TransferMap::stored_texels).sum();
    assert_eq!(set.atlases.len() as u64, stored.div_ceil(32 * 64));
    assert!(
        stdout.contains(&format!("atlases      {} of 32x64", set.atlases.len())),
        "{stdout}"
    );
    assert!(
        stdout.contains(&format!("texels       {stored}")),
        "{stdout}"
    );
    for i in 0..set.atlases.len() {
        for name in [
            format!("atlas_{i:03}.png"),
            format!("atlas_{i:03}_values.png"),
        ] {
            let img = image::open(out.join(&name)).unwrap();
            assert!(img.width() >= 32, "{name}");
        }
    }
    // The atlases written by the tool reproduce the maps' Eq. 9.
    let mut bo = Lightmap::new(40, 24);
    for (k, v) in bo.data.iter_mut().enumerate() {
        *v = [(k % 13) as f32, 1.0, (k % 3) as f32 * 0.25];
    }
    assert_eq!(
        apply_atlas_set(&set, &bo).unwrap(),
        maps::apply(&maps, &bo).unwrap()
    );

    // Default output is the bake directory itself; there the bake key is checked too.
    let o = ortm(
        &[
            "bin".as_ref(),
            bake.path().as_os_str(),
            "--atlas".as_ref(),
            "64".as_ref(),
        ],
        bake.path(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(read_atlas_set(bake.path()).unwrap().atlas_size, (64, 64));
}

#[test]
fn bin_reports_bad_input_clearly() {
    let empty = tempfile::tempdir().unwrap();
    let err = fails(ortm(
        &[OsStr::new("bin"), empty.path().as_os_str()],
        empty.path(),
    ));
    assert!(err.contains("index.json"), "{err}");

    let bake = tempfile::tempdir().unwrap();
    write_bake(bake.path(), 3);
    let index = BakeIndex::read(bake.path()).unwrap();
    let file = bake.path().join(&index.maps[1].file);
    let mut bytes = fs::read(&file).unwrap();
    let mid = bytes.len() / 2;
    bytes[mid] ^= 1;
    fs::write(&file, bytes).unwrap();
    let err = fails(ortm(
        &[OsStr::new("bin"), bake.path().as_os_str()],
        bake.path(),
    ));
    assert!(err.contains(&index.maps[1].file), "{err}");

    let err = fails(ortm(
        &[
            "bin".as_ref(),
            bake.path().as_os_str(),
            "--atlas".as_ref(),
            "1000".as_ref(),
        ],
        bake.path(),
    ));
    assert!(err.contains("power of two"), "{err}");
}
