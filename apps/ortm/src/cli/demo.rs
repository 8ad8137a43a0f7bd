//! `ortm demo [cornell] [-o OUT] [--levels ε] [--offsets K]`: the main job on the built-in
//! Cornell box — inspect, exact solve, bake, bin and render — each step the same as its own
//! subcommand, outputs under `OUT`, with `OUT/guide.md` saying what each output shows and what
//! to look for. The main bake (`OUT/bake`, rendered into `frame.png`) holds multi-resolution
//! maps (`ortm bake --levels ε`), which converge to the transport; a second bake
//! (`OUT/bake_offsets`, `frame_offsets.png`) holds the paper's `K` importance-sampled offsets,
//! for comparison.
//!
//! `ortm demo face [-o OUT] [--size N] [--offsets K | --levels ε] [--falloff dipole|exponential]
//! [--bench]`: the paper's face figures on the scanned head. One bake with radiosity and
//! subsurface scattering combined (`ortm bake head`: the paper's `K` offsets, or
//! multi-resolution maps over the hierarchical transport), `ortm bin`, then one `ortm render` per figure of
//! [`faces::FIGURES`] (Figs. 3, 4, 5, 6a, 6b: lights and camera from the `faces` crate;
//! first order beside the final image where the figure compares them) → `OUT/<figure>.png`,
//! plus `OUT/figures.md` with the captions, what to look for and the scan's credit line.
//! `--bench` then prints the bake and frame times beside the paper's Table 1 (frame times from
//! `ortm bench render --bake OUT/bake`).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use clap::Parser;

/// Which demo.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum Which {
    /// The built-in Cornell box.
    Cornell,
    /// The paper's face figures on the scanned head.
    Face,
}

/// Skin falloff of the face demo.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum FalloffArg {
    /// Jensen et al. 2001 dipole.
    Dipole,
    /// Normalised exponential falloff (mean free path 1/σ_tr).
    Exponential,
}

/// Arguments of `ortm demo`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Which demo: `cornell` (default) or `face`.
    #[arg(value_enum, default_value_t = Which::Cornell)]
    which: Which,
    /// Output folder.
    #[arg(short, long, default_value = "out")]
    output: PathBuf,
    /// Lightmap size (square); default 64 (cornell), 256 (face).
    #[arg(long)]
    size: Option<u32>,
    /// Number of offsets (the face demo's bake; the Cornell demo's comparison bake of the
    /// paper's importance-sampled offsets).
    #[arg(long, default_value_t = 100)]
    offsets: usize,
    /// Multi-resolution maps (`ortm bake --levels ε`): the Cornell demo's main bake (default
    /// 3e-3); the face demo's bake instead of `--offsets` when given (with the hierarchical
    /// transport, `--tolerance 1e-3`).
    #[arg(long)]
    levels: Option<f64>,
    /// Face demo: skin falloff.
    #[arg(long, value_enum, default_value_t = FalloffArg::Dipole)]
    falloff: FalloffArg,
    /// Face demo: rendered image height in pixels (side-by-side figures are twice as wide).
    #[arg(long, default_value_t = 540)]
    height: u32,
    /// Face demo: afterwards, print bake and frame times beside the paper's Table 1.
    #[arg(long)]
    bench: bool,
    /// Display of the rendered images (`--direct`, `--filter`, as `ortm render`).
    #[command(flatten)]
    display: super::render::DisplayArgs,
}

/// Runs one `ortm` subcommand given as words, echoing it.
fn step(words: Vec<String>) -> Result<()> {
    println!("\n$ ortm {}", words.join(" "));
    let cli = super::Cli::try_parse_from(std::iter::once("ortm".to_string()).chain(words.clone()))
        .with_context(|| format!("demo step {}", words[0]))?;
    super::run(cli).with_context(|| format!("demo step `ortm {}`", words.join(" ")))
}

fn words(v: &[&str]) -> Vec<String> {
    v.iter().map(|s| s.to_string()).collect()
}

/// The Cornell demo's default `--levels`.
const CORNELL_LEVELS: f64 = 3e-3;

/// The face demo's `--tolerance` (hierarchical transport) when it bakes `--levels`: the rows of
/// the pair evaluator would cost `n²` visibility rays at 256².
const FACE_LEVELS_TOLERANCE: &str = "1e-3";

/// Runs `ortm demo`.
pub fn run(a: Args) -> Result<()> {
    super::ensure_dir(&a.output)?;
    match a.which {
        Which::Cornell => cornell(&a),
        Which::Face => face(&a),
    }
}

