//! `ortm solve SCENE [--effects radiosity,sss] -o DIR`: the global-illumination solve
//! `B = B_o + R·B_o` of a lightmap with the scene's lights (or `--light` ones, as `ortm render`
//! takes them) and the effects asked for (both by default; one alone splits an error against
//! `ortm reference --effects` by effect); writes the first-order, final and indirect lightmaps
//! as linear OpenEXR (W/m², the inputs of `ortm compare`) and as tone-mapped PNGs, and prints
//! energy figures.
//!
//! `--method dense` is the exact dense solve (up to [`MAX_DENSE_TEXELS`] covered texels: memory
//! n², time n³); `--method hierarchical` the hierarchical operator
//! ([`ortm::bake::transport::hier`], error tolerance `--tolerance`) at any size; `auto` (the
//! default) takes the dense solve where it fits. Progress bars for every phase; Ctrl-C stops
//! between steps and writes nothing.
//!
//! `--first-order-samples N` (odd, default [`DEFAULT_FIRST_ORDER_SAMPLES`]) feeds the transfer
//! the first-order light averaged over each texel's square from N×N sub-texels
//! ([`lighting::first_order_and_input`]); 1 takes its value at the texel's centre, where a
//! sender half in shadow sends all its light or none. The written first order stays the
//! centres' (what a reference's first order is); an opaque texel's final is its centre's first
//! order plus the transfer of the averaged light, a translucent texel's the scattered averaged
//! light — the rule `ortm render --first-order-samples N` follows with a bake's maps (README,
//! *The transfer's input*).
//!
//! `--supersample K` (odd) solves the scene at K× the lightmap's size and writes each texel's
//! centre sub-texel ([`at_centres`]): the same points, a finer discretisation (README,
//! *Resolution*).
//!
//! `--near-field N` (odd, 3–7) adds [`near_field::correction`] to the solve's source: the
//! first scattering of the direct light under the skin from each translucent texel's nearby
//! senders, resolved at N×N sub-texels (README, *The subsurface near field*), emitted beside the
//! texels' own first scattering so that its later bounces are solved as well. With
//! `--near-field-light input` only the sub-texels' weights are resolved, the light on them
//! being each sender's transfer input: the first scattering `ortm bake --near-field N` holds in
//! its maps ([`near_field::near_rows`]); with the sub-texels' own light (the default) a bake's
//! maps do not hold it.
//!
//! `--near-gather G` (2–64) adds [`near_gather::correction`]: the form factors to the texels
//! within `--near-gather-reach` texel sizes gathered by `G × G` rays from each texel's centre
//! (added to the operator: the dense `F`, or every hierarchical gather) and the first bounce
//! of the direct light from opaque surface at the rays' hit points (added beside the direct
//! light in the solve's input; the final is made from the original input). Off by default;
//! a bake's multi-resolution maps take its form factors in their first bounce (`ortm bake
//! --levels ε --tolerance --near-gather G`), not `ΔE` (lights move).

use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::{Arc, Mutex};
use std::time::Instant;

use anyhow::{Context, Result, bail};
use ortm::accuracy::compare::power_w;
use ortm::bake::BakeEvent;
use ortm::bake::lighting;
use ortm::bake::near_field::{self, NearField, NearFieldError, SubTexelLight};
use ortm::bake::near_gather::{self, GatherError, NearGather};
use ortm::bake::raycast::Visibility;
use ortm::bake::report::save_solution_pngs;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::hier::{BuildError, Operator, Settings};
use ortm::bake::transport::{Kernels, SetupProgress, check_balance, texel_patches};
use ortm::render::lightmap_exr::write_lightmap_exr;
use ortm::scene::light::{LIGHT_SYNTAX, parse_light};

use super::progress::Progress;

use ortm::bake::transport::dense::MAX_TEXELS as MAX_DENSE_TEXELS;

/// The largest `--first-order-samples` (the sub-texel grid holds N² times the lightmap's
/// texels).
const MAX_FIRST_ORDER_SAMPLES: u32 = 7;

