//! `ortm bake SCENE -o DIR`: offsets, transfer maps, index and report, with progress bars,
//! Ctrl-C handling and resume; and the sharded bake's three steps (`--plan --shards N`,
//! `--shard I/N`, `--merge`; [`ortm::bake::shard`], `docs/sharding.md`).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use super::progress::Progress;
use anyhow::{Context, Result, bail};
use ortm::bake::offsets::ImportanceMetric;
use ortm::bake::shard::{self, ShardId};
use ortm::bake::transport::Effects;
use ortm::bake::transport::coarse::{AUTO_EXACT_TEXELS, AUTO_MAX_CLUSTERS};
use ortm::bake::transport::hier::{DEFAULT_SUBSURFACE_TOLERANCE, DEFAULT_TOLERANCE};
use ortm::bake::{BakeEvent, BakeSettings, CellRule, Selector, bake};
use ortm::io::limits::{MAX_COARSE_BLOCK, MAX_REFINEMENT_ITERATIONS};

/// `--tolerance` without a value: [`ortm::bake::transport::hier::DEFAULT_TOLERANCE`], as clap
/// takes it (a test checks they agree).
const DEFAULT_TOLERANCE_ARG: &str = "1e-4";

/// Arguments of `ortm bake`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file or built-in scene name ([`super::SCENE_HELP`]).
    #[arg(default_value = "cornell", help = super::SCENE_HELP)]
    pub scene: String,
    /// Output bake directory.
    #[arg(short, long, default_value = "out/bake")]
    pub output: PathBuf,
    /// Lightmap size (square), texels; default: the scene's.
    #[arg(long)]
    pub size: Option<u32>,
    /// Number of offsets (transfer maps).
    #[arg(long, default_value_t = 100)]
    pub offsets: usize,
    /// Effects: comma-separated `radiosity`, `sss`.
    #[arg(long, default_value = "radiosity,sss")]
    pub effects: String,
    /// Random seed of the offset selection.
    #[arg(long, default_value_t = 1)]
    pub seed: u64,
    /// Offset selector: `importance` (the paper's) or `jittered-grid` (baseline).
    #[arg(long, default_value = "importance")]
    pub selector: String,
    /// Transference metric: `max` or `average`.
    #[arg(long, default_value = "max")]
    pub metric: String,
    /// How a map covers its Voronoi cell: `integrated` (the transfer summed over the cell) or
    /// `sampled` (the paper's Eq. 10, `TR·TVA`).
    #[arg(long, default_value = "integrated")]
    pub cell_rule: String,
    /// Refinement iterations of the importance density (0 to MAX_REFINEMENT_ITERATIONS).
    #[arg(
        long,
        default_value_t = BakeSettings::default().refinement_iterations as u32,
        value_parser = clap::value_parser!(u32).range(0..=MAX_REFINEMENT_ITERATIONS as i64),
        help = format!("Refinement iterations of the importance density, 0..={MAX_REFINEMENT_ITERATIONS}")
    )]
    pub iterations: u32,
    /// Texels per side of the clusters of the coarse higher-order solve.
    #[arg(
        long,
        value_parser = clap::value_parser!(u32).range(0..=i64::from(MAX_COARSE_BLOCK)),
        help = format!("Texels per side of the clusters of the coarse higher-order solve, 1..={MAX_COARSE_BLOCK}; 0 = automatic: single texels (the exact solve) up to {AUTO_EXACT_TEXELS} covered texels, else the finest block with at most {AUTO_MAX_CLUSTERS} clusters; 0 when --tolerance is given [default: {}]", BakeSettings::default().coarse_block)
    )]
    pub coarse_block: Option<u32>,
    /// Tolerance of the hierarchical first bounce.
    #[arg(
        long,
        num_args = 0..=1,
        default_missing_value = DEFAULT_TOLERANCE_ARG,
        value_name = "ε",
        help = format!("Hierarchical first bounce: the light between surfaces from links refined to this tolerance (a form factor; smaller is more accurate and takes more memory and time) instead of from the coarse clusters; makes large lightmaps (1024² and up) bakeable. --tolerance alone: {DEFAULT_TOLERANCE_ARG}, the largest tolerance whose evaluator is within 2 % (indirect) of the exact solve on the Cornell box, the maze and the head at 64² (README, \"Transport model\")")
    )]
    pub tolerance: Option<f32>,
    /// With --tolerance: the subsurface walk's own tolerance.
    #[arg(
        long,
        value_name = "ε_S",
        help = format!("With --tolerance: the tolerance of the subsurface term's walk over the cluster tree (the profile's mean over a node may err by this fraction of a sender's power per unit area); on the head at 512² the default is 0.52 % of the subsurface term's RMS off its exact sum and visits 306 nodes per receiver (1e-4: 0.18 %, 487 nodes; README, \"Transport model\") [default: {DEFAULT_SUBSURFACE_TOLERANCE:e}]")
    )]
    pub subsurface_tolerance: Option<f32>,
    /// Multi-resolution maps at this tolerance instead of importance-sampled offsets.
    #[arg(
        long,
        help = format!("Multi-resolution maps instead of --offsets: each receiver's transfer split into blocks of a first-order pyramid, from single texels near it to coarse blocks far away, each block's error at most this tolerance × the brightest first order / 2 (e.g. 3e-3; 0 = every texel, exact). The rows come from the hierarchical transport at --tolerance ({DEFAULT_TOLERANCE_ARG} unless given), or, with --coarse-block P and no --tolerance, from the pair evaluator on P×P clusters (n² visibility rays, lightmaps up to ~128²); n² row entries either way (head 256²: ~70 s on 2 cores)")
    )]
    pub levels: Option<f64>,
    /// With --levels: share blocks between neighbouring receivers (`on`) or not (`off`, the
    /// default).
    #[arg(
        long,
        value_name = "on|off",
        help = "With --levels: share each kept block between the receivers of a 2^r×2^r receiver block when every receiver's own value is within the tolerance / 2 of their mean, stored once per block (on: for any lighting the same error bound per block, but the maps' crops keep most of the zeros between shared blocks, so the GPU work falls little: head 256² at 3e-3, 14.9 M stored texels and 148 k pieces instead of 15.9 M and 94 k), or keep one value per receiver (off, the default)"
    )]
    pub receiver_blocks: Option<String>,
    /// With --levels and --tolerance: gather the interreflection's near field by G×G rays per
    /// texel (2–64; 0 = off): the form factors to the texels within --near-gather-reach texel
    /// sizes in 3D are taken from what the rays hit on the mesh itself and added to every
    /// receiver's first bounce (README, *The interreflection's near field*). Nearer the
    /// path-traced reference in creases and slits of scanned surfaces; costs a gather of
    /// G² rays per texel and larger rows.
    #[arg(long, default_value_t = 0, value_name = "G")]
    pub near_gather: u32,
    /// With --near-gather: the radius of the near set in texel sizes (the receiver's √area),
    /// above 0, at most 64 [default: 16].
    #[arg(long, value_name = "R")]
    pub near_gather_reach: Option<f32>,
    /// With --tolerance: balance the skin weights' rows and columns in R rounds (0 = off, the
    /// columns capped alone), so that what a texel gathers under a uniform irradiance is the
    /// continuous surface's value (README, *The subsurface weights' rows*; as `ortm solve
    /// --balance-subsurface`). Keeps every skin pair's raw weight while the transport is
    /// built (16 bytes each, ~390 MB for the head at 256², checked against the memory limit
    /// first).
    #[arg(long, default_value_t = 0, value_name = "R")]
    pub balance_subsurface: u32,
    /// With --levels on the hierarchical transport (--tolerance, or no --coarse-block): skin's
    /// near field at N×N sub-texels (odd, 3–7; 1 = off):
    /// each skin texel's first scattering from the skin texels within --near-field-reach
    /// texels takes the profile integrated over their sub-texels instead of the transport's
    /// normalised texel weights (README, *In a bake: the near field's weights*; as `ortm solve
    /// --near-field N --near-field-light input`). Nearer the path-traced reference on lit skin
    /// and beside shadow edges; the rows and the maps keep their size. Default: 3 where it
    /// applies — --levels on the hierarchical transport, the sss effect, a scene with a
    /// subsurface material — else 1.
    #[arg(long, value_name = "N")]
    pub near_field: Option<u32>,
    /// With --near-field: the senders within R texels of each skin texel (in x and in y), 0 to 8
    /// [default: 2].
    #[arg(long, value_name = "R")]
    pub near_field_reach: Option<u32>,
    /// With --levels on the hierarchical transport (--tolerance, or no --coarse-block): the
    /// most texels that stay clusters of their own in the
    /// coarse solve of the higher bounces — those facing the surface beside them (lips,
    /// eyelids, ears, a room's corners), whose bounces tiles would average away (README,
    /// *Slits in the remainder*). The solve is dense: more costs time as the cube of the
    /// clusters; on the head at 256² 8192 took the maps from 6.9 % to 4.6 % (indirect) off
    /// their solve for a 112 s transport instead of 32 s. At most 32768 [default: 4096].
    #[arg(long, value_name = "N")]
    pub slit_texels: Option<u32>,
    /// Sharded bake, step 1: the plan (transport, offsets, work split) for `--shards N`.
    #[arg(
        long,
        requires = "shards",
        conflicts_with_all = ["shard", "merge"],
        help = "Sharded bake, step 1 (one process): build the transport and the offset selection once and split the receivers into --shards N cost-balanced shares; writes plan.json and transport.bin into the output folder (docs/sharding.md)"
    )]
    pub plan: bool,
    /// The number of shards (with --plan; with --shard when the index comes from
    /// JOB_COMPLETION_INDEX).
    #[arg(long, value_name = "N")]
    pub shards: Option<u32>,
    /// Sharded bake, step 2: shard I of N.
    #[arg(
        long,
        value_name = "I/N",
        num_args = 0..=1,
        default_missing_value = "",
        conflicts_with = "merge",
        help = "Sharded bake, step 2: compute shard I (0-based) of N of the plan in the output folder, with the plan's scene and options (resumable: rerun it after a failure). Without I/N: I from SLURM_ARRAY_TASK_ID (Slurm job arrays, --array=0-(N-1)) or JOB_COMPLETION_INDEX (Kubernetes Indexed Jobs); N from --shards, else the plan, else SLURM_ARRAY_TASK_COUNT"
    )]
    pub shard: Option<String>,
    /// Sharded bake, step 3: merge the shards.
    #[arg(
        long,
        help = "Sharded bake, step 3 (one process): `ortm bake DIR --merge` checks every shard's files, writes the maps, report and index.json — the same bytes as a single-process bake — and removes the plan, transport and shard folders. Scene and options are the plan's"
    )]
    pub merge: bool,
}

