//! `ortm bench render`: per-pass GPU frame times of the head for the configurations of the
//! paper's Table 1 (lightmap size × number of offsets), next to the paper's FPS column.
//!
//! # What is measured
//! For each configuration: the atlases (1024², as in the paper) and pieces, then
//! [`crate::bench::frame::bench_frame`] on the transfer paths `--paths` names (default all three:
//! blend, compute, rows): first order (with shadow maps), transfer, dilation of the final map, display, and
//! the full-screen additive-blend roofline at the lightmap size with as many blends as the
//! transfer needs. Reported: milliseconds per pass (median of `--iterations` runs, GPU
//! timestamps when the adapter has them), texel blends per frame and per second, the blend
//! path's fraction of the roofline, and the frame rate of first order + blend transfer +
//! dilation + display, and the same with the rows path's transfer (`fps rows`). `--pair off|on|both` times the blend path without and/or with
//! paired pieces (`TransferOptions::pair_pieces`); the paired rows print both map-texel
//! contributions and fragments per second against the roofline.
//!
//! # Where the maps come from
//! `--bake DIR` (repeatable) benches real bakes (atlases from `atlases.json`, or packed in
//! memory). Without it the maps are synthetic ([`crate::bench::synthetic::synthetic_transfer_maps`]):
//! jittered-grid offsets within `|dx|, |dy| < size/8` (`--offset-window`; importance-selected
//! offsets crowd near zero) and maps that are non-zero wherever receiver and sender are both
//! covered, cropped like baked maps — the frame cost depends only on the stored texels and
//! pieces, not on the values. The table shows the resulting atlas count beside the paper's
//! "# Bins" as a check that the amount of transfer data is comparable. Real head bakes at
//! these sizes take hours on a small machine.
//!
//! # Limits
//! Timings only compare on one adapter: lavapipe (CPU) is orders of magnitude slower than
//! the paper's GeForce 6800, so the FPS ratio between rows, not the absolute value, is what
//! to compare with the paper.

use std::path::PathBuf;
use std::time::Instant;

use anyhow::{Context, Result};
use ortm::atlas::AtlasSet;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::Effects;
use ortm::render;
use ortm::scene::Scene;
use passes::Gpu;
use passes::display::{DisplayOptions, SplitMode};
use passes::first_order::FirstOrderOptions;
use passes::frame::{FrameParams, Renderer, RendererOptions};
use passes::transfer::{TransferOptions, TransferPath};
use passes::util::TexelReads;

use crate::bench::frame::bench_frame;
use crate::bench::timing::{BenchReport, BenchRow, Statistic};

/// The paper's Table 1: (lightmap side, offsets, bins, FPS on a GeForce 6800).
pub const TABLE_1: [(u32, usize, u32, f64); 8] = [
    (256, 50, 3, 30.08),
    (256, 100, 6, 15.04),
    (256, 200, 10, 8.59),
    (256, 400, 19, 1.96),
    (384, 100, 13, 7.52),
    (384, 200, 24, 1.43),
    (512, 100, 22, 1.72),
    (512, 200, 43, 1.01),
];

/// Which transfer paths to time.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Paths {
    /// Blend path only.
    Blend,
    /// Compute path only.
    Compute,
    /// Rows path only (each texel sums its row of map entries; `ortm render --path rows`).
    Rows,
    /// Blend and compute.
    Both,
    /// Blend, compute and rows.
    All,
}

