//! Resuming a bake: which map files already in a bake directory can be kept.
//!
//! The bake writes each map as soon as it is done, stamped with its [`BakeKey`]. On a rerun,
//! [`scan_finished_maps`] returns the maps already on disk that decode, pass their content hash,
//! and carry the same bake key and lightmap size, so the bake can skip them (it should also
//! check that each returned entry's offset is the one it planned for that index). Leftover
//! temporary files of interrupted atomic writes are listed, never read.

use std::collections::{BTreeMap, HashMap};
use std::fs;
use std::path::{Path, PathBuf};

use glam::IVec2;
use rayon::prelude::*;

use super::index::MapEntry;
use super::key::{BakeKey, parse_map_file_name};
use super::map_file::decode_map;
use crate::io::{DirKind, FileError, sha256_hex};
use crate::maps::MapsError;

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

/// Scans `dir` for map files a resumed bake can keep: names of the form [`map_file_name`](super::map_file_name) whose
/// file decodes, passes its content hash, was stamped with `key`, has the given lightmap size,
/// and whose header index/offset match its name. A missing `dir` gives an empty scan. Files are
/// never deleted here.
///
/// # Errors
/// [`FileError::Io`] if `dir` exists but cannot be listed. Bad individual files are reported in
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
        Err(e) => return Err(FileError::io("cannot list", dir, DirKind::Bake)(e).into()),
    };
    let mut candidates = Vec::new();
    for entry in entries {
        let entry = entry.map_err(FileError::io("cannot list", dir, DirKind::Bake))?;
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        // Symbolic links are never reused (they could point outside the bake directory).
        let regular = entry.file_type().is_ok_and(|t| t.is_file());
        if crate::io::is_temp_name(&name) {
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
    let bytes = crate::io::read_bounded(path, crate::io::limits::MAX_EXR_BYTES, "MAX_EXR_BYTES")
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
    use crate::bake_dir::write_map_file;

    use crate::bake_dir::fixtures::{maps, settings};

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
