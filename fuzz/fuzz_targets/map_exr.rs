//! Fuzzes the transfer-map OpenEXR decoder (`ortm::maps::decode_map`), with and without an
//! expected lightmap size.
#![no_main]

use std::path::Path;

use libfuzzer_sys::fuzz_target;

fuzz_target!(|data: &[u8]| {
    let path = Path::new("fuzz.exr");
    let _ = ortm::maps::decode_map(path, data, None);
    let _ = ortm::maps::decode_map(path, data, Some((32, 32)));
});
