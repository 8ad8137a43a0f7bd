//! Fuzzes an atlas directory as a whole (`ortm::atlas::read_atlas_set`): the atlas index and its
//! atlas together, next to the fixture bake's unchanged `index.json` and maps.
//!
//! Input layout: the bytes before the first NUL byte are `atlases.json`, the bytes after it
//! `atlas_000.exr` (JSON text holds no raw NUL; the EXR may hold any bytes). Without a NUL the
//! whole input is the index and the atlas is empty.
//!
//! Checksums: in the index part, the fixture atlas's SHA-256 and size (`"bytes": 17555`), where
//! they still appear verbatim, are replaced by the EXR part's SHA-256 and size, so a mutated
//! atlas reaches the OpenEXR decoder together with a mutated index; a mutant that changes those
//! values (or the `"bytes"` spelling) instead exercises the size and checksum refusals. The
//! `bake_index_sha256` is NOT rewritten: it is the digest of `index.json`, which this target does
//! not change, so the fixture's value stays right and mutants of it test that check.
#![no_main]

#[path = "common.rs"]
mod common;

use libfuzzer_sys::fuzz_target;

/// The fixture atlas's SHA-256 and size as `atlases.json` records them.
const FIXTURE_SHA256: &str = "d5758e5e5a4484f3b0640eb8e59f41187dd78e2f0f5243f86e21599cb472e5c0";
const FIXTURE_BYTES: &str = "\"bytes\": 17555";

fuzz_target!(|data: &[u8]| {
    let dir = common::scratch("atlas_set");
    let (json, exr) = match data.iter().position(|&b| b == 0) {
        Some(i) => (&data[..i], &data[i + 1..]),
        None => (data, &[][..]),
    };
    let index = match std::str::from_utf8(json) {
        Ok(text) => text
            .replace(FIXTURE_SHA256, &ortm::io::sha256_hex(exr))
            .replace(FIXTURE_BYTES, &format!("\"bytes\": {}", exr.len()))
            .into_bytes(),
        Err(_) => json.to_vec(),
    };
    std::fs::write(dir.join("atlases.json"), index).expect("write atlases.json");
    std::fs::write(dir.join("atlas_000.exr"), exr).expect("write atlas");
    let _ = ortm::atlas::read_atlas_set(dir);
});