/// Parses `--effects`.
pub fn parse_effects(s: &str) -> Result<Effects> {
    let mut e = Effects {
        radiosity: false,
        subsurface: false,
    };
    for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
        match part {
            "radiosity" => e.radiosity = true,
            "sss" | "subsurface" => e.subsurface = true,
            other => bail!(
                "--effects: unknown effect '{other}'; use radiosity, sss or both (radiosity,sss)"
            ),
        }
    }
    if !e.radiosity && !e.subsurface {
        bail!("--effects: name at least one of radiosity, sss");
    }
    Ok(e)
}

/// `--near-field`'s default: [`DEFAULT_NEAR_FIELD`] sub-texels per side where the near field
/// applies — multi-resolution maps (`levels`) on the hierarchical transport (`tolerance`), with
/// the subsurface effect, in a scene with a translucent material — else `None` (off). Chosen
/// from the head's accuracy at 256² against the 8,192-path reference: the maps' indirect error
/// 20.7 → 16.7 % (64²: 54.5 → 42.0 %) for 1.5 s of a 58 s bake, rows and maps of the same size
/// (README, *In a bake: the near field's weights*).
pub fn default_near_field(
    levels: Option<f64>,
    tolerance: Option<f32>,
    effects: Effects,
    translucent: bool,
) -> Option<u32> {
    (levels.is_some() && tolerance.is_some() && effects.subsurface && translucent)
        .then_some(DEFAULT_NEAR_FIELD)
}

