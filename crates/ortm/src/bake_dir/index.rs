//! The bake index `index.json` (paper Sec. 5.1: "an index file which describes the images and
//! their offsets is written") and the writer of map files that returns their index entries.
//!
//! # Format (version 1; full description in `docs/bake-format.md`)
//! ```json
//! {
//!   "format": "ortm-bake",
//!   "version": 1,
//!   "lightmap": { "width": 512, "height": 512 },
//!   "scene_hash": "<caller's string>",
//!   "bake_key": "<64 hex: BakeKey::new(scene_hash, settings)>",
//!   "settings": { "...": "caller's JSON, stored verbatim" },
//!   "maps": [
//!     { "index": 0, "offset": [3, -2], "voronoi_area": 0.0123, "importance": 4.5,
//!       "rects": [ { "x": 10, "y": 4, "w": 32, "h": 16 } ],
//!       "file": "map_00000_+3_-2.exr", "bytes": 12345, "sha256": "<64 hex>" }
//!   ]
//! }
//! ```
//! A multi-resolution map ([`crate::maps::levels`]) adds `"level": ℓ` (1–15; absent means 0)
//! and its offset is in blocks of `2^ℓ` texels; its file has version 2 (older builds refuse it).
//! A map with one value per `2^r × 2^r` block of receivers adds `"receiver_level": r`
//! (`1..=level`; absent means 0): its rects are then in the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of receiver
//! blocks, and its file has version 3.
//! Offsets are texels, `+y` down the image; rects are lightmap texels (row 0 = `v = 1`). File
//! names are plain names inside the bake directory (no separators, no `..`, not absolute).
//!
//! # Writing and reading
//! The bake writes each map with [`write_map_file`] as soon as it is done (atomic, file name
//! [`map_file_name`]`(index, offset)`), stamped with a [`BakeKey`] derived from the scene hash
//! and the settings, and collects the returned [`MapEntry`]s. `index.json` is written last with
//! [`BakeIndex::write`]. Consumers call [`BakeIndex::read`], then [`BakeIndex::load_maps`].
//!
//! # Float precision
//! `voronoi_area` and `importance` are informational copies; the authoritative values are in
//! each OpenEXR header (exact f64). [`BakeIndex::load_maps`] compares them with a relative
//! tolerance of 1e-12 because JSON parsing of f64 is not guaranteed to be bit-exact here.

use std::collections::HashSet;
use std::fs;
use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::key::{BakeKey, map_file_name};
use super::map_file::{decode_map, encode_map};
use crate::io::{DirKind, FileError, is_hex_digest, sha256_hex};
use crate::maps::transfer_map::{check_rects, check_size};
use crate::maps::{CropRect, MapsError, TransferMap};

/// File name of the index inside a bake directory.
pub const INDEX_FILE_NAME: &str = "index.json";
/// Value of the index's `format` field.
pub const INDEX_FORMAT: &str = "ortm-bake";
/// The index version this build writes and reads.
pub const INDEX_VERSION: u32 = 1;

/// Relative tolerance when comparing the index's f64 copies with the file headers.
const F64_REL_TOL: f64 = 1e-12;

/// Lightmap size in texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct LightmapSize {
    /// Width in texels.
    pub width: u32,
    /// Height in texels.
    pub height: u32,
}

/// One map of the index: its offset, weights, crop rectangles and file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct MapEntry {
    /// Index of the map in the bake (unique; also in the file name and file header).
    pub index: u32,
    /// Offset `[dx, dy]` in texels (+dy down the image), or in blocks of `2^level` texels.
    pub offset: [i32; 2],
    /// Pyramid level of the senders ([`crate::maps::levels`]); absent (0) for the paper's maps.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub level: u32,
    /// Receiver level `r ≤ level` ([`TransferMap::receiver_level`]): the rects are in the grid
    /// of `2^r × 2^r` receiver blocks; absent (0) for one value per texel.
    #[serde(default, skip_serializing_if = "is_zero")]
    pub receiver_level: u32,
    /// Voronoi area of the offset (normalised units, informational).
    pub voronoi_area: f64,
    /// Importance of the offset (informational).
    pub importance: f64,
    /// Crop rectangles in file/part order.
    pub rects: Vec<CropRect>,
    /// File name inside the bake directory.
    pub file: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Lower-case hex SHA-256 of the whole file.
    pub sha256: String,
}

