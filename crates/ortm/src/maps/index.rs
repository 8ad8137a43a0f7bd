//! The bake index `index.json` and the resumable-bake helpers (paper Sec. 5.1: "an index file
//! which describes the images and their offsets is written").
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
//! Offsets are texels, `+y` down the image; rects are lightmap texels (row 0 = `v = 1`). File
//! names are plain names inside the bake directory (no separators, no `..`, not absolute).
//!
//! # Resumable bake
//! The bake writes each map with [`crate::maps::write_map_file`] as soon as it is done (atomic,
//! file name [`map_file_name`]`(index, offset)`), stamped with a [`BakeKey`] derived from the
//! scene hash and the settings. `index.json` is written last with [`BakeIndex::write`]. On a
//! rerun, [`scan_finished_maps`] returns the maps already on disk that decode, pass their content
//! hash, and carry the same bake key and lightmap size, so the bake can skip them (it should also
//! check that each returned entry's offset is the one it planned for that index).
//!
//! # Float precision
//! `voronoi_area` and `importance` are informational copies; the authoritative values are in
//! each OpenEXR header (exact f64). [`BakeIndex::load_maps`] compares them with a relative
//! tolerance of 1e-12 because JSON parsing of f64 is not guaranteed to be bit-exact here.

use std::collections::{BTreeMap, HashMap, HashSet};
use std::fs;
use std::path::{Path, PathBuf};

use glam::IVec2;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::MapsError;
use super::crop::CropRect;
use super::exr_io::{decode_map, sha256_hex, write_atomic};
use super::transfer_map::{TransferMap, check_rects, check_size};

/// File name of the index inside a bake directory.
pub const INDEX_FILE_NAME: &str = "index.json";
/// Value of the index's `format` field.
pub const INDEX_FORMAT: &str = "ortm-bake";
/// The index version this build writes and reads.
pub const INDEX_VERSION: u32 = 1;

/// Relative tolerance when comparing the index's f64 copies with the file headers.
const F64_REL_TOL: f64 = 1e-12;

/// Identifies one bake configuration: SHA-256 (hex) of the scene hash and the canonical JSON of
/// the settings. Files stamped with a different key belong to another bake.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct BakeKey(String);

impl BakeKey {
    /// Key of `(scene_hash, settings)`. Object keys of `settings` are sorted recursively before
    /// hashing, so key order does not matter; number formatting follows `serde_json`.
    pub fn new(scene_hash: &str, settings: &serde_json::Value) -> Self {
        let mut canon = String::new();
        canonical_json(settings, &mut canon);
        let mut bytes = b"ortm-bake-key-v1\0".to_vec();
        bytes.extend_from_slice(&(scene_hash.len() as u64).to_le_bytes());
        bytes.extend_from_slice(scene_hash.as_bytes());
        bytes.extend_from_slice(canon.as_bytes());
        Self(sha256_hex(&bytes))
    }

    /// The key as 64 lower-case hex digits.
    pub fn as_str(&self) -> &str {
        &self.0
    }
}

/// Serialises `v` with object keys sorted at every level.
fn canonical_json(v: &serde_json::Value, out: &mut String) {
    use serde_json::Value;
    match v {
        Value::Object(map) => {
            let mut keys: Vec<&String> = map.keys().collect();
            keys.sort();
            out.push('{');
            for (i, k) in keys.into_iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                out.push_str(&Value::String(k.clone()).to_string());
                out.push(':');
                canonical_json(&map[k], out);
            }
            out.push('}');
        }
        Value::Array(items) => {
            out.push('[');
            for (i, item) in items.iter().enumerate() {
                if i > 0 {
                    out.push(',');
                }
                canonical_json(item, out);
            }
            out.push(']');
        }
        scalar => out.push_str(&scalar.to_string()),
    }
}

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
    /// Offset `[dx, dy]` in texels (+dy down the image).
    pub offset: [i32; 2],
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

/// Deterministic file name of map `index` with `offset`: `map_<index:05>_<±dx>_<±dy>.exr`,
/// e.g. `map_00012_+3_-17.exr`.
pub fn map_file_name(index: u32, offset: IVec2) -> String {
    format!("map_{index:05}_{:+}_{:+}.exr", offset.x, offset.y)
}

