//! Accuracy of a bake against the exact solve: relative RMSE of the indirect term
//! `B − B_o` produced by a set of transfer maps (Eq. 9, [`crate::maps::apply()`]) versus the dense
//! solution ([`crate::bake::transport::dense`]), averaged over random light set-ups.
//!
//! Used by the convergence tests and by `ortm bench bake`. [`ear_texels`] picks the head's ear
//! rims for the back-lit ear check.

use glam::Vec3;
use rand::{RngExt, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::bake::lighting;
use crate::bake::raycast::Visibility;
use crate::bake::texels::TexelGrid;
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
/// channels.
pub fn relative_rmse(indirect: &[Vec3], exact_indirect: &[Vec3]) -> f64 {
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, b) in indirect.iter().zip(exact_indirect) {
        let d = (*a - *b).as_dvec3();
        num += d.length_squared();
        den += b.as_dvec3().length_squared();
    }
    (num / den.max(1e-300)).sqrt()
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