/// `--first-order-samples` of `ortm solve` and `ortm render` (so `ortm demo`).
pub use ortm::bake::lighting::DEFAULT_FIRST_ORDER_SAMPLES;

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
    /// Solver: `auto` (dense up to the dense limit, else hierarchical), `dense` or
    /// `hierarchical`.
    #[arg(long, value_enum, default_value_t = Method::Auto)]
    method: Method,
    /// Error tolerance ε of the hierarchical solve (a form factor per link; smaller is more
    /// accurate and larger).
    #[arg(long, default_value_t = ortm::bake::transport::hier::DEFAULT_TOLERANCE)]
    tolerance: f32,
    /// Effects: comma-separated `radiosity`, `sss` (as `ortm bake`).
    #[arg(long, default_value = "radiosity,sss")]
    effects: String,
    /// The transfer's input: the first-order light averaged over each texel's square from
    /// N×N sub-texels (odd N, 1–7); 1 takes it at the texel centres. Default: 3 where its
    /// sub-texels fit (up to 682² lightmaps), else 1. The written first order is the
    /// centres' either way.
    #[arg(long, value_name = "N")]
    first_order_samples: Option<u32>,
    /// Solve at K× the lightmap's size (odd K, 1–7) and write each texel's value at its centre
    /// (the middle sub-texel of its K×K block): a deterministic answer nearer the continuous
    /// one where light or the subsurface profile changes within a texel, for K²× the texels.
    /// The transfer's input is then the sub-texels' own first order unless
    /// --first-order-samples is given.
    #[arg(long, default_value_t = 1, value_name = "K")]
    supersample: u32,
    /// Resolve the subsurface near field at N×N sub-texels (odd N, 3–7; 1 = off): each
    /// translucent texel's senders within --near-field-reach texels scatter the direct light
    /// as it falls across their footprint, lit at N× the lightmap's size, instead of its value
    /// at their centre
    /// (a source the solve transports; README, *The subsurface near field*). Nearer the
    /// path-traced reference where shadow edges cross skin; the bake's maps do not hold it.
    #[arg(long, default_value_t = 1, value_name = "N")]
    near_field: u32,
    /// With --near-field: the senders within R texels of each skin texel (in x and in y) are
    /// resolved at sub-texels, 0 to 8 [default: 2].
    #[arg(long, value_name = "R")]
    near_field_reach: Option<u32>,
    /// With --near-field: the light the senders' sub-texels scatter — `sub-texels`, each its
    /// own (the scene lit at N× the lightmap's size), or `input`, the sender's transfer input
    /// on all of them (its mean over the texel with the averaged input): only the weights are
    /// resolved, as `ortm bake --near-field` holds them in its maps.
    #[arg(long, value_enum, default_value_t = NearFieldLight::SubTexels)]
    near_field_light: NearFieldLight,
    /// Gather the interreflection's near field by G×G rays per texel (2–64; 0 = off): the form
    /// factors to the texels within --near-gather-reach texel sizes in 3D are taken from what
    /// the rays hit on the mesh itself, and the first bounce of the direct light from opaque
    /// surface there from its value at the hit points (README, *The interreflection's near
    /// field*). Nearer the path-traced reference in creases and slits; `ortm bake --levels
    /// --tolerance --near-gather G` takes its form factors into the maps' first bounce.
    #[arg(long, default_value_t = 0, value_name = "G")]
    near_gather: u32,
    /// With --near-gather: the radius of the near set in texel sizes (the receiver's √area),
    /// above 0, at most 64 [default: 16].
    #[arg(long, value_name = "R")]
    near_gather_reach: Option<f32>,
    /// Balance the subsurface weights in R rounds (0–1000; 0 = off): besides what each texel
    /// re-emits as a sender (the columns, capped at the continuous surface's value without
    /// it), what each texel gathers under a uniform irradiance (the rows) is held to the
    /// continuous surface's value, whose footprints of unequal size leave the capped rows a
    /// few percent off (README, *The subsurface weights' rows*). 50 rounds hold the rows
    /// within ~0.2 %. Keeps every skin pair's raw weight (16 bytes each, ~390 MB for the head
    /// at 256², checked against the memory limit first). Not with --near-field; `ortm bake
    /// --balance-subsurface` bakes it into the maps.
    #[arg(long, default_value_t = 0, value_name = "R")]
    balance_subsurface: u32,
}

/// `--near-field-light`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum NearFieldLight {
    SubTexels,
    Input,
}

/// `--method`.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
enum Method {
    Auto,
    Dense,
    Hierarchical,
}

/// `--first-order-samples` as asked (checked), or the default for a `width × height`
/// lightmap within `budget` sub-texels and `max_side` (saying so when it falls back to the
/// centres).
pub fn first_order_samples(
    asked: Option<u32>,
    (width, height): (u32, u32),
    budget: u64,
    max_side: u32,
) -> Result<u32> {
    if let Some(n) = asked {
        check_first_order_samples(n)?;
        return Ok(n);
    }
    let n = ortm::bake::lighting::default_first_order_samples(width, height, budget, max_side);
    if n != DEFAULT_FIRST_ORDER_SAMPLES {
        let d = DEFAULT_FIRST_ORDER_SAMPLES;
        eprintln!(
            "note: the transfer's input is the first order at the texel centres: averaging it \
             over {d}×{d} sub-texels of this {width}×{height} lightmap would take {} sub-texels \
             (more than the default's {budget}); give --first-order-samples {d} to average \
             anyway",
            (d as u64).pow(2) * width as u64 * height as u64
        );
    }
    Ok(n)
}

