//! `ortm solve SCENE -o DIR`: the exact dense solve `B = B_o + R·B_o` of a small lightmap with
//! the scene's lights (or `--light` ones, as `ortm render` takes them); writes the first-order,
//! final and indirect lightmaps as linear OpenEXR (W/m², the inputs of `ortm compare`) and as
//! tone-mapped PNGs, and prints energy figures.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ortm::accuracy::compare::power_w;
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::report::save_solution_pngs;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, texel_patches};
use ortm::render::lightmap_exr::write_lightmap_exr;
use ortm::scene::light::{LIGHT_SYNTAX, parse_light};

use ortm::bake::transport::dense::MAX_TEXELS as MAX_DENSE_TEXELS;

/// Arguments of `ortm solve`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file or built-in scene name ([`super::SCENE_HELP`]).
    #[arg(default_value = "cornell", help = super::SCENE_HELP)]
    scene: String,
    /// Lightmap size (square), overriding the scene's.
    #[arg(long)]
    size: Option<u32>,
    /// Output folder.
    #[arg(short, long, default_value = "out")]
    output: PathBuf,
    /// A light replacing the scene's lights (repeatable).
    #[arg(long = "light", value_name = "SPEC", allow_hyphen_values = true, help = format!("A light replacing the scene's lights (repeatable): {LIGHT_SYNTAX}"))]
    lights: Vec<String>,
}

/// Runs `ortm solve`.
pub fn run(a: Args) -> Result<()> {
    let mut scene = super::load_scene(&a.scene, a.size)?;
    if !a.lights.is_empty() {
        scene.lights = a
            .lights
            .iter()
            .map(|l| parse_light(l))
            .collect::<Result<_, _>>()?;
    }
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
    for (map, name) in [
        (&first, "first_order.exr"),
        (&fin, "final.exr"),
        (&ind, "indirect.exr"),
    ] {
        write_lightmap_exr(&a.output.join(name), map)?;
    }
    save_solution_pngs(&a.output, &first, &fin, &ind)?;
    let power = |v: &[glam::Vec3]| power_w(&grid, v);
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
        "wrote {0}/first_order.exr, final.exr, indirect.exr (linear W/m²) and {0}/first_order.png, final.png, indirect.png",
        a.output.display()
    );
    Ok(())
}