/// Arguments of `ortm bench render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Lightmap sizes of Table 1 to run with synthetic maps (of 256, 384, 512).
    #[arg(long, value_delimiter = ',', num_args = 1.., default_values_t = [256u32, 384, 512])]
    sizes: Vec<u32>,
    /// Only these offset counts (default: all of Table 1 for each size).
    #[arg(long, value_delimiter = ',', num_args = 1..)]
    offsets: Vec<usize>,
    /// Bench this bake directory instead of synthetic maps (repeatable).
    #[arg(long = "bake")]
    bakes: Vec<PathBuf>,
    /// Scene ([`super::SCENE_HELP`]); for --bake, the scene recorded in the bake's settings
    /// takes precedence.
    #[arg(long, default_value = "head", help = format!("{}; for --bake, the scene recorded in the bake's settings takes precedence", super::SCENE_HELP))]
    scene: String,
    /// Timed runs per measurement (median; one warm-up run first).
    #[arg(long, default_value_t = 3)]
    iterations: u32,
    /// Statistic of the timed runs: `median`, or `min` (the run least disturbed by other
    /// work on a shared machine).
    #[arg(long, value_enum, default_value_t = Stat::Median)]
    statistic: Stat,
    /// Transfer paths to time.
    #[arg(long, value_enum, default_value_t = Paths::All)]
    paths: Paths,
    /// Shadow-map side, texels.
    #[arg(long, default_value_t = 1024)]
    shadow_size: u32,
    /// Sub-texels per texel side of the first-order pass's averaged transfer input (odd, 1–7;
    /// as `ortm render --first-order-samples`).
    #[arg(long, default_value_t = 1, value_name = "N")]
    first_order_samples: u32,
    #[command(flatten)]
    rows: super::render::RowsArgs,
    /// Displayed image size, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720")]
    image: String,
    /// Display: direct light per pixel or from the lightmaps, and the lightmap filter (as
    /// `ortm render`).
    #[command(flatten)]
    display: super::render::DisplayArgs,
    /// Synthetic offsets lie in `|dx|, |dy| < size / N` (a jittered grid there): real
    /// importance-selected offsets crowd near Δt = 0, and with N = 8 the atlas counts come
    /// close to the paper's "# Bins".
    #[arg(long, default_value_t = 8)]
    offset_window: u32,
    /// Seed of the synthetic offsets.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Blend path with paired pieces (two maps drawn per fragment, the renderer's default):
    /// `on` (the default path), `off` (the unpaired blend
    /// path) or `both` (each, same session, for comparison). The main table shows the
    /// unpaired path when it is timed, else the paired one; the paired rows follow it.
    #[arg(long, value_enum, default_value_t = Pair::On)]
    pair: Pair,
    /// How the transfer and first-order shaders read textures: `auto` (the renderer's
    /// default: read-only storage textures where the adapter has them), `sampled` or
    /// `storage`.
    #[arg(long, value_enum, default_value_t = Reads::Auto)]
    texel_reads: Reads,
    /// Per-pixel display: draw the triangles whose pixels all keep the lightmap's diffused
    /// light (subsurface surfaces) or that no light reaches without the light loop (`on`;
    /// the same image), every triangle with the full shader (`off`), or the renderer's
    /// default (`auto`: on for CPU adapters such as lavapipe).
    #[arg(long, value_enum, default_value_t = Split::Auto)]
    split: Split,
}

/// `--split` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Split {
    /// On CPU adapters (lavapipe), off on hardware GPUs (the renderer's default).
    Auto,
    /// Triangles that need no light loop are drawn without it.
    On,
    /// Every triangle with the full per-pixel shader.
    Off,
}

/// `--texel-reads` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Reads {
    /// Storage textures where the adapter has them, else sampled.
    Auto,
    /// Sampled textures (`texture_2d`).
    Sampled,
    /// Read-only storage textures.
    Storage,
}

/// `--pair` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Pair {
    /// Unpaired blend path only.
    Off,
    /// Paired blend path only.
    On,
    /// Both blend paths.
    Both,
}

/// `--statistic` values.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Stat {
    /// Median run.
    Median,
    /// Fastest run.
    Min,
}

/// One line of the output table.
struct Row {
    label: String,
    size: u32,
    maps: usize,
    bins: usize,
    pieces_per_map: f64,
    blend: Option<BenchReport>,
    paired: Option<BenchReport>,
    compute: Option<BenchReport>,
    rows: Option<BenchReport>,
    paper: Option<(u32, f64)>,
}

/// One configuration to bench: its label, the bake directory (`None`: synthetic maps),
/// and for synthetic maps the lightmap side and the number of offsets.
struct Job {
    label: String,
    bake: Option<PathBuf>,
    size: u32,
    offsets: usize,
}

