//! Shared set-up of the `ortm-cli` integration tests (each test file does `mod common;`).
//!
//! - Paths: [`data`] names a file under `tests/data/`, [`head_obj`] the scanned head
//!   (`../shared/faces/head.obj` beside the repository).
//! - The binary: [`ortm_command`] is the built `ortm` as a [`Command`] (for tests that set its
//!   environment or stdio); [`ortm`] runs it with arguments in a folder ([`ortm_no_gpu`]: with
//!   no usable GPU adapter); [`ok`] and [`fails`]
//!   assert the exit status and return its text ([`output_text`]: stdout then stderr).
//! - Bakes on disk: [`tiny_cornell_bake`] copies one tiny Cornell bake made by the binary (made
//!   once per test binary, see [`TINY_CORNELL_BAKE`]); [`fixture_bake`] copies the stored fixture
//!   `tests/data/fuzz/fixture_bake`; [`write_bake`] writes given maps as a bake directory;
//!   [`dir_files`] reads a folder's files back for byte-for-byte comparisons; [`edit_json`]
//!   rewrites a JSON file through a closure (tampering with an index).
//! - Random data (seeded by the caller): [`random_sparse_maps`] and [`random_log_valued_maps`]
//!   (two distributions of transfer maps; each test keeps the one its numbers were set with),
//!   [`random_lightmap`] (a first-order lightmap).
//! - Numbers: [`lightmap_bits`] for bit-exact lightmap comparisons; [`exitance`] (`ρ̄·E`, the
//!   first-order radiosity), [`senders`], [`final_at`] and [`final_all`] (`B = B_o + R·B_o` from
//!   ortm's pair evaluator), and [`luminance`] for the transport tests.

#![allow(
    dead_code,
    reason = "each test binary compiles this module and uses only some of its helpers"
)]

use std::ffi::OsStr;
use std::fs;
use std::path::{Path, PathBuf};
use std::process::{Command, Output};
use std::sync::OnceLock;

use glam::{IVec2, Vec3};
use ortm::Lightmap;
use ortm::bake::texels::TexelGrid;
use ortm::bake_dir::{BakeIndex, BakeKey, LightmapSize, write_map_file};
use ortm::maps::TransferMap;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// `tests/data/<rel>` of this package.
pub fn data(rel: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR"))
        .join("tests/data")
        .join(rel)
}

/// The scanned head's OBJ (`shared/faces/head.obj` beside the repository).
pub fn head_obj() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../../../shared/faces/head.obj")
}

/// The `ortm` binary of this package, to add arguments, environment and stdio to.
pub fn ortm_command() -> Command {
    Command::new(env!("CARGO_BIN_EXE_ortm"))
}

/// Runs `ortm <args>` in the folder `cwd` and returns its output.
pub fn ortm<S: AsRef<OsStr>>(args: &[S], cwd: &Path) -> Output {
    ortm_command()
        .args(args)
        .current_dir(cwd)
        .output()
        .expect("the ortm binary runs")
}

/// `ortm <args>` in `cwd` with no usable GPU adapter (only a backend this build lacks):
/// `ortm render` then runs on the CPU mirrors of the passes.
pub fn ortm_no_gpu(args: &[&str], cwd: &Path) -> Output {
    ortm_command()
        .args(args)
        .current_dir(cwd)
        .env("WGPU_BACKEND", "metal")
        .output()
        .expect("the ortm binary runs")
}

/// What `ortm render` writes as its final from the transfer's input: `applied` (the maps
/// applied to `input`, `input + Σ R·input`) started from `first` instead of `input`.
pub fn started_from(
    applied: &ortm::Lightmap,
    first: &ortm::Lightmap,
    input: &ortm::Lightmap,
) -> ortm::Lightmap {
    let mut out = applied.clone();
    for ((o, f), i) in out.data.iter_mut().zip(&first.data).zip(&input.data) {
        for c in 0..3 {
            o[c] += f[c] - i[c];
        }
    }
    out
}

