//! End-to-end check of the transfer-map storage: crop → OpenEXR files written one by one →
//! index written last → index read → maps loaded → CPU apply. The result from disk must be
//! bit-identical to the result from the in-memory maps (f32 files are lossless), and a resumed
//! bake must find exactly the maps already written.

mod common;

use ortm::Lightmap;
use ortm::bake_dir::{BakeIndex, BakeKey, LightmapSize, scan_finished_maps, write_map_file};
use ortm::maps::apply;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

#[test]
fn bake_directory_round_trip_reproduces_apply() {
    let mut rng = ChaCha8Rng::seed_from_u64(2024);
    let (w, h) = (48, 32);
    let maps = common::random_log_valued_maps(&mut rng, w, h, 12);
    let mut bo = Lightmap::new(w, h);
    for v in bo.data.iter_mut() {
        *v = [rng.random::<f32>() * 10.0, rng.random(), 0.0];
    }

    let dir = tempfile::tempdir().unwrap();
    let settings = serde_json::json!({"offsets": 12, "seed": 2024});
    let key = BakeKey::new("scene-hash", &settings);

    // Interrupted bake: only the first 5 maps reach the disk.
    for (i, m) in maps.iter().enumerate().take(5) {
        write_map_file(dir.path(), i as u32, m, &key).unwrap();
    }
    // Resume: the scan finds exactly those, the bake writes the rest, then the index.
    let scan = scan_finished_maps(dir.path(), &key, w, h).unwrap();
    assert_eq!(
        scan.finished.keys().copied().collect::<Vec<_>>(),
        (0..5).collect::<Vec<_>>()
    );
    assert!(scan.rejected.is_empty() && scan.stale_temp.is_empty());
    let mut entries: Vec<_> = scan.finished.into_values().collect();
    for (i, m) in maps.iter().enumerate().skip(5) {
        entries.push(write_map_file(dir.path(), i as u32, m, &key).unwrap());
    }
    BakeIndex::new(
        LightmapSize {
            width: w,
            height: h,
        },
        "scene-hash".into(),
        settings,
        entries,
    )
    .write(dir.path())
    .unwrap();

    let index = BakeIndex::read(dir.path()).unwrap();
    assert_eq!(index.bake_key, key.as_str());
    let loaded = index.load_maps(dir.path()).unwrap();
    assert_eq!(loaded, maps);

    let from_memory = apply(&maps, &bo).unwrap();
    let from_disk = apply(&loaded, &bo).unwrap();
    assert_eq!(
        common::lightmap_bits(&from_disk),
        common::lightmap_bits(&from_memory)
    );
    // The maps add light: the result is never below B_o (all inputs are non-negative).
    for (f, b) in from_disk.data.iter().zip(&bo.data) {
        for c in 0..3 {
            assert!(f[c] >= b[c]);
        }
    }
}
