//! `ortm inspect SCENE`: mesh and chart statistics, coverage, overlaps, and a coverage PNG
//! (charts coloured, overlapping texels red, enlarged to a readable size, with a legend).
//! Overlapping UVs are reported, not fatal: the inspection is where a user looks at them.

use std::path::PathBuf;

use anyhow::{Context, Result};
use ortm::bake::texels::{TexelError, TexelGrid, overlapping_slots};

/// Arguments of `ortm inspect`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Scene file or built-in scene name ([`super::SCENE_HELP`]).
    #[arg(help = super::SCENE_HELP)]
    scene: String,
    /// Lightmap size (square), overriding the scene's.
    #[arg(long)]
    size: Option<u32>,
    /// Where to write the coverage/charts PNG.
    #[arg(short, long, default_value = "coverage.png")]
    output: PathBuf,
}

/// Runs `ortm inspect` (and reports its peak memory for tests: `ORTM_TEST_REPORT_PEAK`).
pub fn run(a: Args) -> Result<()> {
    let result = inspect(&a);
    ortm::io::limits::report_peak_memory_if_asked();
    result
}

/// `ortm inspect` proper.
fn inspect(a: &Args) -> Result<()> {
    let mut scene = super::load_scene(&a.scene, a.size)?;
    let m = &scene.mesh;
    let (lo, hi) = m.bounds();
    let area: f64 = m
        .triangles
        .iter()
        .map(|t| {
            let p = |k: usize| m.positions_m[t.position[k] as usize];
            0.5 * (p(1) - p(0)).cross(p(2) - p(0)).length() as f64
        })
        .sum();
    println!("scene        {}", scene.name);
    println!(
        "mesh         {} positions, {} UVs, {} triangles, {} materials, {} lights",
        m.positions_m.len(),
        m.uvs.len(),
        m.triangles.len(),
        scene.materials.len(),
        scene.lights.len()
    );
    println!(
        "extent       {:.3} x {:.3} x {:.3} m, surface area {:.4} m²",
        hi.x - lo.x,
        hi.y - lo.y,
        hi.z - lo.z,
        area
    );
    let (w, h) = scene.lightmap_size;
    ortm::io::limits::check_lightmap_memory(w, h)?;
    // Overlapping UVs stop a bake, not the inspection: rasterize accepting them, say what
    // the bake would say, and draw them red.
    let bake_refusal = match TexelGrid::build(&scene) {
        Err(e @ TexelError::Overlap { .. }) => Some(e.to_string()),
        _ => None,
    };
    scene.allow_uv_overlap = true;
    let grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{}'", a.scene))?;
    let s = &grid.stats;
    println!(
        "lightmap     {w}x{h}: {} covered texels ({:.1}%), {} charts",
        s.covered,
        100.0 * s.covered as f64 / (w as f64 * h as f64),
        s.charts
    );
    let mut areas: Vec<f32> = grid.texels.iter().map(|t| t.area_m2).collect();
    areas.sort_by(f32::total_cmp);
    let q = |f: f64| areas[((areas.len() - 1) as f64 * f) as usize].sqrt() * 1000.0;
    println!(
        "texel size   {:.2} mm median (5%: {:.2} mm, 95%: {:.2} mm); covered area {:.4} m² ({:.1}% of the mesh)",
        q(0.5),
        q(0.05),
        q(0.95),
        s.area_m2,
        100.0 * s.area_m2 / area.max(1e-30)
    );
    println!(
        "overlaps     {} texel(s); {} triangle(s) cover no texel centre",
        s.overlapping, s.triangles_without_texels
    );
    for w in s.warnings.iter().filter(|_| bake_refusal.is_none()) {
        println!("warning      {w}");
    }
    if let Some(e) = &bake_refusal {
        println!("warning      `ortm bake` refuses this layout: {e}");
    }
    let overlaps = overlapping_slots(&scene, w, h);
    let picture = ortm::bake::report::coverage_picture(&grid, &overlaps);
    ortm::bake::report::save_png(&picture, &a.output)?;
    println!(
        "wrote        {} ({}x{} px: {} px per texel; charts coloured, overlapping texels red, \
         uncovered black)",
        a.output.display(),
        picture.width(),
        picture.height(),
        ortm::bake::report::readable_factor(w, h)
    );
    Ok(())
}
