//! `ortm compare REF.exr TEST.exr --scene S`: how far a lightmap is from a reference.
//!
//! Data flow: the scene (`--scene`, `--size`) gives the covered texels ([`TexelGrid`] at its
//! lightmap size, which every EXR must have); each EXR (linear W/m², as `ortm solve`,
//! `ortm render --lightmap-out` and `ortm reference` write them) is read and gathered at the
//! covered texels; the library's [`ortm::accuracy::compare`] gives the figures — relative RMSE of
//! the total and (with `--first REF_FIRST TEST_FIRST`) of the indirect term over interior
//! covered texels, the same two away from the reference's first-order edges (with `--first`),
//! energy ratio per channel, worst texels — printed here, and
//! [`error_image`] the false-colour error PNG (`-o`). With the reference's standard error
//! (`--std-error`, or `std_error.exr` beside REF as `ortm reference` writes it) also the
//! reference's own noise as a relative RMSE, the figures less it in quadrature, and the share
//! of covered texels within 3 standard errors ([`reference_noise`]).

use std::path::{Path, PathBuf};

use anyhow::{Context, Result, bail};
use glam::Vec3;
use ortm::accuracy::compare::{compare, error_image, noise_corrected, reference_noise};
use ortm::bake::lighting::from_lightmap;
use ortm::bake::report::save_png;
use ortm::bake::texels::TexelGrid;
use ortm::render::lightmap_exr::read_lightmap_exr;

/// Arguments of `ortm compare`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// The reference's final lightmap (OpenEXR, linear W/m²), e.g. `ortm solve`'s `final.exr`.
    reference: PathBuf,
    /// The lightmap to judge (OpenEXR, linear W/m²), e.g. `ortm render --lightmap-out`.
    test: PathBuf,
    /// The two first-order lightmaps (reference's, then test's) for the indirect figure.
    #[arg(long, num_args = 2, value_names = ["REF_FIRST", "TEST_FIRST"])]
    first: Option<Vec<PathBuf>>,
    /// Scene file or built-in scene name ([`super::SCENE_HELP`]): its covered texels are the
    /// ones compared.
    #[arg(long, help = format!("{}; its covered texels are the ones compared", super::SCENE_HELP))]
    scene: String,
    /// Lightmap size (square), overriding the scene's; must be the EXRs' size.
    #[arg(long)]
    size: Option<u32>,
    /// Where to write the false-colour error PNG.
    #[arg(short, long, default_value = "error.png")]
    output: PathBuf,
    /// How many of the worst interior texels to list.
    #[arg(long, default_value_t = 10)]
    worst: usize,
    /// The reference's per-texel standard error (OpenEXR, W/m², as `ortm reference` writes
    /// it). Default: `std_error.exr` beside REF when there is one.
    #[arg(long, value_name = "STD_ERROR.exr")]
    std_error: Option<PathBuf>,
}

/// Reads `path` as a lightmap of the grid's size and gathers its covered texels; errors name the
/// file, both sizes or the first non-finite texel, and the fix.
fn read_covered(path: &Path, grid: &TexelGrid, scene: &str) -> Result<Vec<Vec3>> {
    let map = read_lightmap_exr(path)?;
    if (map.width, map.height) != (grid.width, grid.height) {
        bail!(
            "'{}' is {}x{} but scene '{scene}' has a {}x{} lightmap: compare lightmaps of the \
             scene's size, or pass --size {} if the scene was solved or baked at that size",
            path.display(),
            map.width,
            map.height,
            grid.width,
            grid.height,
            map.width
        );
    }
    let values = from_lightmap(grid, &map);
    if let Some((t, v)) = grid
        .texels
        .iter()
        .zip(&values)
        .find(|(_, v)| !v.is_finite())
    {
        bail!(
            "'{}' has a non-finite value {v} at covered texel ({}, {}): the lightmap is broken; \
             recompute it",
            path.display(),
            t.x,
            t.y
        );
    }
    Ok(values)
}

