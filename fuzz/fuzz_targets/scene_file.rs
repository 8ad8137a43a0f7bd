//! Fuzzes the scene-file loader (`ortm::scene::load_scene_with_warnings`): TOML text next to a
//! valid mesh (`two_quads.obj`); any bytes must give a scene or a clean error.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("scene_file");
    let path = dir.join("scene.toml");
    std::fs::write(&path, data).expect("write input");
    let _ = ortm::scene::load_scene_with_warnings(&path);
});
