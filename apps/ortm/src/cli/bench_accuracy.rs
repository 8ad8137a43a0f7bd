//! `ortm bench accuracy`: how far each bake is from the truth, as one table.
//!
//! # What is measured
//! For each case (scene × lightmap size; default Cornell 64² and 128², maze 128², head 64² and
//! 256², radiosity + subsurface) under the scene's own lights:
//! - **the reference**: the exact dense solve ([`DenseTransport`]) where the covered texels fit
//!   ([`dense::MAX_TEXELS`]), else the path-traced reference
//!   ([`ortm::accuracy::reference::trace`]) with paths per texel raised (×4 per step, from
//!   `--spp` up to `--max-spp`) until its standard error is under a quarter of the smallest
//!   error it measures (the line above each case's rows says which reference, how many paths and
//!   whether that held);
//! - **the rows**: the bake's pair evaluator summed over every pair (`evaluator, every pair`:
//!   the limit today's maps converge to, no offsets), then for each offset budget a bake with
//!   importance-sampled offsets and each cell rule — today's integrated cells and the paper's
//!   Eq. 10 (`sampled`) — applied on the CPU (Eq. 9, [`ortm::maps::apply`], the mirror of the
//!   GPU's transfer pass);
//! - with `--tolerances`, the same rows on the hierarchical transport at each tolerance `ε`
//!   ([`Transport::build_hierarchical`], `ortm bake --tolerance ε`): its evaluator (every pair,
//!   [`ortm::bake::multires::hierarchical_row`]), its multi-resolution maps and its bakes.
//!
//! Columns: relative RMSE of the total `B` and of the indirect term `B − B_o` over interior
//! covered texels ([`ortm::accuracy::compare`]), energy ratio (power of the row over the
//! reference's, mean of R, G, B), bake time (wall clock, this machine) and frame cost in
//! map-texel contributions (stored texels of all maps: what the GPU's transfer pass reads per
//! frame; for the evaluator row, receivers × senders).

use std::path::PathBuf;
use std::sync::atomic::AtomicBool;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use glam::Vec3;
use ortm::accuracy::compare::{self, Comparison};
use ortm::accuracy::reference::{self, ReferenceMaps};
use ortm::bake::pipeline::CellRule;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::{self, DenseTransport};
use ortm::bake::transport::hier::DEFAULT_SUBSURFACE_TOLERANCE;
use ortm::bake::transport::{Effects, Kernels, Transport, texel_patches};
use ortm::bake::{self, BakeSettings, lighting};
use ortm::io::limits::MAX_SAMPLES_PER_TEXEL;
use ortm::scene::Scene;

/// The cases of the table when `--cases` is not given.
pub const DEFAULT_CASES: [&str; 5] = [
    "cornell-64",
    "cornell-128",
    "maze-128",
    "head-64",
    "head-256",
];

