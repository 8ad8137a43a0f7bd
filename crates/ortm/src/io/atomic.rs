//! Atomic file writes: a reader never sees a half-written file under the final name.

use std::fs;
use std::io::{Cursor, Write};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};

/// Monotonic counter that keeps temporary names unique within the process.
static TMP_COUNTER: AtomicU64 = AtomicU64::new(0);

/// Environment variable of the crash-test hook ([`stop_in_this_write`]).
const STOP_IN_WRITE_VAR: &str = "ORTM_TEST_STOP_IN_WRITE";

/// How long a write stopped by the crash-test hook waits to be killed before it fails.
const STOP_WAIT: std::time::Duration = std::time::Duration::from_secs(120);

/// Crash-test hook (docs/bake-format.md, "Crash tests"): whether this call of [`write_atomic`]
/// is the `N`-th of the process (counted from 1 over all threads) when the environment variable
/// `ORTM_TEST_STOP_IN_WRITE` holds `N`. Unset (or not a number), no write stops and nothing is
/// counted.
fn stop_in_this_write() -> Option<u64> {
    static STOP_AT: std::sync::OnceLock<Option<u64>> = std::sync::OnceLock::new();
    static WRITES: AtomicU64 = AtomicU64::new(0);
    let n = (*STOP_AT.get_or_init(|| std::env::var(STOP_IN_WRITE_VAR).ok()?.parse().ok()))?;
    (WRITES.fetch_add(1, Ordering::Relaxed) + 1 == n).then_some(n)
}

/// Environment variable of the pause hook ([`pause_in_this_write`]).
const PAUSE_IN_WRITE_VAR: &str = "ORTM_TEST_PAUSE_IN_WRITE";

/// Test hook for concurrent writers (docs/bake-format.md, "Crash tests"): when the environment
/// variable `ORTM_TEST_PAUSE_IN_WRITE` holds `N:PATH`, the process's `N`-th call of
/// [`write_atomic`] (counted from 1 over all threads) prints
/// `ORTM_TEST_PAUSE_IN_WRITE: paused in write N` to stderr and waits (up to two minutes) until
/// the file `PATH` exists, then writes normally. Unset or malformed, nothing waits.
fn pause_in_this_write() {
    static PAUSE_AT: std::sync::OnceLock<Option<(u64, PathBuf)>> = std::sync::OnceLock::new();
    static WRITES: AtomicU64 = AtomicU64::new(0);
    let Some((n, go)) = PAUSE_AT.get_or_init(|| {
        let v = std::env::var(PAUSE_IN_WRITE_VAR).ok()?;
        let (n, path) = v.split_once(':')?;
        Some((n.parse().ok()?, PathBuf::from(path)))
    }) else {
        return;
    };
    if WRITES.fetch_add(1, Ordering::Relaxed) + 1 != *n {
        return;
    }
    eprintln!("{PAUSE_IN_WRITE_VAR}: paused in write {n}");
    let start = std::time::Instant::now();
    while !go.exists() && start.elapsed() < STOP_WAIT {
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
}

/// The temporary name [`write_atomic`] writes `path` under: `.<name>.<pid>-<n>.tmp` in the same
/// directory (hidden, unique per process and call). Readers of bake and atlas directories treat
/// `.*.tmp` files as leftovers of interrupted writes.
fn temp_path(path: &Path) -> PathBuf {
    let dir = path.parent().unwrap_or(Path::new("."));
    let name = path.file_name().map_or_else(
        || "unnamed".to_owned(),
        |n| n.to_string_lossy().into_owned(),
    );
    let n = TMP_COUNTER.fetch_add(1, Ordering::Relaxed);
    dir.join(format!(".{name}.{}-{n}.tmp", std::process::id()))
}

/// Whether a file name is one [`write_atomic`] gives its temporary files (`.<name>….tmp`):
/// directory readers skip such files and may delete them as leftovers of interrupted writes.
pub fn is_temp_name(name: &str) -> bool {
    name.starts_with('.') && name.ends_with(".tmp")
}

/// Writes `bytes` to `path` atomically: a temporary file in the same directory (so the rename
/// stays on one file system), `fsync`, then rename over `path`. On failure the temporary file
/// is removed and `path` is untouched.
///
/// With the crash-test hook `ORTM_TEST_STOP_IN_WRITE=N` set, the process's `N`-th call writes
/// only the first half of `bytes` to the temporary file, prints
/// `ORTM_TEST_STOP_IN_WRITE: stopped in write N: <temporary path>` to stderr and sleeps, so that
/// a test can kill the process in the middle of that write; if it is not killed within two
/// minutes, the call fails (the temporary file is removed). The pause hook
/// `ORTM_TEST_PAUSE_IN_WRITE=N:PATH` makes the `N`-th call wait for the file `PATH` first
/// ([`pause_in_this_write`]).
///
/// # Errors
/// The `std::io::Error` of creating, writing, syncing or renaming.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    pause_in_this_write();
    write_temp_then_rename(path, |f, tmp| {
        if let Some(n) = stop_in_this_write() {
            f.write_all(&bytes[..bytes.len() / 2])?;
            eprintln!(
                "{STOP_IN_WRITE_VAR}: stopped in write {n}: {}",
                tmp.display()
            );
            std::thread::sleep(STOP_WAIT);
            return Err(std::io::Error::other(format!(
                "{STOP_IN_WRITE_VAR}: write {n} was not killed within {STOP_WAIT:?}"
            )));
        }
        f.write_all(bytes)
    })
}