/// Sub-texels per side of `--near-field` where it is on by default ([`default_near_field`]):
/// 5 took the head's maps at 256² only from 16.69 % to 16.43 % (indirect), its bake 65.5 s
/// (beside other work) against 60.4–62.0 s (README, *In a bake: the near field's weights*).
pub const DEFAULT_NEAR_FIELD: u32 = 3;

/// Builds the settings from the arguments, the scene's lightmap size and whether the scene has
/// a translucent (subsurface) material, which turns `--near-field` on by default
/// ([`default_near_field`]).
pub fn settings(a: &Args, size: (u32, u32), translucent: bool) -> Result<BakeSettings> {
    let selector = match a.selector.as_str() {
        "importance" => Selector::Importance,
        "jittered-grid" | "jittered" => Selector::JitteredGrid,
        o => bail!("--selector: unknown '{o}'; use importance or jittered-grid"),
    };
    let metric = match a.metric.as_str() {
        "max" => ImportanceMetric::Max,
        "average" | "avg" => ImportanceMetric::Average,
        o => bail!("--metric: unknown '{o}'; use max or average"),
    };
    let cell_rule = match a.cell_rule.as_str() {
        "integrated" => CellRule::Integrated,
        "sampled" => CellRule::Sampled,
        o => bail!("--cell-rule: unknown '{o}'; use integrated or sampled"),
    };
    if let Some(t) = a.tolerance
        && !(t.is_finite() && t > 0.0)
    {
        bail!("--tolerance {t}: give a positive number, e.g. 1e-3");
    }
    // Multi-resolution maps converge to their transport: without a transport named
    // (`--tolerance` or `--coarse-block`) they take the hierarchical one at the default tolerance,
    // which bakes at any size and is within 3 % (indirect) of the exact solve at 64², where the
    // 8×8 clusters are 9–25 % off (README, "Multi-resolution maps").
    let tolerance = match (a.tolerance, a.levels, a.coarse_block) {
        (None, Some(_), None) => Some(DEFAULT_TOLERANCE),
        (t, _, _) => t,
    };
    match (a.subsurface_tolerance, tolerance) {
        (Some(_), None) => bail!(
            "--subsurface-tolerance applies to the hierarchical transport: give --tolerance too \
             (e.g. --tolerance --subsurface-tolerance 1e-3) or bake --levels without \
             --coarse-block, or drop --subsurface-tolerance"
        ),
        (Some(t), Some(_)) if !(t.is_finite() && t > 0.0) => {
            bail!("--subsurface-tolerance {t}: give a positive number, e.g. 1e-3")
        }
        _ => {}
    }
    if let Some(e) = a.levels
        && !(e.is_finite() && e >= 0.0)
    {
        bail!("--levels {e}: give a tolerance ≥ 0, e.g. 3e-3");
    }
    let receiver_blocks = match (a.receiver_blocks.as_deref(), a.levels) {
        (None, _) => false,
        (Some(_), None) => bail!(
            "--receiver-blocks only applies to multi-resolution maps: give --levels ε too (e.g. \
             --levels 3e-3 --receiver-blocks off), or drop --receiver-blocks"
        ),
        (Some("on"), Some(_)) => true,
        (Some("off"), Some(_)) => false,
        (Some(o), Some(_)) => bail!("--receiver-blocks: unknown '{o}'; use on or off"),
    };
    let effects = parse_effects(&a.effects)?;
    let coarse_block = a.coarse_block.unwrap_or(if tolerance.is_some() {
        0
    } else {
        BakeSettings::default().coarse_block
    });
    Ok(BakeSettings {
        size,
        tolerance,
        subsurface_tolerance: tolerance.map(|_| {
            a.subsurface_tolerance
                .unwrap_or(DEFAULT_SUBSURFACE_TOLERANCE)
        }),
        levels: a.levels,
        receiver_blocks,
        near_gather: (a.near_gather != 0).then_some(a.near_gather),
        near_gather_reach: a.near_gather_reach,
        balance_subsurface: (a.balance_subsurface != 0).then_some(a.balance_subsurface),
        near_field: match a.near_field {
            Some(1) => None,
            Some(n) => Some(n),
            None => default_near_field(a.levels, tolerance, effects, translucent),
        },
        near_field_reach: a.near_field_reach,
        slit_texels: a.slit_texels,
        cell_rule,
        offsets: a.offsets,
        effects,
        seed: a.seed,
        selector,
        metric,
        refinement_iterations: a.iterations as usize,
        coarse_block,
        scene: Some(recorded_scene(&a.scene)),
        ..BakeSettings::default()
    })
}

