//! `ortm solve SCENE -o DIR`: the exact dense solve `B = B_o + R·B_o` of a small lightmap with
//! the scene's lights; writes first-order, final and indirect PNGs and prints energy figures.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::report::{lightmap_image, percentile_99, save_png};
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, texel_patches};

use ortm::bake::transport::dense::MAX_TEXELS as MAX_DENSE_TEXELS;

/// Arguments of `ortm solve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file (TOML) or built-in scene name (`cornell`).
    #[arg(default_value = "cornell")]
    scene: String,
    /// Lightmap size (square), overriding the scene's.
    #[arg(long)]
    size: Option<u32>,
    /// Output folder.
    #[arg(short, long, default_value = "out")]
    output: PathBuf,
}

/// Runs `ortm solve`.
pub fn run(a: Args) -> Result<()> {
    let scene = super::load_scene(&a.scene, a.size)?;
    let grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{}'", a.scene))?;
    if grid.texels.len() > MAX_DENSE_TEXELS {
        bail!(
            "{} covered texels: the exact dense solve is limited to {MAX_DENSE_TEXELS} \
             (memory and time grow as n² and n³); use a smaller --size",
            grid.texels.len()
        );
    }
    super::ensure_dir(&a.output)?;
    let t0 = Instant::now();
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let kernels = Kernels::new(&scene, Effects::default(), vis.clone());
    let patches = texel_patches(&grid);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    let dense = DenseTransport::new(&patches, &kernels);
    let t_assemble = t0.elapsed();
    let b = dense.solve(&b_o);
    let t_total = t0.elapsed();
    let first = lighting::to_lightmap(&grid, &b_o);
    let fin = lighting::to_lightmap(&grid, &b);
    let indirect: Vec<_> = b.iter().zip(&b_o).map(|(x, y)| *x - *y).collect();
    let ind = lighting::to_lightmap(&grid, &indirect);
    let white = percentile_99(&fin);
    save_png(
        &lightmap_image(&first, white),
        &a.output.join("first_order.png"),
    )?;
    save_png(&lightmap_image(&fin, white), &a.output.join("final.png"))?;
    save_png(
        &lightmap_image(&ind, percentile_99(&ind)),
        &a.output.join("indirect.png"),
    )?;
    let power = |v: &[glam::Vec3]| -> glam::DVec3 {
        v.iter()
            .zip(&patches)
            .map(|(x, p)| x.as_dvec3() * p.area_m2 as f64)
            .sum()
    };
    println!(
        "{} texels at {}x{}: assembled in {:.2} s, solved in {:.2} s",
        grid.texels.len(),
        grid.width,
        grid.height,
        t_assemble.as_secs_f64(),
        (t_total - t_assemble).as_secs_f64()
    );
    println!(
        "first-order power {:.4?} W, final {:.4?} W (RGB)",
        power(&b_o).to_array(),
        power(&b).to_array()
    );
    println!(
        "wrote {}/first_order.png, final.png, indirect.png",
        a.output.display()
    );
    Ok(())
}
