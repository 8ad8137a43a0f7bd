//! Accuracy of a bake against the exact solve: relative RMSE of the indirect term
//! `B − B_o` produced by a set of transfer maps (Eq. 9, [`crate::maps::apply()`]) versus the dense
//! solution ([`crate::bake::transport::dense`]), averaged over random light set-ups.
//!
//! Used by the convergence tests and by `ortm bench bake`. [`ear_texels`] picks the head's ear
//! rims for the back-lit ear check.

use glam::Vec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rayon::prelude::*;

use crate::bake::lighting;
use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
use crate::bake::transport::Transport;
use crate::maps::{self, TransferMap};
use crate::scene::{Light, Scene};

/// `count` random point-light set-ups around the scene: each has one or two point lights at
/// 1.5–3 bounding radii from the centre, random colours, intensities giving ~10 W/m² at the
/// centre. Deterministic for `seed`.
pub fn random_light_setups(scene: &Scene, count: usize, seed: u64) -> Vec<Vec<Light>> {
    let (centre, radius) = scene.mesh.bounding_sphere().unwrap_or((Vec3::ZERO, 1.0));
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let n = 1 + rng.random_range(0..2usize);
            (0..n)
                .map(|_| {
                    let dir = loop {
                        let v = Vec3::new(
                            rng.random_range(-1.0..1.0f32),
                            rng.random_range(-1.0..1.0f32),
                            rng.random_range(-1.0..1.0f32),
                        );
                        if v.length_squared() > 0.01 && v.length_squared() <= 1.0 {
                            break v.normalize();
                        }
                    };
                    let d = radius * rng.random_range(1.5..3.0f32);
                    Light::Point {
                        position_m: centre + dir * d,
                        color: Vec3::new(
                            rng.random_range(0.3..1.0f32),
                            rng.random_range(0.3..1.0f32),
                            rng.random_range(0.3..1.0f32),
                        ),
                        intensity_w_sr: 10.0 * d * d,
                    }
                })
                .collect()
        })
        .collect()
}

/// Relative RMSE `‖I − I_exact‖ / ‖I_exact‖` of the indirect term over all covered texels and
/// channels ([`crate::accuracy::compare::relative_rmse`] without a mask).
pub fn relative_rmse(indirect: &[Vec3], exact_indirect: &[Vec3]) -> f64 {
    crate::accuracy::compare::relative_rmse(indirect, exact_indirect, None)
}

/// The texels that send light: those whose `b_o` is not zero, in increasing order.
pub fn senders(b_o: &[Vec3]) -> Vec<u32> {
    (0..b_o.len() as u32)
        .filter(|&j| b_o[j as usize] != Vec3::ZERO)
        .collect()
}

/// `B = B_o + Σ_j R(i, j) B_o(j)` at receiver `i` from the bake's pair evaluator
/// ([`Transport::r`]), summed over `senders` ([`senders`]) in their order: what offset maps
/// with every offset and exact cells would store, the limit the bake's maps converge to.
pub fn evaluator_final_at(tr: &Transport, b_o: &[Vec3], senders: &[u32], i: u32) -> Vec3 {
    let mut b = b_o[i as usize];
    for &j in senders {
        b += Vec3::from_array(tr.r(i, j)) * b_o[j as usize];
    }
    b
}

/// [`evaluator_final_at`] for every texel (in parallel; `n × senders` pair evaluations).
pub fn evaluator_final(tr: &Transport, b_o: &[Vec3]) -> Vec<Vec3> {
    let senders = senders(b_o);
    (0..b_o.len() as u32)
        .into_par_iter()
        .map(|i| evaluator_final_at(tr, b_o, &senders, i))
        .collect()
}

/// Relative RMSE of the indirect term `B − B_o` of [`evaluator_final`] against the exact final
/// radiosity `exact` (e.g. [`crate::bake::transport::dense::DenseTransport::solve`]) for the
/// first-order radiosity `b_o`: the figure `ortm bench transport` prints for the evaluator.
pub fn evaluator_error(tr: &Transport, b_o: &[Vec3], exact: &[Vec3]) -> f64 {
    let indirect: Vec<Vec3> = evaluator_final(tr, b_o)
        .iter()
        .zip(b_o)
        .map(|(b, o)| *b - *o)
        .collect();
    let exact_indirect: Vec<Vec3> = exact.iter().zip(b_o).map(|(b, o)| *b - *o).collect();
    relative_rmse(&indirect, &exact_indirect)
}

/// First-order lightings and exact final solutions for a list of light set-ups.
pub struct Reference {
    /// First-order radiosity per set-up, per covered texel (W/m²).
    pub first_order: Vec<Vec<Vec3>>,
    /// Exact final radiosity per set-up (W/m²).
    pub exact: Vec<Vec<Vec3>>,
}

impl Reference {
    /// Lights every set-up with CPU ray-cast shadows and solves each exactly.
    pub fn new(
        grid: &TexelGrid,
        vis: &Visibility,
        dense: &crate::bake::transport::dense::DenseTransport,
        setups: &[Vec<Light>],
    ) -> Self {
        let first_order: Vec<Vec<Vec3>> = setups
            .iter()
            .map(|l| lighting::first_order(grid, l, vis))
            .collect();
        let exact = dense.solve_many(&first_order);
        Self { first_order, exact }
    }

    /// Mean over set-ups of the relative RMSE of the indirect term produced by `maps`.
    pub fn indirect_error(&self, grid: &TexelGrid, maps: &[TransferMap]) -> f64 {
        let mut total = 0.0;
        for (b_o, exact) in self.first_order.iter().zip(&self.exact) {
            let lm = lighting::to_lightmap(grid, b_o);
            let ind = maps::apply_indirect(maps, &lm).expect("maps match the lightmap");
            let ind = lighting::from_lightmap(grid, &ind);
            let exact_ind: Vec<Vec3> = exact.iter().zip(b_o).map(|(b, o)| *b - *o).collect();
            total += relative_rmse(&ind, &exact_ind);
        }
        total / self.first_order.len().max(1) as f64
    }
}

/// Indices of the covered texels of `grid` that lie on the ear rims of the head
/// ([`faces::head::is_ear_point`]): the texels of the back-lit ear check of
/// [`crate::scene::head`].
pub fn ear_texels(grid: &TexelGrid) -> Vec<u32> {
    grid.texels
        .iter()
        .enumerate()
        .filter(|(_, t)| faces::head::is_ear_point(t.position_m))
        .map(|(i, _)| i as u32)
        .collect()
}