/// Inverse of [`map_file_name`]; `None` unless `name` is exactly such a name.
fn parse_map_file_name(name: &str) -> Option<(u32, IVec2)> {
    let stem = name.strip_prefix("map_")?.strip_suffix(".exr")?;
    let mut it = stem.split('_');
    let index: u32 = it.next()?.parse().ok()?;
    let dx: i32 = it.next()?.parse().ok()?;
    let dy: i32 = it.next()?.parse().ok()?;
    let offset = IVec2::new(dx, dy);
    (it.next().is_none() && map_file_name(index, offset) == name).then_some((index, offset))
}

/// Checks that `name` is a plain file name (one normal path component, no `..`).
fn check_file_name(index: &Path, name: &str) -> Result<(), MapsError> {
    let plain = !name.is_empty()
        && !name.contains(['/', '\\', ':', '\0'])
        && !name.contains("..")
        && !name.chars().any(char::is_control)
        && matches!(
            Path::new(name).components().collect::<Vec<_>>().as_slice(),
            [std::path::Component::Normal(_)]
        );
    if plain {
        Ok(())
    } else {
        Err(MapsError::BadFileName {
            index: index.to_owned(),
            name: name.to_owned(),
        })
    }
}

/// Resolves the index's file `name` inside `dir` ([`crate::io::limits::resolve_in_dir`]): a plain
/// name whose real path is a regular file inside the real bake directory. Returns the path and
/// the file's size in bytes.
fn resolve(dir: &Path, name: &str) -> Result<(PathBuf, u64), MapsError> {
    use crate::io::limits::Unresolved;
    check_file_name(&dir.join(INDEX_FILE_NAME), name)?;
    let path = dir.join(name);
    crate::io::limits::resolve_in_dir(dir, name).map_err(|e| match e {
        Unresolved::Missing => MapsError::MissingFile { path: path.clone() },
        Unresolved::Escapes(real) => MapsError::PathEscape {
            path: path.clone(),
            problem: format!(
                "resolves to {}, outside the bake directory {}",
                real.display(),
                dir.display()
            ),
        },
        Unresolved::NotRegular => MapsError::PathEscape {
            path: path.clone(),
            problem: "is not a regular file".into(),
        },
    })
}