/// Refuses a `--first-order-samples` that is even or out of range, with the rule.
pub fn check_first_order_samples(n: u32) -> Result<()> {
    if n.is_multiple_of(2) || n > MAX_FIRST_ORDER_SAMPLES {
        bail!(
            "--first-order-samples {n}: must be odd, 1 to {MAX_FIRST_ORDER_SAMPLES} (N×N \
             sub-texels per texel, one at its centre); 3 is enough"
        );
    }
    Ok(())
}

/// Per texel of `coarse`, the value of `fine` (the same scene at `k×` the size, `k` odd) at its
/// centre sub-texel — the same point, since `k` is odd; where that sub-texel is not covered
/// (a centre exactly on a UV edge, decided the other way by rounding) the mean of its
/// block's covered sub-texels.
fn at_centres(
    coarse: &TexelGrid,
    fine: &TexelGrid,
    k: u32,
    values: &[glam::Vec3],
) -> Vec<glam::Vec3> {
    coarse
        .texels
        .iter()
        .map(|t| {
            let (x0, y0) = ((t.x * k) as i32, (t.y * k) as i32);
            let c = (k / 2) as i32;
            if let Some(j) = fine.at(x0 + c, y0 + c) {
                return values[j as usize];
            }
            let block: Vec<glam::Vec3> = (0..k as i32)
                .flat_map(|dy| (0..k as i32).map(move |dx| (dx, dy)))
                .filter_map(|(dx, dy)| fine.at(x0 + dx, y0 + dy))
                .map(|j| values[j as usize])
                .collect();
            block.iter().copied().sum::<glam::Vec3>() / block.len().max(1) as f32
        })
        .collect()
}

