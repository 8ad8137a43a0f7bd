//! Maps with receiver levels ([`ortm::maps::TransferMap::receiver_level`]) through the files,
//! the index, the atlases and the CPU paths: a map file of receiver level `r > 0` round-trips
//! (version 3) and a version-3 file with wrong fields is refused; the index and atlas JSON carry
//! `receiver_level` (absent = 0, old files still read); and `ortm bake --levels` (receiver blocks
//! on, the default) → `ortm bin` → `apply_atlas_pieces` equals [`multires::apply_blocks`] of the
//! same blocks, with fewer stored texels than `--receiver-blocks off`.

mod common;

use std::fs;
use std::path::Path;

use common::{fails, ok, ortm};
use glam::IVec2;
use ortm::Lightmap;
use ortm::atlas::{AtlasPiece, apply_atlas_pieces, build_atlas_set, read_atlas_set};
use ortm::bake::multires::{self, MultiresSettings};
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::{Effects, SetupProgress, Transport};
use ortm::bake_dir::{BakeIndex, BakeKey, LightmapSize, MapEntry, decode_map, read_map_file};
use ortm::maps::{MapsError, TransferMap, levels};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

/// A level-2 map of receiver level 1 over a 40×24 lightmap (its grid: 20×12), two blobs.
fn block_map(seed: u64, offset: IVec2) -> TransferMap {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut grid = Lightmap::new(20, 12);
    for (x0, y0) in [(1, 1), (14, 7)] {
        for y in y0..y0 + 4 {
            for x in x0..x0 + 5 {
                grid.set(x, y, [rng.random(), rng.random(), rng.random()]);
            }
        }
    }
    let cropped = TransferMap::from_full(offset, 0.0, 0.0, &grid).unwrap();
    TransferMap::from_crops("t", offset, 0.0, 0.0, 40, 24, cropped.crops().to_vec())
        .unwrap()
        .with_level(2)
        .unwrap()
        .with_receiver_level(1)
        .unwrap()
}

/// `bytes` with `from` (which must occur exactly once) replaced by `to` of the same length.
fn patched(bytes: &[u8], from: &str, to: &str) -> Vec<u8> {
    assert_eq!(from.len(), to.len());
    let at: Vec<usize> = bytes
        .windows(from.len())
        .enumerate()
        .filter(|(_, w)| *w == from.as_bytes())
        .map(|(i, _)| i)
        .collect();
    assert_eq!(at.len(), 1, "{from:?} occurs {} times", at.len());
    let mut out = bytes.to_vec();
    out[at[0]..at[0] + to.len()].copy_from_slice(to.as_bytes());
    out
}