/// Arguments of `ortm bench accuracy`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Cases as SCENE-SIZE (a built-in scene or a scene file, then the square lightmap size).
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = DEFAULT_CASES.map(String::from))]
    cases: Vec<String>,
    /// Offset budgets: one bake per budget and cell rule.
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = [100usize, 400])]
    offsets: Vec<usize>,
    /// Tolerances `ε` of the multi-resolution maps (rows where the evaluator row fits): one set
    /// of maps per tolerance, from the evaluator's rows.
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = [1e-2, 3e-3, 1e-3])]
    levels: Vec<f64>,
    /// Paths per texel the path-traced reference starts with.
    #[arg(
        long,
        default_value_t = 64,
        value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SAMPLES_PER_TEXEL)),
        help = format!("Paths per texel the path-traced reference starts with, 1..={MAX_SAMPLES_PER_TEXEL}")
    )]
    spp: u32,
    /// Most paths per texel of the path-traced reference.
    #[arg(
        long,
        default_value_t = 4096,
        value_parser = clap::value_parser!(u32).range(1..=i64::from(MAX_SAMPLES_PER_TEXEL)),
        help = format!("Most paths per texel of the path-traced reference, 1..={MAX_SAMPLES_PER_TEXEL}")
    )]
    max_spp: u32,
    /// Largest covered-texel count for the `evaluator, every pair` row (its cost is n²).
    #[arg(long, default_value_t = 12_000)]
    max_evaluator_texels: usize,
    /// Seed of the bakes' offset selection and of the reference's paths.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Cluster size of the evaluator and the bakes, as `ortm bake --coarse-block` (0 =
    /// automatic).
    #[arg(
        long,
        default_value_t = BakeSettings::default().coarse_block,
        value_parser = clap::value_parser!(u32).range(0..=i64::from(ortm::io::limits::MAX_COARSE_BLOCK))
    )]
    coarse_block: u32,
    /// Tolerances `ε` of the hierarchical transport (`ortm bake --tolerance`): per tolerance, the
    /// evaluator on its operator (where the evaluator row fits), the multi-resolution maps of
    /// `--levels` painted from it and one bake per offset budget and cell rule on it.
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    tolerances: Vec<f32>,
    /// With `--tolerances`: the subsurface walk's own tolerance in every hierarchical row, as
    /// `ortm bake --subsurface-tolerance`.
    #[arg(long, value_name = "ε_S", default_value_t = DEFAULT_SUBSURFACE_TOLERANCE)]
    subsurface_tolerance: f32,
    /// Sub-texels per texel side (odd, 1–7) over which the transfer's input is averaged, as
    /// `ortm render --first-order-samples`: every row (and the exact solve) multiplies the
    /// averaged first order; 1 takes the centres.
    #[arg(long, default_value_t = 1, value_name = "N")]
    first_order_samples: u32,
}

/// One way of producing the final lightmap, measured against the reference.
struct Row {
    method: String,
    offsets: Option<usize>,
    final_b: Vec<Vec3>,
    bake_s: f64,
    frame_cost: u64,
}

/// A case's scene, texels and first order.
struct Case {
    label: String,
    scene: Scene,
    grid: TexelGrid,
    /// The centres' first order (what the reference's indirect term is measured from).
    b_o: Vec<Vec3>,
    /// The first order a lightmap holds and the transfer's input
    /// ([`lighting::first_order_and_input`]; both `b_o` with `--first-order-samples 1`).
    first: Vec<Vec3>,
    input: Vec<Vec3>,
}

impl Case {
    /// A final computed from the transfer's input (`input + Σ R·input`) made to start from
    /// the lightmap's first order ([`lighting::with_first_order`]).
    fn finish(&self, mut final_b: Vec<Vec3>) -> Vec<Vec3> {
        lighting::with_first_order(&mut final_b, &self.first, &self.input);
        final_b
    }
}

/// Runs `ortm bench accuracy`.
pub fn run(a: Args) -> Result<()> {
    if a.offsets.contains(&0) {
        bail!("--offsets: every budget must be at least 1 map");
    }
    if !(a.subsurface_tolerance.is_finite() && a.subsurface_tolerance > 0.0) {
        bail!(
            "--subsurface-tolerance {}: give a number > 0, e.g. 1e-3",
            a.subsurface_tolerance
        );
    }
    if let Some(t) = a.tolerances.iter().find(|t| !(t.is_finite() && **t > 0.0)) {
        bail!("--tolerances: {t} is not a tolerance; give numbers > 0, e.g. 1e-3,1e-4");
    }
    if a.spp == 0 || a.max_spp < a.spp {
        bail!("--spp must be at least 1 and --max-spp at least --spp");
    }
    super::solve::check_first_order_samples(a.first_order_samples)?;
    println!("threads: {}", rayon::current_num_threads());
    if a.first_order_samples > 1 {
        let n = a.first_order_samples;
        println!("transfer input: the first order averaged over {n}×{n} sub-texels per texel");
    }
    println!(
        "| case | texels (interior) | method | offsets | total RMSE | indirect RMSE | energy | bake (s) | frame cost (map texels) |"
    );
    println!("|---|---|---|---|---|---|---|---|---|");
    for spec in &a.cases {
        let case = load_case(spec, a.first_order_samples)?;
        let rows = measure_rows(&case, &a)?;
        let (reference, label) = reference_for(&case, &rows, &a)?;
        println!("| {} | | reference: {label} | | | | | | |", case.label);
        for row in &rows {
            let c = compare::compare(
                &case.grid,
                &reference,
                &row.final_b,
                Some((&case.b_o, &case.b_o)),
                0,
            );
            print_row(&case, row, &c);
        }
    }
    Ok(())
}

