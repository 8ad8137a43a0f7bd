//! [`FileError`]: the failures every directory of index-listed files shares (a bake directory's
//! `index.json` and map files, an atlas directory's `atlases.json` and atlas files). The bake
//! errors ([`crate::maps::MapsError`]) and atlas errors ([`crate::atlas::AtlasError`]) wrap it;
//! [`DirKind`] picks the nouns and the fix its messages name.

use std::fmt;
use std::path::PathBuf;

/// Which kind of directory a file belongs to; decides the wording of a [`FileError`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum DirKind {
    /// A bake directory: `index.json` and the transfer-map files.
    Bake,
    /// An atlas directory: `atlases.json` and the atlas files.
    Atlas,
}

impl DirKind {
    /// What one listed file is ("map", "atlas").
    fn noun(self) -> &'static str {
        match self {
            Self::Bake => "map",
            Self::Atlas => "atlas",
        }
    }

    /// The index that lists the files ("index", "atlas index").
    pub(super) fn index(self) -> &'static str {
        match self {
            Self::Bake => "index",
            Self::Atlas => "atlas index",
        }
    }

    /// The directory ("bake", "atlas").
    pub(super) fn dir(self) -> &'static str {
        match self {
            Self::Bake => "bake",
            Self::Atlas => "atlas",
        }
    }

    /// The command that rewrites the directory.
    fn rerun(self) -> &'static str {
        match self {
            Self::Bake => "re-run the bake",
            Self::Atlas => "re-run `ortm bin`",
        }
    }
}

/// A file of a bake or atlas directory that cannot be read, written or trusted.
#[derive(Debug)]
pub enum FileError {
    /// A file-system operation failed (including files over a byte limit and files that are
    /// not regular files: see [`crate::io::read_bounded`]).
    Io {
        /// What was being done ("cannot read", "cannot create directory", …).
        op: &'static str,
        /// The file or directory.
        path: PathBuf,
        /// The underlying error.
        source: std::io::Error,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// A file name in an index (or one to be written) is not a plain file name.
    BadFileName {
        /// The index naming the file.
        index: PathBuf,
        /// The rejected name.
        name: String,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// A file named in an index resolves (through a symbolic link) outside its directory, or is
    /// not a regular file.
    PathEscape {
        /// The path named by the index.
        path: PathBuf,
        /// What is wrong (where it resolves to).
        problem: String,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// A file listed in the index does not exist.
    MissingFile {
        /// The missing file.
        path: PathBuf,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// A file's size differs from the index.
    FileSize {
        /// The file.
        path: PathBuf,
        /// Size recorded in the index.
        expected: u64,
        /// Size on disk.
        found: u64,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// A file's SHA-256 differs from the index.
    Checksum {
        /// The file.
        path: PathBuf,
        /// Hex digest recorded in the index.
        expected: String,
        /// Hex digest of the file on disk.
        found: String,
        /// Bake or atlas directory.
        kind: DirKind,
    },
    /// The OpenEXR decoder or encoder failed (corrupt or truncated file, unsupported feature).
    Exr {
        /// "decode" or "encode".
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The codec's error.
        source: exr::error::Error,
        /// Bake or atlas directory.
        kind: DirKind,
    },
}

impl FileError {
    /// A closure that wraps an `std::io::Error` of `op` on `path` (for `map_err`).
    pub fn io<'a>(
        op: &'static str,
        path: &'a std::path::Path,
        kind: DirKind,
    ) -> impl FnOnce(std::io::Error) -> Self + 'a {
        move |source| Self::Io {
            op,
            path: path.to_owned(),
            source,
            kind,
        }
    }
}

impl fmt::Display for FileError {
    /// One match over the variants and directory kinds, one message per arm: the table of
    /// messages reads best in one place.
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        use DirKind::{Atlas, Bake};
        match self {
            Self::Io {
                op,
                path,
                source,
                kind,
            } => {
                let fix = match kind {
                    Bake => "check that the directory exists, is writable and has free space",
                    Atlas => {
                        "check that the path exists, is readable/writable and the disk has space"
                    }
                };
                write!(f, "{op} {}: {source}; {fix}", path.display())
            }
            Self::BadFileName { index, name, kind } => match kind {
                Bake => write!(
                    f,
                    "{}: map file name {name:?} is not allowed (it must be a plain file name \
                     inside the bake directory: no '/', '\\', '..', drive or absolute path); \
                     regenerate the index",
                    index.display()
                ),
                Atlas => write!(
                    f,
                    "{}: atlas file name {name:?} is not allowed (it must be a plain file name: \
                     no '/', '\\', ':', '..', not absolute); re-run `ortm bin`",
                    index.display()
                ),
            },
            Self::PathEscape {
                path,
                problem,
                kind,
            } => match kind {
                Bake => write!(
                    f,
                    "{} named in the index {problem}; a bake directory must hold its files \
                     itself (copy the file into the directory instead of linking to it)",
                    path.display()
                ),
                Atlas => write!(
                    f,
                    "atlas file {} {problem}; an atlas directory must hold its files itself \
                     (copy the file instead of linking to it, or re-run `ortm bin`)",
                    path.display()
                ),
            },
            Self::MissingFile { path, kind } => write!(
                f,
                "{} file {} listed in the {} is missing; copy the complete {} directory or {}",
                kind.noun(),
                path.display(),
                kind.index(),
                kind.dir(),
                kind.rerun()
            ),
            Self::FileSize {
                path,
                expected,
                found,
                kind,
            } => write!(
                f,
                "{} file {} has {found} bytes but the {} says {expected}; the file is truncated \
                 or was replaced, {}",
                kind.noun(),
                path.display(),
                kind.index(),
                kind.rerun()
            ),
            Self::Checksum {
                path,
                expected,
                found,
                kind,
            } => write!(
                f,
                "{} file {} has SHA-256 {found} but the {} says {expected}; the file is corrupt \
                 or was replaced, {}",
                kind.noun(),
                path.display(),
                kind.index(),
                kind.rerun()
            ),
            Self::Exr {
                op,
                path,
                source,
                kind,
            } => match kind {
                Bake => write!(
                    f,
                    "cannot {op} OpenEXR file {}: {source}; the file is corrupt or truncated, \
                     delete it and re-run the bake to regenerate it",
                    path.display()
                ),
                Atlas => write!(
                    f,
                    "cannot {op} OpenEXR atlas file {}: {source}; the file is corrupt or \
                     truncated, re-run `ortm bin`",
                    path.display()
                ),
            },
        }
    }
}

impl std::error::Error for FileError {
    fn source(&self) -> Option<&(dyn std::error::Error + 'static)> {
        match self {
            Self::Io { source, .. } => Some(source),
            Self::Exr { source, .. } => Some(source),
            _ => None,
        }
    }
}
