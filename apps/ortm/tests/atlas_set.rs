//! Atlas sets (`ortm::atlas`) built from random transfer maps: every map texel lands in exactly
//! one piece, the atlas-based Eq. 9 equals `maps::apply`, and the files round-trip and refuse
//! tampering with a clear error.

mod common;

use std::fs;
use std::path::Path;

use common::{random_lightmap, random_sparse_maps};
use ortm::Lightmap;
use ortm::atlas::{
    ATLAS_INDEX_FILE_NAME, AtlasError, AtlasSet, apply_atlas_pieces, apply_atlas_set,
    build_atlas_set, read_atlas_index, read_atlas_set, write_atlas_set,
};
use ortm::bake_dir::{BakeIndex, BakeKey};
use ortm::io::FileError;
use ortm::maps::{self, TransferMap};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

const ATLAS_SIZES: [(u32, u32); 5] = [(8, 8), (16, 32), (64, 16), (64, 64), (128, 128)];

/// Rebuilds every map from the pieces and checks that each stored texel is covered exactly once,
/// nothing else is covered except the zero columns that pad a single-crop map's width (see
/// `atlas::padded_columns`), and the values are bit-identical.
#[test]
fn pieces_reconstruct_every_map_bit_exactly() {
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    for round in 0..6 {
        let (w, h) = (rng.random_range(20..60), rng.random_range(10..40));
        let n = rng.random_range(1..25);
        let maps = random_sparse_maps(&mut rng, w, h, n);
        for &(aw, ah) in &ATLAS_SIZES {
            let set = build_atlas_set(&maps, aw, ah).unwrap();
            set.validate().unwrap();
            let stored: u64 = maps.iter().map(TransferMap::stored_texels).sum();
            let placed: u64 = set
                .pieces
                .iter()
                .map(|p| u64::from(p.w) * u64::from(p.h))
                .sum();
            assert!(placed >= stored);
            assert_eq!(
                set.atlases.len() as u64,
                placed.div_ceil(u64::from(aw) * u64::from(ah)),
                "round {round}, atlas {aw}x{ah}: not the optimal atlas count"
            );
            let mut rebuilt = vec![Lightmap::new(w, h); maps.len()];
            let mut count = vec![vec![0u32; (w * h) as usize]; maps.len()];
            for p in &set.pieces {
                let mi = p.map_index as usize;
                assert_eq!(p.offset, maps[mi].offset.to_array());
                for j in 0..p.h {
                    for i in 0..p.w {
                        let v = set.atlases[p.atlas as usize]
                            [((p.src_y + j) * aw + p.src_x + i) as usize];
                        rebuilt[mi].set(p.dst_x + i, p.dst_y + j, v);
                        count[mi][((p.dst_y + j) * w + p.dst_x + i) as usize] += 1;
                    }
                }
            }
            for (mi, m) in maps.iter().enumerate() {
                let rects = m.rects();
                for y in 0..h {
                    for x in 0..w {
                        let stored_here = rects.iter().any(|r| r.contains(x, y));
                        let c = count[mi][(y * w + x) as usize];
                        // Padding (zeros, checked by the bit-exact comparison below) only for
                        // single-crop maps.
                        assert!(
                            if stored_here {
                                c == 1
                            } else {
                                c == 0 || (c == 1 && rects.len() == 1)
                            },
                            "map {mi} texel ({x}, {y}) placed {c} times, atlas {aw}x{ah}"
                        );
                    }
                }
                assert_eq!(
                    common::lightmap_bits(&rebuilt[mi]),
                    common::lightmap_bits(&m.to_full()),
                    "map {mi}"
                );
            }
            // Sorted by atlas, then position.
            assert!(set.pieces.windows(2).all(
                |p| (p[0].atlas, p[0].src_y, p[0].src_x) < (p[1].atlas, p[1].src_y, p[1].src_x)
            ));
        }
    }
}

