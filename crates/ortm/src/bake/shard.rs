//! A bake split over processes or machines: one **plan**, `N` **shards**, one **merge**, over
//! one shared directory, run by whatever batch scheduler the user has (Slurm job arrays,
//! Kubernetes Indexed Jobs; `deploy/`, `docs/sharding.md`). No coordinator and no network
//! between the processes: every file is written once, atomically (temporary file, `fsync`,
//! rename), and read by the steps after it.
//!
//! # Data flow
//! - [`plan`] (one process, `ortm bake SCENE -o DIR --plan --shards N`) does what every shard
//!   needs once: texels, the transport operator ([`Transport::to_bytes`] → `transport.bin`),
//!   the offset selection (`selection.json`, as a single-process bake writes it), and the work
//!   split: the receivers' **work units** — the coarse clusters of the cell integration
//!   ([`crate::bake::cells::Integrator`]) for offset maps, single receivers for multi-resolution
//!   maps (`--levels`) — cut into `N` contiguous runs of equal *estimated cost*
//!   ([`split_by_cost`]: receivers × sender clusters visited + exact-zone texels for clusters;
//!   one row of `n` senders each for receivers), each cut again into chunks. All of it goes to
//!   `plan.json` (format `ortm-bake-plan`, version 1) with the size and SHA-256 of
//!   `transport.bin`.
//! - [`run_shard`] (shard `I` of `N`, `--shard I/N`) computes its units' values — every map's
//!   value at each of its receivers — chunk by chunk into `shard_I_of_N/chunk_C.bin` (magic
//!   `ORTMCHNK`, version, the postcard-encoded [`ChunkRecord`], and the SHA-256 of what precedes
//!   it), then `shard_I_of_N/done.json` listing every chunk's size and SHA-256. A shard rerun
//!   with the same `I/N` keeps every chunk that verifies, so a killed shard resumes; a finished
//!   shard rerun does nothing.
//! - [`merge`] (one process, `ortm bake DIR --merge`) verifies every shard's `done.json` and
//!   chunks (refusing, with the shard named, when one is missing or fails its checksum), puts
//!   the values together in receiver order, writes the maps, report and `index.json` exactly as
//!   [`crate::bake::bake`] does from the same values, then removes `plan.json`,
//!   `transport.bin` and the shard folders.
//!
//! # Why receivers, not maps, are shared out
//! The bake is receiver-major: a map's value at receiver `t` comes from `t`'s whole transfer
//! row, which the cell integration splits over every offset cell at once (and moves between
//! cells at seams), and which the multi-resolution partition splits into blocks of every level.
//! Giving each shard a set of maps would make every shard compute every row; giving it a set of
//! receivers divides the work, and the merge's transposition into maps is the same file writing
//! a single-process bake does. The result is byte-identical to a single-process bake with the
//! same settings: each receiver's values do not depend on which other receivers a process
//! computes, the transport is the plan's bit for bit, and the maps are written by the same code.
//!
//! # Units
//! Costs are estimates in abstract steps (sender clusters or texels visited), used only to
//! balance shards.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use glam::IVec2;
use serde::{Deserialize, Serialize};

use crate::bake::cells::{self, ClusterValues, Integrator};
use crate::bake::multires::Entry;
use crate::bake::pipeline::{self, BakeError, BakeEvent, BakeSettings, CellRule, MapPlan, Setup};
use crate::bake::texels::TexelGrid;
use crate::bake::transport::Transport;
use crate::bake_dir::{self, BakeKey};
use crate::maps::MapsError;
use crate::scene::Scene;

/// The plan's file in the bake directory.
pub const PLAN_FILE_NAME: &str = "plan.json";
/// The transport operator the plan hands to the shards.
pub const TRANSPORT_FILE_NAME: &str = "transport.bin";
/// `format` of `plan.json`.
pub const PLAN_FORMAT: &str = "ortm-bake-plan";
/// `version` of `plan.json`.
pub const PLAN_VERSION: u32 = 1;
/// `format` of a shard's `done.json`.
pub const DONE_FORMAT: &str = "ortm-bake-shard";
/// `version` of a shard's `done.json`.
pub const DONE_VERSION: u32 = 1;
/// A shard's finish record, in its folder.
pub const DONE_FILE_NAME: &str = "done.json";
/// Chunks per shard (fewer when a shard has fewer units): what a killed shard loses at most.
pub const CHUNKS_PER_SHARD: usize = 16;
/// Most shards a plan may have ([`crate::io::limits::MAX_SHARDS`]).
pub use crate::io::limits::MAX_SHARDS;

const CHUNK_MAGIC: &[u8; 8] = b"ORTMCHNK";
const CHUNK_VERSION: u32 = 1;

/// Shard `index` of `count` (0-based).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct ShardId {
    /// 0-based index.
    pub index: u32,
    /// Number of shards.
    pub count: u32,
}

impl std::fmt::Display for ShardId {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}/{}", self.index, self.count)
    }
}

impl ShardId {
    /// Parses `I/N` (0 ≤ I < N ≤ [`MAX_SHARDS`]).
    ///
    /// # Errors
    /// A message naming the expected form.
    pub fn parse(s: &str) -> Result<Self, String> {
        let bad = || format!("--shard '{s}': give I/N with 0 ≤ I < N, e.g. 0/4");
        let (i, n) = s.split_once('/').ok_or_else(bad)?;
        let index: u32 = i.trim().parse().map_err(|_| bad())?;
        let count: u32 = n.trim().parse().map_err(|_| bad())?;
        Self::new(index, count).map_err(|e| format!("--shard '{s}': {e}"))
    }

