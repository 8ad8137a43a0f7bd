//! `selection.json`: the offsets a bake selected (and the importance data points of its
//! report), saved before the maps so that a resumed bake does not select again.
//!
//! The record carries `sha256`, the SHA-256 of its bake key, offsets and data points
//! ([`SelectionRecord::digest`]), so a file edited by hand or damaged on disk is never reused:
//! [`read_selection`] discards a record whose digest, bake key or plausibility check fails and
//! the bake selects again (the same offsets for the same seed). A `selection.json` that is not a
//! regular file (a FIFO, a directory) is an error, found without blocking.

use std::path::Path;

use serde::{Deserialize, Serialize};
use sha2::{Digest, Sha256};

use crate::io::{DirKind, FileError};

/// Name of the selection file in a bake directory.
pub const SELECTION_FILE_NAME: &str = "selection.json";

/// Offsets chosen by a selection, with the data needed for the report.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct SelectionRecord {
    /// Bake key the selection belongs to.
    pub bake_key: String,
    /// Selected offsets `(dx, dy)`.
    pub offsets: Vec<[i32; 2]>,
    /// Evaluated data points `(dx, dy, transference)` of the importance density.
    pub data_points: Vec<[f64; 3]>,
    /// [`Self::digest`] of the other fields (64 lower-case hex digits); empty in files written
    /// before the field existed, which are therefore selected again.
    #[serde(default)]
    pub sha256: String,
}

impl SelectionRecord {
    /// A record with its digest filled in.
    pub fn new(bake_key: &str, offsets: Vec<[i32; 2]>, data_points: Vec<[f64; 3]>) -> Self {
        let mut r = Self {
            bake_key: bake_key.to_owned(),
            offsets,
            data_points,
            sha256: String::new(),
        };
        r.sha256 = r.digest();
        r
    }

    /// SHA-256 (lower-case hex) of the bake key (UTF-8), the offset count and offsets (`i32`
    /// little-endian), and the data-point count and data points (`f64` bits, little-endian).
    pub fn digest(&self) -> String {
        let mut h = Sha256::new();
        h.update(self.bake_key.as_bytes());
        h.update((self.offsets.len() as u64).to_le_bytes());
        for v in self.offsets.iter().flatten() {
            h.update(v.to_le_bytes());
        }
        h.update((self.data_points.len() as u64).to_le_bytes());
        for v in self.data_points.iter().flatten() {
            h.update(v.to_bits().to_le_bytes());
        }
        crate::io::hex(&h.finalize())
    }

    /// Whether a saved selection can be reused for `count` offsets of a `w×h` lightmap: that
    /// many distinct offsets, each inside `(−w, w) × (−h, h)`, and finite data points. A file
    /// that fails is ignored (the bake selects again, which gives the same offsets for a seed).
    pub fn is_plausible(&self, count: usize, w: u32, h: u32) -> bool {
        let (w, h) = (i64::from(w), i64::from(h));
        let inside = |o: &[i32; 2]| i64::from(o[0]).abs() < w && i64::from(o[1]).abs() < h;
        let distinct = self
            .offsets
            .iter()
            .collect::<std::collections::HashSet<_>>()
            .len();
        self.offsets.len() == count
            && distinct == count
            && self.offsets.iter().all(inside)
            && self.data_points.iter().flatten().all(|v| v.is_finite())
    }
}

/// What [`read_selection`] found.
#[derive(Debug)]
pub enum SavedSelection {
    /// No `selection.json`.
    None,
    /// A record of this bake that passed every check.
    Reuse(SelectionRecord),
    /// A record that must not be reused, and why (for a message; the bake selects again).
    Discard(String),
}

