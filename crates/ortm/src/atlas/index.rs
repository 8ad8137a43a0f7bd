//! The atlas index `atlases.json` (format in `docs/atlas-format.md`) and the directory it
//! describes: [`write_atlas_set`] writes the atlas files and then the index, [`read_atlas_index`]
//! and [`read_atlas_set`] read them back with every check a renderer needs (module doc of
//! [`crate::atlas`], steps 2 and 3).

use std::collections::HashSet;
use std::fs;
use std::path::Path;

use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use super::file::{atlas_file_name, decode_atlas, encode_atlas};
use super::validate::{check_coverage, check_geometry};
use super::{AtlasError, AtlasPiece, AtlasSet};
use crate::bake_dir::{INDEX_FILE_NAME, INDEX_FORMAT, LightmapSize};
use crate::io::DirKind::Atlas;
use crate::io::limits::MAX_JSON_BYTES;
use crate::io::{FileError, is_hex_digest, plain_file_name, sha256_hex, write_atomic};

/// File name of the atlas index inside an atlas directory.
pub const ATLAS_INDEX_FILE_NAME: &str = "atlases.json";

/// Value of the atlas index's `format` field.
pub const ATLAS_INDEX_FORMAT: &str = "ortm-atlases";

/// The atlas index version this build writes and reads.
pub const ATLAS_INDEX_VERSION: u32 = 2;

/// One atlas file of the index.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasFileEntry {
    /// Plain file name inside the atlas directory, e.g. `atlas_000.exr`.
    pub file: String,
    /// File size in bytes.
    pub bytes: u64,
    /// Lower-case hex SHA-256 of the whole file.
    pub sha256: String,
}

/// The contents of `atlases.json` (without `format` and `version`).
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct AtlasIndex {
    /// Atlas size, texels.
    pub atlas_size: LightmapSize,
    /// Lightmap size, texels.
    pub lightmap: LightmapSize,
    /// Bake key of the bake whose maps were packed (64 lower-case hex digits).
    pub bake_key: String,
    /// SHA-256 (64 lower-case hex digits) of the bytes of the bake's `index.json` the maps
    /// were packed from; `None` for a set not made from an index file. Readers that find an
    /// `index.json` beside `atlases.json` require it and compare.
    pub bake_index_sha256: Option<String>,
    /// One entry per atlas, in atlas order.
    pub atlases: Vec<AtlasFileEntry>,
    /// Every piece, sorted by `(atlas, src_y, src_x)`.
    pub pieces: Vec<AtlasPiece>,
}

/// Removes temporary files an interrupted `write_atlas_set` left (`.atlas_*.tmp`,
/// `.atlases.json.*.tmp`: never read, since final names are only created by rename). Only
/// called under the directory's lock, so no live writer's temporaries are removed.
fn remove_stale_temp_files(lock: &crate::io::DirLock) {
    let dir = lock.dir();
    let Ok(entries) = fs::read_dir(dir) else {
        return;
    };
    for e in entries.flatten() {
        let name = e.file_name();
        let name = name.to_string_lossy();
        let ours = name.starts_with(".atlas_") || name.starts_with(".atlases.json.");
        if ours && crate::io::is_temp_name(&name) && e.file_type().is_ok_and(|t| t.is_file()) {
            let _ = fs::remove_file(e.path());
        }
    }
}

/// Writes `set` into `dir` (created if needed), holding its write lock ([`crate::io::DirLock`];
/// [`AtlasError::Lock`] when another process holds it): one OpenEXR file per atlas
/// ([`atlas_file_name`]) and then `atlases.json`, each atomically (temporary name, `fsync`,
/// rename). An existing `atlases.json` is removed first, so an interrupted run never leaves an
/// index that points at half-replaced atlases. Files from an earlier run that the new index does
/// not list are left alone (and ignored by readers). Returns the index written.
///
/// `bake_key` is the key of the bake the maps came from (`BakeIndex::bake_key`, 64 lower-case
/// hex digits); [`read_atlas_set`] compares it with the bake's `index.json`.
///
/// # Errors
/// [`AtlasError::InvalidSet`] for an inconsistent set or a malformed key, [`FileError::Io`],
/// [`FileError::Exr`].
pub fn write_atlas_set(
    dir: &Path,
    set: &AtlasSet,
    bake_key: &str,
) -> Result<AtlasIndex, AtlasError> {
    let lock = crate::io::DirLock::acquire(dir)?;
    write_atlas_set_locked(&lock, set, bake_key, None)
}