impl MapEntry {
    /// Entry for map `index` stored in `file` with the given size and digest.
    pub fn new(index: u32, map: &TransferMap, file: String, bytes: u64, sha256: String) -> Self {
        Self {
            index,
            offset: map.offset.to_array(),
            level: map.level(),
            receiver_level: map.receiver_level(),
            voronoi_area: map.voronoi_area,
            importance: map.importance,
            rects: map.rects(),
            file,
            bytes,
            sha256,
        }
    }
}

/// The bake index: everything a consumer needs to find and check the transfer maps.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct BakeIndex {
    /// Lightmap size shared by every map.
    pub lightmap: LightmapSize,
    /// The caller's scene hash.
    pub scene_hash: String,
    /// [`BakeKey`] of `(scene_hash, settings)` as computed by the bake; every map file carries
    /// the same key.
    pub bake_key: String,
    /// The caller's bake settings, stored verbatim.
    pub settings: serde_json::Value,
    /// The maps, in index order.
    pub maps: Vec<MapEntry>,
}

fn is_zero(v: &u32) -> bool {
    *v == 0
}

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= F64_REL_TOL * a.abs().max(b.abs())
}

impl BakeIndex {
    /// A new index; the bake key is computed from `scene_hash` and `settings`.
    pub fn new(
        lightmap: LightmapSize,
        scene_hash: String,
        settings: serde_json::Value,
        maps: Vec<MapEntry>,
    ) -> Self {
        let bake_key = BakeKey::new(&scene_hash, &settings).into_string();
        Self {
            lightmap,
            scene_hash,
            bake_key,
            settings,
            maps,
        }
    }

    /// Checks the index's internal consistency (sizes, unique indices and file names, plain
    /// file names, rectangles, digests). `path` names the index in errors.
    fn validate(&self, path: &Path) -> Result<(), MapsError> {
        let bad = |reason: String| MapsError::BadIndex {
            path: path.to_owned(),
            reason,
        };
        let what = path.display().to_string();
        check_size(&what, self.lightmap.width, self.lightmap.height)?;
        if self.maps.len() > crate::io::limits::MAX_OFFSETS {
            return Err(bad(format!(
                "{} maps exceed the limit MAX_OFFSETS = {}",
                self.maps.len(),
                crate::io::limits::MAX_OFFSETS
            )));
        }
        let mut indices = HashSet::new();
        let mut files = HashSet::new();
        for (n, m) in self.maps.iter().enumerate() {
            if !crate::io::plain_file_name(&m.file) {
                return Err(FileError::BadFileName {
                    index: path.to_owned(),
                    name: m.file.clone(),
                    kind: DirKind::Bake,
                }
                .into());
            }
            if !indices.insert(m.index) {
                return Err(bad(format!(
                    "maps[{n}]: map index {} appears twice",
                    m.index
                )));
            }
            if !files.insert(m.file.as_str()) {
                return Err(bad(format!("maps[{n}]: file {:?} appears twice", m.file)));
            }
            if m.bytes > crate::io::limits::MAX_EXR_BYTES {
                return Err(bad(format!(
                    "maps[{n}]: bytes {} exceeds the limit MAX_EXR_BYTES = {}",
                    m.bytes,
                    crate::io::limits::MAX_EXR_BYTES
                )));
            }
            if !is_hex_digest(&m.sha256) {
                return Err(bad(format!(
                    "maps[{n}]: sha256 {:?} is not 64 lower-case hex digits",
                    m.sha256
                )));
            }
            if !m.voronoi_area.is_finite() || m.voronoi_area < 0.0 || !m.importance.is_finite() {
                return Err(bad(format!(
                    "maps[{n}]: voronoi_area {} / importance {} invalid",
                    m.voronoi_area, m.importance
                )));
            }
            if m.level > crate::maps::MAX_MAP_LEVEL || m.receiver_level > m.level {
                return Err(bad(format!(
                    "maps[{n}]: level {} / receiver_level {} invalid (0 ≤ receiver_level ≤ \
                     level ≤ {})",
                    m.level,
                    m.receiver_level,
                    crate::maps::MAX_MAP_LEVEL
                )));
            }
            let (gw, gh) = crate::maps::receiver_grid(
                (self.lightmap.width, self.lightmap.height),
                m.receiver_level,
            );
            check_rects(
                &if m.receiver_level > 0 {
                    format!(
                        "{what} maps[{n}] (receiver_level {}: the {gw}×{gh} grid of receiver \
                         blocks)",
                        m.receiver_level
                    )
                } else {
                    format!("{what} maps[{n}]")
                },
                &m.rects,
                gw,
                gh,
            )?;
        }
        Ok(())
    }

