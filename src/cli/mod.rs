//! Subcommands of the `ortm` tool.

mod inspect;
mod solve;

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
    /// Mesh and chart statistics, coverage, overlaps, and a PNG of the texel charts.
    Inspect(inspect::Args),
    /// Exact dense solve (small lightmaps): first-order, final and indirect lightmaps as PNG.
    Solve(solve::Args),
}

/// Runs a parsed command line.
pub fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Inspect(a) => inspect::run(a),
        Command::Solve(a) => solve::run(a),
    }
}

/// Loads a scene argument: the name of a built-in scene (`cornell`) or a scene-file path.
/// `size` overrides the lightmap size (square).
pub fn load_scene(arg: &str, size: Option<u32>) -> Result<Scene> {
    let mut scene = match arg {
        "cornell" => ortm::scene::cornell::cornell_box(size.unwrap_or(64)),
        path => ortm::scene::file::load_scene(&PathBuf::from(path))
            .with_context(|| format!("loading scene '{path}'"))?,
    };
    if let Some(s) = size {
        if s == 0 || s > 8192 {
            anyhow::bail!("--size {s} is out of range: use 1..=8192 texels");
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