#[test]
fn apply_atlas_set_equals_maps_apply() {
    let mut rng = ChaCha8Rng::seed_from_u64(99);
    for _ in 0..5 {
        let (w, h) = (rng.random_range(16..50), rng.random_range(16..50));
        let n = rng.random_range(1..30);
        let maps = random_sparse_maps(&mut rng, w, h, n);
        let bo = random_lightmap(&mut rng, w, h);
        let reference = maps::apply(&maps, &bo).unwrap();
        for &(aw, ah) in &ATLAS_SIZES {
            let set = build_atlas_set(&maps, aw, ah).unwrap();
            let got = apply_atlas_set(&set, &bo).unwrap();
            assert_eq!((got.width, got.height), (w, h));
            for (k, (a, b)) in got.data.iter().zip(&reference.data).enumerate() {
                for c in 0..3 {
                    let tol = 1e-6 * a[c].abs().max(b[c].abs());
                    assert!(
                        (a[c] - b[c]).abs() <= tol,
                        "texel {k} channel {c}: {} vs {} (atlas {aw}x{ah})",
                        a[c],
                        b[c]
                    );
                }
            }
            // Same terms, same order, same arithmetic: bit-identical (see its doc).
            assert_eq!(got, reference);
        }
    }
    // A first-order map of the wrong size is refused.
    let maps = random_sparse_maps(&mut rng, 10, 10, 3);
    let set = build_atlas_set(&maps, 8, 8).unwrap();
    assert!(matches!(
        apply_atlas_set(&set, &Lightmap::new(10, 11)),
        Err(AtlasError::FirstOrderSize { .. })
    ));
}

#[test]
fn apply_atlas_pieces_of_a_map_subset_equals_maps_apply_of_that_subset() {
    // `ortm view` applies the first K maps and single maps through `apply_atlas_pieces`:
    // filtering pieces by map index must equal `maps::apply` of the same maps alone.
    let mut rng = ChaCha8Rng::seed_from_u64(7);
    let (w, h) = (40, 30);
    let maps = random_sparse_maps(&mut rng, w, h, 12);
    let bo = random_lightmap(&mut rng, w, h);
    let set = build_atlas_set(&maps, 64, 64).unwrap();
    for keep in [
        vec![],
        vec![3],
        vec![0, 5, 11],
        (0..12).collect::<Vec<u32>>(),
    ] {
        let got = apply_atlas_pieces(&set, |p| keep.contains(&p.map_index), &bo, None).unwrap();
        let subset: Vec<TransferMap> = keep.iter().map(|&m| maps[m as usize].clone()).collect();
        let want = maps::apply(&subset, &bo).unwrap();
        for (a, b) in got.data.iter().zip(&want.data) {
            for c in 0..3 {
                assert!(
                    (a[c] - b[c]).abs() <= 1e-6 * a[c].abs().max(b[c].abs()),
                    "maps {keep:?}: {} vs {}",
                    a[c],
                    b[c]
                );
            }
        }
    }
}

fn settings() -> serde_json::Value {
    serde_json::json!({ "offsets": 12, "seed": 3 })
}

/// Writes a bake directory (map files + index.json) and returns its maps and index.
fn write_bake(dir: &Path, seed: u64) -> (Vec<TransferMap>, BakeIndex) {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let (w, h) = (48, 40);
    let maps = random_sparse_maps(&mut rng, w, h, 12);
    let index = common::write_bake(dir, &maps, (w, h), "scene", settings());
    (maps, index)
}

/// A bake directory with its atlases (16×16, so there are several) written into it.
fn baked_with_atlases() -> (tempfile::TempDir, AtlasSet) {
    let dir = tempfile::tempdir().unwrap();
    let (_, index) = write_bake(dir.path(), 5);
    let maps = index.load_maps(dir.path()).unwrap();
    let set = build_atlas_set(&maps, 16, 16).unwrap();
    assert!(set.atlases.len() >= 3, "want several atlases");
    write_atlas_set(dir.path(), &set, &index.bake_key).unwrap();
    (dir, set)
}