    /// Shard `index` of `count`.
    ///
    /// # Errors
    /// A message when `index ≥ count`, `count` is 0 or more than [`MAX_SHARDS`].
    pub fn new(index: u32, count: u32) -> Result<Self, String> {
        if count == 0 || count > MAX_SHARDS {
            return Err(format!(
                "{count} shards: give between 1 and {MAX_SHARDS} (MAX_SHARDS)"
            ));
        }
        if index >= count {
            return Err(format!(
                "shard index {index} of {count}: indices run from 0 to {}",
                count - 1
            ));
        }
        Ok(Self { index, count })
    }

    /// The shard's folder in the bake directory, `shard_I_of_N`.
    pub fn folder(&self) -> String {
        format!("shard_{}_of_{}", self.index, self.count)
    }
}

/// What the shards compute per unit.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum WorkKind {
    /// Offset maps: receiving clusters of the cell integration.
    Cells,
    /// Multi-resolution maps: single receivers' partitioned rows.
    Rows,
}

/// A file a record names: its name in its folder, size and SHA-256.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct FileRecord {
    /// File name.
    pub file: String,
    /// Size, bytes.
    pub bytes: u64,
    /// SHA-256, lowercase hex.
    pub sha256: String,
}

/// One shard's share in the plan.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct ShardPlan {
    /// Unit ranges `[start, end)` of its chunks, contiguous, in order.
    pub chunks: Vec<[u32; 2]>,
    /// Receivers (covered texels) in its units.
    pub receivers: u64,
    /// Estimated cost of its units.
    pub estimated_cost: u64,
}

/// `plan.json`.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlanRecord {
    /// The bake's key (scene hash + settings).
    pub bake_key: String,
    /// The scene's hash.
    pub scene_hash: String,
    /// The bake's settings ([`BakeSettings::to_json`]).
    pub settings: serde_json::Value,
    /// Covered texels.
    pub texels: u64,
    /// What a unit is.
    pub work: WorkKind,
    /// Units in all.
    pub units: u32,
    /// Per shard, its share.
    pub shards: Vec<ShardPlan>,
    /// The transport operator.
    pub transport: FileRecord,
}

impl PlanRecord {
    /// The bake's settings.
    ///
    /// # Errors
    /// [`BakeError::Settings`] when they do not parse.
    pub fn bake_settings(&self) -> Result<BakeSettings, BakeError> {
        serde_json::from_value(self.settings.clone()).map_err(|e| {
            BakeError::Settings(format!(
                "{PLAN_FILE_NAME}: its settings do not parse ({e}); plan again"
            ))
        })
    }
}

/// A shard's `done.json`.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct DoneRecord {
    /// The bake's key.
    pub bake_key: String,
    /// Shard index.
    pub shard: u32,
    /// Shard count.
    pub of: u32,
    /// Its chunk files, in order.
    pub chunks: Vec<FileRecord>,
}

/// The payload of a chunk file.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub enum Payload {
    /// Per receiving cluster of the chunk, its receivers (texel indices) and values.
    Cells(Vec<(Vec<u32>, ClusterValues)>),
    /// Per receiver of the chunk, its kept blocks.
    Rows(Vec<Vec<Entry>>),
}

/// A chunk file's content.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct ChunkRecord {
    /// The bake's key.
    pub bake_key: String,
    /// Shard index.
    pub shard: u32,
    /// Shard count.
    pub of: u32,
    /// Chunk index within the shard.
    pub chunk: u32,
    /// Units `[start, end)`.
    pub units: [u32; 2],
    /// The values.
    pub payload: Payload,
}

/// What [`plan`] did.
#[derive(Clone, Debug)]
pub struct PlanSummary {
    /// Covered texels.
    pub texels: usize,
    /// Units and what they are.
    pub units: u32,
    /// What a unit is.
    pub work: WorkKind,
    /// Per shard, its estimated cost as a fraction of the total.
    pub shares: Vec<f64>,
    /// Bytes of `transport.bin`.
    pub transport_bytes: u64,
    /// Seconds: transport, selection, writing the plan.
    pub seconds: [f64; 3],
    /// True when a valid plan of the same bake and shard count was already there.
    pub reused: bool,
}

/// What [`run_shard`] did.
#[derive(Clone, Debug)]
pub struct ShardSummary {
    /// Chunks written now.
    pub written: usize,
    /// Chunks kept from an earlier run.
    pub reused: usize,
    /// Receivers of the shard.
    pub receivers: u64,
    /// Seconds: loading the plan and transport, computing and writing.
    pub seconds: [f64; 2],
}

/// Splits units of costs `costs` into `parts` contiguous runs of nearly equal total cost:
/// run `p` ends at the first unit where the running cost reaches `(p+1)/parts` of the total
/// (every unit counted at least 1). Returns `parts` ranges `[start, end)` covering `0..len`
/// in order (some empty when there are fewer units than parts).
pub fn split_by_cost(costs: &[u64], parts: usize) -> Vec<[u32; 2]> {
    let total: u128 = costs.iter().map(|&c| u128::from(c.max(1))).sum();
    let mut out = Vec::with_capacity(parts);
    let (mut start, mut acc, mut u) = (0usize, 0u128, 0usize);
    for p in 0..parts {
        let goal = total * (p as u128 + 1) / parts.max(1) as u128;
        while u < costs.len() && (acc < goal || p + 1 == parts) {
            acc += u128::from(costs[u].max(1));
            u += 1;
        }
        out.push([start as u32, u as u32]);
        start = u;
    }
    out
}