/// The scene argument as the bake records it: a built-in name as given, a scene file as its
/// absolute path (so that `ortm render DIR` finds it from any folder; a file outside the bake
/// folder is still only opened when named with `--scene`, see
/// [`ortm::bake_dir::check_recorded_scene`]).
fn recorded_scene(arg: &str) -> String {
    if super::BUILTIN_SCENES.contains(&arg) {
        return arg.to_owned();
    }
    std::fs::canonicalize(arg)
        .ok()
        .and_then(|p| p.to_str().map(str::to_owned))
        .unwrap_or_else(|| arg.to_owned())
}

/// After a finished bake in `dir`: removes the map files its new `index.json` does not name
/// (left by an earlier bake with other settings) and, when the atlases of `atlases.json` were
/// not packed from this index's bake, the atlas index, atlas files and their pictures. Returns
/// how many files were removed. A resumed bake is not affected: this runs only once the index
/// is written, and the files it names are kept.
fn remove_stale_files(dir: &std::path::Path) -> Result<usize> {
    let (index, index_sha256) = ortm::bake_dir::BakeIndex::read_with_sha256(dir)
        .with_context(|| format!("reading the new index of '{}'", dir.display()))?;
    let named: std::collections::HashSet<&str> =
        index.maps.iter().map(|m| m.file.as_str()).collect();
    let atlases_stale = match ortm::atlas::read_atlas_index(dir) {
        Ok(atlases) => {
            atlases.bake_key != index.bake_key
                || atlases
                    .bake_index_sha256
                    .is_some_and(|sha| sha != index_sha256)
        }
        Err(_) => dir.join(ortm::atlas::ATLAS_INDEX_FILE_NAME).exists(),
    };
    let mut removed = 0;
    let listing = std::fs::read_dir(dir).with_context(|| format!("listing '{}'", dir.display()))?;
    for entry in listing {
        let entry = entry.with_context(|| format!("listing '{}'", dir.display()))?;
        let Ok(name) = entry.file_name().into_string() else {
            continue;
        };
        let stale_map =
            name.starts_with("map_") && name.ends_with(".exr") && !named.contains(name.as_str());
        let stale_atlas = atlases_stale
            && (name == ortm::atlas::ATLAS_INDEX_FILE_NAME
                || (name.starts_with("atlas_")
                    && (name.ends_with(".exr") || name.ends_with(".png"))));
        if (stale_map || stale_atlas) && entry.file_type().is_ok_and(|t| t.is_file()) {
            std::fs::remove_file(entry.path())
                .with_context(|| format!("removing the stale file '{}'", entry.path().display()))?;
            removed += 1;
        }
    }
    Ok(removed)
}