/// [`write_atlas_set`] into the directory of `lock`, which the caller holds (so that it can
/// write more files, such as pictures, under the same lock). `bake_index_sha256` is the
/// SHA-256 of the bake's `index.json` the maps came from ([`crate::bake_dir::BakeIndex::read_with_sha256`]);
/// `None` records that of the `index.json` in the directory, if there is one.
///
/// # Errors
/// Those of [`write_atlas_set`] but [`AtlasError::Lock`].
pub fn write_atlas_set_locked(
    lock: &crate::io::DirLock,
    set: &AtlasSet,
    bake_key: &str,
    bake_index_sha256: Option<&str>,
) -> Result<AtlasIndex, AtlasError> {
    let dir = lock.dir();
    set.validate()?;
    if !is_hex_digest(bake_key) {
        return Err(AtlasError::InvalidSet {
            reason: format!("bake key {bake_key:?} is not 64 lower-case hex digits"),
        });
    }
    let bake_index_sha256 = match bake_index_sha256 {
        Some(d) if is_hex_digest(d) => Some(d.to_owned()),
        Some(d) => {
            return Err(AtlasError::InvalidSet {
                reason: format!("bake index digest {d:?} is not 64 lower-case hex digits"),
            });
        }
        None => {
            let path = dir.join(INDEX_FILE_NAME);
            match crate::io::read_bounded(&path, MAX_JSON_BYTES, "MAX_JSON_BYTES") {
                Ok(bytes) => crate::bake_dir::index_digest(&bytes).ok(),
                Err(e) if e.kind() == std::io::ErrorKind::NotFound => None,
                Err(e) => {
                    return Err(FileError::io("cannot read bake index", &path, Atlas)(e).into());
                }
            }
        }
    };
    let atlas_count = u32::try_from(set.atlases.len()).map_err(|_| AtlasError::InvalidSet {
        reason: format!("{} atlases is too many", set.atlases.len()),
    })?;
    fs::create_dir_all(dir).map_err(FileError::io("cannot create directory", dir, Atlas))?;
    remove_stale_temp_files(lock);
    let index_path = dir.join(ATLAS_INDEX_FILE_NAME);
    match fs::remove_file(&index_path) {
        Ok(()) => {}
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {}
        Err(e) => {
            return Err(
                FileError::io("cannot remove the old atlas index", &index_path, Atlas)(e).into(),
            );
        }
    }
    let entries: Vec<Result<AtlasFileEntry, AtlasError>> = (0..atlas_count)
        .into_par_iter()
        .map(|i| {
            let file = atlas_file_name(i);
            let path = dir.join(&file);
            let bytes = encode_atlas(&path, i, set.atlas_size, &set.atlases[i as usize], bake_key)?;
            write_atomic(&path, &bytes).map_err(FileError::io("cannot write", &path, Atlas))?;
            Ok(AtlasFileEntry {
                file,
                bytes: bytes.len() as u64,
                sha256: sha256_hex(&bytes),
            })
        })
        .collect();
    let index = AtlasIndex {
        atlas_size: LightmapSize {
            width: set.atlas_size.0,
            height: set.atlas_size.1,
        },
        lightmap: LightmapSize {
            width: set.lightmap_size.0,
            height: set.lightmap_size.1,
        },
        bake_key: bake_key.to_owned(),
        bake_index_sha256,
        atlases: entries.into_iter().collect::<Result<_, _>>()?,
        pieces: set.pieces.clone(),
    };
    let json = crate::io::to_versioned_json(ATLAS_INDEX_FORMAT, ATLAS_INDEX_VERSION, &index)
        .map_err(|source| AtlasError::Json {
            path: index_path.clone(),
            source,
        })?;
    write_atomic(&index_path, json.as_bytes()).map_err(FileError::io(
        "cannot write",
        &index_path,
        Atlas,
    ))?;
    Ok(index)
}

