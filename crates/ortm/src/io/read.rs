//! Reading files that come from users and other machines: a byte bound before anything is
//! read, plain names resolved inside their directory, and the size and SHA-256 an index
//! recorded for a file checked before its content is trusted.

use std::fs;
use std::io::Read;
use std::path::{Component, Path, PathBuf};

use super::digest::sha256_hex;
use super::error::{DirKind, FileError};

/// What a path names when it is not a regular file that can be read: the words messages use
/// ("is a directory", "is a FIFO (named pipe)", …), found from metadata alone, which never
/// blocks (opening a FIFO for reading waits for a writer).
///
/// Returns `None` for a regular file (following symbolic links).
pub fn not_a_regular_file(path: &Path) -> Option<String> {
    match fs::metadata(path) {
        Ok(meta) => kind_problem(&meta),
        Err(e) => Some(metadata_problem(path, &e)),
    }
}

/// Why metadata that was read does not describe a regular file (`None` when it does).
fn kind_problem(meta: &fs::Metadata) -> Option<String> {
    use std::os::unix::fs::FileTypeExt;
    let t = meta.file_type();
    let what = if t.is_file() {
        return None;
    } else if t.is_dir() {
        "is a directory"
    } else if t.is_fifo() {
        "is a FIFO (named pipe)"
    } else if t.is_block_device() || t.is_char_device() {
        "is a device"
    } else if t.is_socket() {
        "is a socket"
    } else {
        "is not a regular file"
    };
    Some(format!("{what}, not a regular file"))
}

/// Words for an error of `fs::metadata(path)`: a missing file, a symbolic link loop, a
/// dangling link, or the error itself.
fn metadata_problem(path: &Path, e: &std::io::Error) -> String {
    if e.raw_os_error() == Some(libc::ELOOP) {
        return "is a symbolic link loop (too many levels of symbolic links)".into();
    }
    if e.kind() == std::io::ErrorKind::NotFound {
        if fs::symlink_metadata(path).is_ok() {
            return "is a symbolic link to a file that does not exist".into();
        }
        return "does not exist".into();
    }
    format!("cannot be inspected: {e}")
}

/// Opens `path` for reading only if it is a regular file, without ever blocking: the file
/// type is checked from metadata first, the file is opened with `O_NONBLOCK` (so a FIFO put
/// in its place between the two steps cannot make `open` wait for a writer) and the opened
/// file's type is checked again. Every reader of user files goes through here (scene, mesh,
/// textures, indexes, selection, maps, atlases).
///
/// Returns the open file and its metadata.
///
/// # Errors
/// `NotFound` for a missing file; otherwise an error of kind `InvalidInput` whose message says
/// what the path is ("is a FIFO (named pipe), not a regular file", "is a directory, …", "is a
/// device, …", "is a symbolic link loop …"), or the error of opening.
pub fn open_regular(path: &Path) -> std::io::Result<(fs::File, fs::Metadata)> {
    use std::os::unix::fs::OpenOptionsExt;
    let invalid = |msg: String| std::io::Error::new(std::io::ErrorKind::InvalidInput, msg);
    match fs::metadata(path) {
        Ok(meta) => {
            if let Some(p) = kind_problem(&meta) {
                return Err(invalid(p));
            }
        }
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            if fs::symlink_metadata(path).is_err() {
                return Err(e);
            }
            return Err(invalid(metadata_problem(path, &e)));
        }
        Err(e) => return Err(invalid(metadata_problem(path, &e))),
    }
    let file = fs::OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK)
        .open(path)?;
    let meta = file.metadata()?;
    if let Some(p) = kind_problem(&meta) {
        return Err(invalid(p));
    }
    Ok((file, meta))
}

/// Reads a whole file of at most `limit` bytes: refuses anything that is not a regular file
/// (a FIFO, a device such as `/dev/zero`, a directory; [`open_regular`], which never blocks)
/// and files larger than `limit`, before reading; a file that grows while being read is cut at
/// `limit + 1` bytes and refused.
///
/// # Errors
/// The `std::io::Error` of opening or reading; a file that is not a regular file gives an
/// error of kind `InvalidInput` saying what it is; a file over the limit an error of kind
/// `InvalidData` whose message names the limit (`limit_name`).
pub fn read_bounded(path: &Path, limit: u64, limit_name: &str) -> std::io::Result<Vec<u8>> {
    let (file, meta) = open_regular(path)?;
    let too_large = |size: u64| {
        std::io::Error::new(
            std::io::ErrorKind::InvalidData,
            format!("{size} bytes exceeds the limit {limit_name} = {limit} bytes"),
        )
    };
    if meta.len() > limit {
        return Err(too_large(meta.len()));
    }
    let mut bytes = Vec::with_capacity(meta.len() as usize);
    file.take(limit + 1).read_to_end(&mut bytes)?;
    if bytes.len() as u64 > limit {
        return Err(too_large(bytes.len() as u64));
    }
    Ok(bytes)
}