/// Runs `ortm bake` (and reports its peak memory for tests: `ORTM_TEST_REPORT_PEAK`).
pub fn run(a: Args) -> Result<()> {
    let result = run_bake(a);
    ortm::io::limits::report_peak_memory_if_asked();
    result
}

/// The shard of `--shard [I/N]`: `value` when given, else the index from the scheduler's
/// environment (`env` looks a variable up) and the count from `shards` (`--shards`), else the
/// plan's count `plan_count`, else (Slurm) the array's size.
pub fn shard_from(
    value: &str,
    shards: Option<u32>,
    env: &dyn Fn(&str) -> Option<String>,
    plan_count: &dyn Fn() -> Option<u32>,
) -> Result<ShardId> {
    if !value.is_empty() {
        return ShardId::parse(value).map_err(anyhow::Error::msg);
    }
    let num = |name: &str| -> Result<Option<u32>> {
        env(name)
            .map(|v| {
                v.trim().parse::<u32>().map_err(|_| {
                    anyhow::anyhow!("{name}='{v}' is not a shard number (an integer ≥ 0)")
                })
            })
            .transpose()
    };
    // The array task id is the shard index (arrays run 0..N−1), so a single index resubmitted
    // alone (`sbatch --array=2`) is still shard 2; the count comes from --shards, else the
    // plan, else the array's size.
    let (index, count, source) = if let Some(index) = num("SLURM_ARRAY_TASK_ID")? {
        let count = match shards.or_else(plan_count) {
            Some(c) => Some(c),
            None => num("SLURM_ARRAY_TASK_COUNT")?,
        };
        (index, count, "SLURM_ARRAY_TASK_ID")
    } else if let Some(index) = num("JOB_COMPLETION_INDEX")? {
        (index, shards, "JOB_COMPLETION_INDEX")
    } else {
        bail!(
            "--shard without I/N: give it (e.g. --shard 0/4), or run it as a Slurm array task \
             (SLURM_ARRAY_TASK_ID) or a Kubernetes Indexed Job pod (JOB_COMPLETION_INDEX)"
        );
    };
    let count = count.or_else(plan_count).ok_or_else(|| {
        anyhow::anyhow!(
            "--shard: {source} gives the index {index} but not the number of shards: add \
             --shards N (or plan first, whose plan.json holds it)"
        )
    })?;
    ShardId::new(index, count).map_err(|e| anyhow::anyhow!("--shard from {source}: {e}"))
}

