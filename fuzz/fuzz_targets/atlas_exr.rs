//! Fuzzes the atlas OpenEXR decoder through `read_atlas_set`: the input becomes the fixture's
//! `atlas_000.exr`, and `atlases.json` is rewritten with the input's size and SHA-256 so the
//! decoder (not the checksum) sees it.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("atlas_exr");
    let fixture = std::fs::read_to_string(common::fixture_dir().join("atlases.json"))
        .expect("fixture atlases.json");
    let digest = ortm::io::sha256_hex(data);
    // Replace the first atlas's "bytes" and "sha256" values (the fixture has one atlas).
    let mut text = String::new();
    for line in fixture.lines() {
        let t = line.trim_start();
        if t.starts_with("\"bytes\"") {
            text.push_str(&format!("\"bytes\": {},\n", data.len()));
        } else if t.starts_with("\"sha256\"") {
            text.push_str(&format!("\"sha256\": \"{digest}\"\n"));
        } else {
            text.push_str(line);
            text.push('\n');
        }
    }
    std::fs::write(dir.join("atlases.json"), text).expect("write atlases.json");
    std::fs::write(dir.join("atlas_000.exr"), data).expect("write input");
    let _ = ortm::atlas::read_atlas_set(dir);
});
