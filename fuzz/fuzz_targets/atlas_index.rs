//! Fuzzes the atlas index reader: the input replaces `atlases.json` of a copy of the fixture
//! bake; `read_atlas_set` must accept it or fail cleanly.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("atlas_index");
    std::fs::write(dir.join("atlases.json"), data).expect("write input");
    let _ = ortm::atlas::read_atlas_set(dir);
});