/// Whether `name` is a plain file name: one normal path component, no separators (`/`, `\`),
/// no drive (`:`), no `..`, no control characters.
pub fn plain_file_name(name: &str) -> bool {
    !name.is_empty()
        && !name.contains(['/', '\\', ':', '\0'])
        && !name.contains("..")
        && !name.chars().any(char::is_control)
        && matches!(
            Path::new(name).components().collect::<Vec<_>>().as_slice(),
            [Component::Normal(_)]
        )
}

/// Why a file name from an index does not resolve to a regular file inside its directory.
#[derive(Debug, Clone, PartialEq, Eq)]
enum Unresolved {
    /// The file does not exist (or cannot be inspected).
    Missing,
    /// The name resolves (through a symbolic link) to this path outside the directory.
    Escapes(PathBuf),
    /// The name resolves to something that is not a regular file (directory, device, pipe).
    NotRegular,
}

/// Resolves the plain file `name` (already checked: one normal path component) inside `dir`,
/// following symbolic links, and refuses anything whose real path is not a regular file inside
/// the real path of `dir`. Returns `dir.join(name)` (the path to open) and its size in bytes.
///
/// # Errors
/// [`Unresolved`] saying why.
fn resolve_in_dir(dir: &Path, name: &str) -> Result<(PathBuf, u64), Unresolved> {
    let path = dir.join(name);
    let real = fs::canonicalize(&path).map_err(|_| {
        // A dangling link or a link loop exists but does not resolve: say what it is.
        if fs::symlink_metadata(&path).is_ok() {
            Unresolved::NotRegular
        } else {
            Unresolved::Missing
        }
    })?;
    let real_dir = fs::canonicalize(dir).map_err(|_| Unresolved::Missing)?;
    if real == real_dir || !real.starts_with(&real_dir) {
        return Err(Unresolved::Escapes(real));
    }
    let meta = fs::metadata(&real).map_err(|_| Unresolved::Missing)?;
    if !meta.is_file() {
        return Err(Unresolved::NotRegular);
    }
    Ok((path, meta.len()))
}

/// Resolves the file `name` that the index `dir/index_name` lists: a [`plain_file_name`] whose
/// real path is a regular file inside the real `dir` ([`resolve_in_dir`]). Returns the path to
/// open and the file's size in bytes.
///
/// # Errors
/// [`FileError::BadFileName`], [`FileError::MissingFile`], [`FileError::PathEscape`].
pub fn resolve_listed(
    dir: &Path,
    index_name: &str,
    name: &str,
    kind: DirKind,
) -> Result<(PathBuf, u64), FileError> {
    if !plain_file_name(name) {
        return Err(FileError::BadFileName {
            index: dir.join(index_name),
            name: name.to_owned(),
            kind,
        });
    }
    let path = dir.join(name);
    resolve_in_dir(dir, name).map_err(|e| match e {
        Unresolved::Missing => FileError::MissingFile { path, kind },
        Unresolved::Escapes(real) => FileError::PathEscape {
            problem: format!(
                "resolves to {}, outside the {} directory {}",
                real.display(),
                kind.dir(),
                dir.display()
            ),
            path,
            kind,
        },
        Unresolved::NotRegular => FileError::PathEscape {
            problem: not_a_regular_file(&path).unwrap_or_else(|| "is not a regular file".into()),
            path,
            kind,
        },
    })
}

/// A file listed in an index, read and checked against the index's record.
#[derive(Debug)]
pub struct ListedFile {
    /// The path it was read from (`dir/name`).
    pub path: PathBuf,
    /// Its content: exactly the recorded size, with the recorded SHA-256.
    pub bytes: Vec<u8>,
}