/// Runs `ortm bench render`.
pub fn run(a: Args) -> Result<()> {
    let (img_w, img_h) = render::parse_size(&a.image)?;
    super::solve::check_first_order_samples(a.first_order_samples)?;
    a.rows.check()?;
    let gpu = Gpu::new_headless()?;
    println!(
        "adapter: {} ({:?}); iterations: {} ({:?}, after 1 warm-up); shadow maps {}²; \
         first order {}×{} sub-texels per texel; display {img_w}×{img_h}; rows pruned at τ = {}",
        gpu.adapter_info.name,
        gpu.adapter_info.backend,
        a.iterations,
        a.statistic,
        a.shadow_size,
        a.first_order_samples,
        a.first_order_samples,
        a.rows.rows_prune
    );
    let mut rows = Vec::new();
    for job in jobs(&a) {
        rows.push(bench_job(&a, &gpu, (img_w, img_h), job)?);
    }
    if let Some(r) = rows.iter().find_map(|r| {
        r.blend
            .as_ref()
            .or(r.paired.as_ref())
            .or(r.compute.as_ref())
            .or(r.rows.as_ref())
    }) {
        println!("timing: {}", r.timing);
    }
    print_table(&rows);
    print_cpu_table(&rows);
    print_paired(&rows);
    Ok(())
}

/// The configurations: every `--bake`, else the rows of Table 1 that `--sizes` and
/// `--offsets` select.
fn jobs(a: &Args) -> Vec<Job> {
    if !a.bakes.is_empty() {
        return a
            .bakes
            .iter()
            .map(|d| Job {
                label: d.display().to_string(),
                bake: Some(d.clone()),
                size: 0,
                offsets: 0,
            })
            .collect();
    }
    TABLE_1
        .iter()
        .filter(|&&(size, n, _, _)| {
            a.sizes.contains(&size) && (a.offsets.is_empty() || a.offsets.contains(&n))
        })
        .map(|&(size, n, _, _)| Job {
            label: format!("synthetic {size}²/{n}"),
            bake: None,
            size,
            offsets: n,
        })
        .collect()
}

/// The scene, its texel grid and the atlas set of a job: synthetic maps (jittered-grid
/// offsets, [`crate::bench::synthetic::synthetic_transfer_maps`]) or a bake's atlases.
fn load_job(a: &Args, job: &Job) -> Result<(Scene, TexelGrid, AtlasSet, Effects)> {
    let Some(dir) = &job.bake else {
        let size = job.size;
        let mut scene = super::load_scene(&a.scene, Some(size))?;
        scene.lightmap_size = (size, size);
        let grid = TexelGrid::build_with_size(&scene, size, size)?;
        // Jittered grid over the window |dx|, |dy| < size/window (importance-selected
        // offsets of a real bake crowd near Δt = 0, where the transfer is strong).
        let sub = (size / a.offset_window.max(1)).max(2);
        let offsets = ortm::bake::offsets::select_jittered_grid(sub, sub, job.offsets, a.seed)?;
        let maps = crate::bench::synthetic::synthetic_transfer_maps(&grid, &offsets)?;
        let set = ortm::atlas::build_atlas_set(&maps, 1024, 1024)?;
        return Ok((scene, grid, set, Effects::default()));
    };
    let (index, set, _) = render::load_bake_atlases(dir, render::DEFAULT_ATLAS_SIDE)
        .with_context(|| format!("reading bake directory '{}'", dir.display()))?;
    let arg = index
        .as_ref()
        .and_then(render::scene_arg_from_settings)
        .unwrap_or_else(|| a.scene.clone());
    let (w, h) = set.lightmap_size;
    let mut scene = super::load_scene(&arg, (w == h).then_some(w))?;
    scene.lightmap_size = (w, h);
    if let Some(index) = &index {
        render::check_scene(dir, index, &scene, &arg)?;
    }
    let grid = TexelGrid::build_with_size(&scene, w, h)?;
    Ok((scene, grid, set, render::effects_of(index.as_ref())))
}