/// The progress bars and messages of a bake's events.
fn event_printer(bar: &std::sync::Mutex<Progress>) -> impl Fn(BakeEvent) + Sync + '_ {
    move |e: BakeEvent| match e {
        BakeEvent::Phase { name, total } => {
            let mut b = bar.lock().expect("progress lock");
            b.finish();
            *b = Progress::new(total, name);
        }
        BakeEvent::Advance(n) => bar.lock().expect("progress lock").inc(n),
        BakeEvent::Message(m) => bar.lock().expect("progress lock").println(m),
    }
}

/// Ctrl-C: the first lets the current map (or chunk) finish, a second exits at once.
fn cancel_on_ctrl_c() -> Arc<AtomicBool> {
    let cancel = Arc::new(AtomicBool::new(false));
    let c = cancel.clone();
    let _ = ctrlc::set_handler(move || {
        if c.swap(true, Ordering::SeqCst) {
            std::process::exit(130);
        }
        eprintln!("\ninterrupt: finishing the current map, then stopping (Ctrl-C again to abort)");
    });
    cancel
}

/// `ortm bake DIR --merge` (or `-o DIR --merge`): the plan's scene, then [`shard::merge`].
fn run_merge(a: &Args) -> Result<()> {
    let dir = if std::path::Path::new(&a.scene).is_dir() {
        PathBuf::from(&a.scene)
    } else {
        a.output.clone()
    };
    let plan = shard::read_plan(&dir)?;
    let settings = plan.bake_settings()?;
    let name = settings.scene.clone().ok_or_else(|| {
        anyhow::anyhow!(
            "the plan in '{}' does not record its scene: plan again",
            dir.display()
        )
    })?;
    let scene = super::load_scene(&name, Some(settings.size.0))
        .with_context(|| format!("loading the plan's scene '{name}'"))?;
    let cancel = cancel_on_ctrl_c();
    let bar = std::sync::Mutex::new(Progress::hidden());
    let events = event_printer(&bar);
    let summary = shard::merge(&scene, &dir, &events, &cancel)
        .with_context(|| format!("merging the shards in '{}'", dir.display()));
    bar.lock().expect("progress lock").finish();
    let summary = summary?;
    let removed = remove_stale_files(&dir)?;
    if removed > 0 {
        println!(
            "removed {removed} file(s) of an earlier bake in {}",
            dir.display()
        );
    }
    println!(
        "merged {} shards: {} maps ({} reused) for {} texels into {}",
        summary.shards,
        summary.maps,
        summary.reused,
        summary.texels,
        dir.display()
    );
    println!(
        "time: verifying and reading shards {:.2} s, maps and index {:.2} s; stored {} texels; \
         removed the plan, transport and {} shard folder(s)",
        summary.seconds[0],
        summary.seconds[1],
        summary.stored_texels,
        (summary.removed.iter())
            .filter(|p| p
                .file_name()
                .and_then(|n| n.to_str())
                .is_some_and(|n| n.starts_with("shard_")))
            .count()
    );
    Ok(())
}