/// Reads and validates `dir/atlases.json` (format, version, schema, sizes, file names, digest
/// syntax, piece geometry) and, if `dir/index.json` exists, checks that it is the bake the
/// atlases were packed from (same bake key and lightmap size). Atlas files are not opened.
///
/// # Errors
/// [`AtlasError::MissingIndex`], [`FileError::Io`], [`AtlasError::Json`],
/// [`AtlasError::Format`], [`AtlasError::Version`], [`AtlasError::BadIndex`],
/// [`FileError::BadFileName`], [`AtlasError::BakeIndex`], [`AtlasError::BakeMismatch`].
pub fn read_atlas_index(dir: &Path) -> Result<AtlasIndex, AtlasError> {
    let path = dir.join(ATLAS_INDEX_FILE_NAME);
    let text = match crate::io::read_bounded(&path, MAX_JSON_BYTES, "MAX_JSON_BYTES") {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(AtlasError::MissingIndex { path });
        }
        Err(e) => return Err(FileError::io("cannot read atlas index", &path, Atlas)(e).into()),
    };
    let index = parse_atlas_index(&path, &text)?;
    check_entries(&path, &index)?;
    check_files(dir, &path, &index)?;
    check_geometry(
        (index.atlas_size.width, index.atlas_size.height),
        (index.lightmap.width, index.lightmap.height),
        index.atlases.len(),
        &index.pieces,
    )
    .map_err(|reason| AtlasError::BadIndex {
        path: path.clone(),
        reason,
    })?;
    check_bake(dir, &path, &index)?;
    Ok(index)
}

/// Parses the JSON of the atlas index at `path`: `format` and `version` first, then the schema
/// ([`crate::io::from_versioned_json`]).
fn parse_atlas_index(path: &Path, text: &[u8]) -> Result<AtlasIndex, AtlasError> {
    use crate::io::VersionedError as V;
    crate::io::from_versioned_json(text, ATLAS_INDEX_FORMAT, ATLAS_INDEX_VERSION).map_err(|e| {
        let path = path.to_owned();
        match e {
            V::Json(source) => AtlasError::Json { path, source },
            V::NotObject => AtlasError::BadIndex {
                path,
                reason: "the top level is not a JSON object".into(),
            },
            V::Format(found) => AtlasError::Format { path, found },
            V::Version(found) => AtlasError::Version { path, found },
        }
    })
}

/// The bake key and every file entry's name (plain, unique) and digest are well-formed.
fn check_entries(path: &Path, index: &AtlasIndex) -> Result<(), AtlasError> {
    let bad = |reason: String| AtlasError::BadIndex {
        path: path.to_owned(),
        reason,
    };
    if !is_hex_digest(&index.bake_key) {
        return Err(bad(format!(
            "bake_key {:?} is not 64 lower-case hex digits",
            index.bake_key
        )));
    }
    if let Some(d) = &index.bake_index_sha256
        && !is_hex_digest(d)
    {
        return Err(bad(format!(
            "bake_index_sha256 {d:?} is not 64 lower-case hex digits"
        )));
    }
    let mut names = HashSet::new();
    for (i, a) in index.atlases.iter().enumerate() {
        if !plain_file_name(&a.file) {
            return Err(FileError::BadFileName {
                index: path.to_owned(),
                name: a.file.clone(),
                kind: Atlas,
            }
            .into());
        }
        if !names.insert(a.file.as_str()) {
            return Err(bad(format!(
                "atlases[{i}]: file {:?} appears twice",
                a.file
            )));
        }
        if !is_hex_digest(&a.sha256) {
            return Err(bad(format!(
                "atlases[{i}]: sha256 {:?} is not 64 lower-case hex digits",
                a.sha256
            )));
        }
    }
    Ok(())
}