fn io_error(path: &Path, e: impl std::fmt::Display) -> BakeError {
    BakeError::Io {
        path: path.to_owned(),
        source: std::io::Error::other(e.to_string()),
    }
}

fn write_file(path: &Path, bytes: &[u8]) -> Result<(), BakeError> {
    crate::io::write_atomic(path, bytes).map_err(|e| BakeError::Io {
        path: path.to_owned(),
        source: e,
    })
}

/// Reads and parses `dir/plan.json`.
///
/// # Errors
/// [`BakeError::Settings`] naming the file and the fix when it is missing, of another format or
/// version, or does not parse.
pub fn read_plan(dir: &Path) -> Result<PlanRecord, BakeError> {
    let path = dir.join(PLAN_FILE_NAME);
    let bytes =
        match crate::io::read_bounded(&path, crate::io::limits::MAX_JSON_BYTES, "MAX_JSON_BYTES") {
            Ok(b) => b,
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
                return Err(BakeError::Settings(format!(
                    "no plan in '{}' ({PLAN_FILE_NAME} is missing): run `ortm bake SCENE -o {} \
                 --plan --shards N` first, with the same options",
                    dir.display(),
                    dir.display()
                )));
            }
            Err(e) => return Err(io_error(&path, e)),
        };
    crate::io::from_versioned_json(&bytes, PLAN_FORMAT, PLAN_VERSION).map_err(|e| {
        BakeError::Settings(format!(
            "'{}' is not a plan this ortm reads ({e:?}): plan again with `--plan --shards N`",
            path.display()
        ))
    })
}

/// The plan of a sharded bake of `scene` into `dir` with `shards` shards; see the module docs.
/// A valid plan of the same bake and shard count already in `dir` is kept.
///
/// # Errors
/// As [`crate::bake::bake`]; [`BakeError::Settings`] for a shard count out of range.
pub fn plan(
    scene: &Scene,
    settings: &BakeSettings,
    dir: &Path,
    shards: u32,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<PlanSummary, BakeError> {
    ShardId::new(0, shards).map_err(|e| BakeError::Settings(format!("--shards: {e}")))?;
    if settings.levels.is_none() && settings.cell_rule == CellRule::Sampled {
        return Err(BakeError::Settings(
            "--cell-rule sampled (the paper's Eq. 10, kept for comparison) is not sharded: \
             shard the default integrated rule or multi-resolution maps (--levels)"
                .into(),
        ));
    }
    if let Some(t) = settings.levels {
        pipeline::check_level_tolerance(t)?;
    }
    let t0 = std::time::Instant::now();
    let _lock = crate::io::DirLock::acquire(dir)?;
    let setup = Setup::new(scene, settings)?;
    if let Ok(old) = read_plan(dir)
        && old.bake_key == setup.key.as_str()
        && old.shards.len() == shards as usize
        && verify_file(dir, &old.transport).is_ok()
    {
        events(BakeEvent::Message(format!(
            "{} already holds the plan of this bake for {shards} shards: kept",
            dir.display()
        )));
        return Ok(PlanSummary {
            texels: setup.grid.texels.len(),
            units: old.units,
            work: old.work,
            shares: shares(&old.shards),
            transport_bytes: old.transport.bytes,
            seconds: [0.0, 0.0, t0.elapsed().as_secs_f64()],
            reused: true,
        });
    }
    let transport = setup.transport(scene, settings, events, cancel)?;
    let t_transport = t0.elapsed().as_secs_f64();
    let grid = &setup.grid;
    let (work, costs, receivers_of): (WorkKind, Vec<u64>, Vec<u64>) = match settings.levels {
        Some(_) => {
            let n = grid.texels.len();
            (WorkKind::Rows, vec![n as u64; n], vec![1; n])
        }
        None => {
            let (offset_list, _) = pipeline::saved_or_new_selection(
                dir, &setup.key, &transport, grid, settings, events,
            )?;
            let cells =
                crate::bake::offsets::discrete_cells(&offset_list, grid.width, grid.height)?;
            let run = Integrator::new(&transport, grid, &offset_list, &cells);
            let receivers = run.receivers_by_cluster();
            (
                WorkKind::Cells,
                run.cluster_costs(),
                receivers.iter().map(|r| r.len() as u64).collect(),
            )
        }
    };
    let t_select = t0.elapsed().as_secs_f64() - t_transport;
    let shard_plans: Vec<ShardPlan> = split_by_cost(&costs, shards as usize)
        .into_iter()
        .map(|[a, b]| {
            let (a, b) = (a as usize, b as usize);
            let chunks = split_by_cost(&costs[a..b], CHUNKS_PER_SHARD.min(b - a).max(1))
                .into_iter()
                .filter(|[s, e]| s < e || a == b)
                .map(|[s, e]| [s + a as u32, e + a as u32])
                .collect();
            ShardPlan {
                chunks,
                receivers: receivers_of[a..b].iter().sum(),
                estimated_cost: costs[a..b].iter().sum(),
            }
        })
        .collect();
    let transport_path = dir.join(TRANSPORT_FILE_NAME);
    let mut digest = None;
    crate::io::write_atomic_with(&transport_path, |w| {
        let mut hashing = Hashing {
            inner: w,
            sha: sha2::Sha256::default(),
            bytes: 0,
        };
        transport.write_to(&mut hashing)?;
        digest = Some((hashing.bytes, sha2::Digest::finalize(hashing.sha)));
        Ok(())
    })
    .map_err(|e| BakeError::Io {
        path: transport_path.clone(),
        source: e,
    })?;
    drop(transport);
    let (bytes, sha) = digest.expect("set by a successful write");
    let record = FileRecord {
        file: TRANSPORT_FILE_NAME.into(),
        bytes,
        sha256: crate::io::hex(&sha),
    };
    let plan = PlanRecord {
        bake_key: setup.key.as_str().to_owned(),
        scene_hash: setup.hash.clone(),
        settings: setup.settings_json.clone(),
        texels: grid.texels.len() as u64,
        work,
        units: costs.len() as u32,
        shards: shard_plans,
        transport: record,
    };
    let text = crate::io::to_versioned_json(PLAN_FORMAT, PLAN_VERSION, &plan)
        .map_err(|e| io_error(&dir.join(PLAN_FILE_NAME), e))?;
    write_file(&dir.join(PLAN_FILE_NAME), text.as_bytes())?;
    Ok(PlanSummary {
        texels: grid.texels.len(),
        units: plan.units,
        work,
        shares: shares(&plan.shards),
        transport_bytes: plan.transport.bytes,
        seconds: [
            t_transport,
            t_select,
            t0.elapsed().as_secs_f64() - t_transport - t_select,
        ],
        reused: false,
    })
}

/// A writer that passes bytes on to `inner` and hashes and counts them.
struct Hashing<'w> {
    inner: &'w mut dyn std::io::Write,
    sha: sha2::Sha256,
    bytes: u64,
}