/// `ortm bake` proper.
fn run_bake(a: Args) -> Result<()> {
    if a.merge {
        return run_merge(&a);
    }
    let scene = super::load_scene(&a.scene, a.size)?;
    let translucent = (0..scene.materials.len() as u32).any(|m| scene.is_translucent(m));
    let s = settings(&a, scene.lightmap_size, translucent)?;
    ortm::io::limits::check_lightmap_memory(s.size.0, s.size.1)?;
    if a.shards.is_some() && !a.plan && a.shard.is_none() {
        bail!("--shards N goes with --plan (or with --shard under a Kubernetes Indexed Job)");
    }
    if a.plan {
        let n = a.shards.expect("clap: --plan requires --shards");
        let cancel = cancel_on_ctrl_c();
        let bar = std::sync::Mutex::new(Progress::hidden());
        let events = event_printer(&bar);
        let p = shard::plan(&scene, &s, &a.output, n, &events, &cancel)
            .with_context(|| format!("planning '{}' into '{}'", a.scene, a.output.display()));
        bar.lock().expect("progress lock").finish();
        let p = p?;
        let spread = p
            .shares
            .iter()
            .fold((f64::MAX, 0.0f64), |(lo, hi), &x| (lo.min(x), hi.max(x)));
        println!(
            "planned {n} shards of {} {} ({} texels) in {}{}: estimated shares {:.1}–{:.1} %; \
             transport {:.1} MB",
            p.units,
            match p.work {
                shard::WorkKind::Cells => "receiving clusters",
                shard::WorkKind::Rows => "receivers",
            },
            p.texels,
            a.output.display(),
            if p.reused {
                " (kept the existing plan)"
            } else {
                ""
            },
            100.0 * spread.0,
            100.0 * spread.1,
            p.transport_bytes as f64 / 1e6
        );
        println!(
            "time: transport {:.2} s, offset selection and work split {:.2} s, writing {:.2} s",
            p.seconds[0], p.seconds[1], p.seconds[2]
        );
        return Ok(());
    }
    if let Some(v) = &a.shard {
        let id = shard_from(v, a.shards, &|name| std::env::var(name).ok(), &|| {
            shard::read_plan(&a.output)
                .ok()
                .map(|p| p.shards.len() as u32)
        })?;
        let cancel = cancel_on_ctrl_c();
        let bar = std::sync::Mutex::new(Progress::hidden());
        let events = event_printer(&bar);
        let r = shard::run_shard(&scene, &s, &a.output, id, &events, &cancel)
            .with_context(|| format!("shard {id} of '{}' in '{}'", a.scene, a.output.display()));
        bar.lock().expect("progress lock").finish();
        let r = r?;
        println!(
            "shard {id}: {} receivers, {} chunks written, {} kept; time: loading {:.2} s, \
             computing and writing {:.2} s",
            r.receivers, r.written, r.reused, r.seconds[0], r.seconds[1]
        );
        return Ok(());
    }
    let cancel = cancel_on_ctrl_c();
    let bar = std::sync::Mutex::new(Progress::hidden());
    let events = event_printer(&bar);
    let summary = bake(&scene, &s, &a.output, &events, &cancel)
        .with_context(|| format!("baking '{}' into '{}'", a.scene, a.output.display()));
    bar.lock().expect("progress lock").finish();
    let summary = summary?;
    let removed = remove_stale_files(&a.output)?;
    if removed > 0 {
        println!(
            "removed {removed} file(s) of an earlier bake in {} (maps not in the new index, \
             atlases of the old maps)",
            a.output.display()
        );
    }
    println!(
        "baked {} maps ({} reused) for {} texels at {}x{} into {}",
        summary.maps,
        summary.reused,
        summary.texels,
        s.size.0,
        s.size.1,
        a.output.display()
    );
    println!(
        "time: transport {:.2} s, {} {:.2} s, maps {:.2} s; stored {} texels ({:.1} per map)",
        summary.seconds[0],
        if s.levels.is_some() {
            "multi-resolution rows"
        } else {
            "offset selection"
        },
        summary.seconds[1],
        summary.seconds[2],
        summary.stored_texels,
        summary.stored_texels as f64 / summary.maps.max(1) as f64
    );
    Ok(())
}

#[cfg(test)]
mod tests {
    /// `--tolerance` alone means the library's default tolerance.
    #[test]
    fn tolerance_alone_is_the_default_tolerance() {
        assert_eq!(
            super::DEFAULT_TOLERANCE_ARG.parse::<f32>().ok(),
            Some(ortm::bake::transport::hier::DEFAULT_TOLERANCE)
        );
    }