fn cornell(a: &Args) -> Result<()> {
    let out = |p: &str| a.output.join(p).display().to_string();
    let size = a.size.unwrap_or(64).to_string();
    let offsets = a.offsets.to_string();
    let levels = a.levels.unwrap_or(CORNELL_LEVELS).to_string();
    let render = |bake: &str, png: &str, exrs: bool| -> Vec<String> {
        let mut v = words(&[
            "render",
            &out(bake),
            "--scene",
            "cornell",
            "--side-by-side",
            "-o",
            &out(png),
        ]);
        if exrs {
            v.extend(words(&[
                "--lightmap-out",
                &out("final.exr"),
                "--first-order-out",
                &out("first_order.exr"),
            ]));
        }
        v.extend(display_words(a));
        v
    };
    let steps = [
        words(&[
            "inspect",
            "cornell",
            "--size",
            &size,
            "-o",
            &out("coverage.png"),
        ]),
        words(&["solve", "cornell", "--size", &size, "-o", &out("exact")]),
        words(&[
            "bake",
            "cornell",
            "--size",
            &size,
            "--levels",
            &levels,
            "--coarse-block",
            "0",
            "-o",
            &out("bake"),
        ]),
        words(&["bin", &out("bake")]),
        render("bake", "frame.png", true),
        words(&[
            "bake",
            "cornell",
            "--size",
            &size,
            "--offsets",
            &offsets,
            "--coarse-block",
            "0",
            "-o",
            &out("bake_offsets"),
        ]),
        words(&["bin", &out("bake_offsets")]),
        render("bake_offsets", "frame_offsets.png", false),
    ];
    for s in steps {
        step(s)?;
    }
    write_text(
        &a.output.join("guide.md"),
        &cornell_guide(&a.output, &size, &levels, &offsets),
    )?;
    println!(
        "\ndemo outputs in {}; what each file shows: {}",
        a.output.display(),
        a.output.join("guide.md").display()
    );
    Ok(())
}

/// `guide.md` of the Cornell demo written into `out`: each output, what it shows and what to
/// look for (the Cornell counterpart of the face demo's `figures.md`).
fn cornell_guide(out: &Path, size: &str, levels: &str, offsets: &str) -> String {
    let o = out.display();
    format!(
        "# The Cornell demo (`ortm demo`, {size}² lightmap, multi-resolution maps at ε = \
         {levels}; the paper's {offsets} offsets for comparison)\n\n\
         Every step below is an `ortm` subcommand; the demo printed each command line. \
         Lightmaps are in W/m² (radiosity per texel, linear); the PNGs carry a legend.\n\n\
         ## 1. The lightmap layout: `coverage.png`\n\n![coverage](coverage.png)\n\n\
         `ortm inspect cornell`: each chart (UV island: a wall, a box face) in its own colour, \
         black where no surface maps, red where two triangles' UVs would overlap (none here). \
         One square of pixels is one texel.\n\n\
         ## 2. The exact answer: `exact/`\n\n\
         ![first order](exact/first_order.png) ![final](exact/final.png) \
         ![indirect](exact/indirect.png)\n\n\
         `ortm solve cornell`: the dense solve `B = B_o + R·B_o` over every pair of texels. \
         `first_order` is the light arriving straight from the lamp (black in shadow), \
         `final` adds every bounce, `indirect` is their difference (its own scale). \
         Look for: the white walls and the boxes tinted red and green near the side walls, \
         and the shadows under the boxes no longer black in `final`.\n\n\
         ## 3. The bake: `bake/`\n\n\
         `ortm bake cornell --levels {levels} --coarse-block 0`: multi-resolution transfer \
         maps over the exact transport (`--coarse-block 0`: single-texel clusters up to 4,096 \
         covered texels) (`map_*.exr`, \
         listed in `index.json` with their pyramid level and offset). Each texel's transfer \
         is split into blocks of a pyramid of the first-order lightmap — single texels near \
         it, coarser blocks farther away — each block kept whole only where taking the \
         first order as its mean errs by at most ε × the brightest first order / 2, whatever \
         the lighting. So the maps converge to the transport as ε falls (ε = 0 is exact).\n\n\
         ## 4. The atlases: `bake/atlas_*.png`\n\n\
         ![packing](bake/atlas_000.png)\n\n\
         `ortm bin`: the maps cut into power-of-two slices and packed into texture atlases \
         (one colour per map; `atlas_NNN_values.png` shows the values). The atlas size fits \
         the maps (`atlases.json` records it).\n\n\
         ## 5. The frame: `frame.png`, `first_order.exr`, `final.exr`\n\n\
         ![frame](frame.png)\n\n\
         `ortm render`: left the first order (shadow maps on a GPU, ray-cast shadows on the \
         CPU), right the final image (each map modulating the first-order pyramid level at its \
         offset, Eq. 9 of the paper). Look for the same colour bleeding and lit shadows as in \
         `exact/final.png`. The lightmaps the frame shows are `final.exr` and \
         `first_order.exr`; how far they are from the exact solve:\n\n\
         ```sh\n\
         ortm compare {o}/exact/final.exr {o}/final.exr --first {o}/exact/first_order.exr \
         {o}/first_order.exr --scene cornell --size {size} -o {o}/error.png\n\
         ```\n\n\
         ## 6. The paper's offsets: `bake_offsets/`, `frame_offsets.png`\n\n\
         ![offsets](bake_offsets/report_offsets.png) \
         ![density](bake_offsets/report_density.png) ![frame](frame_offsets.png)\n\n\
         `ortm bake cornell --offsets {offsets} --coarse-block 0`: the paper's form — {offsets} offsets drawn \
         by importance (`report_offsets.png`: the offsets as white dots in the square of \
         offsets from −1 to 1 lightmap side, each Voronoi cell coloured by its importance; \
         `report_density.png`: the density they were drawn from), each map multiplying the \
         first order at one site per cell. Look for the bright blotches on the red and green \
         walls and the back wall: a cell's transfer lands on one site while its senders lie \
         on several walls. The multi-resolution maps above have none.\n\n\
         Move the light yourself: `ortm view {o}/bake` (a window), or \
         `ortm render {o}/bake --light point:0.15,0.45,0.2:8 -o moved.png`.\n"
    )
}