fn is_hex_digest(s: &str) -> bool {
    s.len() == 64
        && s.bytes()
            .all(|b| b.is_ascii_digit() || (b'a'..=b'f').contains(&b))
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
        let bake_key = BakeKey::new(&scene_hash, &settings).0;
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
            check_file_name(path, &m.file)?;
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
            check_rects(
                &format!("{what} maps[{n}]"),
                &m.rects,
                self.lightmap.width,
                self.lightmap.height,
            )?;
        }
        Ok(())
    }

    /// Writes `dir/index.json` atomically (pretty-printed), after validating the index.
    ///
    /// # Errors
    /// [`MapsError::BadIndex`] / [`MapsError::BadFileName`] / [`MapsError::InvalidCrop`] /
    /// [`MapsError::LightmapSize`] for an inconsistent index, [`MapsError::Io`] on write failure.
    pub fn write(&self, dir: &Path) -> Result<(), MapsError> {
        let path = dir.join(INDEX_FILE_NAME);
        self.validate(&path)?;
        #[derive(Serialize)]
        struct Wire<'a> {
            format: &'static str,
            version: u32,
            #[serde(flatten)]
            body: &'a BakeIndex,
        }
        let wire = Wire {
            format: INDEX_FORMAT,
            version: INDEX_VERSION,
            body: self,
        };
        let mut text = serde_json::to_string_pretty(&wire).map_err(|source| MapsError::Json {
            path: path.clone(),
            source,
        })?;
        text.push('\n');
        write_atomic(&path, text.as_bytes())
    }

    /// Reads `dir/index.json`: checks `format` and `version` first, then the schema and the
    /// consistency rules, and that every listed file exists with the recorded size. Checksums
    /// are verified by [`BakeIndex::load_maps`].
    ///
    /// # Errors
    /// [`MapsError::Io`], [`MapsError::Json`], [`MapsError::IndexFormat`],
    /// [`MapsError::IndexVersion`], [`MapsError::BadIndex`], [`MapsError::BadFileName`],
    /// [`MapsError::InvalidCrop`], [`MapsError::LightmapSize`], [`MapsError::MissingFile`],
    /// [`MapsError::FileSize`].
    pub fn read(dir: &Path) -> Result<Self, MapsError> {
        let path = dir.join(INDEX_FILE_NAME);
        let text =
            crate::io::limits::read_bounded(&path, crate::io::limits::MAX_JSON_BYTES, "MAX_JSON_BYTES")
                .map_err(|source| MapsError::Io {
                    op: "cannot read bake index",
                    path: path.clone(),
                    source,
                })?;
        let json_err = |source| MapsError::Json {
            path: path.clone(),
            source,
        };
        let mut value: serde_json::Value = serde_json::from_slice(&text).map_err(json_err)?;
        let obj = value.as_object_mut().ok_or_else(|| MapsError::BadIndex {
            path: path.clone(),
            reason: "the top level is not a JSON object".into(),
        })?;
        match obj.remove("format") {
            Some(serde_json::Value::String(f)) if f == INDEX_FORMAT => {}
            other => {
                return Err(MapsError::IndexFormat {
                    path,
                    found: other.map_or_else(|| "<missing>".into(), |v| v.to_string()),
                });
            }
        }
        match obj.remove("version") {
            Some(v) if v.as_u64() == Some(INDEX_VERSION as u64) => {}
            other => {
                return Err(MapsError::IndexVersion {
                    path,
                    found: other.map_or_else(|| "<missing>".into(), |v| v.to_string()),
                });
            }
        }
        let index: BakeIndex = serde_json::from_value(value).map_err(json_err)?;
        index.validate(&path)?;
        for m in &index.maps {
            let (file, len) = resolve(dir, &m.file)?;
            if len != m.bytes {
                return Err(MapsError::FileSize {
                    path: file,
                    expected: m.bytes,
                    found: len,
                });
            }
        }
        Ok(index)
    }

    /// Loads every map listed in the index (in parallel), in index order. Each file must have
    /// the recorded size and SHA-256, decode and validate ([`crate::maps::decode_map`]), have
    /// the index's lightmap size, and match its entry (map index, offset, rectangles, area and
    /// importance) and the index's bake key. On several failures the first entry's error is
    /// returned.
    ///
    /// # Errors
    /// [`MapsError::Io`], [`MapsError::FileSize`], [`MapsError::Checksum`],
    /// [`MapsError::EntryMismatch`], and the decoding errors of [`crate::maps::decode_map`].
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
        let (path, len) = resolve(dir, &m.file)?;
        if len != m.bytes {
            return Err(MapsError::FileSize {
                path,
                expected: m.bytes,
                found: len,
            });
        }
        let bytes = crate::io::limits::read_bounded(&path, m.bytes, "the size recorded in the index")
            .map_err(|source| {
            if source.kind() == std::io::ErrorKind::NotFound {
                MapsError::MissingFile { path: path.clone() }
            } else {
                MapsError::Io {
                    op: "cannot read",
                    path: path.clone(),
                    source,
                }
            }
        })?;
        if bytes.len() as u64 != m.bytes {
            return Err(MapsError::FileSize {
                path,
                expected: m.bytes,
                found: bytes.len() as u64,
            });
        }
        let digest = sha256_hex(&bytes);
        if digest != m.sha256 {
            return Err(MapsError::Checksum {
                path,
                expected: m.sha256.clone(),
                found: digest,
            });
        }
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

/// What [`scan_finished_maps`] found in a bake directory.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ResumeScan {
    /// Valid, complete maps with the expected bake key and lightmap size, by map index. Their
    /// entries are ready for the index (size and SHA-256 computed from the file).
    pub finished: BTreeMap<u32, MapEntry>,
    /// Map files that cannot be reused (corrupt, other bake key, other size, duplicate index),
    /// with the reason. The bake should rewrite these maps (the atomic writer overwrites them).
    pub rejected: Vec<(PathBuf, String)>,
    /// Leftover temporary files of interrupted writes (`.*.tmp`); safe to delete.
    pub stale_temp: Vec<PathBuf>,
}