/// The atlas files exist inside `dir` with the recorded sizes, and those sizes can hold the
/// declared atlas size: this bounds the work of the geometry checks by the files on disk, not
/// by numbers in the JSON.
fn check_files(dir: &Path, path: &Path, index: &AtlasIndex) -> Result<(), AtlasError> {
    let atlas_texels = u64::from(index.atlas_size.width) * u64::from(index.atlas_size.height);
    for a in &index.atlases {
        let (file, len) = crate::io::resolve_listed(dir, ATLAS_INDEX_FILE_NAME, &a.file, Atlas)?;
        if len != a.bytes {
            return Err(FileError::FileSize {
                path: file,
                expected: a.bytes,
                found: len,
                kind: Atlas,
            }
            .into());
        }
        crate::io::limits::check_exr_pixels(
            &format!("atlas size in {} for {}", path.display(), file.display()),
            atlas_texels,
            len,
        )
        .map_err(|e| AtlasError::BadIndex {
            path: path.to_owned(),
            reason: e.to_string(),
        })?;
    }
    Ok(())
}

/// If `dir/index.json` exists, checks its bake key and lightmap size against the atlas index,
/// and that every piece's map exists in it with the piece's offset.
fn check_bake(dir: &Path, atlas_index: &Path, index: &AtlasIndex) -> Result<(), AtlasError> {
    let path = dir.join(INDEX_FILE_NAME);
    let text = match crate::io::read_bounded(&path, MAX_JSON_BYTES, "MAX_JSON_BYTES") {
        Ok(t) => t,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(FileError::io("cannot read bake index", &path, Atlas)(e).into()),
    };
    let bad = |reason: String| AtlasError::BakeIndex {
        path: path.clone(),
        reason,
    };
    let v: serde_json::Value =
        serde_json::from_slice(&text).map_err(|e| bad(format!("not valid JSON ({e})")))?;
    if v.get("format").and_then(|f| f.as_str()) != Some(INDEX_FORMAT) {
        return Err(bad(format!("field \"format\" is not \"{INDEX_FORMAT}\"")));
    }
    let key = v
        .get("bake_key")
        .and_then(|k| k.as_str())
        .ok_or_else(|| bad("field \"bake_key\" is missing".into()))?;
    let lightmap: LightmapSize = v
        .get("lightmap")
        .and_then(|l| serde_json::from_value(l.clone()).ok())
        .ok_or_else(|| bad("field \"lightmap\" is missing or malformed".into()))?;
    let mismatch = |what| AtlasError::BakeMismatch {
        index: atlas_index.to_owned(),
        bake: path.clone(),
        atlas_key: index.bake_key.clone(),
        bake_key: key.to_owned(),
        what,
    };
    if key != index.bake_key {
        return Err(mismatch("bake key"));
    }
    if lightmap != index.lightmap {
        return Err(mismatch("lightmap size"));
    }
    // Every piece's map is in the bake index with the piece's offset.
    let maps = v
        .get("maps")
        .and_then(|m| m.as_array())
        .ok_or_else(|| bad("field \"maps\" is missing or not an array".into()))?;
    let offsets: Vec<Option<([i32; 2], u32, u32)>> = maps
        .iter()
        .map(|m| {
            let o = m
                .get("offset")
                .and_then(|o| serde_json::from_value(o.clone()).ok())?;
            let level = |name| match m.get(name) {
                None => Some(0),
                Some(l) => serde_json::from_value(l.clone()).ok(),
            };
            Some((o, level("level")?, level("receiver_level")?))
        })
        .collect();
    for (i, p) in index.pieces.iter().enumerate() {
        match offsets.get(p.map_index as usize) {
            Some(Some(o)) if *o == (p.offset, p.level, p.receiver_level) => {}
            found => {
                return Err(AtlasError::BadIndex {
                    path: atlas_index.to_owned(),
                    reason: format!(
                        "piece {i} is map {} with {}, but the bake index {} has {}; the \
                         atlases were packed from another bake: re-run `ortm bin`",
                        p.map_index,
                        offset_text(p.offset, p.level, p.receiver_level),
                        path.display(),
                        match found {
                            None => format!("{} maps", offsets.len()),
                            Some(Some((o, l, r))) => {
                                format!("{} for that map", offset_text(*o, *l, *r))
                            }
                            Some(None) => "no readable offset for that map".into(),
                        }
                    ),
                });
            }
        }
    }
    // The pieces of each map cover its crop rectangles exactly once (a single rectangle padded
    // to the width the packer stores, inside the map's receiver grid: docs/atlas-format.md,
    // "Width padding").
    let lightmap = (index.lightmap.width, index.lightmap.height);
    let pad = |r: Vec<[u32; 4]>, level: u32| {
        let lw = crate::maps::receiver_grid(lightmap, level).0;
        match r.as_slice() {
            [[x, y, w, h]] if *w <= lw => match super::build::padded_columns(*x, *w, lw) {
                Some((xp, wp)) => vec![[xp, *y, wp, *h]],
                None => r,
            },
            _ => r,
        }
    };
    let rects = maps
        .iter()
        .enumerate()
        .map(|(m, e)| {
            let level = offsets[m].map_or(0, |o| o.2);
            e.get("rects")
                .and_then(|r| serde_json::from_value::<Vec<crate::maps::CropRect>>(r.clone()).ok())
                .map(|r| pad(r.iter().map(|r| [r.x, r.y, r.w, r.h]).collect(), level))
                .ok_or_else(|| {
                    bad(format!(
                        "maps[{m}]: field \"rects\" is missing or malformed"
                    ))
                })
        })
        .collect::<Result<Vec<Vec<[u32; 4]>>, _>>()?;
    check_coverage(&index.pieces, &rects).map_err(|reason| AtlasError::BadIndex {
        path: atlas_index.to_owned(),
        reason,
    })?;
    // Last, so that the checks above name what differs when they can.
    let digest = sha256_hex(&serde_json::to_vec(&v).map_err(|e| bad(e.to_string()))?);
    match &index.bake_index_sha256 {
        Some(d) if *d == digest => {}
        recorded => {
            return Err(AtlasError::BadIndex {
                path: atlas_index.to_owned(),
                reason: format!(
                    "it records the bake index SHA-256 {}, but {} has {digest}: the atlases were \
                     not made from this bake index",
                    recorded.as_deref().unwrap_or("null"),
                    path.display()
                ),
            });
        }
    }
    Ok(())
}