/// The renderer of one timed path: `--shadow-size`, `--texel-reads`, the display at
/// `--image` size, the transfer `path` (paired or not), the rest as `ortm render`.
fn renderer_options(
    a: &Args,
    gpu: &Gpu,
    scene: &Scene,
    (img_w, img_h): (u32, u32),
    path: TransferPath,
    pair_pieces: bool,
) -> RendererOptions {
    let texel_reads = match a.texel_reads {
        Reads::Auto => None,
        Reads::Sampled => Some(TexelReads::Sampled),
        Reads::Storage => Some(TexelReads::Storage),
    };
    RendererOptions {
        first_order: FirstOrderOptions {
            shadow_map_size: a.shadow_size,
            max_shadow_layers: render::shadow_layers_for(&scene.lights),
            texel_reads,
            samples: a.first_order_samples,
            ..Default::default()
        },
        transfer: TransferOptions {
            path,
            pair_pieces,
            texel_reads: texel_reads.unwrap_or(gpu.best_texel_reads()),
            rows_prune: a.rows.rows_prune,
            ..TransferOptions::best_for(gpu)
        },
        display: DisplayOptions {
            width: img_w,
            height: img_h,
            side_by_side: false,
            direct: a.display.direct.direct(),
            sampling: a.display.filter.sampling(),
            split: match a.split {
                Split::Auto => SplitMode::Auto,
                Split::On => SplitMode::On,
                Split::Off => SplitMode::Off,
            },
        },
        ..Default::default()
    }
}

/// Loads a job and times the transfer paths `--paths` and `--pair` select.
fn bench_job(a: &Args, gpu: &Gpu, (img_w, img_h): (u32, u32), job: Job) -> Result<Row> {
    let t0 = Instant::now();
    let (scene, grid, set, effects) = load_job(a, &job)?;
    let (w, h) = set.lightmap_size;
    let stats = set.stats();
    eprintln!(
        "{}: {} maps, {} atlases, {} pieces (prepared in {:.1} s)",
        job.label,
        stats.maps,
        stats.atlases,
        stats.pieces,
        t0.elapsed().as_secs_f64()
    );
    let (atlases, pieces) = render::transfer_inputs(&set, (w, h))?;
    let lights: Vec<_> = scene.lights.iter().map(render::light_desc).collect();
    let mesh = render::mesh_data(&scene.mesh);
    let albedo = render::albedo_map(&grid);
    let weights = render::texel_weights(&grid);
    let aspect = img_w as f32 / img_h as f32;
    let params = FrameParams {
        lights: &lights,
        camera: render::default_camera(&scene.mesh, aspect, 40.0),
        exposure: 1.0,
        specular: None,
    };
    let statistic = match a.statistic {
        Stat::Median => Statistic::Median,
        Stat::Min => Statistic::Min,
    };
    let diffusion = render::diffusion_lengths(&scene, &grid, effects);
    let time_path = |path: TransferPath, pair_pieces: bool| -> Result<BenchReport> {
        let options = renderer_options(a, gpu, &scene, (img_w, img_h), path, pair_pieces);
        let renderer = Renderer::new(gpu, &options)?;
        let mut rs = renderer.prepare_with_weights(
            gpu,
            &mesh,
            &albedo,
            &atlases,
            &pieces,
            Some(&weights),
        )?;
        // The display `ortm render` shows: subsurface texels keep their diffused light where
        // it spreads over more than a pixel.
        if let Some(lengths) = &diffusion {
            renderer.set_diffusion_lengths(gpu, &mut rs, lengths)?;
        }
        Ok(bench_frame(
            gpu,
            &renderer,
            &rs,
            &params,
            a.iterations,
            statistic,
        )?)
    };
    let blend_timed = matches!(a.paths, Paths::Blend | Paths::Both | Paths::All);
    let blend = if blend_timed && a.pair != Pair::On {
        Some(time_path(TransferPath::Blend, false)?)
    } else {
        None
    };
    let paired = if blend_timed && a.pair != Pair::Off {
        Some(time_path(TransferPath::Blend, true)?)
    } else {
        None
    };
    let compute = match a.paths {
        Paths::Compute | Paths::Both | Paths::All => Some(time_path(TransferPath::Compute, false)?),
        Paths::Blend | Paths::Rows => None,
    };
    let rows = match a.paths {
        Paths::Rows | Paths::All => Some(time_path(TransferPath::Rows, false)?),
        _ => None,
    };
    let paper = TABLE_1
        .iter()
        .find(|r| w == h && r.0 == w && r.1 == stats.maps)
        .map(|r| (r.2, r.3));
    Ok(Row {
        label: job.label,
        size: w,
        maps: stats.maps,
        bins: stats.atlases,
        pieces_per_map: stats.mean_pieces_per_map,
        blend,
        paired,
        compute,
        rows,
        paper,
    })
}