/// Scans `dir` for map files a resumed bake can keep: names of the form [`map_file_name`] whose
/// file decodes, passes its content hash, was stamped with `key`, has the given lightmap size,
/// and whose header index/offset match its name. A missing `dir` gives an empty scan. Files are
/// never deleted here.
///
/// # Errors
/// [`MapsError::Io`] if `dir` exists but cannot be listed. Bad individual files are reported in
/// [`ResumeScan::rejected`], not as errors.
pub fn scan_finished_maps(
    dir: &Path,
    key: &BakeKey,
    width: u32,
    height: u32,
) -> Result<ResumeScan, MapsError> {
    let mut scan = ResumeScan::default();
    let entries = match fs::read_dir(dir) {
        Ok(entries) => entries,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(scan),
        Err(source) => {
            return Err(MapsError::Io {
                op: "cannot list",
                path: dir.to_owned(),
                source,
            });
        }
    };
    let mut candidates = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|source| MapsError::Io {
            op: "cannot list",
            path: dir.to_owned(),
            source,
        })?;
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        // Symbolic links are never reused (they could point outside the bake directory).
        let regular = entry.file_type().is_ok_and(|t| t.is_file());
        if name.starts_with('.') && name.ends_with(".tmp") {
            if regular {
                scan.stale_temp.push(entry.path());
            }
        } else if let Some((index, offset)) = parse_map_file_name(&name) {
            if regular {
                candidates.push((index, offset, name));
            } else {
                scan.rejected
                    .push((entry.path(), "not a regular file (a link?)".into()));
            }
        }
    }
    candidates.sort_by(|a, b| (a.0, a.1.to_array(), &a.2).cmp(&(b.0, b.1.to_array(), &b.2)));
    scan.stale_temp.sort();
    let checked: Vec<(PathBuf, Result<MapEntry, String>)> = candidates
        .into_par_iter()
        .map(|(index, offset, name)| {
            let path = dir.join(&name);
            let result = check_finished(&path, index, offset, name, key, (width, height));
            (path, result)
        })
        .collect();
    let mut by_index: HashMap<u32, Vec<(PathBuf, MapEntry)>> = HashMap::new();
    for (path, result) in checked {
        match result {
            Ok(e) => by_index.entry(e.index).or_default().push((path, e)),
            Err(reason) => scan.rejected.push((path, reason)),
        }
    }
    for (index, mut found) in by_index {
        if found.len() == 1 {
            let (_, e) = found.pop().unwrap_or_else(|| unreachable!("len checked"));
            scan.finished.insert(index, e);
        } else {
            for (path, _) in found {
                scan.rejected
                    .push((path, format!("several valid files claim map index {index}")));
            }
        }
    }
    scan.rejected.sort();
    Ok(scan)
}

