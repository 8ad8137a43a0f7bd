//! Fuzzes the OBJ mesh loader (`ortm::scene::load_obj_with`): any bytes must give a mesh or a
//! clean error, within the time and memory limits.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;
use ortm::scene::obj::{ObjOptions, load_obj_with};

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("obj");
    let path = dir.join("mesh.obj");
    std::fs::write(&path, data).expect("write input");
    let skip = data.first().is_some_and(|b| b & 1 == 1);
    let options = ObjOptions {
        skip_degenerate_faces: skip,
    };
    let _ = load_obj_with(&path, 0.01, &options);
});