    /// Writes `dir/index.json` atomically (pretty-printed), after validating the index.
    ///
    /// # Errors
    /// [`MapsError::BadIndex`] / [`FileError::BadFileName`] / [`MapsError::InvalidCrop`] /
    /// [`MapsError::LightmapSize`] for an inconsistent index, [`FileError::Io`] on write failure.
    pub fn write(&self, dir: &Path) -> Result<(), MapsError> {
        let path = dir.join(INDEX_FILE_NAME);
        self.validate(&path)?;
        let text =
            crate::io::to_versioned_json(INDEX_FORMAT, INDEX_VERSION, self).map_err(|source| {
                MapsError::Json {
                    path: path.clone(),
                    source,
                }
            })?;
        crate::io::write_atomic(&path, text.as_bytes())
            .map_err(|e| FileError::io("cannot write", &path, DirKind::Bake)(e).into())
    }

    /// Reads `dir/index.json`: checks `format` and `version` first, then the schema and the
    /// consistency rules, and that every listed file exists with the recorded size. Checksums
    /// are verified by [`BakeIndex::load_maps`].
    ///
    /// # Errors
    /// [`FileError::Io`], [`MapsError::Json`], [`MapsError::IndexFormat`],
    /// [`MapsError::IndexVersion`], [`MapsError::BadIndex`], [`FileError::BadFileName`],
    /// [`MapsError::InvalidCrop`], [`MapsError::LightmapSize`], [`FileError::MissingFile`],
    /// [`FileError::FileSize`].
    pub fn read(dir: &Path) -> Result<Self, MapsError> {
        Self::read_with_sha256(dir).map(|(index, _)| index)
    }

