//! `ortm bench transport|bake`: the bake's speed figures, printed as tables.
//!
//! - `transport`: visibility rays per second on the head, the exact dense solve at 64²,
//!   and `K` / `R` pair-evaluation throughput (the budget of the bake);
//! - `bake`: the paper's Table 1 configurations on the head (map-generation time per row beside
//!   the paper's), with the atlases and pieces per map of each bake binned at 1024².

use std::sync::Arc;
use std::time::Instant;

use anyhow::Result;
use glam::Vec3;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, Transport, texel_patches};
use ortm::bake::{self, BakeSettings};
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

/// Arguments of `ortm bench`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// What to measure: `transport` or `bake`.
    what: String,
    /// Only the first N rows of the `bake` table (they grow in cost).
    #[arg(long)]
    rows: Option<usize>,
}

/// Runs `ortm bench`.
pub fn run(a: Args) -> Result<()> {
    println!("threads: {}", rayon::current_num_threads());
    match a.what.as_str() {
        "transport" => transport(),
        "bake" => bake_table(a.rows.unwrap_or(usize::MAX)),
        o => anyhow::bail!("unknown benchmark '{o}': use transport or bake"),
    }
}

/// `ortm bench transport`: one table of shadow-ray, exact-solve, evaluator-accuracy and
/// pair-evaluation figures (one random stream, seed 1, for the random pairs).
fn transport() -> Result<()> {
    let mut scene = super::head_scene()?;
    scene.lightmap_size = (256, 256);
    let grid = TexelGrid::build(&scene)?;
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(1);
    println!("| measurement | value |");
    println!("|---|---|");
    shadow_ray_rate(&scene, &grid, &mut rng);
    exact_solve_times()?;
    evaluator_accuracy()?;
    pair_evaluation_rates(&scene, &grid, &mut rng);
    Ok(())
}

/// Shadow rays per second between 2 M random pairs of covered texels of the head.
fn shadow_ray_rate(scene: &ortm::scene::Scene, grid: &TexelGrid, rng: &mut ChaCha8Rng) {
    let vis = Visibility::new(&scene.mesh);
    let n = grid.texels.len();
    let pairs: Vec<(Vec3, Vec3)> = (0..2_000_000)
        .map(|_| {
            let a = &grid.texels[rng.random_range(0..n)];
            let b = &grid.texels[rng.random_range(0..n)];
            (
                a.position_m + a.face_normal * 1e-5,
                b.position_m + b.face_normal * 1e-5,
            )
        })
        .collect();
    let t = Instant::now();
    let visible = pairs
        .par_iter()
        .filter(|(p, q)| vis.visible(*p, *q, 1e-5))
        .count();
    let ray_s = pairs.len() as f64 / t.elapsed().as_secs_f64();
    println!(
        "| shadow rays/s, head ({} triangles), random texel pairs ({:.0}% unoccluded) | {:.2} M |",
        scene.mesh.triangles.len(),
        100.0 * visible as f64 / pairs.len() as f64,
        ray_s / 1e6
    );
}

/// Assembly and LU-solve times of the exact dense solve at 64² (Cornell box, head).
fn exact_solve_times() -> Result<()> {
    for (name, mut s) in [
        ("cornell", ortm::scene::cornell::cornell_box(64)),
        ("head", super::head_scene()?),
    ] {
        s.lightmap_size = (64, 64);
        let g = TexelGrid::build(&s)?;
        let t = Instant::now();
        let k = Kernels::new(&s, Effects::default(), Arc::new(Visibility::new(&s.mesh)));
        let dense = DenseTransport::new(&texel_patches(&g), &k);
        let t_asm = t.elapsed().as_secs_f64();
        let b_o = vec![Vec3::ONE; dense.n];
        let _ = dense.solve(&b_o);
        println!(
            "| exact solve 64², {name} ({} texels): assembly / LU solve | {:.2} s / {:.2} s |",
            dense.n,
            t_asm,
            t.elapsed().as_secs_f64() - t_asm
        );
    }
    Ok(())
}

/// Accuracy of the pair evaluator (exact first bounce + coarse remainder) against the exact
/// dense solve: head at 64², one random light set-up, all pairs.
fn evaluator_accuracy() -> Result<()> {
    let mut s = super::head_scene()?;
    s.lightmap_size = (64, 64);
    let g = TexelGrid::build(&s)?;
    let lights = ortm::bake::eval::random_light_setups(&s, 1, 11).remove(0);
    let b_o = ortm::bake::lighting::first_order(&g, &lights, &vis_of(&s));
    for (label, eff) in [
        (
            "radiosity",
            Effects {
                radiosity: true,
                subsurface: false,
            },
        ),
        (
            "subsurface",
            Effects {
                radiosity: false,
                subsurface: true,
            },
        ),
        ("both", Effects::default()),
    ] {
        let tr = Transport::new(&s, &g, eff, 4);
        let dense = DenseTransport::new(&texel_patches(&g), &tr.kernels);
        let exact = dense.solve(&b_o);
        println!(
            "| R(t,t') evaluator vs exact solve, head 64², 4×4 clusters, {label}: relative RMSE of the indirect term | {:.1}% |",
            100.0 * ortm::bake::eval::evaluator_error(&tr, &b_o, &exact)
        );
    }
    Ok(())
}

