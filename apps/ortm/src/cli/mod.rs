//! Subcommands of the `ortm` tool: each file parses one subcommand's arguments, calls the
//! `ortm` library (bake, bin, render, …) and prints the results, progress and errors. The
//! work itself — file formats, checks, conversions — is the library's; what lives here is
//! arguments and printing (and `load_scene`, which maps a scene argument to a built-in
//! scene or a scene file).

mod bake;
mod bench;
mod bench_accuracy;
mod bench_render;
mod bin;
mod compare;
mod demo;
mod inspect;
mod progress;
mod reference;
pub(crate) mod render;
mod render_cpu;
mod solve;
mod unwrap;
mod view;

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use ortm::scene::Scene;

/// Offset Radiance Transfer Mapping: bake, bin and render multi-bounce and subsurface transfer.
#[derive(Parser, Debug)]
#[command(version, about, long_about = None)]
pub struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand, Debug)]
enum Command {
    /// Demos: `cornell` (default; inspect, exact solve, bake, bin, render) or `face` (the
    /// paper's face figures on the scanned head).
    Demo(demo::Args),
    /// Mesh and chart statistics, coverage, overlaps, and a PNG of the texel charts.
    Inspect(inspect::Args),
    /// Bake offset transfer maps (OpenEXR + index.json) for a scene; resumable.
    Bake(bake::Args),
    /// Pack a bake's transfer maps into texture atlases (OpenEXR + atlases.json + PNGs).
    Bin(bin::Args),
    /// Benchmarks printed as tables: `transport`, `bake`, `render`, `accuracy`.
    Bench(BenchArgs),
    /// Exact dense solve (small lightmaps): first-order, final and indirect lightmaps as
    /// OpenEXR and PNG.
    Solve(solve::Args),
    /// Path-traced texture-space reference (Monte Carlo): final, first-order, indirect and
    /// standard-error lightmaps as OpenEXR (+ PNGs).
    Reference(reference::Args),
    /// How far a lightmap is from a reference (OpenEXRs): relative RMSE of total and indirect,
    /// energy ratio, worst texels, false-colour error PNG.
    Compare(compare::Args),
    /// Relight a bake on the GPU: frame PNG, final and first-order lightmaps (OpenEXR).
    Render(render::Args),
    /// Interactive viewer: move lights and watch the relit bake (egui window).
    View(view::Args),
    /// Generate lightmap UVs for an OBJ or glTF mesh and write it with them.
    Unwrap(unwrap::Args),
}

/// `ortm bench render …` (a subcommand with its own options) or `ortm bench transport|bake`.
#[derive(clap::Args, Debug)]
#[command(args_conflicts_with_subcommands = true, subcommand_negates_reqs = true)]
struct BenchArgs {
    #[command(subcommand)]
    sub: Option<BenchCommand>,
    #[command(flatten)]
    other: Option<bench::Args>,
}

/// `ortm bench …` subcommands with their own options.
#[derive(Subcommand, Debug)]
enum BenchCommand {
    /// Per-pass GPU frame times for the paper's Table 1 configurations (head).
    Render(bench_render::Args),
    /// Accuracy of bakes against the exact solve or the path-traced reference, one table.
    Accuracy(bench_accuracy::Args),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Demo(a) => demo::run(a),
        Command::Inspect(a) => inspect::run(a),
        Command::Solve(a) => solve::run(a),
        Command::Reference(a) => reference::run(a),
        Command::Compare(a) => compare::run(a),
        Command::Bake(a) => bake::run(a),
        Command::Bench(BenchArgs {
            sub: Some(BenchCommand::Render(a)),
            ..
        }) => bench_render::run(a),
        Command::Bench(BenchArgs {
            sub: Some(BenchCommand::Accuracy(a)),
            ..
        }) => bench_accuracy::run(a),
        Command::Bench(BenchArgs { other: Some(a), .. }) => bench::run(a),
        Command::Bench(_) => {
            anyhow::bail!("ortm bench: name a benchmark: transport, bake, render or accuracy")
        }
        Command::Bin(a) => bin::run(a),
        Command::Render(a) => render::run(a),
        Command::View(a) => view::run(a),
        Command::Unwrap(a) => unwrap::run(a),
    }
}

/// The built-in scene names [`load_scene`] accepts.
pub const BUILTIN_SCENES: [&str; 4] = ["cornell", "maze", "head", "head-exponential"];

/// Help text of a scene argument (every subcommand taking one says the same).
pub const SCENE_HELP: &str = "Scene file (TOML) or built-in scene name: `cornell` (the Cornell box), \
     `maze` (four bays, indirect light), `head` or `head-exponential` (the scanned head; its OBJ \
     is read from $ORTM_HEAD_OBJ, else ../shared/faces/head.obj beside the repository)";