/// The paired blend path's rows (`--pair on|both`): its transfer time, CPU time, both
/// counts of work and both roofline ratios, and the frame rate with it as the transfer.
fn print_paired(rows: &[Row]) {
    if rows.iter().all(|r| r.paired.is_none()) {
        return;
    }
    println!();
    println!(
        "paired blend path (two maps per fragment): contributions = map texels added (+ the \
         copy), the same count as the unpaired path's blends; fragments = quads' texels \
         actually blended (pair bounding boxes + unpaired pieces + the copy)"
    );
    println!(
        "{:<24} {:>9} {:>9} {:>12} {:>12} {:>10} {:>10} {:>10} {:>9} {:>9} {:>8} {:>8}",
        "configuration",
        "pair ms",
        "pair cpu",
        "contrib.",
        "fragments",
        "contrib/s",
        "frag/s",
        "roofline/s",
        "roof.%c",
        "roof.%f",
        "fps",
        "fps st."
    );
    for r in rows {
        let Some(p) = &r.paired else { continue };
        let Some(t) = p.rows.get(1) else { continue };
        let ms = |i: usize| p.rows.get(i).map(|x| x.ms);
        let roof = p.rows.get(4).map(|x| x.blends_per_s);
        let fps = |first: Option<f64>| {
            [first, Some(t.ms), ms(2), ms(3)]
                .iter()
                .try_fold(0.0, |acc, v| v.map(|v| acc + v))
                .map_or("—".to_string(), |m| format!("{:.2}", 1000.0 / m))
        };
        let pct = |v: f64| roof.map_or("—".to_string(), |r| format!("{:.1}", 100.0 * v / r));
        println!(
            "{:<24} {:>9.2} {:>9} {:>12} {:>12} {:>10.3e} {:>10.3e} {:>10} {:>9} {:>9} {:>8} {:>8}",
            r.label,
            t.ms,
            t.cpu_ms.map_or("—".to_string(), |c| format!("{c:.2}")),
            t.texel_blends,
            t.fragments,
            t.blends_per_s,
            t.fragments_per_s(),
            roof.map_or("—".to_string(), |v| format!("{v:.3e}")),
            pct(t.blends_per_s),
            pct(t.fragments_per_s()),
            fps(ms(0)),
            fps(ms(5)),
        );
        println!("{:<24} {}", "", t.name);
    }
}

impl Row {
    /// The blend report the main tables show: the unpaired blend path when timed, else the
    /// paired one (`--pair on`).
    fn blend_report(&self) -> &Option<BenchReport> {
        if self.blend.is_some() {
            &self.blend
        } else {
            &self.paired
        }
    }
}

/// Row `i` of a report ([`bench_frame`]'s rows: first order (moving lights), transfer,
/// dilate, display, roofline, first order (static lights)).
fn get(rep: &Option<BenchReport>, i: usize) -> Option<&BenchRow> {
    rep.as_ref().and_then(|x| x.rows.get(i))
}

/// The main table: per configuration the pass times, blend rates against the roofline and
/// the frame rates, beside the paper's.
fn print_table(rows: &[Row]) {
    println!(
        "{:<24} {:>5} {:>5} {:>5} {:>6} {:>12} {:>9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>8} {:>10} {:>10} {:>9} {:>8} {:>8} {:>8} {:>9} {:>10}",
        "configuration",
        "size",
        "maps",
        "bins",
        "pc/map",
        "blends",
        "1st ms",
        "1st st.ms",
        "blend ms",
        "compute ms",
        "rows ms",
        "dil ms",
        "disp ms",
        "blends/s",
        "roofline/s",
        "roof.%",
        "fps",
        "fps st.",
        "fps rows",
        "fps r.st.",
        "paper fps"
    );
    for r in rows {
        print_row(r);
    }
    println!(
        "fps = 1000 / (first order + transfer (blend if timed) + dilation + display) with moving \
         lights (1st ms: shadow maps re-rendered every frame); fps st. = the same with static \
         lights (1st st.ms: shadow maps reused); fps rows, fps r.st. = the same two with the \
         rows path's transfer (--paths rows|all); roof.% = blend-path texel blends/s ÷ \
         full-screen additive-blend roofline at the lightmap size; blend = the unpaired blend \
         path with --pair off|both, the paired one with --pair on (texel blends = map-texel \
         contributions; fragments in the paired table below)"
    );
    println!();
}