/// (a) A receiver-block map file round-trips bit-exactly as version 3 (display window = the
/// receiver grid), through the index too; a version-3 file whose receiver level, lightmap size
/// or version is edited is refused, naming the field; `with_receiver_level` refuses `r > ℓ` and
/// crops outside the grid.
#[test]
fn map_files_with_receiver_levels_round_trip_and_wrong_fields_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let key = BakeKey::new("scene", &serde_json::json!({"levels": 3e-3}));
    let maps = vec![
        TransferMap::from_full(IVec2::new(1, 0), 0.0, 0.0, &{
            let mut l = Lightmap::new(40, 24);
            l.set(3, 4, [1.0, 2.0, 3.0]);
            l
        })
        .unwrap(),
        block_map(1, IVec2::new(-1, 2)),
        block_map(2, IVec2::new(0, 0)),
    ];
    let entries: Vec<MapEntry> = maps
        .iter()
        .enumerate()
        .map(|(i, m)| ortm::bake_dir::write_map_file(dir.path(), i as u32, m, &key).unwrap())
        .collect();
    assert_eq!(entries[0].receiver_level, 0);
    assert_eq!((entries[1].level, entries[1].receiver_level), (2, 1));
    let path = dir.path().join(&entries[1].file);
    let f = read_map_file(&path, Some((40, 24))).unwrap();
    assert_eq!(f.map, maps[1]);
    assert_eq!((f.map.width(), f.map.height()), (20, 12));
    assert_eq!(f.map.lightmap_size(), (40, 24));
    // Index round trip: the field is written only where r > 0 and checked against the file.
    let idx = BakeIndex::new(
        LightmapSize {
            width: 40,
            height: 24,
        },
        "scene".into(),
        serde_json::json!({"levels": 3e-3}),
        entries.clone(),
    );
    idx.write(dir.path()).unwrap();
    let text = fs::read_to_string(dir.path().join("index.json")).unwrap();
    let v: serde_json::Value = serde_json::from_str(&text).unwrap();
    assert!(v["maps"][0].get("receiver_level").is_none());
    assert_eq!(v["maps"][1]["receiver_level"], 1);
    let back = BakeIndex::read(dir.path()).unwrap();
    assert_eq!(back.maps, entries);
    assert_eq!(back.load_maps(dir.path()).unwrap(), maps);
    let mut wrong = back.clone();
    wrong.maps[1].receiver_level = 2;
    let e = wrong.load_maps(dir.path()).unwrap_err();
    assert!(
        matches!(e, MapsError::EntryMismatch { .. }) && e.to_string().contains("receiver level"),
        "{e}"
    );

    // Edited version-3 files.
    let bytes = fs::read(&path).unwrap();
    let refused = |from: &str, to: &str, says: &str| {
        let e = decode_map(&path, &patched(&bytes, from, to), Some((40, 24))).unwrap_err();
        assert!(e.to_string().contains(says), "{from} → {to}: {e}");
    };
    refused(
        "ortmReceiverLevel=1",
        "ortmReceiverLevel=3",
        "ortmReceiverLevel",
    );
    refused(
        "ortmReceiverLevel=1",
        "ortmReceiverLevel=0",
        "ortmReceiverLevel",
    );
    refused(
        "ortmLightmapSize=40,24",
        "ortmLightmapSize=38,24",
        "ortmLightmapSize",
    );
    refused(
        "ortmLightmapSize=40,24",
        "ortmLightmapSize=40,22",
        "ortmLightmapSize",
    );
    refused(
        "ortmLightmapSize=40,24",
        "ortmLightmapSize=39,24",
        "ortmLightmapSize",
    );
    refused("ortmVersion=3", "ortmVersion=2", "size mismatch");
    refused(
        "ortmVersion=3",
        "ortmVersion=4",
        "version 4 is not supported",
    );
    // Without the expected size: the lightmap size is in the content hash, and the version-2
    // reading of the file fails it too.
    for (from, to) in [
        ("ortmLightmapSize=40,24", "ortmLightmapSize=39,24"),
        ("ortmVersion=3", "ortmVersion=2"),
    ] {
        let e = decode_map(&path, &patched(&bytes, from, to), None).unwrap_err();
        assert!(e.to_string().contains("content SHA-256"), "{to}: {e}");
    }

    // The receiver level needs a pyramid level at least as coarse, and crops inside its grid.
    let plain = TransferMap::from_full(IVec2::ZERO, 0.0, 0.0, &Lightmap::new(8, 8)).unwrap();
    assert!(plain.clone().with_receiver_level(1).is_err());
    assert!(plain.with_level(3).unwrap().with_receiver_level(3).is_ok());
    let mut wide = Lightmap::new(8, 8);
    wide.set(6, 1, [1.0; 3]);
    let wide = TransferMap::from_full(IVec2::ZERO, 0.0, 0.0, &wide)
        .unwrap()
        .with_level(1)
        .unwrap();
    let e = wide.with_receiver_level(1).unwrap_err();
    assert!(e.to_string().contains("4×4"), "{e}");
}