/// `ortm render --light` text of a figure light ([`ortm::scene::light::LIGHT_SYNTAX`]), with
/// the figure's numbers as given: a directional light's direction is left unnormalised, so
/// that `--light` normalises it once, exactly as [`ortm::scene::head::light`] does
/// (normalising twice can move the last bit).
pub fn light_spec(l: &faces::FigLight) -> String {
    let light = match *l {
        faces::FigLight::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => ortm::scene::Light::Directional {
            direction,
            color,
            irradiance_w_m2,
        },
        faces::FigLight::Point { .. } => ortm::scene::head::light(l),
    };
    light.to_string()
}

/// `ortm render --camera` syntax of a figure camera.
pub fn camera_spec(c: &faces::FigCamera) -> String {
    let v = |v: glam::Vec3| format!("{},{},{}", v.x, v.y, v.z);
    format!("{}:{}:{}", v(c.eye_m), v(c.target_m), c.fov_y_deg)
}

/// The scene argument of the face demo for a falloff.
pub fn face_scene_arg(f: FalloffArg) -> &'static str {
    match f {
        FalloffArg::Dipole => "head",
        FalloffArg::Exponential => "head-exponential",
    }
}

fn face(a: &Args) -> Result<()> {
    let out = |p: &str| a.output.join(p).display().to_string();
    let size = a.size.unwrap_or(faces::head::HEAD_LIGHTMAP_SIDE);
    let scene = face_scene_arg(a.falloff);
    let bake_dir = out("bake");
    if a.bench && a.output.join("bake").join("index.json").exists() {
        anyhow::bail!(
            "--bench times a fresh bake, but '{}' already holds one (its maps would be reused): \
             remove it or choose another -o",
            bake_dir
        );
    }
    if a.bench && a.levels.is_some() {
        anyhow::bail!(
            "--bench compares the paper's importance-sampled offsets with its Table 1: drop \
             --levels (or time a levels bake with `ortm bench render --bake DIR`)"
        );
    }
    let form = match a.levels {
        Some(l) => vec![
            "--levels".to_string(),
            l.to_string(),
            "--tolerance".into(),
            FACE_LEVELS_TOLERANCE.into(),
        ],
        None => vec!["--offsets".to_string(), a.offsets.to_string()],
    };
    let t = Instant::now();
    step(
        words(&["bake", scene, "--size", &size.to_string()])
            .into_iter()
            .chain(form)
            .chain(words(&["--effects", "radiosity,sss", "-o", &bake_dir]))
            .collect(),
    )?;
    let bake_s = t.elapsed().as_secs_f64();
    step(words(&["bin", &bake_dir, "--atlas", "1024"]))?;
    let maps = match a.levels {
        Some(l) => format!(
            "multi-resolution maps at ε = {l} (hierarchical transport at \
             {FACE_LEVELS_TOLERANCE}, skin's near field at {n}×{n} sub-texels)",
            n = super::bake::DEFAULT_NEAR_FIELD
        ),
        None => format!("{} offsets", a.offsets),
    };
    let mut md = format!(
        "# Face figures (`ortm demo face`, {size}² lightmap, {maps}, radiosity + {:?} \
         subsurface scattering in one bake)\n\n{}.\n\n",
        a.falloff,
        faces::HEAD_CREDIT
    );
    let mut render_s = Vec::new();
    for f in &faces::FIGURES {
        let png = format!("{}.png", f.id);
        let t = Instant::now();
        step(render_figure_command(a, f, &bake_dir, &out(&png)))?;
        render_s.push((f.id, t.elapsed().as_secs_f64()));
        md.push_str(&figure_section(f, &png));
    }
    write_text(&a.output.join("figures.md"), &md)?;
    println!("\nface demo outputs in {}", a.output.display());
    println!("{}", faces::HEAD_CREDIT);
    if a.bench {
        bench_table(a, size, bake_s, &render_s, Path::new(&bake_dir))?;
    }
    Ok(())
}

