//! The on-disk contract of a bake directory: `index.json` and one OpenEXR file per transfer map
//! (format in `docs/bake-format.md`).
//!
//! # Data flow
//! 1. The bake hands each finished [`crate::maps::TransferMap`] to [`write_map_file`], which
//!    encodes it ([`map_file`]), writes `map_<i>_<±dx>_<±dy>.exr` atomically and returns the
//!    [`MapEntry`] (file name, size, SHA-256). After all maps it writes `index.json` with
//!    [`BakeIndex::write`].
//! 2. A rerun of the same bake ([`BakeKey`]) keeps the map files [`scan_finished_maps`] accepts.
//! 3. Consumers (`ortm bin`, `ortm render`, the viewer) read the index with [`BakeIndex::read`]
//!    and the maps with [`BakeIndex::load_maps`] (size, SHA-256, header and bake key checked),
//!    or one file with [`read_map_file`].
//!
//! # Modules
//! - [`key`] — [`BakeKey`] and [`map_file_name`], used by both the files and the index.
//! - [`map_file`] — the map file codec (bytes ↔ [`MapFile`]).
//! - [`index`] — `index.json` ([`BakeIndex`]) and [`write_map_file`].
//! - [`resume`] — [`scan_finished_maps`].
//! - [`selection`] — `selection.json` ([`SelectionRecord`], checksummed; [`read_selection`]).
//! - [`trust`] — [`check_recorded_scene`]: which recorded scene a reader may open unasked.
//!
//! The arrows point one way: `resume → index → map_file → key`. Errors are
//! [`crate::maps::MapsError`]; the file-level ones are [`crate::io::FileError`]s worded for a
//! bake directory.

#[cfg(test)]
mod fixtures;
pub mod index;
pub mod key;
pub mod map_file;
pub mod resume;
pub mod selection;
pub mod trust;

pub use index::{
    BakeIndex, INDEX_FILE_NAME, INDEX_FORMAT, INDEX_VERSION, LightmapSize, MapEntry, index_digest,
    write_map_file,
};
pub use key::{BakeKey, map_file_name};
pub use map_file::{MapFile, decode_map, encode_map, read_map_file};
pub use resume::{ResumeScan, scan_finished_maps};
pub use selection::{SELECTION_FILE_NAME, SavedSelection, SelectionRecord, read_selection};
pub use trust::check_recorded_scene;