    fn parse(args: &[&str]) -> anyhow::Result<ortm::bake::BakeSettings> {
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            bake: super::Args,
        }
        let cli = <Cli as clap::Parser>::try_parse_from(
            ["bake", "head", "-o", "out"].iter().chain(args),
        )?;
        super::settings(&cli.bake, (64, 64), true)
    }

    /// `--levels` without `--tolerance` takes the hierarchical transport at the default
    /// tolerance; `--coarse-block P` keeps the pair evaluator on `P×P` clusters; the offsets'
    /// bake keeps its clusters unless `--tolerance` is given.
    #[test]
    fn levels_take_the_hierarchical_transport_unless_clusters_are_named() {
        use ortm::bake::transport::hier::DEFAULT_TOLERANCE;
        let s = parse(&["--levels", "3e-3"]).unwrap();
        assert_eq!((s.tolerance, s.coarse_block), (Some(DEFAULT_TOLERANCE), 0));
        assert!(s.subsurface_tolerance.is_some());
        let s = parse(&["--levels", "3e-3", "--tolerance", "1e-3"]).unwrap();
        assert_eq!(s.tolerance, Some(1e-3));
        let s = parse(&["--levels", "3e-3", "--coarse-block", "2"]).unwrap();
        assert_eq!((s.tolerance, s.coarse_block), (None, 2));
        let s = parse(&["--levels", "3e-3", "--subsurface-tolerance", "1e-4"]).unwrap();
        assert_eq!(s.subsurface_tolerance, Some(1e-4));
        let s = parse(&[]).unwrap();
        assert_eq!((s.tolerance, s.coarse_block), (None, 8));
    }

    /// Skin's near field: 3 by default for a levels bake on the hierarchical transport of a
    /// scene with skin and the subsurface effect; off (`None`) with `--near-field 1`, with the
    /// clusters' evaluator, without `--levels`, without `sss` and without a translucent
    /// material; as given otherwise.
    #[test]
    fn the_near_field_is_on_by_default_for_skin_levels_bakes() {
        let near = |args: &[&str]| parse(args).unwrap().near_field;
        assert_eq!(near(&["--levels", "3e-3"]), Some(super::DEFAULT_NEAR_FIELD));
        assert_eq!(near(&["--levels", "3e-3", "--tolerance", "1e-3"]), Some(3));
        assert_eq!(near(&["--levels", "3e-3", "--near-field", "5"]), Some(5));
        assert_eq!(near(&["--levels", "3e-3", "--near-field", "1"]), None);
        assert_eq!(near(&["--levels", "3e-3", "--coarse-block", "2"]), None);
        assert_eq!(near(&["--levels", "3e-3", "--effects", "radiosity"]), None);
        assert_eq!(near(&["--tolerance"]), None);
        assert_eq!(near(&[]), None);
        #[derive(clap::Parser)]
        struct Cli {
            #[command(flatten)]
            bake: super::Args,
        }
        let cli =
            <Cli as clap::Parser>::try_parse_from(["bake", "cornell", "--levels", "3e-3"]).unwrap();
        let opaque = super::settings(&cli.bake, (64, 64), false).unwrap();
        assert_eq!(opaque.near_field, None);
    }

    /// The subsurface walk's tolerance: the default with `--tolerance`, as given with
    /// `--subsurface-tolerance`, none without the hierarchical transport, and refused alone
    /// or when not a positive number.
    #[test]
    fn subsurface_tolerance_goes_with_the_hierarchical_transport() {
        use ortm::bake::transport::hier::DEFAULT_SUBSURFACE_TOLERANCE;
        let s = parse(&["--tolerance"]).unwrap();
        assert_eq!(s.subsurface_tolerance, Some(DEFAULT_SUBSURFACE_TOLERANCE));
        let s = parse(&["--tolerance", "1e-3", "--subsurface-tolerance", "3e-4"]).unwrap();
        assert_eq!(s.subsurface_tolerance, Some(3e-4));
        assert_eq!(parse(&[]).unwrap().subsurface_tolerance, None);
        let e = parse(&["--subsurface-tolerance", "1e-3"]).unwrap_err();
        assert!(e.to_string().contains("give --tolerance too"), "{e}");
        let e = parse(&["--tolerance", "--subsurface-tolerance", "0"]).unwrap_err();
        assert!(e.to_string().contains("positive number"), "{e}");
    }
}
