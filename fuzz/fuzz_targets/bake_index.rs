//! Fuzzes the bake index reader: the input replaces `index.json` of a copy of the fixture bake;
//! `BakeIndex::read` and then `load_maps` must accept it or fail cleanly.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use ortm::bake_dir::BakeIndex;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("bake_index");
    std::fs::write(dir.join("index.json"), data).expect("write input");
    if let Ok(index) = BakeIndex::read(dir) {
        let _ = index.load_maps(dir);
    }
    // The atlas reader also reads index.json (to check the bake key).
    let _ = ortm::atlas::read_atlas_index(dir);
});
