//! Fuzzes a scene file together with its mesh (`ortm::scene::load_scene_with_warnings`).
//!
//! Input layout: the bytes before the first NUL byte are the scene TOML (`scene.toml`), the
//! bytes after it the OBJ (`two_quads.obj`, the file the seed scenes name); without a NUL the
//! whole input is the TOML and the OBJ is empty. TOML text cannot hold a raw NUL, so the split
//! loses nothing. Any bytes must give a scene or a clean error.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("scene_mesh");
    let (toml, obj) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let path = dir.join("scene.toml");
    std::fs::write(&path, toml).expect("write scene");
    std::fs::write(dir.join("two_quads.obj"), obj).expect("write mesh");
    let _ = ortm::scene::load_scene_with_warnings(&path);
});
