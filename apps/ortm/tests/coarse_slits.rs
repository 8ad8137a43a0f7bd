//! The coarse level's slit texels (`ortm::bake::transport::coarse::slit_texels`): with the
//! hierarchical operator (`ortm bake --tolerance ε`) the higher-order remainder is solved over
//! tiles of the lightmap, and where a tile folds — the two sides of the lips, the eyelids, the
//! folds of an ear — a tile's centroid and mean normal lose the light the two sides trade, and
//! the remainder spreads what is left over the whole tile. The texels that see the surface
//! beside them are clusters of their own, and near tile pairs take their members' form factor.
//!
//! On the head at 64² with 4×4-texel tiles (so the remainder is coarse, as it is at every
//! lightmap above 4,096 covered texels), the bake's rows (the links' first bounce, the
//! subsurface walk and the remainder) against the exact dense solve of the same texels.

use glam::Vec3;
use ortm::accuracy::compare::{interior_mask, relative_rmse};
use ortm::bake::lighting;
use ortm::bake::multires::hierarchical_row;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::coarse::Remainder;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, SetupProgress, Transport, hier, texel_patches};
use rayon::prelude::*;

/// The indirect light `Σ_j R(i, j) B_o(j)` of every texel from the bake's rows.
fn rows_indirect(tr: &Transport, b_o: &[Vec3]) -> Vec<Vec3> {
    let row = hierarchical_row(tr).expect("hierarchical transport");
    (0..b_o.len() as u32)
        .into_par_iter()
        .map(|i| {
            let mut out = vec![[0.0f32; 3]; b_o.len()];
            row(i, &mut out);
            (out.iter().zip(b_o)).fold(Vec3::ZERO, |acc, (r, b)| acc + Vec3::from(*r) * *b)
        })
        .collect()
}

/// Measured (head 64², its lamp, radiosity + subsurface, ε = 10⁻⁴, 4×4 tiles; 1,501 clusters
/// of which 1,275 slit texels, coupling above `SLIT_COUPLING` = 0.005): indirect relative RMSE
/// against the exact solve 0.0232 with the slit texels and the near tiles' member form factors,
/// 0.2530 without either (rendered maps of `ortm bake head --size 64 --levels 0 --tolerance
/// 1e-4 --coarse-block 4` against `ortm solve head --size 64 --method dense
/// --first-order-samples 1`: 0.0232). With the coupling threshold at 0.05: 426 slit texels,
/// 0.0503. Bounds: measured + 25 %, and the slit texels must take at least half of the error
/// away.
#[test]
fn slit_texels_keep_the_higher_bounces_of_lips_and_eyelids() {
    let mut scene = ortm::scene::head::head_scene().expect("head scene (../shared/faces/head.obj)");
    scene.lightmap_size = (64, 64);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let b_o = lighting::first_order(&grid, &scene.lights, &vis);
    let settings = hier::Settings {
        tolerance: 1e-4,
        ..hier::Settings::default()
    };
    let none = SetupProgress::none();
    let mut tr =
        Transport::build_hierarchical(&scene, &grid, Effects::default(), 4, &settings, &none)
            .unwrap();
    let alone = tr.remainder.alone;
    let clusters = tr.remainder.clusters.len();
    assert!(alone > 0, "no slit texels on the head");
    let dense = DenseTransport::new(&texel_patches(&grid), &tr.kernels);
    let exact = dense.solve(&b_o);
    let exact_ind: Vec<Vec3> = exact.iter().zip(&b_o).map(|(b, o)| *b - *o).collect();
    let mask = interior_mask(&grid);
    let with = relative_rmse(&rows_indirect(&tr, &b_o), &exact_ind, Some(&mask));
    // The same operator with the remainder over the tiles alone.
    tr.remainder = Remainder::build(&grid, &tr.patches, &tr.kernels, 4, false, &none).unwrap();
    let without = relative_rmse(&rows_indirect(&tr, &b_o), &exact_ind, Some(&mask));
    eprintln!(
        "head 64², 4×4 tiles: {clusters} clusters of which {alone} slit texels; indirect \
         relative RMSE against the exact solve {with:.4} (tiles alone: {without:.4})"
    );
    assert!(with < 0.029, "with the slit texels: {with:.4}");
    assert!(
        with < 0.5 * without,
        "{with:.4} against {without:.4} without"
    );
}