/// Loads a scene argument: the name of a built-in scene ([`BUILTIN_SCENES`]) or a scene-file
/// path. `size` overrides the lightmap size (square). A word that is neither a built-in name
/// nor an existing file is answered with the built-in names, the closest first.
pub fn load_scene(arg: &str, size: Option<u32>) -> Result<Scene> {
    let mut scene = match arg {
        "cornell" => {
            let min = ortm::scene::cornell::MIN_LIGHTMAP_SIZE;
            if size.is_some_and(|s| s < min) {
                anyhow::bail!(
                    "the built-in cornell scene needs --size {min} or more (its charts have 2-texel gutters)"
                );
            }
            ortm::scene::cornell::cornell_box(size.unwrap_or(64))
        }
        "maze" => {
            let min = ortm::scene::maze::MIN_LIGHTMAP_SIZE;
            if size.is_some_and(|s| s < min) {
                anyhow::bail!(
                    "the built-in maze scene needs --size {min} or more (its charts have 2-texel gutters)"
                );
            }
            ortm::scene::maze::maze(size.unwrap_or(ortm::scene::maze::DEFAULT_LIGHTMAP_SIZE))
        }
        "head" => head_scene()?,
        "head-exponential" => {
            check_head_obj()?;
            ortm::scene::head::head_scene_with(faces::Falloff::Exponential)
                .with_context(|| format!("loading the head scan {}", head_obj_location()))?
        }
        name if looks_like_a_name(name) => bail_unknown_scene(name)?,
        path => ortm::scene::file::load_scene_sized(&PathBuf::from(path), size)
            .with_context(|| format!("loading scene '{path}'"))?,
    };
    if let Some(s) = size {
        let max = ortm::io::limits::MAX_LIGHTMAP_SIDE;
        if s == 0 || s > max {
            anyhow::bail!("--size {s} is out of range: use 1..={max} texels");
        }
        scene.lightmap_size = (s, s);
    }
    Ok(scene)
}

/// Creates `dir` (and parents), with a clear error.
pub fn ensure_dir(dir: &std::path::Path) -> Result<()> {
    std::fs::create_dir_all(dir)
        .with_context(|| format!("cannot create output folder '{}'", dir.display()))
}

/// The built-in `head` scene ([`ortm::scene::head::head_scene`]): the scanned head at
/// [`faces::HEAD_METRES_PER_UNIT`] m per model unit, Jensen et al. 2001 "skin1" dipole, 256²
/// lightmap, the point light of the paper's Fig. 5. The mesh comes from `$ORTM_HEAD_OBJ` or
/// `../shared/faces/head.obj`. Head scan © Lee Perry-Smith / Infinite Realities, CC BY 3.0.
pub fn head_scene() -> Result<Scene> {
    check_head_obj()?;
    ortm::scene::head::head_scene().with_context(|| {
        format!(
            "loading the head scan {} (it is {})",
            head_obj_location(),
            faces::head::HEAD_SOURCE
        )
    })
}

/// Where the head OBJ is looked for, in words: the path and where the path came from.
fn head_obj_location() -> String {
    let path = faces::head_obj_path();
    let env = faces::HEAD_OBJ_ENV;
    if std::env::var_os(env).is_some_and(|v| !v.is_empty()) {
        format!("'{}' (from ${env})", path.display())
    } else {
        format!(
            "'{}' (the default, ../shared/faces/head.obj beside the repository; ${env} is not set)",
            path.display()
        )
    }
}

/// An error naming where the head OBJ was looked for, and how to point at it, when it is not
/// a file there.
fn check_head_obj() -> Result<()> {
    let path = faces::head_obj_path();
    if !path.is_file() {
        anyhow::bail!(
            "the scanned head OBJ is not found at {}; set {}=/path/to/head.obj (it is {})",
            head_obj_location(),
            faces::HEAD_OBJ_ENV,
            faces::head::HEAD_SOURCE
        );
    }
    Ok(())
}

/// True when a scene argument is a bare word (no folder, no extension) that names no file:
/// meant as a built-in scene name.
fn looks_like_a_name(arg: &str) -> bool {
    let p = std::path::Path::new(arg);
    !arg.is_empty() && !arg.contains(['/', '\\', '.']) && std::fs::symlink_metadata(p).is_err()
}

/// The error for an unknown built-in scene name: the built-in names, closest first.
fn bail_unknown_scene(name: &str) -> Result<Scene> {
    let mut names = BUILTIN_SCENES.to_vec();
    names.sort_by_key(|n| edit_distance(name, n));
    let hint = if edit_distance(name, names[0]) <= 2 {
        format!("did you mean `{}`? ", names[0])
    } else {
        String::new()
    };
    anyhow::bail!(
        "unknown scene '{name}': it is neither a built-in scene nor a file; {hint}the built-in \
         scenes are {}; or give the path of a scene file (TOML, see docs/scene-format.md)",
        BUILTIN_SCENES.map(|n| format!("`{n}`")).join(", ")
    )
}

/// Levenshtein distance between two short words (characters inserted, removed or replaced).
fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut diag = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let next = (row[j + 1] + 1)
                .min(row[j] + 1)
                .min(diag + usize::from(ca != *cb));
            diag = row[j + 1];
            row[j + 1] = next;
        }
    }
    row[b.len()]
}