/// (c) `receiver_level` in the index and atlas JSON: absent reads as 0 (files written before
/// the field), written only where > 0; the atlas set keeps it, checks `dst` against the level-r
/// grid and refuses `r > level`.
#[test]
fn json_fields_default_to_zero_and_round_trip() {
    let old_entry = serde_json::json!({
        "index": 0, "offset": [1, -2], "level": 2, "voronoi_area": 0.0, "importance": 0.0,
        "rects": [{"x": 0, "y": 0, "w": 2, "h": 1}], "file": "map_00000_+1_-2.exr",
        "bytes": 10, "sha256": "00"
    });
    let e: MapEntry = serde_json::from_value(old_entry.clone()).unwrap();
    assert_eq!((e.level, e.receiver_level), (2, 0));
    assert_eq!(serde_json::to_value(&e).unwrap(), old_entry);
    let mut new_entry = old_entry.clone();
    new_entry["receiver_level"] = 1.into();
    let e: MapEntry = serde_json::from_value(new_entry.clone()).unwrap();
    assert_eq!(e.receiver_level, 1);
    assert_eq!(serde_json::to_value(&e).unwrap(), new_entry);

    let old_piece = serde_json::json!({
        "atlas": 0, "src_x": 0, "src_y": 0, "w": 3, "h": 2, "dst_x": 4, "dst_y": 5,
        "offset": [0, 1], "map_index": 7, "level": 3
    });
    let p: AtlasPiece = serde_json::from_value(old_piece.clone()).unwrap();
    assert_eq!((p.level, p.receiver_level), (3, 0));
    assert_eq!(serde_json::to_value(p).unwrap(), old_piece);
    let mut new_piece = old_piece.clone();
    new_piece["receiver_level"] = 2.into();
    let p: AtlasPiece = serde_json::from_value(new_piece.clone()).unwrap();
    assert_eq!(p.receiver_level, 2);
    assert_eq!(serde_json::to_value(p).unwrap(), new_piece);

    // An atlas set of a receiver-block map: pieces in the 20×12 grid of a 40×24 lightmap.
    let maps = vec![block_map(3, IVec2::new(1, 1))];
    let set = build_atlas_set(&maps, 64, 64).unwrap();
    assert_eq!(set.lightmap_size, (40, 24));
    assert!(
        set.pieces
            .iter()
            .all(|p| p.receiver_level == 1 && p.level == 2)
    );
    set.validate().unwrap();
    let mut s = set.clone();
    s.pieces[0].dst_x = 20 - s.pieces[0].w + 1;
    let e = s.validate().unwrap_err();
    assert!(e.to_string().contains("grid of receiver blocks"), "{e}");
    let mut s = set.clone();
    s.pieces[0].receiver_level = 3;
    assert!(s.validate().is_err());
    // Through `atlases.json` and back: the field survives, the bake index must agree.
    let dir = tempfile::tempdir().unwrap();
    let key = BakeKey::new("scene", &serde_json::json!({}));
    let entries = vec![ortm::bake_dir::write_map_file(dir.path(), 0, &maps[0], &key).unwrap()];
    let idx = BakeIndex::new(
        LightmapSize {
            width: 40,
            height: 24,
        },
        "scene".into(),
        serde_json::json!({}),
        entries,
    );
    idx.write(dir.path()).unwrap();
    ortm::atlas::write_atlas_set(dir.path(), &set, &idx.bake_key).unwrap();
    let back = read_atlas_set(dir.path()).unwrap();
    assert_eq!(back, set);
    common::edit_json(&dir.path().join("index.json"), |v| {
        v["maps"][0]["receiver_level"] = 2.into();
    });
    let e = ortm::atlas::read_atlas_index(dir.path()).unwrap_err();
    assert!(e.to_string().contains("receiver level"), "{e}");
}

/// The blocks the bake makes for Cornell 32² at `--levels 3e-3 --coarse-block 0` (single-texel
/// clusters, rows from the pair evaluator), computed here the same way.
fn cornell_blocks() -> (TexelGrid, Vec<multires::BlockEntry>) {
    let scene = ortm::scene::cornell::cornell_box(32);
    let grid = TexelGrid::build(&scene).unwrap();
    let block = ortm::bake::transport::coarse::auto_block(&grid);
    let tr = Transport::build(
        &scene,
        &grid,
        Effects::default(),
        block,
        &SetupProgress::none(),
    )
    .unwrap();
    let settings = MultiresSettings {
        tolerance: 3e-3,
        ..Default::default()
    };
    let entries = multires::partition_rows(
        &grid,
        multires::transport_row(&tr),
        &[settings],
        &SetupProgress::none(),
    )
    .unwrap()
    .remove(0);
    let blocks = multires::coarsen_receivers(&grid, &entries, settings.tolerance);
    (grid, blocks)
}

fn stored(dir: &Path) -> u64 {
    BakeIndex::read(dir)
        .unwrap()
        .maps
        .iter()
        .flat_map(|m| &m.rects)
        .map(|r| r.area())
        .sum()
}