/// Parses `SCENE-SIZE` and loads the scene, its texels and its first order.
fn load_case(spec: &str, samples: u32) -> Result<Case> {
    let (name, size) = spec
        .rsplit_once('-')
        .and_then(|(n, s)| s.parse::<u32>().ok().map(|s| (n, s)))
        .with_context(|| {
            format!("--cases: '{spec}' is not SCENE-SIZE (e.g. cornell-64, maze-128, head-256)")
        })?;
    let scene = super::load_scene(name, Some(size))?;
    let grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{name}' at {size}²"))?;
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    let (first, input) =
        lighting::first_order_and_input(&scene, &grid, &scene.lights, &vis, samples, |m| {
            scene.is_translucent(m)
        })?;
    Ok(Case {
        label: format!("{name} {size}²"),
        scene,
        grid,
        b_o,
        first,
        input,
    })
}

/// The evaluator row (where it fits) and one bake per budget and cell rule.
fn measure_rows(case: &Case, a: &Args) -> Result<Vec<Row>> {
    let n = case.grid.texels.len();
    let mut rows = Vec::new();
    if n <= a.max_evaluator_texels {
        eprintln!("{}: evaluator over {n}² pairs", case.label);
        let t = Instant::now();
        let tr = Transport::new(&case.scene, &case.grid, Effects::default(), a.coarse_block);
        let block = tr.remainder.block;
        let final_b = case.finish(ortm::bake::eval::evaluator_final(&tr, &case.input));
        let senders = ortm::bake::eval::senders(&case.input).len() as u64;
        let build_s = t.elapsed().as_secs_f64();
        rows.push(Row {
            method: format!("evaluator, every pair ({block}×{block} clusters)"),
            offsets: None,
            final_b,
            bake_s: build_s,
            frame_cost: n as u64 * senders,
        });
        rows.extend(level_rows(
            case,
            &ortm::bake::multires::transport_row(&tr),
            build_s,
            a,
        )?);
    }
    offset_rows(case, None, a, &mut rows)?;
    for &tolerance in &a.tolerances {
        rows.extend(hierarchical_rows(case, tolerance, a)?);
        offset_rows(case, Some(tolerance), a, &mut rows)?;
    }
    Ok(rows)
}

/// One bake per offset budget and cell rule, on the coarse clusters (`tolerance` `None`) or on
/// the hierarchical transport at `tolerance`.
fn offset_rows(case: &Case, tolerance: Option<f32>, a: &Args, rows: &mut Vec<Row>) -> Result<()> {
    for &k in &a.offsets {
        for (rule, name) in [
            (CellRule::Integrated, "integrated cells"),
            (CellRule::Sampled, "Eq. 10 (sampled)"),
        ] {
            let name = match tolerance {
                Some(t) => format!("{name}, hierarchical ε = {t:.0e}"),
                None => name.to_string(),
            };
            eprintln!("{}: bake, {k} offsets, {name}", case.label);
            rows.push(bake_row(case, k, rule, tolerance, &name, a)?);
        }
    }
    Ok(())
}