/// Reads an atlas directory written by [`write_atlas_set`]: [`read_atlas_index`]'s checks, then
/// every atlas file (in parallel): present, recorded size and SHA-256
/// ([`crate::io::read_listed`]), a single-part `B, G, R` f32 OpenEXR image of the atlas size
/// stamped with its atlas number and the bake key, finite values. On several bad files the
/// first atlas's error is returned.
///
/// # Errors
/// Those of [`read_atlas_index`], and [`FileError::MissingFile`], [`FileError::FileSize`],
/// [`FileError::Checksum`], [`FileError::Exr`], [`AtlasError::BadAtlasFile`],
/// [`FileError::Io`].
pub fn read_atlas_set(dir: &Path) -> Result<AtlasSet, AtlasError> {
    let index = read_atlas_index(dir)?;
    let size = (index.atlas_size.width, index.atlas_size.height);
    let atlases: Vec<Result<Vec<[f32; 3]>, AtlasError>> = index
        .atlases
        .par_iter()
        .enumerate()
        .map(|(i, a)| {
            let f = crate::io::read_listed(
                dir,
                ATLAS_INDEX_FILE_NAME,
                &a.file,
                a.bytes,
                &a.sha256,
                Atlas,
            )?;
            decode_atlas(&f.path, &f.bytes, i as u32, size, &index.bake_key)
        })
        .collect();
    Ok(AtlasSet {
        atlas_size: size,
        lightmap_size: (index.lightmap.width, index.lightmap.height),
        atlases: atlases.into_iter().collect::<Result<_, _>>()?,
        pieces: index.pieces,
    })
}

/// `offset [dx, dy]`, with ` at level ℓ` for a multi-resolution map and `, receiver level r`
/// for receiver blocks.
fn offset_text(offset: [i32; 2], level: u32, receiver_level: u32) -> String {
    match (level, receiver_level) {
        (0, 0) => format!("offset {offset:?}"),
        (l, 0) => format!("offset {offset:?} at level {l}"),
        (l, r) => format!("offset {offset:?} at level {l}, receiver level {r}"),
    }
}
