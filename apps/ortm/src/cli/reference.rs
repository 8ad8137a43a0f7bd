//! `ortm reference SCENE --size N --spp S --seed K [--replicates R] [--effects radiosity,sss] -o DIR`: the
//! path-traced texture-space reference ([`ortm::accuracy::reference`]) with the scene's lights.
//! Writes `final.exr`, `first_order.exr`, `indirect.exr` and `std_error.exr` (W/m², linear RGB,
//! uncovered texels 0) plus `first_order.png`, `final.png` and `indirect.png` as `ortm solve`
//! does; prints texels, samples, time, rays/s, the mean relative standard error and the power
//! figures. Every file is written atomically after the trace, so Ctrl-C (which stops the trace
//! within a moment) leaves no half-written file.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use ortm::accuracy::compare::power_w;
use ortm::accuracy::reference::{self, ReferenceError, Settings};
use ortm::bake::lighting;
use ortm::bake::report::save_solution_pngs;
use ortm::bake::texels::TexelGrid;
use ortm::render::lightmap_exr::write_lightmap_exr;

/// Arguments of `ortm reference`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file or built-in scene name ([`super::SCENE_HELP`]).
    #[arg(default_value = "cornell", help = super::SCENE_HELP)]
    scene: String,
    /// Lightmap size (square), overriding the scene's.
    #[arg(long)]
    size: Option<u32>,
    /// Paths per covered texel (the standard error falls as 1/√spp, faster where the
    /// stratified paths pay).
    #[arg(
        long,
        default_value_t = 256,
        value_parser = clap::value_parser!(u32).range(1..=i64::from(ortm::io::limits::MAX_SAMPLES_PER_TEXEL)),
        help = format!("Paths per covered texel, 1..={} (the standard error falls as 1/√spp or faster)", ortm::io::limits::MAX_SAMPLES_PER_TEXEL)
    )]
    spp: u32,
    /// Seed of the random streams (same seed → same output, whatever the thread count).
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Independent replicates the paths of a texel are split into: each replicate's paths are
    /// an Owen-scrambled Sobol point set (stratified), the spread of the replicates' means is
    /// the standard error; `--replicates` equal to `--spp` traces independent paths (plain
    /// Monte Carlo). Paths per texel are rounded up to a multiple of it.
    #[arg(long, default_value_t = reference::DEFAULT_REPLICATES,
        value_parser = clap::value_parser!(u32).range(1..))]
    replicates: u32,
    /// Effects: comma-separated `radiosity`, `sss` (as `ortm bake`).
    #[arg(long, default_value = "radiosity,sss")]
    effects: String,
    /// Output folder.
    #[arg(short, long, default_value = "out")]
    output: PathBuf,
}

/// Runs `ortm reference`.
pub fn run(a: Args) -> Result<()> {
    if a.spp == 0 {
        bail!("--spp 0: trace at least 1 path per texel (2 or more for a standard error)");
    }
    if a.replicates == 1 && a.spp > 1 {
        eprintln!(
            "note: --replicates 1 gives no standard error (std_error.exr is 0); 2 or more give one"
        );
    }
    let effects = super::bake::parse_effects(&a.effects)?;
    let scene = super::load_scene(&a.scene, a.size)?;
    let grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{}'", a.scene))?;
    super::ensure_dir(&a.output)?;
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second Ctrl-C exits at once; the first stops the trace and writes nothing.
        let _ = ctrlc::set_handler(move || {
            if c.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupt: stopping the reference (nothing is written)");
        });
    }
    let bar = super::progress::Progress::new(grid.texels.len() as u64, "reference (texels)");
    let settings = Settings {
        samples_per_texel: a.spp,
        replicates: a.replicates,
        seed: a.seed,
        effects,
    };
    let result = reference::trace_with_stats(
        &scene,
        &grid,
        &scene.lights,
        &settings,
        &|done, _| bar.set_position(done as u64),
        &cancel,
    );
    bar.finish_and_clear();
    let (maps, stats) = match result {
        Ok(r) => r,
        Err(ReferenceError::Cancelled) => bail!("interrupted: the reference was not written"),
    };
    let indirect = maps.indirect();
    let write = |name: &str, values: &[Vec3]| -> Result<()> {
        let path = a.output.join(name);
        write_lightmap_exr(&path, &lighting::to_lightmap(&grid, values))
            .with_context(|| format!("writing '{}'", path.display()))
    };
    write("final.exr", &maps.final_b)?;
    write("first_order.exr", &maps.first_order)?;
    write("indirect.exr", &indirect)?;
    write("std_error.exr", &maps.std_error)?;
    let first = lighting::to_lightmap(&grid, &maps.first_order);
    let fin = lighting::to_lightmap(&grid, &maps.final_b);
    let ind = lighting::to_lightmap(&grid, &indirect);
    save_solution_pngs(&a.output, &first, &fin, &ind)?;
    println!(
        "{} texels at {}x{}, {} paths per texel ({} replicates): {:.2} s, {:.2} Mrays/s ({} rays)",
        grid.texels.len(),
        grid.width,
        grid.height,
        maps.samples_per_texel,
        maps.replicates,
        stats.seconds,
        stats.rays_per_second() / 1e6,
        stats.rays
    );
    println!(
        "mean relative standard error: final {:.4}, indirect {:.4}; as a relative RMSE \
         (sqrt Σσ² / sqrt ΣB²): final {:.4}, indirect {:.4}",
        maps.mean_relative_std_error(&maps.final_b),
        maps.mean_relative_std_error(&indirect),
        maps.rms_relative_std_error(&maps.final_b),
        maps.rms_relative_std_error(&indirect)
    );
    println!(
        "first-order power {:.4?} W, final {:.4?} W (RGB)",
        power_w(&grid, &maps.first_order).to_array(),
        power_w(&grid, &maps.final_b).to_array()
    );
    println!(
        "wrote {}/final.exr, first_order.exr, indirect.exr, std_error.exr and PNGs",
        a.output.display()
    );
    Ok(())
}