/// The evaluator on the hierarchical transport at `tolerance` (every pair, where it fits) and
/// the multi-resolution maps of `--levels` painted from its rows.
fn hierarchical_rows(case: &Case, tolerance: f32, a: &Args) -> Result<Vec<Row>> {
    use ortm::bake::multires;
    use ortm::bake::transport::hier;
    let n = case.grid.texels.len();
    if n > a.max_evaluator_texels {
        return Ok(Vec::new());
    }
    eprintln!(
        "{}: hierarchical transport at ε = {tolerance:e}, evaluator over {n}² pairs",
        case.label
    );
    let t = Instant::now();
    let settings = hier::Settings {
        tolerance,
        subsurface_tolerance: Some(a.subsurface_tolerance),
        ..hier::Settings::default()
    };
    let tr = Transport::build_hierarchical(
        &case.scene,
        &case.grid,
        Effects::default(),
        0,
        &settings,
        &ortm::bake::transport::SetupProgress::none(),
    )
    .map_err(|e| anyhow::anyhow!("hierarchical transport at ε = {tolerance:e}: {e}"))?;
    let row_of = multires::hierarchical_row(&tr).expect("built with the hierarchical operator");
    let build_s = t.elapsed().as_secs_f64();
    let t = Instant::now();
    let final_b = case.finish(evaluator_from_rows(&row_of, &case.input));
    let mut rows = vec![Row {
        method: format!("evaluator, every pair, hierarchical ε = {tolerance:.0e}"),
        offsets: None,
        final_b,
        bake_s: build_s + t.elapsed().as_secs_f64(),
        frame_cost: n as u64 * ortm::bake::eval::senders(&case.input).len() as u64,
    }];
    for mut row in level_rows(case, &row_of, build_s, a)? {
        row.method = format!("{}, hierarchical ε = {tolerance:.0e}", row.method);
        rows.push(row);
    }
    Ok(rows)
}

/// `B = B_o + Σ_j R(i, j) B_o(j)` for every receiver `i` from its transfer row.
fn evaluator_from_rows(row_of: &(impl Fn(u32, &mut [[f32; 3]]) + Sync), b_o: &[Vec3]) -> Vec<Vec3> {
    use rayon::prelude::*;
    (0..b_o.len() as u32)
        .into_par_iter()
        .map_init(
            || vec![[0.0f32; 3]; b_o.len()],
            |row, i| {
                row_of(i, row);
                let mut b = b_o[i as usize];
                for (r, o) in row.iter().zip(b_o) {
                    b += Vec3::from_array(*r) * *o;
                }
                b
            },
        )
        .collect()
}

/// Multi-resolution maps from the transfer rows `row_of` (the pair evaluator's or the
/// hierarchical transport's), one set per tolerance of `--levels`, applied on the CPU
/// ([`ortm::maps::levels::apply_levels`]). Bake time: the transport's set-up (`build_s`) plus
/// the rows and their partition, shared by the tolerances.
fn level_rows(
    case: &Case,
    row_of: &(impl Fn(u32, &mut [[f32; 3]]) + Sync),
    build_s: f64,
    a: &Args,
) -> Result<Vec<Row>> {
    use ortm::bake::multires::{self, MultiresSettings};
    if a.levels.is_empty() {
        return Ok(Vec::new());
    }
    if let Some(e) = a.levels.iter().find(|e| !(e.is_finite() && **e >= 0.0)) {
        bail!("--levels: tolerance {e} must be a finite number ≥ 0");
    }
    eprintln!(
        "{}: multi-resolution maps at ε = {:?}",
        case.label, a.levels
    );
    let t = Instant::now();
    let settings: Vec<MultiresSettings> = a
        .levels
        .iter()
        .map(|&tolerance| MultiresSettings {
            tolerance,
            ..MultiresSettings::default()
        })
        .collect();
    let entries = multires::partition_rows(
        &case.grid,
        row_of,
        &settings,
        &ortm::bake::transport::SetupProgress::none(),
    )
    .expect("never cancelled");
    let shared_s = build_s + t.elapsed().as_secs_f64();
    let first = lighting::to_lightmap(&case.grid, &case.input);
    let area = case.grid.area_map();
    let mut rows = Vec::new();
    for (eps, e) in a.levels.iter().zip(&entries) {
        let t = Instant::now();
        let maps = multires::to_maps(&case.grid, e)?;
        let bake_s = shared_s + t.elapsed().as_secs_f64();
        let final_map = ortm::maps::levels::apply_levels(&maps, &first, &area)?;
        rows.push(Row {
            method: format!("multi-resolution maps, ε = {eps:.0e}"),
            offsets: Some(maps.len()),
            final_b: case.finish(lighting::from_lightmap(&case.grid, &final_map)),
            bake_s,
            frame_cost: ortm::maps::levels::stored_texels(&maps),
        });
        let t = Instant::now();
        let blocks = multires::coarsen_receivers(&case.grid, e, *eps);
        let block_maps = multires::to_block_maps(&case.grid, &blocks)?;
        let final_map = multires::apply_blocks(&case.grid, &blocks, &first, &area)?;
        let shared = blocks.iter().filter(|b| b.receiver_level > 0).count();
        rows.push(Row {
            method: format!(
                "multi-resolution maps, ε = {eps:.0e}, receiver blocks ({:.0} % shared, {} \
                 non-zero)",
                100.0 * shared as f64 / blocks.len().max(1) as f64,
                thousands(blocks.len() as u64)
            ),
            offsets: Some(block_maps.len()),
            final_b: case.finish(lighting::from_lightmap(&case.grid, &final_map)),
            bake_s: shared_s + t.elapsed().as_secs_f64(),
            // What the GPU draws: the maps' cropped rectangles, zeros between blocks included.
            frame_cost: ortm::maps::levels::stored_texels(&block_maps),
        });
    }
    Ok(rows)
}