/// One line of the main table.
fn print_row(r: &Row) {
    let blend_rep = r.blend_report();
    let any = blend_rep
        .as_ref()
        .or(r.compute.as_ref())
        .or(r.rows.as_ref());
    let ms = |i: usize| any.and_then(|x| x.rows.get(i)).map(|x| x.ms);
    let blend = get(blend_rep, 1);
    let compute = get(&r.compute, 1);
    let rows_ms = get(&r.rows, 1).map(|x| x.ms);
    let roof = get(blend_rep, 4).or(get(&r.compute, 4));
    let transfer_ms = blend.or(compute).map(|x| x.ms).or(rows_ms);
    // Frames per second of first order (`ms(0)` moving lights, `ms(5)` static) + `transfer`
    // + dilation + display; `None` when a pass was not timed.
    let fps = |first: Option<f64>, transfer: Option<f64>| {
        [first, transfer, ms(2), ms(3)]
            .iter()
            .try_fold(0.0, |acc, v| v.map(|v| acc + v))
            .map(|m| 1000.0 / m)
    };
    let f = |v: Option<f64>, p: usize| v.map_or("—".to_string(), |v| format!("{v:.p$}"));
    let e = |v: Option<f64>| v.map_or("—".to_string(), |v| format!("{v:.3e}"));
    let blends = blend
        .or(compute)
        .or(get(&r.rows, 1))
        .map_or(0, |x| x.texel_blends);
    let rate = blend.or(compute).map(|x| x.blends_per_s);
    println!(
        "{:<24} {:>5} {:>5} {:>5} {:>6.2} {:>12} {:>9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>8} {:>10} {:>10} {:>9} {:>8} {:>8} {:>8} {:>9} {:>10}",
        r.label,
        r.size,
        r.maps,
        r.bins,
        r.pieces_per_map,
        blends,
        f(ms(0), 2),
        f(ms(5), 2),
        f(blend.map(|x| x.ms), 2),
        f(compute.map(|x| x.ms), 2),
        f(rows_ms, 2),
        f(ms(2), 2),
        f(ms(3), 2),
        e(rate),
        e(roof.map(|x| x.blends_per_s)),
        f(
            rate.zip(roof.map(|x| x.blends_per_s))
                .map(|(a, b)| 100.0 * a / b),
            1
        ),
        f(fps(ms(0), transfer_ms), 2),
        f(fps(ms(5), transfer_ms), 2),
        f(fps(ms(0), rows_ms), 2),
        f(fps(ms(5), rows_ms), 2),
        r.paper.map_or("—".to_string(), |(bins, fps)| format!(
            "{fps:.2} ({bins} bins)"
        )),
    );
}

/// The CPU time per run of every pass (the process's threads: lavapipe's work).
fn print_cpu_table(rows: &[Row]) {
    println!(
        "CPU time per run, all threads of this process (lavapipe's work; independent of waiting \
         for cores other processes hold), ms:"
    );
    println!(
        "{:<24} {:>9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>8} {:>10}",
        "configuration", "1st", "1st st.", "blend", "compute", "rows", "dil", "disp", "roofline"
    );
    for r in rows {
        let cpu = |rep: &Option<BenchReport>, i: usize| {
            get(rep, i)
                .and_then(|x| x.cpu_ms)
                .map_or("—".to_string(), |v| format!("{v:.2}"))
        };
        let blend_rep = r.blend_report();
        let any = if blend_rep.is_some() {
            blend_rep
        } else if r.compute.is_some() {
            &r.compute
        } else {
            &r.rows
        };
        println!(
            "{:<24} {:>9} {:>9} {:>9} {:>10} {:>8} {:>8} {:>8} {:>10}",
            r.label,
            cpu(any, 0),
            cpu(any, 5),
            cpu(blend_rep, 1),
            cpu(&r.compute, 1),
            cpu(&r.rows, 1),
            cpu(any, 2),
            cpu(any, 3),
            cpu(any, 4),
        );
    }
}
