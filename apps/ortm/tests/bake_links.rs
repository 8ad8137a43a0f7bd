//! The bake's cell integration with the hierarchical first bounce (`ortm bake --tolerance ε`,
//! `ortm::bake::cells`, "With the hierarchical operator") against the exact dense solve.
//!
//! With every integer offset selected each cell is one offset, so the maps hold `R(t, t + Δt)`
//! itself; with single-texel clusters the higher-order remainder is exact, so what is left is
//! the first bounce from the links. Its error must fall as `ε` falls, towards the exact solve.

use glam::{IVec2, Vec3};
use ortm::accuracy::compare::{interior_mask, relative_rmse};
use ortm::bake::eval::random_light_setups;
use ortm::bake::lighting;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, SetupProgress, Transport, hier, texel_patches};
use ortm::bake::{self, CellRule};
use ortm::maps;
use ortm::scene::{Light, Scene};

/// Every integer offset that can pair two texels.
fn all_offsets(w: u32, h: u32) -> Vec<IVec2> {
    let mut v = vec![IVec2::ZERO];
    for dy in -(h as i32 - 1)..=(h as i32 - 1) {
        for dx in -(w as i32 - 1)..=(w as i32 - 1) {
            if dx != 0 || dy != 0 {
                v.push(IVec2::new(dx, dy));
            }
        }
    }
    v
}

/// Relative RMSE (interior texels) of the indirect term of all-offset maps baked with the
/// hierarchical first bounce at each of `tolerances`, against the exact solve for `lights`.
fn all_offset_errors(scene: &Scene, lights: &[Light], tolerances: &[f32]) -> Vec<f64> {
    let grid = TexelGrid::build(scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, lights, &vis);
    let offsets = all_offsets(grid.width, grid.height);
    let mask = interior_mask(&grid);
    let mut exact_ind = None;
    tolerances
        .iter()
        .map(|&tolerance| {
            let settings = hier::Settings {
                tolerance,
                ..hier::Settings::default()
            };
            let tr = Transport::build_hierarchical(
                scene,
                &grid,
                Effects::default(),
                1,
                &settings,
                &SetupProgress::none(),
            )
            .unwrap();
            let exact_ind: &Vec<Vec3> = exact_ind.get_or_insert_with(|| {
                let dense = DenseTransport::new(&texel_patches(&grid), &tr.kernels);
                let exact = dense.solve(&b_o);
                exact.iter().zip(&b_o).map(|(b, o)| *b - *o).collect()
            });
            let maps =
                bake::bake_maps(&tr, &grid, &offsets, CellRule::Integrated, &|_| {}).unwrap();
            let out = maps::apply(&maps, &lighting::to_lightmap(&grid, &b_o)).unwrap();
            let got = lighting::from_lightmap(&grid, &out);
            let ind: Vec<Vec3> = got.iter().zip(&b_o).map(|(b, o)| *b - *o).collect();
            let err = relative_rmse(&ind, exact_ind, Some(&mask));
            eprintln!(
                "{} {}² ({} texels), all offsets, links at ε = {tolerance:e} ({} links): indirect \
                 relative RMSE {err:.4}",
                scene.name,
                grid.width,
                grid.texels.len(),
                tr.links.as_ref().unwrap().link_count()
            );
            err
        })
        .collect()
}

fn check_falls(name: &str, e: &[f64], bound: f64) {
    for w in e.windows(2) {
        assert!(w[1] < w[0], "{name}: {e:?} does not fall with ε");
    }
    let last = *e.last().unwrap();
    assert!(last < bound, "{name}: {last} ≥ {bound}");
}

const TOLERANCES: [f32; 3] = [1e-2, 1e-3, 1e-4];

/// Cornell 32², the box's light. Measured: 0.0729 (15.5 k links), 0.0142 (49.6 k), 0.00090
/// (77.9 k). Bound: measured + 33 %.
#[test]
fn cornell_all_offsets_converge_to_the_exact_solve_as_the_tolerance_falls() {
    let scene = ortm::scene::cornell::cornell_box(32);
    let lights = scene.lights.clone();
    let e = all_offset_errors(&scene, &lights, &TOLERANCES);
    check_falls("cornell 32²", &e, 0.0012);
}

/// The head at 48², radiosity and subsurface, a random light. Measured: 0.0557 (21.4 k links),
/// 0.0225 (43.2 k), 0.0070 (127 k). Bound: measured + 25 %.
#[test]
fn head_all_offsets_converge_to_the_exact_solve_as_the_tolerance_falls() {
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (48, 48);
    let lights = random_light_setups(&scene, 1, 7).remove(0);
    let e = all_offset_errors(&scene, &lights, &TOLERANCES);
    check_falls("head 48²", &e, 0.0088);
}