#[test]
fn write_then_read_round_trips() {
    let (dir, set) = baked_with_atlases();
    let back = read_atlas_set(dir.path()).unwrap();
    assert_eq!(back, set);
    // Bit-exact atlas values (f32 files).
    for (a, b) in back.atlases.iter().zip(&set.atlases) {
        assert!(
            a.iter()
                .zip(b)
                .all(|(x, y)| x.map(f32::to_bits) == y.map(f32::to_bits))
        );
    }
    let text = fs::read_to_string(dir.path().join(ATLAS_INDEX_FILE_NAME)).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert_eq!(v["format"], "ortm-atlases");
    assert_eq!(v["version"], 2);
    assert_eq!(
        v["atlas_size"],
        serde_json::json!({"width": 16, "height": 16})
    );
    assert_eq!(
        v["lightmap"],
        serde_json::json!({"width": 48, "height": 40})
    );
    assert_eq!(v["atlases"][1]["file"], "atlas_001.exr");
    assert_eq!(v["pieces"].as_array().unwrap().len(), set.pieces.len());
    // No temporary files are left behind.
    for e in fs::read_dir(dir.path()).unwrap() {
        let name = e.unwrap().file_name().into_string().unwrap();
        assert!(!name.ends_with(".tmp"), "{name}");
    }
    // Into a separate directory (no index.json there, so no bake check) with another size.
    let out = tempfile::tempdir().unwrap();
    let index = BakeIndex::read(dir.path()).unwrap();
    let maps = index.load_maps(dir.path()).unwrap();
    let set2 = build_atlas_set(&maps, 32, 64).unwrap();
    let written = write_atlas_set(out.path(), &set2, &index.bake_key).unwrap();
    assert_eq!(read_atlas_index(out.path()).unwrap(), written);
    assert_eq!(read_atlas_set(out.path()).unwrap(), set2);
    // Rewriting with fewer atlases replaces the index; the set read back is the new one.
    let set3 = build_atlas_set(&maps, 128, 128).unwrap();
    write_atlas_set(out.path(), &set3, &index.bake_key).unwrap();
    assert_eq!(read_atlas_set(out.path()).unwrap(), set3);
}

/// Rewrites `atlases.json` after `edit` and returns the read error.
fn read_after_edit(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) -> AtlasError {
    common::edit_json(&dir.join(ATLAS_INDEX_FILE_NAME), edit);
    read_atlas_set(dir).unwrap_err()
}