/// Runs `ortm compare`.
pub fn run(a: Args) -> Result<()> {
    let scene = super::load_scene(&a.scene, a.size)?;
    let grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{}'", a.scene))?;
    let reference = read_covered(&a.reference, &grid, &a.scene)?;
    let test = read_covered(&a.test, &grid, &a.scene)?;
    let firsts = match &a.first {
        Some(paths) => Some((
            read_covered(&paths[0], &grid, &a.scene)?,
            read_covered(&paths[1], &grid, &a.scene)?,
        )),
        None => None,
    };
    let c = compare(
        &grid,
        &reference,
        &test,
        firsts.as_ref().map(|(r, t)| (r.as_slice(), t.as_slice())),
        a.worst,
    );
    if c.interior == 0 {
        bail!(
            "scene '{}' has no interior covered texels at {}x{} (every covered texel touches a \
             chart border): use a larger --size",
            a.scene,
            grid.width,
            grid.height
        );
    }
    println!(
        "reference {}, test {}, scene '{}' at {}x{}",
        a.reference.display(),
        a.test.display(),
        scene.name,
        grid.width,
        grid.height
    );
    println!(
        "texels          {} covered, {} interior (all 4 neighbours covered; the RMSE figures use these)",
        c.covered, c.interior
    );
    println!(
        "total           relative RMSE {:.6} ({:.2} %)",
        c.total,
        100.0 * c.total
    );
    match c.indirect {
        Some(e) => println!("indirect        relative RMSE {e:.6} ({:.2} %)", 100.0 * e),
        None => println!("indirect        (pass --first REF_FIRST.exr TEST_FIRST.exr)"),
    }
    if let Some((n, total, indirect)) = c.away_from_edges {
        println!(
            "away from edges {n} interior texels not within 2.5 texels of a 2x change of the \
             reference's first order (shadow edges, terminators): total {:.2} %, indirect {:.2} %",
            100.0 * total,
            100.0 * indirect
        );
    }
    let r = c.energy_ratio;
    println!(
        "energy ratio    test / reference power, R G B: {:.6} {:.6} {:.6}",
        r.x, r.y, r.z
    );
    let std_error = a.std_error.clone().or_else(|| {
        let beside = a.reference.with_file_name("std_error.exr");
        (beside.is_file() && beside != a.reference).then_some(beside)
    });
    if let Some(path) = std_error {
        let se = read_covered(&path, &grid, &a.scene)?;
        let n = reference_noise(
            &grid,
            &reference,
            &se,
            &test,
            firsts.as_ref().map(|(r, _)| r.as_slice()),
        );
        let indirect = n
            .indirect
            .map_or(String::new(), |i| format!(", indirect {:.2} %", 100.0 * i));
        let indirect_corrected = (c.indirect.zip(n.indirect)).map_or(String::new(), |(e, i)| {
            format!(", indirect {:.2} %", 100.0 * noise_corrected(e, i))
        });
        println!(
            "reference noise {}: its standard error as a relative RMSE: total {:.2} %{indirect}; \
             less that noise in quadrature: total {:.2} %{indirect_corrected}",
            path.display(),
            100.0 * n.total,
            100.0 * noise_corrected(c.total, n.total),
        );
        println!(
            "within 3σ       {:.2} % of covered texels (|test − reference| ≤ 3 standard errors in every channel)",
            100.0 * n.within_three_sigma
        );
        if let Some((lit, share)) = n.within_lit {
            println!(
                "                {:.2} % of the {lit} texels the reference's first order lights at their centre",
                100.0 * share
            );
        }
        if n.unlit_misses > 0 {
            println!(
                "                of the misses, {} ({:.2} % of covered texels) where the reference is 0 ± 0 \
                 (none of its paths found light): the test there at most {:.3e} W/m², {:.2e} of \
                 the reference's RMS",
                n.unlit_misses,
                100.0 * n.unlit_misses as f64 / grid.texels.len() as f64,
                n.unlit_largest,
                n.unlit_largest / c.reference_rms
            );
        }
    }
    print_worst(&c);
    let img = error_image(&grid, &reference, &test, c.reference_rms);
    save_png(&img, &a.output)?;
    println!(
        "wrote {}: |test − reference| per texel on the viridis ramp, dark purple 0 → yellow {:.4} \
         W/m² (the reference's RMS) and above; uncovered texels grey; colour bar along the bottom",
        a.output.display(),
        c.reference_rms
    );
    Ok(())
}

/// Prints the worst interior texels.
fn print_worst(c: &ortm::accuracy::compare::Comparison) {
    if c.worst.is_empty() {
        return;
    }
    println!(
        "worst texels    error = |test − reference| / the reference's RMS ({:.4} W/m²)",
        c.reference_rms
    );
    println!(
        "  {:>5} {:>5}  {:>32}  {:>32}  {:>8}",
        "x", "y", "reference R G B (W/m²)", "test R G B (W/m²)", "error"
    );
    let rgb = |v: Vec3| format!("{:.4e} {:.4e} {:.4e}", v.x, v.y, v.z);
    for w in &c.worst {
        println!(
            "  {:>5} {:>5}  {:>32}  {:>32}  {:>8.4}",
            w.x,
            w.y,
            rgb(w.reference),
            rgb(w.test),
            w.relative_error
        );
    }
}