/// Decodes and checks one candidate file for [`scan_finished_maps`].
fn check_finished(
    path: &Path,
    index: u32,
    offset: IVec2,
    name: String,
    key: &BakeKey,
    size: (u32, u32),
) -> Result<MapEntry, String> {
    let bytes = crate::io::limits::read_bounded(path, crate::io::limits::MAX_EXR_BYTES, "MAX_EXR_BYTES")
        .map_err(|e| format!("cannot read: {e}"))?;
    let f = decode_map(path, &bytes, Some(size)).map_err(|e| e.to_string())?;
    if f.bake_key != key.as_str() {
        return Err(format!(
            "stamped with bake key {}, expected {}",
            f.bake_key,
            key.as_str()
        ));
    }
    if f.index != index || f.map.offset != offset {
        return Err(format!(
            "header says map {} offset {:?}, name says map {index} offset {:?}",
            f.index,
            f.map.offset.to_array(),
            offset.to_array()
        ));
    }
    Ok(MapEntry::new(
        index,
        &f.map,
        name,
        bytes.len() as u64,
        sha256_hex(&bytes),
    ))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::Lightmap;
    use crate::maps::write_map_file;

    fn settings() -> serde_json::Value {
        serde_json::json!({"offsets": 3, "seed": 42, "nested": {"b": [1, 2.5], "a": "x"}})
    }

    fn maps() -> Vec<TransferMap> {
        (0..3)
            .map(|i| {
                let mut full = Lightmap::new(16, 8);
                if i != 1 {
                    full.set(i, 2, [0.25, 0.5, 1.0 / (i as f32 + 3.0)]);
                    full.set(10, 7, [1e-6, 0.0, 0.0]);
                }
                TransferMap::from_full(IVec2::new(i as i32 - 1, 2), 0.1 * i as f64, 1.5, &full)
                    .unwrap()
            })
            .collect()
    }

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
    fn file_names_round_trip_and_reject_paths() {
        for (i, o) in [
            (0, IVec2::ZERO),
            (12, IVec2::new(3, -17)),
            (123456, IVec2::new(-9, 0)),
        ] {
            let n = map_file_name(i, o);
            assert_eq!(parse_map_file_name(&n), Some((i, o)), "{n}");
            check_file_name(Path::new("i"), &n).unwrap();
        }
        assert_eq!(
            map_file_name(12, IVec2::new(3, -17)),
            "map_00012_+3_-17.exr"
        );
        for bad in [
            "map_1_+0_+0.exr",
            "map_00001_0_+0.exr",
            "map_00001_+0_+0.png",
            "x.exr",
        ] {
            assert_eq!(parse_map_file_name(bad), None, "{bad}");
        }
        for bad in [
            "", ".", "..", "../a.exr", "a/b.exr", "/abs.exr", "a\\b.exr", "C:x.exr",
        ] {
            assert!(
                check_file_name(Path::new("i"), bad).is_err(),
                "{bad:?} accepted"
            );
        }
    }

    #[test]
    fn bake_key_ignores_key_order_but_not_values() {
        let a = serde_json::json!({"x": 1, "y": {"p": true, "q": [1, 2]}});
        let b: serde_json::Value =
            serde_json::from_str(r#"{"y": {"q": [1, 2], "p": true}, "x": 1}"#).unwrap();
        assert_eq!(BakeKey::new("s", &a), BakeKey::new("s", &b));
        assert_ne!(BakeKey::new("s", &a), BakeKey::new("t", &a));
        let c = serde_json::json!({"x": 2, "y": {"p": true, "q": [1, 2]}});
        assert_ne!(BakeKey::new("s", &a), BakeKey::new("s", &c));
        // Scene hash and settings are length-separated: shifting text between them differs.
        assert_ne!(
            BakeKey::new("a", &serde_json::json!("b")),
            BakeKey::new("a\"", &serde_json::json!(""))
        );
        assert!(is_hex_digest(BakeKey::new("s", &a).as_str()));
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
        assert!(matches!(e, MapsError::BadFileName { .. }), "{e}");
        let e = try_with(&|v| v["maps"][0]["file"] = "/etc/passwd".into());
        assert!(matches!(e, MapsError::BadFileName { .. }), "{e}");
        let e = try_with(&|v| v["maps"][1]["file"] = "missing.exr".into());
        assert!(matches!(e, MapsError::MissingFile { .. }), "{e}");
        let e = try_with(&|v| v["maps"][0]["bytes"] = 3.into());
        assert!(matches!(e, MapsError::FileSize { .. }), "{e}");
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
            Err(MapsError::Io { .. })
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
            Err(MapsError::Checksum { .. })
        ));
        // Truncated: size error.
        fs::write(&f0, &original[..original.len() - 10]).unwrap();
        assert!(matches!(
            idx.load_maps(dir.path()),
            Err(MapsError::FileSize { .. })
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

    #[test]
    fn resume_scan_keeps_only_valid_files_of_this_bake() {
        let dir = tempfile::tempdir().unwrap();
        let key = BakeKey::new("scene", &settings());
        let ms = maps();
        let mut entries = Vec::new();
        for (i, m) in ms.iter().enumerate() {
            entries.push(write_map_file(dir.path(), i as u32, m, &key).unwrap());
        }
        // Map 3 from another bake; map 1's file corrupted; a stale temp file; an unrelated file.
        let other = BakeKey::new("scene", &serde_json::json!({"offsets": 4}));
        let e3 = write_map_file(dir.path(), 3, &ms[0], &other).unwrap();
        let p1 = dir.path().join(&entries[1].file);
        let mut b = fs::read(&p1).unwrap();
        b.truncate(b.len() / 2);
        fs::write(&p1, b).unwrap();
        fs::write(
            dir.path().join(".map_00004_+0_+0.exr.123-0.tmp"),
            b"partial",
        )
        .unwrap();
        fs::write(dir.path().join("notes.txt"), b"hello").unwrap();

        let scan = scan_finished_maps(dir.path(), &key, 16, 8).unwrap();
        assert_eq!(
            scan.finished.keys().copied().collect::<Vec<_>>(),
            vec![0, 2]
        );
        assert_eq!(scan.finished[&0], entries[0]);
        assert_eq!(scan.finished[&2], entries[2]);
        let rejected: Vec<PathBuf> = scan.rejected.iter().map(|(p, _)| p.clone()).collect();
        assert_eq!(rejected, vec![p1, dir.path().join(&e3.file)]);
        assert_eq!(scan.stale_temp.len(), 1);
        // Wrong lightmap size rejects everything.
        let scan = scan_finished_maps(dir.path(), &key, 16, 9).unwrap();
        assert!(scan.finished.is_empty());
        // A missing directory is an empty scan.
        let scan = scan_finished_maps(&dir.path().join("nope"), &key, 16, 8).unwrap();
        assert_eq!(scan, ResumeScan::default());
    }
}