impl std::io::Write for Hashing<'_> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        sha2::Digest::update(&mut self.sha, &buf[..n]);
        self.bytes += n as u64;
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

fn shares(shards: &[ShardPlan]) -> Vec<f64> {
    let total: u64 = shards.iter().map(|s| s.estimated_cost).sum();
    (shards.iter())
        .map(|s| s.estimated_cost as f64 / total.max(1) as f64)
        .collect()
}

/// Checks that `dir/record.file` has the recorded size and SHA-256; returns its bytes.
fn verify_file(dir: &Path, record: &FileRecord) -> Result<Vec<u8>, String> {
    let path = dir.join(&record.file);
    let meta = std::fs::metadata(&path).map_err(|e| format!("'{}': {e}", path.display()))?;
    if meta.len() != record.bytes {
        return Err(format!(
            "'{}' has {} bytes, {} recorded",
            path.display(),
            meta.len(),
            record.bytes
        ));
    }
    let bytes = std::fs::read(&path).map_err(|e| format!("'{}': {e}", path.display()))?;
    let sha = crate::io::sha256_hex(&bytes);
    if sha != record.sha256 {
        return Err(format!(
            "'{}' fails its SHA-256 check (recorded {}, found {sha})",
            path.display(),
            record.sha256
        ));
    }
    Ok(bytes)
}

/// The plan of `dir` for the bake `key` with `shard.count` shards.
fn plan_for(dir: &Path, key: &BakeKey, shard: ShardId) -> Result<PlanRecord, BakeError> {
    let plan = read_plan(dir)?;
    if plan.bake_key != key.as_str() {
        return Err(BakeError::Settings(format!(
            "the plan in '{}' is for another scene or other settings (bake key {} there, {} \
             here): give the shard exactly the scene and options of the plan, or plan again",
            dir.display(),
            plan.bake_key,
            key.as_str()
        )));
    }
    if plan.shards.len() != shard.count as usize {
        return Err(BakeError::Settings(format!(
            "shard {shard}: the plan in '{}' is for {} shards; run shards 0/{n} … {}/{n}, or \
             plan again with --shards {}",
            dir.display(),
            plan.shards.len(),
            plan.shards.len().saturating_sub(1),
            shard.count,
            n = plan.shards.len(),
        )));
    }
    Ok(plan)
}

fn encode_chunk(chunk: &ChunkRecord) -> Vec<u8> {
    let mut out = CHUNK_MAGIC.to_vec();
    out.extend_from_slice(&CHUNK_VERSION.to_le_bytes());
    postcard::to_io(chunk, &mut out).expect("writing to a Vec cannot fail");
    let digest = <sha2::Sha256 as sha2::Digest>::digest(&out);
    out.extend_from_slice(&digest);
    out
}

/// Decodes a chunk file's bytes (magic, version, trailing SHA-256, then the record).
fn decode_chunk(bytes: &[u8]) -> Result<ChunkRecord, String> {
    let head = CHUNK_MAGIC.len() + 4;
    if bytes.len() < head + 32 || &bytes[..CHUNK_MAGIC.len()] != CHUNK_MAGIC {
        return Err("not an ortm shard chunk".into());
    }
    let version = u32::from_le_bytes(bytes[CHUNK_MAGIC.len()..head].try_into().expect("4"));
    if version != CHUNK_VERSION {
        return Err(format!(
            "chunk version {version}, this ortm reads version {CHUNK_VERSION}"
        ));
    }
    let (body, digest) = bytes.split_at(bytes.len() - 32);
    if <sha2::Sha256 as sha2::Digest>::digest(body).as_slice() != digest {
        return Err("its trailing SHA-256 does not match its content".into());
    }
    postcard::from_bytes(&body[head..]).map_err(|e| e.to_string())
}