/// Transport set-up time at 256², then `K` and `R` evaluations per second over 2 M random
/// texel pairs.
fn pair_evaluation_rates(scene: &ortm::scene::Scene, grid: &TexelGrid, rng: &mut ChaCha8Rng) {
    let n = grid.texels.len();
    let t = Instant::now();
    let tr = Transport::new(scene, grid, Effects::default(), 8);
    println!(
        "| transport set-up 256² head (BVH + coarse solve, {} clusters) | {:.2} s |",
        tr.remainder.clusters.len(),
        t.elapsed().as_secs_f64()
    );
    let idx: Vec<(u32, u32)> = (0..2_000_000)
        .map(|_| (rng.random_range(0..n) as u32, rng.random_range(0..n) as u32))
        .collect();
    let t = Instant::now();
    let s: f64 = idx
        .par_iter()
        .map(|&(i, j)| {
            tr.kernels
                .r_fine(&tr.patches[i as usize], &tr.patches[j as usize], i == j)[0]
        })
        .sum();
    println!(
        "| K (first bounce + subsurface) pair evaluations/s, random pairs | {:.2} M |",
        idx.len() as f64 / t.elapsed().as_secs_f64() / 1e6
    );
    let t = Instant::now();
    let s2: f32 = idx.par_iter().map(|&(i, j)| tr.r(i, j)[0]).sum();
    println!(
        "| R (all bounces) pair evaluations/s, random pairs | {:.2} M |",
        idx.len() as f64 / t.elapsed().as_secs_f64() / 1e6
    );
    std::hint::black_box((s, s2));
}

fn vis_of(s: &ortm::scene::Scene) -> Visibility {
    Visibility::new(&s.mesh)
}

/// Map-generation seconds of the paper's Table 1, row by row beside
/// [`super::bench_render::TABLE_1`] (Pentium 4 2.53 GHz).
pub const PAPER_MAPGEN_S: [f64; 8] = [22.0, 28.0, 42.0, 57.0, 36.0, 107.0, 197.0, 226.0];

/// `ortm bench bake`: the first `rows` configurations of the paper's Table 1 baked on the head.
fn bake_table(rows: usize) -> Result<()> {
    println!(
        "| lightmap | offsets | ortm map generation (s) | of which transport / selection / maps | paper (s) | stored texels/map | atlases 1024² (paper) | pieces/map mean (max) |"
    );
    println!("|---|---|---|---|---|---|---|---|");
    let table = super::bench_render::TABLE_1.iter().zip(PAPER_MAPGEN_S);
    for (&(size, k, bins, _fps), paper_s) in table.take(rows) {
        let mut scene = super::head_scene()?;
        scene.lightmap_size = (size, size);
        let dir = tempfile_dir(size, k)?;
        let settings = BakeSettings {
            size: (size, size),
            offsets: k,
            ..BakeSettings::default()
        };
        let t = Instant::now();
        let cancel = std::sync::atomic::AtomicBool::new(false);
        let s = bake::bake(&scene, &settings, &dir, &|_| {}, &cancel)?;
        let total = t.elapsed().as_secs_f64();
        let maps = ortm::bake_dir::BakeIndex::read(&dir)?.load_maps(&dir)?;
        let (set, _) = ortm::atlas::build_atlas_set_with_stats(&maps, 1024, 1024)?;
        let st = set.stats();
        let _ = std::fs::remove_dir_all(&dir);
        println!(
            "| {size}² | {k} | {total:.1} | {:.1} / {:.1} / {:.1} | {paper_s:.0} | {:.0} | {} ({bins}) | {:.2} ({}) |",
            s.seconds[0],
            s.seconds[1],
            s.seconds[2],
            s.stored_texels as f64 / k as f64,
            st.atlases,
            st.mean_pieces_per_map,
            st.max_pieces_per_map
        );
    }
    Ok(())
}

fn tempfile_dir(size: u32, k: usize) -> Result<std::path::PathBuf> {
    let d = std::env::temp_dir().join(format!("ortm-bench-{}-{size}-{k}", std::process::id()));
    std::fs::create_dir_all(&d)?;
    Ok(d)
}
