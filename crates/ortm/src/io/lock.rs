//! One writer per directory: an advisory lock (`flock`, through std's [`std::fs::File::try_lock`])
//! on the file [`LOCK_FILE_NAME`] in a bake or atlas directory, held by every writer (`ortm
//! bake`, `ortm bin`) from before its first write, including the sweep of stale temporary
//! files, to its last. A second writer fails at once naming the process that holds the lock
//! (its id is written into the lock file). The lock goes with the process: a writer killed at
//! any moment leaves no stale lock, only the file, which the next writer reuses; a writer that
//! ends normally removes the file (while still holding the lock, and a writer that locked a file
//! no longer at [`LOCK_FILE_NAME`] tries again, so two writers never hold different files).
//! Readers take no lock (every file is replaced by rename, so a reader never sees half a file).

use std::fs;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};

/// Name of the lock file in a bake or atlas directory (hidden; readers ignore it).
pub const LOCK_FILE_NAME: &str = ".ortm.lock";

/// Why a directory could not be locked.
#[derive(Debug, thiserror::Error)]
pub enum LockError {
    /// Another process holds the lock.
    #[error(
        "'{}' is being written by process {pid}; wait for it to finish, or write to another \
         folder",
        dir.display()
    )]
    Busy {
        /// The directory.
        dir: PathBuf,
        /// The process id recorded in the lock file (`unknown` if it had not written it yet).
        pid: String,
    },
    /// The lock file could not be created, opened or locked.
    #[error(
        "cannot lock '{}' for writing ({}): {source}; check that the folder is writable",
        dir.display(),
        LOCK_FILE_NAME
    )]
    Io {
        /// The directory.
        dir: PathBuf,
        /// Cause.
        source: std::io::Error,
    },
}

/// The held lock of one directory; released when dropped (or when the process ends).
#[derive(Debug)]
pub struct DirLock {
    /// The open, locked lock file.
    _file: fs::File,
    /// The locked directory.
    dir: PathBuf,
}

impl DirLock {
    /// Creates `dir` (and its parents) if needed and takes its write lock without waiting.
    ///
    /// # Errors
    /// [`LockError::Busy`] when another process (or another [`DirLock`] of this one) holds it;
    /// [`LockError::Io`] when the directory or lock file cannot be created or is not a regular
    /// file (the lock file is opened without following symbolic links and without blocking).
    pub fn acquire(dir: &Path) -> Result<Self, LockError> {
        let io = |source| LockError::Io {
            dir: dir.to_owned(),
            source,
        };
        fs::create_dir_all(dir).map_err(io)?;
        let path = dir.join(LOCK_FILE_NAME);
        // A holder that ends removes the file; one that locked a removed file tries again.
        for _ in 0..100 {
            let mut file = open_lock_file(&path).map_err(io)?;
            match file.try_lock() {
                Ok(()) => {}
                Err(fs::TryLockError::WouldBlock) => {
                    return Err(LockError::Busy {
                        dir: dir.to_owned(),
                        pid: recorded_pid(&mut file),
                    });
                }
                Err(fs::TryLockError::Error(e)) => return Err(io(e)),
            }
            if !same_file(&file, &path) {
                continue;
            }
            file.set_len(0).map_err(io)?;
            file.rewind().map_err(io)?;
            writeln!(file, "{}", std::process::id()).map_err(io)?;
            return Ok(Self {
                _file: file,
                dir: dir.to_owned(),
            });
        }
        Err(io(std::io::Error::other(
            "the lock file kept being replaced by other processes",
        )))
    }

    /// The locked directory.
    pub fn dir(&self) -> &Path {
        &self.dir
    }
}

impl Drop for DirLock {
    /// Removes the lock file while still holding the lock; closing the file then releases it.
    fn drop(&mut self) {
        let _ = fs::remove_file(self.dir.join(LOCK_FILE_NAME));
    }
}

/// Opens (creating) the lock file for reading and writing, without following a symbolic link
/// and without blocking, and refuses anything but a regular file.
fn open_lock_file(path: &Path) -> std::io::Result<fs::File> {
    use std::os::unix::fs::OpenOptionsExt;
    let file = fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(false)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOFOLLOW)
        .open(path)?;
    if !file.metadata()?.is_file() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::InvalidInput,
            format!("{} is not a regular file", path.display()),
        ));
    }
    Ok(file)
}

/// Whether the open `file` is still the file at `path` (same device and inode).
fn same_file(file: &fs::File, path: &Path) -> bool {
    use std::os::unix::fs::MetadataExt;
    match (file.metadata(), fs::symlink_metadata(path)) {
        (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
        _ => false,
    }
}

/// The process id the holder wrote into the lock file (`unknown` if not written yet).
fn recorded_pid(file: &mut fs::File) -> String {
    let mut text = String::new();
    let _ = file.take(32).read_to_string(&mut text);
    let pid = text.trim();
    if pid.is_empty() || !pid.bytes().all(|b| b.is_ascii_digit()) {
        "unknown".to_owned()
    } else {
        pid.to_owned()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_second_lock_fails_until_the_first_is_dropped() {
        let dir = tempfile::tempdir().unwrap();
        let d = dir.path().join("new");
        let first = DirLock::acquire(&d).unwrap();
        let e = DirLock::acquire(&d).unwrap_err();
        let me = std::process::id().to_string();
        assert!(
            matches!(&e, LockError::Busy { pid, .. } if *pid == me),
            "{e}"
        );
        assert!(e.to_string().contains("is being written by process"), "{e}");
        assert!(d.join(LOCK_FILE_NAME).exists());
        drop(first);
        // Released and removed: the directory holds nothing of the lock.
        assert!(!d.join(LOCK_FILE_NAME).exists());
        let again = DirLock::acquire(&d).unwrap();
        assert_eq!(again.dir(), d);
    }
}