/// [`write_atomic`] for content produced by a writer: `fill` writes into a buffered temporary
/// file in `path`'s directory, which is then `fsync`ed and renamed over `path` (removed on
/// failure). For large outputs that should not be held in memory twice (a sharded bake's
/// `transport.bin`). The test hooks of [`write_atomic`] do not apply.
///
/// # Errors
/// The `std::io::Error` of creating, `fill`, syncing or renaming.
pub fn write_atomic_with(
    path: &Path,
    fill: impl FnOnce(&mut dyn Write) -> std::io::Result<()>,
) -> std::io::Result<()> {
    write_temp_then_rename(path, |f, _| {
        let mut w = std::io::BufWriter::with_capacity(1 << 20, f);
        fill(&mut w)?;
        w.flush()
    })
}

/// The mechanism of [`write_atomic`] and [`write_atomic_with`]: `fill` writes the temporary file
/// ([`temp_path`], given with its path), which is `fsync`ed and renamed over `path`; on any
/// failure it is removed and `path` is untouched.
fn write_temp_then_rename(
    path: &Path,
    fill: impl FnOnce(&mut fs::File, &Path) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let tmp = temp_path(path);
    let result = (|| {
        let mut f = fs::File::create(&tmp)?;
        fill(&mut f, &tmp)?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, path)
    })();
    if result.is_err() {
        let _ = fs::remove_file(&tmp);
    }
    result
}

/// Threads of [`with_write_pool`]: enough concurrent writers for the file system to commit
/// their `fsync`s together. Measured on ext4, 2 cores, 6,678 small map files (`ortm bake
/// cornell --size 64 --levels 3e-3`): the bake's maps phase 11.5 s with 2 writers, 1.8–4.3 s
/// with 16.
pub const WRITE_THREADS: usize = 16;

/// Runs `f` in a thread pool of [`WRITE_THREADS`] threads (made once per process), so that the
/// `par_iter`s inside it keep many [`write_atomic`] calls (each waiting in `fsync`) in flight
/// at once; each file stays atomic and durable on its own. If the pool cannot be made, `f` runs
/// in the current pool.
pub fn with_write_pool<R: Send>(f: impl FnOnce() -> R + Send) -> R {
    static POOL: std::sync::OnceLock<Option<rayon::ThreadPool>> = std::sync::OnceLock::new();
    let pool = POOL.get_or_init(|| {
        rayon::ThreadPoolBuilder::new()
            .num_threads(WRITE_THREADS.max(rayon::current_num_threads()))
            .thread_name(|i| format!("ortm-write-{i}"))
            .build()
            .ok()
    });
    match pool {
        Some(p) => p.install(f),
        None => f(),
    }
}

/// Encodes `img` as PNG in memory and writes it with [`write_atomic`].
///
/// # Errors
/// The encoder's error (as [`std::io::ErrorKind::Other`]) or the write's.
pub fn write_png_atomic<P, C>(img: &image::ImageBuffer<P, C>, path: &Path) -> std::io::Result<()>
where
    P: image::PixelWithColorType,
    [P::Subpixel]: image::EncodableLayout,
    C: std::ops::Deref<Target = [P::Subpixel]>,
{
    let mut bytes = Cursor::new(Vec::new());
    img.write_to(&mut bytes, image::ImageFormat::Png)
        .map_err(std::io::Error::other)?;
    write_atomic(path, bytes.get_ref())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn writes_replace_whole_files_and_leave_no_temporaries() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("f.txt");
        write_atomic(&p, b"first").unwrap();
        write_atomic(&p, b"second").unwrap();
        assert_eq!(fs::read(&p).unwrap(), b"second");
        let names: Vec<_> = fs::read_dir(dir.path())
            .unwrap()
            .map(|d| d.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("f.txt")]);
        // A parent that is a file: the write fails and nothing is left behind.
        assert!(write_atomic(&p.join("x"), b"y").is_err());
        assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1);
    }

    #[test]
    fn png_round_trips() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("i.png");
        let img = image::RgbImage::from_pixel(3, 2, image::Rgb([1, 2, 3]));
        write_png_atomic(&img, &p).unwrap();
        assert_eq!(image::open(&p).unwrap().to_rgb8(), img);
    }
}