fn chunk_file_name(c: usize) -> String {
    format!("chunk_{c:05}.bin")
}

/// A chunk file of `shard`, when present, whole and of this bake and place.
fn existing_chunk(
    folder: &Path,
    key: &BakeKey,
    shard: ShardId,
    c: usize,
    units: [u32; 2],
) -> Option<FileRecord> {
    let name = chunk_file_name(c);
    let bytes = std::fs::read(folder.join(&name)).ok()?;
    let rec = decode_chunk(&bytes).ok()?;
    (rec.bake_key == key.as_str()
        && rec.shard == shard.index
        && rec.of == shard.count
        && rec.chunk as usize == c
        && rec.units == units)
        .then(|| FileRecord {
            file: name,
            bytes: bytes.len() as u64,
            sha256: crate::io::sha256_hex(&bytes),
        })
}

/// Runs shard `shard` of the plan in `dir` for `scene` with `settings` (which must be the
/// plan's); see the module docs. Resumes from the chunks an earlier run of the same shard left.
///
/// # Errors
/// [`BakeError::Settings`] when there is no plan, it is for another bake or shard count, or its
/// transport fails its checksum; [`BakeError::Interrupted`] when cancelled (finished chunks are
/// kept); I/O errors.
pub fn run_shard(
    scene: &Scene,
    settings: &BakeSettings,
    dir: &Path,
    shard: ShardId,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<ShardSummary, BakeError> {
    let t0 = std::time::Instant::now();
    let setup = Setup::new(scene, settings)?;
    let plan = plan_for(dir, &setup.key, shard)?;
    // Only a shard of the plan makes its folder.
    let folder = dir.join(shard.folder());
    let _lock = crate::io::DirLock::acquire(&folder)?;
    let mine = &plan.shards[shard.index as usize];
    let existing: Vec<Option<FileRecord>> = (mine.chunks.iter().enumerate())
        .map(|(c, &u)| existing_chunk(&folder, &setup.key, shard, c, u))
        .collect();
    let reused = existing.iter().filter(|e| e.is_some()).count();
    if reused == mine.chunks.len() && folder.join(DONE_FILE_NAME).exists() {
        events(BakeEvent::Message(format!(
            "shard {shard} is already finished ({reused} chunks): nothing to do"
        )));
        return Ok(ShardSummary {
            written: 0,
            reused,
            receivers: mine.receivers,
            seconds: [t0.elapsed().as_secs_f64(), 0.0],
        });
    }
    let grid = &setup.grid;
    events(BakeEvent::Message(format!(
        "shard {shard}: {} of {} receivers in {} chunks ({reused} already done); loading the \
         plan's transport ({:.1} MB)",
        mine.receivers,
        grid.texels.len(),
        mine.chunks.len(),
        plan.transport.bytes as f64 / 1e6
    )));
    let bytes = verify_file(dir, &plan.transport).map_err(|e| {
        BakeError::Settings(format!(
            "shard {shard}: the plan's transport {e}: plan again"
        ))
    })?;
    let transport = Transport::from_bytes(scene, grid, &bytes).map_err(|e| {
        BakeError::Settings(format!(
            "shard {shard}: '{}': {e}; plan again",
            dir.join(TRANSPORT_FILE_NAME).display()
        ))
    })?;
    drop(bytes);
    let t_load = t0.elapsed().as_secs_f64();
    let offsets: Vec<IVec2> = match plan.work {
        WorkKind::Rows => Vec::new(),
        WorkKind::Cells => saved_selection(dir, &setup.key, settings)?.0,
    };
    let cells = match plan.work {
        WorkKind::Rows => None,
        WorkKind::Cells => Some(crate::bake::offsets::discrete_cells(
            &offsets,
            grid.width,
            grid.height,
        )?),
    };
    let integrator = cells
        .as_ref()
        .map(|c| Integrator::new(&transport, grid, &offsets, c));
    let receivers = integrator.as_ref().map(Integrator::receivers_by_cluster);
    // The near fields (rows of multi-resolution maps) of this shard's receivers: the chunks are
    // contiguous ranges of texel indices, in order.
    let near = match (&plan.work, mine.chunks.first(), mine.chunks.last()) {
        (WorkKind::Rows, Some(&[a, _]), Some(&[_, b])) => Some(pipeline::NearFieldRows::build(
            scene,
            &transport,
            grid,
            settings,
            a..b,
            events,
            cancel,
        )?),
        _ => None,
    };
    let todo: u64 = (mine.chunks.iter().zip(&existing))
        .filter(|(_, e)| e.is_none())
        .map(|(&[a, b], _)| match &receivers {
            Some(r) => r[a as usize..b as usize]
                .iter()
                .map(|v| v.len() as u64)
                .sum(),
            None => u64::from(b - a),
        })
        .sum();
    let progress = |n: u64| events(BakeEvent::Advance(n));
    // The rows' own phase events are folded into this one.
    let quiet = |e: BakeEvent| {
        if let BakeEvent::Advance(n) = e {
            events(BakeEvent::Advance(n));
        }
    };
    events(BakeEvent::Phase {
        name: "shard receivers",
        total: todo,
    });
    let mut records = Vec::with_capacity(mine.chunks.len());
    let mut written = 0;
    for (c, (&units, done)) in mine.chunks.iter().zip(existing).enumerate() {
        if let Some(r) = done {
            records.push(r);
            continue;
        }
        if cancel.load(Ordering::Relaxed) {
            return Err(BakeError::Interrupted {
                done: records.len(),
                total: mine.chunks.len(),
            });
        }
        let [a, b] = units;
        let payload = match (&integrator, &receivers) {
            (Some(run), Some(recv)) => {
                let values = run.clusters_in(a as usize..b as usize, &progress);
                Payload::Cells(
                    recv[a as usize..b as usize]
                        .iter()
                        .cloned()
                        .zip(values)
                        .collect(),
                )
            }
            _ => {
                let tolerance = settings.levels.unwrap_or(0.0);
                Payload::Rows(pipeline::level_rows_in(
                    &transport,
                    grid,
                    tolerance,
                    near.as_ref(),
                    a..b,
                    &quiet,
                    cancel,
                )?)
            }
        };
        let bytes = encode_chunk(&ChunkRecord {
            bake_key: setup.key.as_str().to_owned(),
            shard: shard.index,
            of: shard.count,
            chunk: c as u32,
            units,
            payload,
        });
        let name = chunk_file_name(c);
        write_file(&folder.join(&name), &bytes)?;
        written += 1;
        records.push(FileRecord {
            file: name,
            bytes: bytes.len() as u64,
            sha256: crate::io::sha256_hex(&bytes),
        });
    }
    let done = DoneRecord {
        bake_key: setup.key.as_str().to_owned(),
        shard: shard.index,
        of: shard.count,
        chunks: records,
    };
    let text = crate::io::to_versioned_json(DONE_FORMAT, DONE_VERSION, &done)
        .map_err(|e| io_error(&folder.join(DONE_FILE_NAME), e))?;
    write_file(&folder.join(DONE_FILE_NAME), text.as_bytes())?;
    Ok(ShardSummary {
        written,
        reused,
        receivers: mine.receivers,
        seconds: [t_load, t0.elapsed().as_secs_f64() - t_load],
    })
}

/// The offsets the plan selected and the importance density's data points (`selection.json`).
fn saved_selection(
    dir: &Path,
    key: &BakeKey,
    settings: &BakeSettings,
) -> Result<(Vec<IVec2>, Vec<[f64; 3]>), BakeError> {
    match bake_dir::read_selection(dir, key.as_str(), settings.offsets, settings.size)
        .map_err(MapsError::from)?
    {
        bake_dir::SavedSelection::Reuse(s) => Ok((
            s.offsets.iter().map(|o| IVec2::from_array(*o)).collect(),
            s.data_points,
        )),
        bake_dir::SavedSelection::Discard(why) => Err(BakeError::Settings(format!(
            "the plan's offset selection cannot be used ({why}): plan again"
        ))),
        bake_dir::SavedSelection::None => Err(BakeError::Settings(format!(
            "'{}' is missing: plan again",
            dir.join(bake_dir::SELECTION_FILE_NAME).display()
        ))),
    }
}

/// Reads and checks a shard's `done.json` and chunks; returns the chunks in order.
fn verified_shard(
    dir: &Path,
    plan: &PlanRecord,
    shard: ShardId,
) -> Result<Vec<ChunkRecord>, BakeError> {
    let folder = dir.join(shard.folder());
    let rerun = format!("rerun shard {shard} (`--shard {shard}` with the plan's options)");
    let done_path = folder.join(DONE_FILE_NAME);
    let bytes = match crate::io::read_bounded(
        &done_path,
        crate::io::limits::MAX_JSON_BYTES,
        "MAX_JSON_BYTES",
    ) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            return Err(BakeError::Settings(format!(
                "shard {shard} has not finished ('{}' is missing): {rerun}",
                done_path.display()
            )));
        }
        Err(e) => return Err(io_error(&done_path, e)),
    };
    let done: DoneRecord = crate::io::from_versioned_json(&bytes, DONE_FORMAT, DONE_VERSION)
        .map_err(|e| {
            BakeError::Settings(format!(
                "shard {shard}: '{}' does not parse ({e:?}): delete it and {rerun}",
                done_path.display()
            ))
        })?;
    let expected = &plan.shards[shard.index as usize].chunks;
    if done.bake_key != plan.bake_key
        || done.shard != shard.index
        || done.of != shard.count
        || done.chunks.len() != expected.len()
    {
        return Err(BakeError::Settings(format!(
            "shard {shard}: '{}' is not this plan's (another bake or shard): delete the folder \
             '{}' and {rerun}",
            done_path.display(),
            folder.display()
        )));
    }
    let mut out = Vec::with_capacity(expected.len());
    for (c, (rec, &units)) in done.chunks.iter().zip(expected).enumerate() {
        if rec.file != chunk_file_name(c) {
            return Err(BakeError::Settings(format!(
                "shard {shard}: '{}' names chunk {c} '{}': delete the folder '{}' and {rerun}",
                done_path.display(),
                rec.file,
                folder.display()
            )));
        }
        let bytes = verify_file(&folder, rec).map_err(|e| {
            BakeError::Settings(format!("shard {shard}: chunk {e}: delete it and {rerun}"))
        })?;
        let chunk = decode_chunk(&bytes).map_err(|e| {
            BakeError::Settings(format!(
                "shard {shard}: '{}': {e}: delete it and {rerun}",
                folder.join(&rec.file).display()
            ))
        })?;
        if chunk.bake_key != plan.bake_key
            || chunk.shard != shard.index
            || chunk.of != shard.count
            || chunk.chunk as usize != c
            || chunk.units != units
        {
            return Err(BakeError::Settings(format!(
                "shard {shard}: '{}' is not the plan's chunk {c}: delete it and {rerun}",
                folder.join(&rec.file).display()
            )));
        }
        out.push(chunk);
    }
    Ok(out)
}