/// Bakes `case` with `k` offsets and `rule` into a temporary folder and applies the maps to the
/// first order on the CPU.
fn bake_row(
    case: &Case,
    k: usize,
    rule: CellRule,
    tolerance: Option<f32>,
    name: &str,
    a: &Args,
) -> Result<Row> {
    let dir = scratch_dir(&case.label, k)?;
    let settings = BakeSettings {
        size: case.scene.lightmap_size,
        offsets: k,
        cell_rule: rule,
        seed: a.seed,
        // As `ortm bake --tolerance`: the coarse clusters of the remainder sized automatically.
        coarse_block: if tolerance.is_some() {
            0
        } else {
            a.coarse_block
        },
        tolerance,
        subsurface_tolerance: tolerance.map(|_| a.subsurface_tolerance),
        ..BakeSettings::default()
    };
    let cancel = AtomicBool::new(false);
    let t = Instant::now();
    let result = bake::bake(&case.scene, &settings, &dir, &|_| {}, &cancel)
        .with_context(|| format!("baking {} with {k} offsets", case.label))
        .and_then(|summary| {
            let maps = ortm::bake_dir::BakeIndex::read(&dir)?.load_maps(&dir)?;
            Ok((summary, maps))
        });
    let bake_s = t.elapsed().as_secs_f64();
    let _ = std::fs::remove_dir_all(&dir);
    let (summary, maps) = result?;
    let first = lighting::to_lightmap(&case.grid, &case.input);
    let final_map = ortm::maps::apply(&maps, &first)?;
    Ok(Row {
        method: format!("importance offsets, {name}"),
        offsets: Some(k),
        final_b: case.finish(lighting::from_lightmap(&case.grid, &final_map)),
        bake_s,
        frame_cost: summary.stored_texels,
    })
}

