//! Fuzzes the transfer-map OpenEXR decoder (`ortm::bake_dir::decode_map`), with and without an
//! expected lightmap size.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.exr");
    let _ = ortm::bake_dir::decode_map(path, data, None);
    let _ = ortm::bake_dir::decode_map(path, data, Some((32, 32)));
});