/// Runs `ortm solve`.
pub fn run(a: Args) -> Result<()> {
    let effects = super::bake::parse_effects(&a.effects)?;
    let k = a.supersample;
    if k.is_multiple_of(2) || k > MAX_FIRST_ORDER_SAMPLES {
        bail!(
            "--supersample {k}: must be odd, 1 to {MAX_FIRST_ORDER_SAMPLES} (each texel's \
             centre is then a sub-texel's centre)"
        );
    }
    let mut scene = super::load_scene(&a.scene, a.size)?;
    if !a.lights.is_empty() {
        scene.lights = a
            .lights
            .iter()
            .map(|l| parse_light(l))
            .collect::<Result<_, _>>()?;
    }
    let out_grid = TexelGrid::build(&scene)
        .with_context(|| format!("rasterizing the lightmap UVs of '{}'", a.scene))?;
    // The grid solved: the lightmap's, or K× finer.
    let grid = if k == 1 {
        out_grid.clone()
    } else {
        TexelGrid::build_with_size(&scene, out_grid.width * k, out_grid.height * k).with_context(
            || {
                format!(
                    "rasterizing the lightmap UVs of '{}' at --supersample {k}",
                    a.scene
                )
            },
        )?
    };
    let samples = if k > 1 {
        a.first_order_samples
            .map_or(Ok(1), |n| check_first_order_samples(n).map(|_| n))?
    } else {
        first_order_samples(
            a.first_order_samples,
            (grid.width, grid.height),
            lighting::DEFAULT_SAMPLES_CPU_BUDGET,
            u32::MAX,
        )?
    };
    if let (1, Some(r)) = (a.near_field, a.near_field_reach) {
        bail!("--near-field-reach {r}: applies to --near-field N (odd, 3–7), which is off");
    }
    if a.near_field == 1 && a.near_field_light != NearFieldLight::SubTexels {
        bail!("--near-field-light input: applies to --near-field N (odd, 3–7), which is off");
    }
    let light = match a.near_field_light {
        NearFieldLight::SubTexels => SubTexelLight::SubTexels,
        NearFieldLight::Input => SubTexelLight::Input,
    };
    let near = (a.near_field != 1)
        .then(|| NearField::from_flags(a.near_field, a.near_field_reach, light))
        .transpose()
        .map_err(anyhow::Error::msg)?;
    if a.balance_subsurface > 0 && near.is_some_and(|n| n.light == SubTexelLight::SubTexels) {
        bail!(
            "--balance-subsurface {} with --near-field {}: not combined with the sub-texels' \
             own light (the near field's sub-texels are not balanced, and the two together \
             measured further from the path-traced reference than either alone; README, *The \
             subsurface weights' rows*); drop one, or give --near-field-light input",
            a.balance_subsurface,
            a.near_field
        );
    }
    if let (0, Some(r)) = (a.near_gather, a.near_gather_reach) {
        bail!(
            "--near-gather-reach {r}: applies to --near-gather G (2–64 rays per side), which is off"
        );
    }
    let gather = (a.near_gather != 0)
        .then(|| {
            let g = NearGather {
                reach: a.near_gather_reach.unwrap_or(near_gather::DEFAULT_REACH),
                ..NearGather::new(a.near_gather)
            };
            g.check().map(|_| g).map_err(|e| match a.near_gather_reach {
                Some(r) if NearGather::new(a.near_gather).check().is_ok() => {
                    anyhow::anyhow!("--near-gather-reach {r}: {e}")
                }
                _ => anyhow::anyhow!("--near-gather {}: {e}; 0 turns it off", a.near_gather),
            })
        })
        .transpose()?;
    let dense = match a.method {
        Method::Dense => true,
        Method::Hierarchical => false,
        Method::Auto => grid.texels.len() <= MAX_DENSE_TEXELS,
    };
    if dense && grid.texels.len() > MAX_DENSE_TEXELS {
        bail!(
            "{} covered texels: the exact dense solve is limited to {MAX_DENSE_TEXELS} \
             (memory and time grow as n² and n³); use a smaller --size or --method hierarchical",
            grid.texels.len()
        );
    }
    if !(a.tolerance.is_finite() && a.tolerance > 0.0) {
        bail!(
            "--tolerance {}: give a positive number (e.g. 1e-4)",
            a.tolerance
        );
    }
    if let Some(near) = near {
        near.check_memory(&grid, ortm::io::limits::memory_limit_bytes()?, (2, "half"))
            .map_err(anyhow::Error::msg)?;
    }
    check_balance(
        &scene,
        &grid,
        effects,
        a.balance_subsurface,
        ortm::io::limits::memory_limit_bytes()?,
    )
    .map_err(|e| anyhow::anyhow!("--balance-subsurface {}: {e}", a.balance_subsurface))?;
    super::ensure_dir(&a.output)?;
    let cancel = Arc::new(AtomicBool::new(false));
    {
        let c = cancel.clone();
        // A second Ctrl-C exits at once; the first stops between steps and writes nothing.
        let _ = ctrlc::set_handler(move || {
            if c.swap(true, Ordering::SeqCst) {
                std::process::exit(130);
            }
            eprintln!("\ninterrupt: stopping the solve (nothing is written)");
        });
    }
    let t0 = Instant::now();
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let mut kernels = Kernels::new(&scene, effects, vis.clone());
    kernels.balance_rounds = a.balance_subsurface;
    let patches = texel_patches(&grid);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    // The final starts from `first` (the centres' first order on opaque texels, the input on
    // translucent ones, whose transfer holds `−B_in` at the texel itself).
    let (first, b_in) =
        lighting::first_order_and_input(&scene, &grid, &scene.lights, &vis, samples, |m| {
            kernels.is_translucent(m)
        })?;
    let bar = Mutex::new(Progress::hidden());
    let events = |e: BakeEvent| match e {
        BakeEvent::Phase { name, total } => {
            let mut b = bar.lock().expect("progress lock");
            b.finish();
            *b = Progress::new(total, name);
        }
        BakeEvent::Advance(n) => bar.lock().expect("progress lock").inc(n),
        BakeEvent::Message(m) => bar.lock().expect("progress lock").println(m),
    };
    let progress = SetupProgress::new(&events, &cancel);
    let interrupted = || anyhow::anyhow!("interrupted: nothing was written");
    // Skin's near field: a radiosity source beside the first scattering, so the solve carries
    // its bounces too (across a crease, light scattered under one side lights the other).
    let delta = match near {
        None => None,
        Some(near) => {
            let t_near = Instant::now();
            let delta = near_field::correction(
                &scene,
                &grid,
                &kernels,
                &scene.lights,
                &vis,
                &b_in,
                near,
                &progress,
            )
            .map_err(|e| match e {
                NearFieldError::Cancelled => interrupted(),
                NearFieldError::Texels(e) => anyhow::Error::new(e).context(format!(
                    "rasterizing the lightmap UVs of '{}' for --near-field {}",
                    a.scene, near.subdivision
                )),
            })?;
            bar.lock().expect("progress lock").finish_and_clear();
            eprintln!(
                "near field: {}×{} sub-texels per texel, senders within {} texels, in {:.2} s",
                near.subdivision,
                near.subdivision,
                near.reach,
                t_near.elapsed().as_secs_f64()
            );
            Some(delta)
        }
    };
    // The interreflection's near field: gathered form factors (an operator correction) and the
    // first bounce at the hit points (an irradiance beside the direct light, in the input).
    let gathered = match gather {
        None => None,
        Some(g) => {
            // Its rows may take a quarter of the memory limit (the links take half).
            let g = NearGather {
                max_bytes: ortm::io::limits::memory_limit_bytes()?.map(|l| l / 4),
                ..g
            };
            let t_gather = Instant::now();
            let c = near_gather::correction(
                &scene,
                &grid,
                &patches,
                &kernels,
                &scene.lights,
                &vis,
                &b_in,
                g,
                &progress,
            )
            .map_err(|e| match e {
                GatherError::Cancelled => interrupted(),
                e @ GatherError::TooLarge { .. } => anyhow::anyhow!(
                    "--near-gather {}: {e} (a quarter of the memory limit: physical memory or \
                     ORTM_MEMORY_LIMIT_BYTES); give a smaller --near-gather-reach, --size or \
                     --supersample",
                    g.rays_per_side
                ),
            })?;
            bar.lock().expect("progress lock").finish_and_clear();
            eprintln!(
                "near gather: {}×{} rays per texel, near set within {} texel sizes, {} form-factor \
                 corrections, in {:.2} s",
                g.rays_per_side,
                g.rays_per_side,
                g.reach,
                c.entries(),
                t_gather.elapsed().as_secs_f64()
            );
            Some(c)
        }
    };
    let solve_input = match &gathered {
        Some(c) => c.input(&b_in, &patches),
        None => b_in.clone(),
    };
    let (b, t_assemble, how) = if dense {
        let mut dense =
            DenseTransport::build(&patches, &kernels, &progress).map_err(|_| interrupted())?;
        if let Some(c) = &gathered {
            c.add_to(&mut dense.form_factors);
        }
        let t_assemble = t0.elapsed();
        (
            dense
                .factor()
                .solve_with_source(&solve_input, delta.as_deref()),
            t_assemble,
            "exact dense solve".to_string(),
        )
    } else {
        // The links may take at most half the memory limit (the rest: texels, BVH, solve).
        let limit = ortm::io::limits::memory_limit_bytes()?;
        let settings = Settings {
            tolerance: a.tolerance,
            max_bytes: limit.map(|l| l / 2),
            ..Settings::default()
        };
        let op = match Operator::build(&patches, &kernels, &settings, &progress) {
            Ok(op) => op,
            Err(BuildError::Cancelled) => return Err(interrupted()),
            Err(e @ BuildError::TooLarge { .. }) => {
                bar.lock().expect("progress lock").finish_and_clear();
                bail!(
                    "{e} (--tolerance {:e}; the limit is half of the memory limit: physical \
                     memory or ORTM_MEMORY_LIMIT_BYTES)",
                    a.tolerance
                )
            }
        };
        let t_assemble = t0.elapsed();
        let correct = gathered
            .as_ref()
            .map(|c| move |b: &[glam::Vec3], e: &mut [glam::Vec3]| c.gather(b, e));
        let sol = op
            .solve_corrected(
                &solve_input,
                delta.as_deref(),
                correct
                    .as_ref()
                    .map(|f| f as &(dyn Fn(&[glam::Vec3], &mut [glam::Vec3]) + Sync)),
                &settings,
                &progress,
            )
            .map_err(|_| interrupted())?;
        let how = format!(
            "hierarchical solve, ε = {:e}: {} links ({:.1} MB), {} sweeps (last change {:.1e})",
            a.tolerance,
            op.link_count(),
            op.memory_bytes() as f64 / 1e6,
            sol.iterations,
            sol.change
        );
        (sol.b, t_assemble, how)
    };
    bar.lock().expect("progress lock").finish_and_clear();
    let t_total = t0.elapsed();
    let mut b = b;
    lighting::with_first_order(&mut b, &first, &b_in);
    // Supersampled: each texel takes its centre sub-texel's values.
    let (b, b_o) = if k > 1 {
        (
            at_centres(&out_grid, &grid, k, &b),
            at_centres(&out_grid, &grid, k, &b_o),
        )
    } else {
        (b, b_o)
    };
    let solved = grid.texels.len();
    let grid = out_grid;
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
    let at = if k > 1 {
        format!(" (solved at {k}× the size: {solved} texels, each texel its centre's value)")
    } else {
        String::new()
    };
    println!(
        "{how}: {} texels at {}x{}{at}: assembled in {:.2} s, solved in {:.2} s",
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