/// One atlas directory tampered with case by case (each case restores what it broke before
/// the next), so all cases share one set-up: a long list of short cases, not one long algorithm.
#[test]
fn tampered_or_inconsistent_atlases_are_refused() {
    let (dir, _) = baked_with_atlases();
    let d = dir.path();
    let index_path = d.join(ATLAS_INDEX_FILE_NAME);
    let good = fs::read(&index_path).unwrap();
    let restore = || fs::write(&index_path, &good).unwrap();

    // One byte of an atlas flipped: checksum error naming the file.
    let f1 = d.join("atlas_001.exr");
    let original = fs::read(&f1).unwrap();
    let mut flipped = original.clone();
    let mid = flipped.len() / 2;
    flipped[mid] ^= 0x40;
    fs::write(&f1, &flipped).unwrap();
    let e = read_atlas_set(d).unwrap_err();
    assert!(
        matches!(e, AtlasError::File(FileError::Checksum { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("atlas_001.exr"), "{e}");
    // Truncated: size error.
    fs::write(&f1, &original[..original.len() - 7]).unwrap();
    assert!(matches!(
        read_atlas_set(d),
        Err(AtlasError::File(FileError::FileSize { .. }))
    ));
    // Missing.
    fs::remove_file(&f1).unwrap();
    let e = read_atlas_set(d).unwrap_err();
    assert!(
        matches!(e, AtlasError::File(FileError::MissingFile { .. })),
        "{e}"
    );
    assert!(e.to_string().contains("atlas_001.exr"), "{e}");
    fs::write(&f1, &original).unwrap();
    read_atlas_set(d).unwrap();

    // Wrong version / format / missing version.
    let e = read_after_edit(d, |v| v["version"] = 3.into());
    assert!(matches!(e, AtlasError::Version { .. }), "{e}");
    assert!(e.to_string().contains("version 2"), "{e}");
    restore();
    let e = read_after_edit(d, |v| {
        v.as_object_mut().unwrap().remove("version");
    });
    assert!(matches!(e, AtlasError::Version { .. }), "{e}");
    restore();
    let e = read_after_edit(d, |v| v["format"] = "ortm-bake".into());
    assert!(matches!(e, AtlasError::Format { .. }), "{e}");
    restore();

    // A piece outside its atlas, outside the lightmap, naming a missing atlas.
    let e = read_after_edit(d, |v| v["pieces"][0]["src_x"] = 16.into());
    assert!(matches!(e, AtlasError::BadIndex { .. }), "{e}");
    assert!(e.to_string().contains("outside the 16×16 atlas"), "{e}");
    restore();
    let e = read_after_edit(d, |v| v["pieces"][0]["dst_y"] = 40.into());
    assert!(e.to_string().contains("outside the 48×40 lightmap"), "{e}");
    restore();
    let e = read_after_edit(d, |v| {
        let n = v["pieces"].as_array().unwrap().len();
        v["pieces"][n - 1]["atlas"] = 99.into();
    });
    assert!(matches!(e, AtlasError::BadIndex { .. }), "{e}");
    restore();
    // Two pieces in the same place.
    let e = read_after_edit(d, |v| {
        let p0 = v["pieces"][0].clone();
        v["pieces"].as_array_mut().unwrap().insert(1, p0);
    });
    assert!(matches!(e, AtlasError::BadIndex { .. }), "{e}");
    restore();

    // Unsafe file names.
    for bad in [
        "../atlas_000.exr",
        "/tmp/atlas_000.exr",
        "sub/atlas_000.exr",
    ] {
        let e = read_after_edit(d, |v| v["atlases"][0]["file"] = bad.into());
        assert!(
            matches!(e, AtlasError::File(FileError::BadFileName { .. })),
            "{bad}: {e}"
        );
        restore();
    }
    // Two atlas files swapped in the index (sizes and digests swapped too): each file is
    // stamped with its atlas number.
    let e = read_after_edit(d, |v| {
        let a = v["atlases"].as_array_mut().unwrap();
        a.swap(0, 1);
    });
    assert!(matches!(e, AtlasError::BadAtlasFile { .. }), "{e}");
    assert!(e.to_string().contains("atlas_001.exr"), "{e}");
    restore();

    // The bake beside the atlases was re-baked with other settings: stale atlases.
    let bake = BakeIndex::read(d).unwrap();
    let other = BakeIndex::new(
        bake.lightmap,
        "scene".into(),
        serde_json::json!({ "offsets": 13 }),
        Vec::new(),
    );
    other.write(d).unwrap();
    let e = read_atlas_set(d).unwrap_err();
    assert!(matches!(e, AtlasError::BakeMismatch { .. }), "{e}");
    assert!(e.to_string().contains("index.json"), "{e}");
    bake.write(d).unwrap();
    read_atlas_set(d).unwrap();

    // No atlases.json at all.
    fs::remove_file(&index_path).unwrap();
    let e = read_atlas_set(d).unwrap_err();
    assert!(matches!(e, AtlasError::MissingIndex { .. }), "{e}");
    assert!(e.to_string().contains("ortm bin"), "{e}");
}

#[test]
fn write_refuses_inconsistent_sets() {
    let mut rng = ChaCha8Rng::seed_from_u64(1);
    let maps = random_sparse_maps(&mut rng, 20, 20, 6);
    let set = build_atlas_set(&maps, 16, 16).unwrap();
    let dir = tempfile::tempdir().unwrap();
    let key = BakeKey::new("s", &settings());
    assert!(matches!(
        write_atlas_set(dir.path(), &set, "not-a-key"),
        Err(AtlasError::InvalidSet { .. })
    ));
    let mut bad = set.clone();
    bad.atlases[0].pop();
    assert!(matches!(
        write_atlas_set(dir.path(), &bad, key.as_str()),
        Err(AtlasError::InvalidSet { .. })
    ));
    let mut bad = set;
    bad.pieces.first_mut().expect("the maps have texels").dst_x = 20;
    assert!(matches!(
        write_atlas_set(dir.path(), &bad, key.as_str()),
        Err(AtlasError::InvalidSet { .. })
    ));
    // Nothing was written.
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 0);
}
