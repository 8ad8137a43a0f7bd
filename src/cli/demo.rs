//! `ortm demo [-o OUT]`: the main job on the built-in Cornell box — inspect, exact solve, bake,
//! bin and render — each step the same as its own subcommand, outputs under `OUT`.

use std::path::PathBuf;

use anyhow::{Context, Result};
use clap::Parser;

/// Arguments of `ortm demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Output folder.
    #[arg(short, long, default_value = "out")]
    output: PathBuf,
    /// Lightmap size (square).
    #[arg(long, default_value_t = 64)]
    size: u32,
    /// Number of offsets.
    #[arg(long, default_value_t = 100)]
    offsets: usize,
}

/// Runs `ortm demo`.
pub fn run(a: Args) -> Result<()> {
    super::ensure_dir(&a.output)?;
    let out = |p: &str| a.output.join(p).display().to_string();
    let size = a.size.to_string();
    let offsets = a.offsets.to_string();
    let steps: Vec<Vec<String>> = vec![
        vec![
            "inspect",
            "cornell",
            "--size",
            &size,
            "-o",
            &out("coverage.png"),
        ],
        vec!["solve", "cornell", "--size", &size, "-o", &out("exact")],
        vec![
            "bake",
            "cornell",
            "--size",
            &size,
            "--offsets",
            &offsets,
            "-o",
            &out("bake"),
        ],
        vec!["bin", &out("bake")],
        vec![
            "render",
            &out("bake"),
            "--scene",
            "cornell",
            "--side-by-side",
            "-o",
            &out("frame.png"),
            "--lightmap-out",
            &out("final.exr"),
            "--first-order-out",
            &out("first_order.exr"),
        ],
    ]
    .into_iter()
    .map(|v| v.into_iter().map(String::from).collect())
    .collect();
    for step in steps {
        println!("\n$ ortm {}", step.join(" "));
        let cli =
            super::Cli::try_parse_from(std::iter::once("ortm".to_string()).chain(step.clone()))
                .with_context(|| format!("demo step {}", step[0]))?;
        super::run(cli).with_context(|| format!("demo step `ortm {}`", step.join(" ")))?;
    }
    println!("\ndemo outputs in {}", a.output.display());
    Ok(())
}