/// The `ortm render` command line of figure `f` from the bake in `bake_dir`, writing `png`.
fn render_figure_command(a: &Args, f: &faces::Figure, bake_dir: &str, png: &str) -> Vec<String> {
    let h = a.height.max(16);
    let w = if f.side_by_side {
        2 * h * 8 / 9
    } else {
        h * 8 / 9
    };
    let mut v = words(&[
        "render",
        bake_dir,
        &format!("--camera={}", camera_spec(&f.camera)),
        "--size",
        &format!("{w}x{h}"),
        "-o",
        png,
    ]);
    for l in f.lights {
        // `--light=SPEC`: a spec may start with a minus sign.
        v.push(format!("--light={}", light_spec(l)));
    }
    if f.side_by_side {
        v.push("--side-by-side".into());
    }
    v.extend(display_words(a));
    v
}

/// `--direct` and `--filter` for the demo's `ortm render` steps.
fn display_words(a: &Args) -> Vec<String> {
    fn name(v: impl clap::ValueEnum) -> String {
        v.to_possible_value()
            .map_or_else(String::new, |p| p.get_name().to_string())
    }
    vec![
        format!("--direct={}", name(a.display.direct)),
        format!("--filter={}", name(a.display.filter)),
    ]
}

/// The `figures.md` section of figure `f` shown in `png`: caption, image, what to look for.
fn figure_section(f: &faces::Figure, png: &str) -> String {
    format!(
        "## {}\n\n![{}]({png})\n\n{}{}.\nLook for: {}.\n\n",
        f.paper,
        f.id,
        if f.side_by_side {
            "Left: first order; right: final (radiosity + subsurface scattering). "
        } else {
            ""
        },
        faces::HEAD_CREDIT,
        f.look_for
    )
}

/// Writes a text file atomically ([`ortm::io::write_atomic`]).
fn write_text(path: &Path, text: &str) -> Result<()> {
    ortm::io::write_atomic(path, text.as_bytes())
        .with_context(|| format!("cannot write '{}'", path.display()))
}

fn bench_table(
    a: &Args,
    size: u32,
    bake_s: f64,
    render_s: &[(&str, f64)],
    bake_dir: &Path,
) -> Result<()> {
    let atlases = ortm::atlas::read_atlas_index(bake_dir)
        .map(|i| i.atlases.len())
        .ok();
    let paper = super::bench_render::TABLE_1
        .iter()
        .find(|r| r.0 == size && r.1 == a.offsets);
    let paper_mapgen = super::bench_render::TABLE_1
        .iter()
        .position(|r| r.0 == size && r.1 == a.offsets)
        .map(|i| super::bench::PAPER_MAPGEN_S[i]);
    println!(
        "\nface demo configuration beside the paper's Table 1 (paper: Pentium 4 2.53 GHz, GeForce 6800)"
    );
    println!(
        "| lightmap | offsets | ortm bake (s) | paper map-gen (s) | atlases 1024² | paper bins | paper FPS |"
    );
    println!("|---|---|---|---|---|---|---|");
    println!(
        "| {size}² | {} | {bake_s:.1} | {} | {} | {} | {} |",
        a.offsets,
        paper_mapgen.map_or("—".into(), |s| format!("{s:.0}")),
        atlases.map_or("—".into(), |n| n.to_string()),
        paper.map_or("—".into(), |r| r.2.to_string()),
        paper.map_or("—".into(), |r| format!("{:.2}", r.3)),
    );
    println!("\nwall time of each `ortm render` (adapter start-up, upload, one frame, PNG):");
    for (id, s) in render_s {
        println!("  {id}: {s:.1} s");
    }
    println!("\nper-pass frame times of this bake (median GPU time):");
    step(words(&[
        "bench",
        "render",
        "--bake",
        &bake_dir.display().to_string(),
        "--paths",
        "blend",
        "--iterations",
        "3",
    ]))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn figure_light_specs_read_back_as_the_figure_lights() {
        for f in &faces::FIGURES {
            for l in f.lights {
                let spec = light_spec(l);
                assert_eq!(
                    ortm::scene::light::parse_light(&spec),
                    Ok(ortm::scene::head::light(l)),
                    "{}: {spec}",
                    f.id
                );
            }
        }
    }
}