/// Reads the file `name` listed in the index `dir/index_name` with the recorded size `bytes`
/// and SHA-256 `sha256` ([`resolve_listed`], then at most `bytes` bytes, then the digest).
///
/// # Errors
/// Those of [`resolve_listed`]; [`FileError::FileSize`] or [`FileError::Checksum`] when the
/// file differs from the record; [`FileError::Io`] when it cannot be read.
pub fn read_listed(
    dir: &Path,
    index_name: &str,
    name: &str,
    bytes: u64,
    sha256: &str,
    kind: DirKind,
) -> Result<ListedFile, FileError> {
    let (path, len) = resolve_listed(dir, index_name, name, kind)?;
    let size_error = |path: PathBuf, found: u64| FileError::FileSize {
        path,
        expected: bytes,
        found,
        kind,
    };
    if len != bytes {
        return Err(size_error(path, len));
    }
    let limit_name = format!("the size recorded in the {}", kind.index());
    let content = match read_bounded(&path, bytes, &limit_name) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(FileError::MissingFile { path, kind });
        }
        Err(e) => return Err(FileError::io("cannot read", &path, kind)(e)),
    };
    if content.len() as u64 != bytes {
        return Err(size_error(path, content.len() as u64));
    }
    let digest = sha256_hex(&content);
    if digest != sha256 {
        return Err(FileError::Checksum {
            path,
            expected: sha256.to_owned(),
            found: digest,
            kind,
        });
    }
    Ok(ListedFile {
        path,
        bytes: content,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn read_bounded_refuses_large_and_special_files() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f");
        fs::write(&p, vec![7u8; 100]).unwrap();
        assert_eq!(read_bounded(&p, 100, "L").unwrap().len(), 100);
        let e = read_bounded(&p, 99, "L").unwrap_err();
        assert!(
            e.to_string().contains("100 bytes exceeds the limit L = 99"),
            "{e}"
        );
        // A directory and a device are not regular files (and /dev/zero would never end).
        assert!(read_bounded(dir.path(), 1 << 20, "L").is_err());
        if Path::new("/dev/zero").exists() {
            let e = read_bounded(Path::new("/dev/zero"), 1 << 20, "L").unwrap_err();
            assert!(e.to_string().contains("is a device"), "{e}");
        }
        let e = read_bounded(dir.path(), 1 << 20, "L").unwrap_err();
        assert!(e.to_string().contains("is a directory"), "{e}");
        // A symbolic link loop is named as one, and a missing file stays NotFound.
        std::os::unix::fs::symlink(dir.path().join("a"), dir.path().join("b")).unwrap();
        std::os::unix::fs::symlink(dir.path().join("b"), dir.path().join("a")).unwrap();
        let e = read_bounded(&dir.path().join("a"), 1 << 20, "L").unwrap_err();
        assert!(e.to_string().contains("symbolic link loop"), "{e}");
        let e = read_bounded(&dir.path().join("none"), 1 << 20, "L").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::NotFound);
        assert_eq!(not_a_regular_file(&p), None);
        assert_eq!(
            not_a_regular_file(&dir.path().join("none")).as_deref(),
            Some("does not exist")
        );
    }

    #[test]
    fn plain_names_only() {
        assert!(plain_file_name("map_00012_+3_-17.exr"));
        for bad in [
            "", ".", "..", "../a.exr", "a/b.exr", "/abs.exr", "a\\b.exr", "C:x.exr", "a\nb",
        ] {
            assert!(!plain_file_name(bad), "{bad:?} accepted");
        }
    }

    #[test]
    fn listed_files_are_checked_against_their_record() {
        let dir = tempfile::tempdir().unwrap();
        fs::write(dir.path().join("a"), b"abc").unwrap();
        let digest = sha256_hex(b"abc");
        let d = dir.path();
        let ok = read_listed(d, "i.json", "a", 3, &digest, DirKind::Atlas).unwrap();
        assert_eq!(ok.bytes, b"abc");
        let e = read_listed(d, "i.json", "a", 4, &digest, DirKind::Atlas).unwrap_err();
        assert!(matches!(e, FileError::FileSize { found: 3, .. }), "{e}");
        let e = read_listed(d, "i.json", "a", 3, &"0".repeat(64), DirKind::Bake).unwrap_err();
        assert!(matches!(e, FileError::Checksum { .. }), "{e}");
        let e = read_listed(d, "i.json", "b", 3, &digest, DirKind::Bake).unwrap_err();
        assert!(matches!(e, FileError::MissingFile { .. }), "{e}");
        let e = read_listed(d, "i.json", "../a", 3, &digest, DirKind::Bake).unwrap_err();
        assert!(matches!(e, FileError::BadFileName { .. }), "{e}");
    }
}