/// (b) `ortm bake --levels 3e-3 --coarse-block 0 --receiver-blocks on` writes receiver-block maps that
/// equal `to_block_maps` of the blocks computed in memory; `ortm bin` packs them; the atlas
/// pieces applied on the CPU equal `apply_blocks` of the same blocks within 1e-5 relative per
/// texel (so does `apply_levels` of the maps); they store strictly fewer texels than
/// `--receiver-blocks off`, which is refused without `--levels`.
#[test]
fn cornell_bake_with_receiver_blocks_applies_like_the_blocks() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let bake = |out: &str, extra: &[&str]| {
        let mut args = vec![
            "bake",
            "cornell",
            "--size",
            "32",
            "--levels",
            "3e-3",
            "--coarse-block",
            "0",
            "-o",
            out,
        ];
        args.extend(extra);
        ok(ortm(&args, dir))
    };
    let text = bake("on", &["--receiver-blocks", "on"]);
    assert!(text.contains("% shared"), "{text}");
    // One value per receiver is the default.
    let text = bake("off", &[]);
    assert!(!text.contains("% shared"), "{text}");
    let e = fails(ortm(
        &[
            "bake",
            "cornell",
            "--size",
            "32",
            "--receiver-blocks",
            "off",
            "-o",
            "x",
        ],
        dir,
    ));
    assert!(e.contains("--receiver-blocks only applies"), "{e}");
    let e = fails(ortm(
        &[
            "bake",
            "cornell",
            "--size",
            "32",
            "--levels",
            "3e-3",
            "--receiver-blocks",
            "maybe",
        ],
        dir,
    ));
    assert!(e.contains("use on or off"), "{e}");
    let on = dir.join("on");
    let (on_texels, off_texels) = (stored(&on), stored(&dir.join("off")));
    eprintln!(
        "Cornell 32², ε 3e-3: {on_texels} stored texels with receiver blocks, {off_texels} without"
    );
    assert!(on_texels < off_texels, "{on_texels} vs {off_texels}");
    let index = BakeIndex::read(&on).unwrap();
    assert_ne!(
        index.bake_key,
        BakeIndex::read(&dir.join("off")).unwrap().bake_key,
        "the setting is part of the key"
    );
    assert_eq!(index.settings["receiver_blocks"], true);
    let loaded = index.load_maps(&on).unwrap();
    assert!(
        loaded.iter().any(|m| m.receiver_level() > 0),
        "blocks shared"
    );

    let (grid, blocks) = cornell_blocks();
    let want = multires::to_block_maps(&grid, &blocks).unwrap();
    assert_eq!(
        want, loaded,
        "the bake writes to_block_maps of the same blocks"
    );

    ok(ortm(&["bin", "on", "--atlas", "256"], dir));
    let set = read_atlas_set(&on).unwrap();
    assert!(set.pieces.iter().any(|p| p.receiver_level > 0));
    let area = grid.area_map();
    let mut rng = ChaCha8Rng::seed_from_u64(5);
    let mut first = Lightmap::new(grid.width, grid.height);
    for t in &grid.texels {
        first.set(
            t.x,
            t.y,
            std::array::from_fn(|_| rng.random_range(0.0..10.0)),
        );
    }
    let reference = multires::apply_blocks(&grid, &blocks, &first, &area).unwrap();
    let from_atlas = apply_atlas_pieces(&set, |_| true, &first, Some(&area)).unwrap();
    let from_maps = levels::apply_levels(&loaded, &first, &area).unwrap();
    assert!(matches!(
        apply_atlas_pieces(&set, |p| p.receiver_level > 0, &first, None),
        Err(ortm::atlas::AtlasError::NeedsWeights { .. })
    ));
    let mut worst = 0.0f64;
    for (i, r) in reference.data.iter().enumerate() {
        for (name, got) in [("atlas", &from_atlas), ("maps", &from_maps)] {
            for (ch, (&a, &b)) in got.data[i].iter().zip(r).enumerate() {
                let (a, b) = (f64::from(a), f64::from(b));
                let rel = (a - b).abs() / b.abs().max(1e-6);
                worst = worst.max(rel);
                assert!(
                    rel <= 1e-5,
                    "{name}: texel ({}, {}) ch {ch}: {a} vs apply_blocks {b}",
                    i as u32 % grid.width,
                    i as u32 / grid.width
                );
            }
        }
    }
    eprintln!("largest relative difference from apply_blocks: {worst:.2e}");
    // Uncovered texels keep their first order (0 here): receiver blocks add nothing there.
    let covered: std::collections::HashSet<(u32, u32)> =
        grid.texels.iter().map(|t| (t.x, t.y)).collect();
    for y in 0..grid.height {
        for x in 0..grid.width {
            if !covered.contains(&(x, y)) {
                assert_eq!(from_atlas.get(x, y), [0.0; 3], "uncovered ({x}, {y})");
            }
        }
    }
}