    /// [`BakeIndex::read`], also returning the [`index_digest`] of the `index.json` that was
    /// read (recorded by `ortm bin` in `atlases.json`).
    ///
    /// # Errors
    /// Those of [`BakeIndex::read`].
    pub fn read_with_sha256(dir: &Path) -> Result<(Self, String), MapsError> {
        let path = dir.join(INDEX_FILE_NAME);
        let text =
            crate::io::read_bounded(&path, crate::io::limits::MAX_JSON_BYTES, "MAX_JSON_BYTES")
                .map_err(FileError::io(
                    "cannot read bake index",
                    &path,
                    DirKind::Bake,
                ))?;
        use crate::io::VersionedError as V;
        let index: BakeIndex = crate::io::from_versioned_json(&text, INDEX_FORMAT, INDEX_VERSION)
            .map_err(|e| match e {
            V::Json(source) => MapsError::Json {
                path: path.clone(),
                source,
            },
            V::NotObject => MapsError::BadIndex {
                path: path.clone(),
                reason: "the top level is not a JSON object".into(),
            },
            V::Format(found) => MapsError::IndexFormat {
                path: path.clone(),
                expected: INDEX_FORMAT,
                found,
            },
            V::Version(found) => MapsError::IndexVersion {
                path: path.clone(),
                expected: INDEX_VERSION,
                found,
            },
        })?;
        index.validate(&path)?;
        for m in &index.maps {
            let (file, len) =
                crate::io::resolve_listed(dir, INDEX_FILE_NAME, &m.file, DirKind::Bake)?;
            if len != m.bytes {
                return Err(FileError::FileSize {
                    path: file,
                    expected: m.bytes,
                    found: len,
                    kind: DirKind::Bake,
                }
                .into());
            }
        }
        let digest = index_digest(&text).map_err(|source| MapsError::Json {
            path: path.clone(),
            source,
        })?;
        Ok((index, digest))
    }

    /// Loads every map listed in the index (in parallel), in index order. Each file must have
    /// the recorded size and SHA-256, decode and validate ([`crate::bake_dir::decode_map`]), have
    /// the index's lightmap size, and match its entry (map index, offset, rectangles, area and
    /// importance) and the index's bake key. On several failures the first entry's error is
    /// returned.
    ///
    /// # Errors
    /// The [`FileError`]s of [`crate::io::read_listed`], [`MapsError::EntryMismatch`], and the decoding errors of [`crate::bake_dir::decode_map`].
    pub fn load_maps(&self, dir: &Path) -> Result<Vec<TransferMap>, MapsError> {
        let size = (self.lightmap.width, self.lightmap.height);
        let results: Vec<Result<TransferMap, MapsError>> = self
            .maps
            .par_iter()
            .map(|m| self.load_one(dir, m, size))
            .collect();
        results.into_iter().collect()
    }

    fn load_one(
        &self,
        dir: &Path,
        m: &MapEntry,
        size: (u32, u32),
    ) -> Result<TransferMap, MapsError> {
        let crate::io::ListedFile { path, bytes } = crate::io::read_listed(
            dir,
            INDEX_FILE_NAME,
            &m.file,
            m.bytes,
            &m.sha256,
            DirKind::Bake,
        )?;
        let f = decode_map(&path, &bytes, Some(size))?;
        let mismatch = |reason: String| MapsError::EntryMismatch {
            path: path.clone(),
            reason,
        };
        if f.index != m.index {
            return Err(mismatch(format!(
                "file has map index {}, index says {}",
                f.index, m.index
            )));
        }
        if f.map.offset.to_array() != m.offset {
            return Err(mismatch(format!(
                "file has offset {:?}, index says {:?}",
                f.map.offset.to_array(),
                m.offset
            )));
        }
        if f.map.level() != m.level {
            return Err(mismatch(format!(
                "file has pyramid level {}, index says {}",
                f.map.level(),
                m.level
            )));
        }
        if f.map.receiver_level() != m.receiver_level {
            return Err(mismatch(format!(
                "file has receiver level {}, index says {}",
                f.map.receiver_level(),
                m.receiver_level
            )));
        }
        if f.map.rects() != m.rects {
            return Err(mismatch("crop rectangles differ".into()));
        }
        if !close(f.map.voronoi_area, m.voronoi_area) || !close(f.map.importance, m.importance) {
            return Err(mismatch(format!(
                "file has voronoi_area {} / importance {}, index says {} / {}",
                f.map.voronoi_area, f.map.importance, m.voronoi_area, m.importance
            )));
        }
        if f.bake_key != self.bake_key {
            return Err(mismatch(format!(
                "file has bake key {}, index has {}",
                f.bake_key, self.bake_key
            )));
        }
        Ok(f.map)
    }
}