/// A run's stdout followed by its stderr, as text.
pub fn output_text(out: &Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

/// Asserts that the run succeeded; returns its stdout and stderr.
pub fn ok(out: Output) -> String {
    let text = output_text(&out);
    assert!(out.status.success(), "ortm failed:\n{text}");
    text
}

/// Asserts that the run failed; returns its stderr.
pub fn fails(out: Output) -> String {
    assert!(!out.status.success(), "ortm should have failed");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// Peak resident bytes that a run under the test hook `ORTM_TEST_REPORT_PEAK` reported
/// (`ORTM_TEST_PEAK_BYTES: N` on stderr).
pub fn reported_peak(stderr: &str) -> u64 {
    stderr
        .lines()
        .find_map(|l| l.strip_prefix("ORTM_TEST_PEAK_BYTES: "))
        .and_then(|v| v.trim().parse().ok())
        .unwrap_or_else(|| panic!("no peak reported: {stderr}"))
}

/// The tiny Cornell bake that [`tiny_cornell_bake`] copies, as typed after `ortm` (without
/// `-o`): 32² lightmap, 12 jittered-grid offsets, the default seed and effects.
pub const TINY_CORNELL_BAKE: &str = "bake cornell --size 32 --offsets 12 --selector jittered-grid";

/// Writes the output of `ortm bake <TINY_CORNELL_BAKE> -o <name>` run in `dir` into the new
/// folder `dir/<name>` and returns its path. The binary bakes once per test binary (the first
/// caller bakes, callers at the same time wait); every call gets its own copy of the files, so
/// tests may change them.
pub fn tiny_cornell_bake(dir: &Path, name: &str) -> PathBuf {
    static FILES: OnceLock<Vec<(String, Vec<u8>)>> = OnceLock::new();
    let files = FILES.get_or_init(|| {
        let tmp = tempfile::tempdir().unwrap();
        let mut args: Vec<&str> = TINY_CORNELL_BAKE.split(' ').collect();
        args.extend(["-o", "bake"]);
        ok(ortm(&args, tmp.path()));
        dir_files(&tmp.path().join("bake"))
    });
    let out = dir.join(name);
    fs::create_dir(&out).unwrap();
    for (file, bytes) in files {
        fs::write(out.join(file), bytes).unwrap();
    }
    out
}

/// A scratch copy of the stored fixture `tests/data/fuzz/fixture_bake`: a tiny Cornell bake
/// (`ortm bake cornell --size 32 --offsets 8`) binned with `ortm bin --atlas 64`.
pub fn fixture_bake() -> tempfile::TempDir {
    let dir = tempfile::tempdir().unwrap();
    for e in fs::read_dir(data("fuzz/fixture_bake")).unwrap() {
        let e = e.unwrap();
        fs::copy(e.path(), dir.path().join(e.file_name())).unwrap();
    }
    dir
}

/// Every file of `dir` as (name, bytes), sorted by name (panics on a subfolder).
pub fn dir_files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut v: Vec<(String, Vec<u8>)> = fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .map(|e| {
            (
                e.file_name().into_string().unwrap(),
                fs::read(e.path()).unwrap(),
            )
        })
        .collect();
    v.sort();
    v
}

/// Reads the JSON file at `path`, applies `edit` and writes it back (pretty-printed).
pub fn edit_json(path: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let mut v: serde_json::Value = serde_json::from_slice(&fs::read(path).unwrap()).unwrap();
    edit(&mut v);
    fs::write(path, serde_json::to_vec_pretty(&v).unwrap()).unwrap();
}

/// Writes `maps` of a `size` lightmap as a bake directory in `dir` (one map file each, then
/// `index.json` with `scene_hash` and `settings`) and returns the index.
pub fn write_bake(
    dir: &Path,
    maps: &[TransferMap],
    size: (u32, u32),
    scene_hash: &str,
    settings: serde_json::Value,
) -> BakeIndex {
    let key = BakeKey::new(scene_hash, &settings);
    let entries = maps
        .iter()
        .enumerate()
        .map(|(i, m)| write_map_file(dir, i as u32, m, &key).unwrap())
        .collect();
    let index = BakeIndex::new(
        LightmapSize {
            width: size.0,
            height: size.1,
        },
        scene_hash.into(),
        settings,
        entries,
    );
    index.write(dir).unwrap();
    index
}

/// The lightmap's values as bit patterns, for bit-exact comparisons.
pub fn lightmap_bits(l: &Lightmap) -> Vec<[u32; 3]> {
    l.data.iter().map(|v| v.map(f32::to_bits)).collect()
}

/// Rec. 709 luminance weights.
pub const LUMA: Vec3 = Vec3::new(0.2126, 0.7152, 0.0722);

/// Rec. 709 luminance of a linear RGB value.
pub fn luminance(v: Vec3) -> f32 {
    v.dot(LUMA)
}

/// First-order radiosity `B_o = ρ̄·E` per texel from the irradiance `e` (W/m²).
pub fn exitance(grid: &TexelGrid, e: &[Vec3]) -> Vec<Vec3> {
    e.iter()
        .zip(&grid.texels)
        .map(|(e, t)| *e * t.albedo)
        .collect()
}

#[allow(unused_imports, reason = "not every test binary uses them")]
pub use ortm::bake::eval::{
    evaluator_error, evaluator_final as final_all, evaluator_final_at as final_at, senders,
};

/// `n` random sparse maps of a `w×h` lightmap, for atlas packing: up to 3 blobs (≤ 20×12) of
/// random values and up to 2 scattered texels each (some maps empty), offsets within ±7.
pub fn random_sparse_maps(rng: &mut ChaCha8Rng, w: u32, h: u32, n: usize) -> Vec<TransferMap> {
    (0..n)
        .map(|_| {
            let mut full = Lightmap::new(w, h);
            for _ in 0..rng.random_range(0..4) {
                let (bx, by) = (rng.random_range(0..w), rng.random_range(0..h));
                let bw = rng.random_range(1..=(w - bx).min(20));
                let bh = rng.random_range(1..=(h - by).min(12));
                for y in by..by + bh {
                    for x in bx..bx + bw {
                        full.set(
                            x,
                            y,
                            [rng.random(), rng.random::<f32>() * 1e-3, rng.random()],
                        );
                    }
                }
            }
            for _ in 0..rng.random_range(0..3) {
                let (x, y) = (rng.random_range(0..w), rng.random_range(0..h));
                full.set(x, y, [0.0, rng.random_range(1e-7..1.0), 0.0]);
            }
            let offset = IVec2::new(rng.random_range(-7..=7), rng.random_range(-7..=7));
            TransferMap::from_full(offset, rng.random_range(0.0..1.0), 1.0, &full).unwrap()
        })
        .collect()
}

/// A `w×h` lightmap of independent uniform values in [0, 10) per channel.
pub fn random_lightmap(rng: &mut ChaCha8Rng, w: u32, h: u32) -> Lightmap {
    let mut m = Lightmap::new(w, h);
    for v in &mut m.data {
        *v = [
            rng.random_range(0.0..10.0),
            rng.random_range(0.0..10.0),
            rng.random_range(0.0..10.0),
        ];
    }
    m
}

/// `n` random maps of a `w×h` lightmap, for the storage round trip: up to 2 blobs (≤ 8×8) each
/// with log-uniform values in 1e-7..1, offsets within ±20 × ±12.
pub fn random_log_valued_maps(rng: &mut ChaCha8Rng, w: u32, h: u32, n: usize) -> Vec<TransferMap> {
    (0..n)
        .map(|i| {
            let mut full = Lightmap::new(w, h);
            // A couple of blobs per map, values spanning 1e-7..1.
            for _ in 0..rng.random_range(0..3) {
                let (bx, by) = (rng.random_range(0..w), rng.random_range(0..h));
                let (bw, bh) = (
                    rng.random_range(1..=(w - bx).min(8)),
                    rng.random_range(1..=(h - by).min(8)),
                );
                for y in by..by + bh {
                    for x in bx..bx + bw {
                        let s = 10f32.powf(-rng.random_range(0.0..7.0f32));
                        full.set(x, y, [s, s * rng.random::<f32>(), s * 0.5]);
                    }
                }
            }
            let offset = IVec2::new(rng.random_range(-20..20), rng.random_range(-12..12));
            TransferMap::from_full(offset, 0.01 * (i + 1) as f64, rng.random(), &full).unwrap()
        })
        .collect()
}

/// Every integer offset that can pair two texels of a `w × h` lightmap, `(0, 0)` first.
pub fn all_offsets(w: u32, h: u32) -> Vec<glam::IVec2> {
    let mut v = vec![glam::IVec2::ZERO];
    for dy in -(h as i32 - 1)..=(h as i32 - 1) {
        for dx in -(w as i32 - 1)..=(w as i32 - 1) {
            if dx != 0 || dy != 0 {
                v.push(glam::IVec2::new(dx, dy));
            }
        }
    }
    v
}