/// What [`merge`] did.
#[derive(Clone, Debug)]
pub struct MergeSummary {
    /// Maps in the index.
    pub maps: usize,
    /// Maps kept from an interrupted merge.
    pub reused: usize,
    /// Covered texels.
    pub texels: usize,
    /// Shards merged.
    pub shards: usize,
    /// Stored (cropped) texels over all maps.
    pub stored_texels: u64,
    /// Seconds: verifying and reading the shards, writing maps and index.
    pub seconds: [f64; 2],
    /// Files and folders of the plan and shards removed after the index was written.
    pub removed: Vec<PathBuf>,
}

/// Merges the shards of the plan in `dir` for `scene` (the plan's scene; its hash is checked)
/// into maps, report and `index.json`, then removes the plan, transport and shard folders; see
/// the module docs.
///
/// # Errors
/// [`BakeError::Settings`] naming the shard and the fix when a shard is missing or a chunk fails
/// its checksum, or when `scene` is not the plan's; I/O errors; [`BakeError::Interrupted`].
pub fn merge(
    scene: &Scene,
    dir: &Path,
    events: &(dyn Fn(BakeEvent) + Sync),
    cancel: &AtomicBool,
) -> Result<MergeSummary, BakeError> {
    let t0 = std::time::Instant::now();
    let _lock = crate::io::DirLock::acquire(dir)?;
    let plan = read_plan(dir)?;
    let settings = plan.bake_settings()?;
    let Setup {
        grid,
        hash,
        settings_json,
        key,
        ..
    } = Setup::new(scene, &settings)?;
    if key.as_str() != plan.bake_key {
        return Err(BakeError::Settings(format!(
            "the scene given to the merge is not the plan's (its hash is {hash}, the plan's {}): \
             merge with the scene the plan was made from",
            plan.scene_hash
        )));
    }
    let grid = &grid;
    let n = plan.shards.len() as u32;
    events(BakeEvent::Phase {
        name: "verifying shards",
        total: u64::from(n),
    });
    let mut chunks = Vec::new();
    for i in 0..n {
        chunks.extend(verified_shard(dir, &plan, ShardId { index: i, count: n })?);
        events(BakeEvent::Advance(1));
    }
    let t_read = t0.elapsed().as_secs_f64();
    let written_maps;
    let (reused, stored_texels);
    match plan.work {
        WorkKind::Cells => {
            let (offsets, points) = saved_selection(dir, &key, &settings)?;
            let mut receivers = Vec::new();
            let mut values = Vec::new();
            for c in chunks {
                let Payload::Cells(v) = c.payload else {
                    return Err(BakeError::Settings(format!(
                        "shard {}/{n}: chunk {} holds rows, the plan cells: delete the shard \
                         folders and rerun the shards",
                        c.shard, c.chunk
                    )));
                };
                for (r, cv) in v {
                    if cv.values.len() != r.len() * offsets.len() {
                        return Err(BakeError::Settings(format!(
                            "shard {}/{n}: chunk {} has {} values for {} receivers and {} \
                             maps: delete it and rerun the shard",
                            c.shard,
                            c.chunk,
                            cv.values.len(),
                            r.len(),
                            offsets.len()
                        )));
                    }
                    receivers.push(r);
                    values.push(cv);
                }
            }
            check_every_receiver_once(grid, receivers.iter().flatten().copied())?;
            let iv = cells::assemble(grid, offsets.len(), &receivers, values);
            let map_plan = MapPlan::with_values(grid, &offsets, iv)?;
            let w = pipeline::write_maps(dir, &key, None, grid, map_plan, events, cancel)?;
            (reused, stored_texels) = (w.reused, w.stored_texels);
            written_maps = w.entries.len();
            pipeline::finish_offset_bake(dir, (grid, hash, settings_json), (&offsets, &points), w)?;
        }
        WorkKind::Rows => {
            let mut entries = Vec::with_capacity(grid.texels.len());
            let mut next = 0u32;
            for c in chunks {
                let Payload::Rows(rows) = c.payload else {
                    return Err(BakeError::Settings(format!(
                        "shard {}/{n}: chunk {} holds cells, the plan rows: delete the shard \
                         folders and rerun the shards",
                        c.shard, c.chunk
                    )));
                };
                if c.units[0] != next || (c.units[1] - c.units[0]) as usize != rows.len() {
                    return Err(BakeError::Settings(format!(
                        "shard {}/{n}: chunk {} covers receivers {}..{} with {} rows, expected \
                         from {next}: delete it and rerun the shard",
                        c.shard,
                        c.chunk,
                        c.units[0],
                        c.units[1],
                        rows.len()
                    )));
                }
                next = c.units[1];
                entries.extend(rows);
            }
            if entries.len() != grid.texels.len() {
                return Err(BakeError::Settings(format!(
                    "the shards hold rows of {} receivers, the lightmap {}: plan again",
                    entries.len(),
                    grid.texels.len()
                )));
            }
            let tolerance = settings.levels.unwrap_or(0.0);
            let w = pipeline::write_level_entries(
                dir,
                &key,
                grid,
                entries,
                (tolerance, settings.receiver_blocks),
                events,
                cancel,
            )?;
            (reused, stored_texels) = (w.reused, w.stored_texels);
            written_maps = w.entries.len();
            pipeline::bake_index((grid.width, grid.height), hash, settings_json, w.entries)
                .write(dir)?;
        }
    }
    // The bake is complete: what only the sharded run needed goes, shard folders of earlier
    // plans with other counts included.
    let mut removed = Vec::new();
    for folder in shard_folders(dir) {
        if std::fs::remove_dir_all(&folder).is_ok() {
            removed.push(folder);
        }
    }
    for name in [TRANSPORT_FILE_NAME, PLAN_FILE_NAME] {
        let p = dir.join(name);
        if std::fs::remove_file(&p).is_ok() {
            removed.push(p);
        }
    }
    Ok(MergeSummary {
        maps: written_maps,
        reused,
        texels: grid.texels.len(),
        shards: n as usize,
        stored_texels,
        seconds: [t_read, t0.elapsed().as_secs_f64() - t_read],
        removed,
    })
}