/// The exact solve where it fits, else the path-traced reference with enough paths; returns
/// the final radiosity and a label saying which.
fn reference_for(case: &Case, rows: &[Row], a: &Args) -> Result<(Vec<Vec3>, String)> {
    let n = case.grid.texels.len();
    if n <= dense::MAX_TEXELS {
        eprintln!("{}: exact dense solve of {n} texels", case.label);
        let vis = std::sync::Arc::new(Visibility::new(&case.scene.mesh));
        let kernels = Kernels::new(&case.scene, Effects::default(), vis);
        let dense = DenseTransport::new(&texel_patches(&case.grid), &kernels);
        return Ok((
            case.finish(dense.solve(&case.input)),
            "exact dense solve".into(),
        ));
    }
    let mask = compare::interior_mask(&case.grid);
    let mut spp = a.spp;
    loop {
        let r = traced_reference(case, spp, a.seed)?;
        // The reference's own noise against the smallest error it has to resolve: both are
        // absolute (the rows share the reference's first order), so compare RMS over interior
        // texels.
        let noise = rms(&r.std_error, &mask);
        let smallest = rows
            .iter()
            .map(|row| {
                let d: Vec<Vec3> = row
                    .final_b
                    .iter()
                    .zip(&r.final_b)
                    .map(|(x, y)| *x - *y)
                    .collect();
                rms(&d, &mask)
            })
            .fold(f64::INFINITY, f64::min);
        let resolved = noise < 0.25 * smallest;
        if resolved || spp.saturating_mul(4) > a.max_spp {
            let label = format!(
                "path traced, {spp} paths/texel, standard error {:.2}% of the reference's RMS ({} a quarter of the smallest error)",
                100.0 * noise / rms(&r.final_b, &mask).max(1e-300),
                if resolved { "under" } else { "NOT under" }
            );
            return Ok((r.final_b, label));
        }
        spp *= 4;
    }
}

/// Runs the path tracer with a progress bar.
fn traced_reference(case: &Case, spp: u32, seed: u64) -> Result<ReferenceMaps> {
    let n = case.grid.texels.len() as u64;
    let bar = super::progress::Progress::new(n, format!("reference {spp} paths/texel"));
    let progress = |done: usize, _total: usize| bar.set_position(done as u64);
    let settings = reference::Settings {
        samples_per_texel: spp,
        replicates: reference::DEFAULT_REPLICATES,
        seed,
        effects: Effects::default(),
    };
    let cancel = AtomicBool::new(false);
    let r = reference::trace(
        &case.scene,
        &case.grid,
        &case.scene.lights,
        &settings,
        &progress,
        &cancel,
    );
    bar.finish_and_clear();
    Ok(r?)
}

/// Root mean square of `|v|` over the texels where `mask` is true.
fn rms(v: &[Vec3], mask: &[bool]) -> f64 {
    let (mut s, mut n) = (0.0f64, 0usize);
    for (x, m) in v.iter().zip(mask) {
        if *m {
            s += x.as_dvec3().length_squared();
            n += 1;
        }
    }
    (s / n.max(1) as f64).sqrt()
}

fn print_row(case: &Case, row: &Row, c: &Comparison) {
    let pct = |x: f64| format!("{:.1}%", 100.0 * x);
    println!(
        "| {} | {} ({}) | {} | {} | {} | {} | {:.3} | {:.1} | {} |",
        case.label,
        c.covered,
        c.interior,
        row.method,
        row.offsets.map_or("all pairs".into(), |k| k.to_string()),
        pct(c.total),
        c.indirect.map_or("—".into(), pct),
        c.energy_ratio.element_sum() / 3.0,
        row.bake_s,
        thousands(row.frame_cost)
    );
}

/// `1234567` → `1.23 M`, `12345` → `12.3 k`.
fn thousands(x: u64) -> String {
    match x {
        0..1_000 => x.to_string(),
        1_000..1_000_000 => format!("{:.1} k", x as f64 / 1e3),
        _ => format!("{:.2} M", x as f64 / 1e6),
    }
}

/// A fresh scratch folder for one bake of the table.
fn scratch_dir(label: &str, k: usize) -> Result<PathBuf> {
    let tag: String = label
        .chars()
        .map(|c| if c.is_ascii_alphanumeric() { c } else { '_' })
        .collect();
    let d = std::env::temp_dir().join(format!(
        "ortm-bench-accuracy-{}-{tag}-{k}",
        std::process::id()
    ));
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d)
        .with_context(|| format!("cannot create scratch folder '{}'", d.display()))?;
    Ok(d)
}
