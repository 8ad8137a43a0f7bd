//! File and resource utilities shared by every stage.
//!
//! - [`limits`]: every limit on untrusted inputs and on the memory a request may need.
//! - Reading ([`open_regular`], which checks the file type without blocking, [`read_bounded`], [`resolve_listed`], [`read_listed`]): a byte bound before
//!   anything is read, plain names resolved inside their directory, and a listed file checked
//!   against the size and SHA-256 its index recorded.
//! - Writing ([`write_atomic`], [`write_png_atomic`]): temporary file in the same directory,
//!   `fsync`, rename; readers never see a half-written file; [`with_write_pool`] keeps many
//!   such writes in flight so that their `fsync`s are committed together.
//! - [`DirLock`]: the one-writer lock of a bake or atlas directory (`flock` on
//!   [`LOCK_FILE_NAME`]).
//! - Digests ([`sha256_hex`], [`is_hex_digest`]): SHA-256 as lower-case hex, as the indexes
//!   record it.
//! - [`FileError`]: the failures shared by bake directories (`docs/bake-format.md`) and atlas
//!   directories (`docs/atlas-format.md`), worded for each by [`DirKind`].
//! - Versioned JSON ([`to_versioned_json`], [`from_versioned_json`]): the `format` and
//!   `version` fields of `index.json` and `atlases.json`, checked before the body.
//! - [`exr`]: the OpenEXR pieces shared by the map and atlas file codecs (the `ortmMeta`
//!   attribute, accepted compressions, RGB f32 channels).

mod atomic;
mod digest;
mod error;
pub mod exr;
pub mod limits;
mod lock;
mod read;
mod versioned;

pub use atomic::{
    WRITE_THREADS, is_temp_name, with_write_pool, write_atomic, write_atomic_with, write_png_atomic,
};
pub use digest::{hex, is_hex_digest, sha256_hex};
pub use error::{DirKind, FileError};
pub use lock::{DirLock, LOCK_FILE_NAME, LockError};
pub use read::{
    ListedFile, not_a_regular_file, open_regular, plain_file_name, read_bounded, read_listed,
    resolve_listed,
};
pub use versioned::{VersionedError, from_versioned_json, to_versioned_json};