/// The folders `shard_I_of_N` of `dir` (any `I`, `N`).
fn shard_folders(dir: &Path) -> Vec<PathBuf> {
    let Ok(listing) = std::fs::read_dir(dir) else {
        return Vec::new();
    };
    let is_shard = |name: &str| {
        name.strip_prefix("shard_")
            .and_then(|r| r.split_once("_of_"))
            .is_some_and(|(i, n)| i.parse::<u32>().is_ok() && n.parse::<u32>().is_ok())
    };
    let mut out: Vec<PathBuf> = listing
        .flatten()
        .filter(|e| e.file_type().is_ok_and(|t| t.is_dir()))
        .filter(|e| e.file_name().to_str().is_some_and(is_shard))
        .map(|e| e.path())
        .collect();
    out.sort();
    out
}

/// Refuses receivers that do not cover every covered texel exactly once.
fn check_every_receiver_once(
    grid: &TexelGrid,
    receivers: impl Iterator<Item = u32>,
) -> Result<(), BakeError> {
    let mut seen = vec![false; grid.texels.len()];
    for r in receivers {
        match seen.get_mut(r as usize) {
            Some(s) if !*s => *s = true,
            _ => {
                return Err(BakeError::Settings(format!(
                    "the shards hold receiver {r} twice or out of range: delete the shard \
                     folders, plan again and rerun the shards"
                )));
            }
        }
    }
    if let Some(miss) = seen.iter().position(|s| !s) {
        return Err(BakeError::Settings(format!(
            "no shard holds receiver {miss}: plan again and rerun the shards"
        )));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_by_cost_covers_every_unit_once_and_balances() {
        let costs: Vec<u64> = (0..1000u64).map(|i| (i * 7919) % 101 + 1).collect();
        for parts in [1, 2, 3, 5, 16, 999, 1000, 1500] {
            let runs = split_by_cost(&costs, parts);
            assert_eq!(runs.len(), parts);
            assert_eq!(runs[0][0], 0);
            assert_eq!(runs[parts - 1][1], 1000);
            for w in runs.windows(2) {
                assert_eq!(w[0][1], w[1][0]);
            }
            if parts <= 16 {
                let total: u64 = costs.iter().sum();
                let max = costs.iter().max().copied().unwrap_or(0);
                for r in &runs {
                    let c: u64 = costs[r[0] as usize..r[1] as usize].iter().sum();
                    // Within one unit of the even share.
                    assert!(
                        c.abs_diff(total / parts as u64) <= max + 1,
                        "{parts}: {c} vs {}",
                        total / parts as u64
                    );
                }
            }
        }
        // One dear unit among cheap ones: the split follows the cost, not the count.
        let mut costs = vec![1u64; 100];
        costs[10] = 1000;
        let runs = split_by_cost(&costs, 2);
        assert_eq!(runs[0], [0, 11]);
    }

    #[test]
    fn shard_ids_parse_and_refuse_with_the_fix() {
        assert_eq!(ShardId::parse("2/4"), Ok(ShardId { index: 2, count: 4 }));
        for bad in ["4/4", "1", "a/2", "0/0", "-1/3", "1/20000"] {
            let e = ShardId::parse(bad).expect_err(bad);
            assert!(e.contains("--shard"), "{e}");
        }
    }

    #[test]
    fn chunks_round_trip_and_refuse_a_flipped_bit() {
        let rec = ChunkRecord {
            bake_key: "k".into(),
            shard: 1,
            of: 3,
            chunk: 2,
            units: [5, 9],
            payload: Payload::Rows(vec![vec![Entry {
                level: 1,
                offset: IVec2::new(-3, 4),
                value: [0.5, f32::MIN_POSITIVE, -1e-30],
            }]]),
        };
        let mut bytes = encode_chunk(&rec);
        assert_eq!(decode_chunk(&bytes), Ok(rec));
        let mid = bytes.len() / 2;
        bytes[mid] ^= 1;
        assert!(decode_chunk(&bytes).unwrap_err().contains("SHA-256"));
    }
}
