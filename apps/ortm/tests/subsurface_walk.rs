//! The subsurface walk (`ortm::bake::transport::hier::subsurface`) on the head against its own
//! exact sum (every texel of the support, ε = 0): how far its node values take the subsurface
//! term, and how many nodes a receiver visits, with the second-order node means and with the
//! centroid values of the first-order rule. A measurement at sizes the dense solve cannot
//! reach; ignored (minutes).
//!
//! `cargo test --release --test subsurface_walk -- --ignored --nocapture` (`ORTM_WALK_SIZE`,
//! default 512; `ORTM_WALK_TOLERANCES`, default `1e-4,3e-4,1e-3`).

use std::sync::Arc;
use std::time::Instant;

use glam::Vec3;
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::hier::subsurface::SubsurfaceWalk;
use ortm::bake::transport::hier::tree::Tree;
use ortm::bake::transport::{Effects, Kernels, Patch, SetupProgress, texel_patches};

/// Per sampled receiver: the subsurface term `Σ_s R·Σ_{j∈s} w_j B_j − B_i` under the head's
/// lamps (first-order light `b_o`), and the nodes visited in all.
fn term(
    tree: &Tree,
    patches: &[Patch],
    kernels: &Kernels,
    walk: &SubsurfaceWalk,
    receivers: &[usize],
    b_o: &[Vec3],
) -> (Vec<[f64; 3]>, usize) {
    let mut visits = 0usize;
    let out = receivers
        .iter()
        .map(|&i| {
            let mut t = [0.0f64; 3];
            walk.walk(tree, patches, kernels, i, |s, rd, me| {
                visits += 1;
                for &j in tree.members(s) {
                    let w = walk.weight(tree.leaf_of[j as usize]);
                    for c in 0..3 {
                        t[c] += rd[c] * w[c] as f64 * b_o[j as usize][c] as f64;
                    }
                }
                if me {
                    for c in 0..3 {
                        t[c] -= b_o[i][c] as f64;
                    }
                }
            });
            t
        })
        .collect();
    (out, visits)
}

fn rms(v: &[[f64; 3]]) -> f64 {
    (v.iter().flatten().map(|x| x * x).sum::<f64>() / (3 * v.len()) as f64).sqrt()
}

#[test]
#[ignore = "minutes: the head at 512², every pair of the support summed"]
fn walk_against_its_exact_sum_on_the_head() {
    let size: u32 = std::env::var("ORTM_WALK_SIZE")
        .ok()
        .and_then(|s| s.parse().ok())
        .unwrap_or(512);
    let tolerances: Vec<f32> = std::env::var("ORTM_WALK_TOLERANCES")
        .unwrap_or_else(|_| "1e-4,3e-4,1e-3".into())
        .split(',')
        .map(|s| s.trim().parse().expect("ORTM_WALK_TOLERANCES: numbers"))
        .collect();
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (size, size);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Arc::new(Visibility::new(&scene.mesh));
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    let kernels = Kernels::new(&scene, Effects::default(), vis);
    let patches = texel_patches(&grid);
    let tree = Tree::build(&patches);
    let step = (patches.len() / 3000).max(1);
    let receivers: Vec<usize> = (0..patches.len())
        .step_by(step)
        .filter(|&i| kernels.is_translucent(patches[i].material))
        .collect();
    // Each walk normalises the senders itself, as the bake does.
    let run = |tolerance: f32, centroid: bool| {
        let mut p = patches.clone();
        let t0 = Instant::now();
        let mut walk = SubsurfaceWalk::new(&tree, &p, tolerance);
        if centroid {
            walk = walk.with_centroid_values();
        }
        walk.normalise(&tree, &mut p, &kernels, &SetupProgress::none())
            .unwrap();
        let t_norm = t0.elapsed().as_secs_f64();
        let (t, visits) = term(&tree, &p, &kernels, &walk, &receivers, &b_o);
        (t, visits as f64 / receivers.len() as f64, t_norm)
    };
    let (exact, visits, t) = run(0.0, false);
    println!(
        "head {size}², {} receivers: exact sum {visits:.0} texels per receiver (normalised in \
         {t:.1} s); the term's RMS {:.4e}",
        receivers.len(),
        rms(&exact)
    );
    let mut rows = Vec::new();
    for &tolerance in &tolerances {
        for centroid in [false, true] {
            let (t, visits, t_norm) = run(tolerance, centroid);
            let diff: Vec<[f64; 3]> = (t.iter().zip(&exact))
                .map(|(a, b)| [0, 1, 2].map(|c| a[c] - b[c]))
                .collect();
            let err = rms(&diff) / rms(&exact);
            println!(
                "ε {tolerance:e}, {}: {visits:.0} nodes per receiver, error {:.3} % of the \
                 term's RMS (normalised in {t_norm:.1} s)",
                if centroid {
                    "centroid values (first order)"
                } else {
                    "second-order means"
                },
                100.0 * err
            );
            rows.push((tolerance, centroid, visits, err));
        }
    }
    // At every tolerance the second-order means visit fewer nodes and err less.
    for pair in rows.chunks(2) {
        let (second, first) = (pair[0], pair[1]);
        assert!(second.2 < first.2, "{second:?} vs {first:?}: visits");
        assert!(second.3 < first.3, "{second:?} vs {first:?}: error");
    }
}