/// The digest of a bake index that `atlases.json` records (`bake_index_sha256`): the SHA-256
/// (lower-case hex) of the index's JSON value written compactly with object keys sorted, so
/// that it names the index's content, not its formatting.
///
/// # Errors
/// The parser's error when `text` is not JSON.
pub fn index_digest(text: &[u8]) -> Result<String, serde_json::Error> {
    let v: serde_json::Value = serde_json::from_slice(text)?;
    Ok(crate::io::sha256_hex(&serde_json::to_vec(&v)?))
}

/// Encodes map `index` and writes it atomically to `dir/`[`map_file_name`]`(index, offset)`
/// (creating `dir` if needed). Returns the index entry (file name, byte size, SHA-256) for
/// [`BakeIndex`].
///
/// # Errors
/// [`FileError::Io`] if the directory or file cannot be written, [`FileError::Exr`] if encoding
/// fails.
pub fn write_map_file(
    dir: &Path,
    index: u32,
    map: &TransferMap,
    key: &BakeKey,
) -> Result<MapEntry, MapsError> {
    fs::create_dir_all(dir).map_err(FileError::io(
        "cannot create directory",
        dir,
        DirKind::Bake,
    ))?;
    let bytes = encode_map(index, map, key)?;
    let file = map_file_name(index, map.offset);
    let path = dir.join(&file);
    crate::io::write_atomic(&path, &bytes).map_err(FileError::io(
        "cannot write",
        &path,
        DirKind::Bake,
    ))?;
    Ok(MapEntry::new(
        index,
        map,
        file,
        bytes.len() as u64,
        sha256_hex(&bytes),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;

    use crate::bake_dir::fixtures::{maps, settings};

    fn bake(dir: &Path) -> BakeIndex {
        let key = BakeKey::new("scene", &settings());
        let entries = maps()
            .iter()
            .enumerate()
            .map(|(i, m)| write_map_file(dir, i as u32, m, &key).unwrap())
            .collect();
        let idx = BakeIndex::new(
            LightmapSize {
                width: 16,
                height: 8,
            },
            "scene".into(),
            settings(),
            entries,
        );
        idx.write(dir).unwrap();
        idx
    }

    #[test]
    fn write_read_load_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let idx = bake(dir.path());
        let text = fs::read_to_string(dir.path().join(INDEX_FILE_NAME)).unwrap();
        let v: serde_json::Value = serde_json::from_str(&text).unwrap();
        assert_eq!(v["format"], "ortm-bake");
        assert_eq!(v["version"], 1);
        assert_eq!(v["settings"], settings());
        assert_eq!(v["maps"][0]["offset"], serde_json::json!([-1, 2]));
        let back = BakeIndex::read(dir.path()).unwrap();
        assert_eq!(back.maps.len(), 3);
        assert_eq!(back.lightmap, idx.lightmap);
        assert_eq!(back.bake_key, idx.bake_key);
        assert_eq!(back.settings, idx.settings);
        for (a, b) in back.maps.iter().zip(&idx.maps) {
            assert_eq!(
                (a.index, a.offset, &a.rects, &a.file),
                (b.index, b.offset, &b.rects, &b.file)
            );
            assert_eq!((a.bytes, &a.sha256), (b.bytes, &b.sha256));
            assert!(close(a.voronoi_area, b.voronoi_area));
        }
        let loaded = back.load_maps(dir.path()).unwrap();
        assert_eq!(loaded, maps());
    }

    #[test]
    fn read_rejects_bad_indexes() {
        let dir = tempfile::tempdir().unwrap();
        bake(dir.path());
        let path = dir.path().join(INDEX_FILE_NAME);
        let good: serde_json::Value =
            serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
        let try_with = |edit: &dyn Fn(&mut serde_json::Value)| {
            let mut v = good.clone();
            edit(&mut v);
            fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
            BakeIndex::read(dir.path()).unwrap_err()
        };
        let e = try_with(&|v| v["version"] = 2.into());
        assert!(matches!(e, MapsError::IndexVersion { .. }));
        assert!(e.to_string().contains("version 1"), "{e}");
        let e = try_with(&|v| {
            v.as_object_mut().unwrap().remove("version");
        });
        assert!(matches!(e, MapsError::IndexVersion { .. }));
        let e = try_with(&|v| v["format"] = "something-else".into());
        assert!(matches!(e, MapsError::IndexFormat { .. }));
        let e = try_with(&|v| v["maps"][0]["file"] = "../escape.exr".into());
        assert!(
            matches!(e, MapsError::File(FileError::BadFileName { .. })),
            "{e}"
        );
        let e = try_with(&|v| v["maps"][0]["file"] = "/etc/passwd".into());
        assert!(
            matches!(e, MapsError::File(FileError::BadFileName { .. })),
            "{e}"
        );
        let e = try_with(&|v| v["maps"][1]["file"] = "missing.exr".into());
        assert!(
            matches!(e, MapsError::File(FileError::MissingFile { .. })),
            "{e}"
        );
        let e = try_with(&|v| v["maps"][0]["bytes"] = 3.into());
        assert!(
            matches!(e, MapsError::File(FileError::FileSize { .. })),
            "{e}"
        );
        let e = try_with(&|v| v["maps"][2]["index"] = 0.into());
        assert!(matches!(e, MapsError::BadIndex { .. }), "{e}");
        let e = try_with(&|v| v["maps"][0]["rects"][0]["x"] = 100.into());
        assert!(matches!(e, MapsError::InvalidCrop { .. }), "{e}");
        let e = try_with(&|v| v["lightmap"] = serde_json::json!({"width": 0, "height": 8}));
        assert!(matches!(e, MapsError::LightmapSize { .. }), "{e}");
        fs::write(&path, "{ not json").unwrap();
        assert!(matches!(
            BakeIndex::read(dir.path()),
            Err(MapsError::Json { .. })
        ));
        fs::remove_file(&path).unwrap();
        assert!(matches!(
            BakeIndex::read(dir.path()),
            Err(MapsError::File(FileError::Io { .. }))
        ));
    }

    #[test]
    fn load_detects_corrupt_or_swapped_files() {
        let dir = tempfile::tempdir().unwrap();
        let idx = bake(dir.path());
        let f0 = dir.path().join(&idx.maps[0].file);
        let original = fs::read(&f0).unwrap();
        // Same size, one byte flipped: checksum error.
        let mut flipped = original.clone();
        let mid = flipped.len() / 2;
        flipped[mid] ^= 1;
        fs::write(&f0, &flipped).unwrap();
        assert!(matches!(
            idx.load_maps(dir.path()),
            Err(MapsError::File(FileError::Checksum { .. }))
        ));
        // Truncated: size error.
        fs::write(&f0, &original[..original.len() - 10]).unwrap();
        assert!(matches!(
            idx.load_maps(dir.path()),
            Err(MapsError::File(FileError::FileSize { .. }))
        ));
        fs::write(&f0, &original).unwrap();
        idx.load_maps(dir.path()).unwrap();
        // An index whose bake key differs from the files' (files from another bake).
        let mut other = idx.clone();
        other.bake_key = BakeKey::new("other scene", &settings()).as_str().to_owned();
        assert!(matches!(
            other.load_maps(dir.path()),
            Err(MapsError::EntryMismatch { .. })
        ));
        // An entry pointing at another map's (valid) file.
        let mut swapped = idx.clone();
        let e2 = swapped.maps[2].clone();
        swapped.maps[0].file = e2.file;
        swapped.maps[0].bytes = e2.bytes;
        swapped.maps[0].sha256 = e2.sha256;
        assert!(matches!(
            swapped.load_maps(dir.path()),
            Err(MapsError::EntryMismatch { .. })
        ));
    }
}