/// Reads `dir/selection.json` for the bake `key` with `count` offsets on a `w×h` lightmap.
///
/// # Errors
/// [`FileError::Io`] when the path exists but is not a regular file (a FIFO, a directory, a
/// device, a link loop) or cannot be read.
pub fn read_selection(
    dir: &Path,
    key: &str,
    count: usize,
    (w, h): (u32, u32),
) -> Result<SavedSelection, FileError> {
    let path = dir.join(SELECTION_FILE_NAME);
    let limit = crate::io::limits::MAX_JSON_BYTES;
    let bytes = match crate::io::read_bounded(&path, limit, "MAX_JSON_BYTES") {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(SavedSelection::None),
        Err(e) if e.kind() == std::io::ErrorKind::InvalidData => {
            return Ok(SavedSelection::Discard(format!("{}: {e}", path.display())));
        }
        Err(e) => return Err(FileError::io("cannot read", &path, DirKind::Bake)(e)),
    };
    let record: SelectionRecord = match serde_json::from_slice(&bytes) {
        Ok(r) => r,
        Err(e) => {
            return Ok(SavedSelection::Discard(format!(
                "{} is not a valid selection record ({e})",
                path.display()
            )));
        }
    };
    let why = if record.bake_key != key {
        "belongs to another bake"
    } else if record.sha256 != record.digest() {
        "does not match its checksum (edited or damaged)"
    } else if !record.is_plausible(count, w, h) {
        "holds offsets that do not fit this bake"
    } else {
        return Ok(SavedSelection::Reuse(record));
    };
    Ok(SavedSelection::Discard(format!("{} {why}", path.display())))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn write(dir: &Path, r: &SelectionRecord) {
        std::fs::write(
            dir.join(SELECTION_FILE_NAME),
            serde_json::to_vec_pretty(r).unwrap(),
        )
        .unwrap();
    }

    /// Data points as the selection computes them (arbitrary `f64`s) survive the JSON file bit
    /// for bit, so a resumed bake reuses its selection (serde_json's `float_roundtrip`; without
    /// it some values came back one ulp off and every resume selected again).
    #[test]
    fn arbitrary_data_points_round_trip_and_are_reused() {
        let dir = tempfile::tempdir().unwrap();
        let mut x = 0x9e37_79b9_7f4a_7c15u64;
        let mut next = || {
            x ^= x << 13;
            x ^= x >> 7;
            x ^= x << 17;
            (x >> 11) as f64 / (1u64 << 53) as f64 * 10f64.powi((x % 9) as i32 - 6)
        };
        let points: Vec<[f64; 3]> = (0..2000).map(|_| [next(), next(), next()]).collect();
        let good = SelectionRecord::new("k", vec![[1, 0], [0, -3]], points);
        std::fs::write(
            dir.path().join(SELECTION_FILE_NAME),
            serde_json::to_vec_pretty(&good).unwrap(),
        )
        .unwrap();
        match read_selection(dir.path(), "k", 2, (8, 8)).unwrap() {
            SavedSelection::Reuse(r) => assert_eq!(r.data_points, good.data_points),
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn only_an_unaltered_record_of_this_bake_is_reused() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path();
        let key = "k";
        assert!(matches!(
            read_selection(d, key, 2, (8, 8)).unwrap(),
            SavedSelection::None
        ));
        let good = SelectionRecord::new(key, vec![[1, 0], [0, -3]], vec![[1.0, 0.0, 0.1]]);
        write(d, &good);
        match read_selection(d, key, 2, (8, 8)).unwrap() {
            SavedSelection::Reuse(r) => assert_eq!(r.offsets, good.offsets),
            other => panic!("{other:?}"),
        }
        // One offset edited, checksum left alone.
        let mut edited = good.clone();
        edited.offsets[1] = [0, -2];
        write(d, &edited);
        let SavedSelection::Discard(why) = read_selection(d, key, 2, (8, 8)).unwrap() else {
            panic!("edited record reused");
        };
        assert!(why.contains("checksum"), "{why}");
        // A data point changed by one ulp is caught too.
        let mut edited = good.clone();
        edited.data_points[0][2] = f64::from_bits(0.1f64.to_bits() + 1);
        write(d, &edited);
        assert!(matches!(
            read_selection(d, key, 2, (8, 8)).unwrap(),
            SavedSelection::Discard(_)
        ));
        // Another bake's record, and a directory in the file's place.
        write(d, &good);
        assert!(matches!(
            read_selection(d, "other", 2, (8, 8)).unwrap(),
            SavedSelection::Discard(_)
        ));
        std::fs::remove_file(d.join(SELECTION_FILE_NAME)).unwrap();
        std::fs::create_dir(d.join(SELECTION_FILE_NAME)).unwrap();
        let e = read_selection(d, key, 2, (8, 8)).unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
    }
}
