//! The random numbers of one path: randomised quasi-Monte Carlo for its first vertices, a
//! pseudo-random stream beyond.
//!
//! A texel's paths are split into `R` replicates of `n` paths each. Replicate `r` takes its
//! paths' first [`QMC_DIMENSIONS`] numbers from an Owen-scrambled Sobol sequence of its own
//! (points `0..n`, scrambled by a seed drawn for the replicate); every later number comes from
//! the texel's ChaCha8 stream. Each point of a scrambled sequence is uniform on the unit cube,
//! so every path is an unbiased sample, as with independent numbers; within a replicate the
//! points are stratified (a `(t, m, s)`-net at power-of-two `n`), which cancels much of the
//! variance of smooth integrands — the subsurface profile's exit points over a lit patch, a
//! bounce's hemisphere. The replicates are independent, so the spread of their means gives an
//! honest standard error (the sample variance of stratified points would not).
//!
//! Dimensions are laid out per path vertex: vertex `v` (the texel's is 0) reads its numbers at
//! `v·VERTEX_DIMENSIONS + slot`, each use at a fixed slot ([`Slot`]), so a dimension keeps one
//! meaning across the paths of a replicate whatever earlier vertices did.

use glam::DVec3;
use rand::RngExt;
use rand_chacha::ChaCha8Rng;

/// Numbers per path vertex.
pub const VERTEX_DIMENSIONS: u32 = 10;

/// Path vertices whose numbers are quasi-random (the first three: the texel's, and two
/// bounces); later vertices draw from the pseudo-random stream.
pub const QMC_VERTICES: u32 = 3;

/// Dimensions taken from the Sobol sequence (at most `sobol_burley::NUM_DIMENSIONS`).
pub const QMC_DIMENSIONS: u32 = QMC_VERTICES * VERTEX_DIMENSIONS;

/// Longest replicate (the Sobol sequence's length).
pub const MAX_REPLICATE_PATHS: u32 = 1 << 16;

/// Where a vertex's uses of numbers sit among its [`VERTEX_DIMENSIONS`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Slot {
    /// The subsurface exit point: axis and channel, radius, angle, hit (4 numbers).
    Exit = 0,
    /// The first-order light's point: cell, and two in the cell (3 numbers).
    Light = 4,
    /// Russian roulette (1 number).
    Roulette = 7,
    /// The cosine-sampled bounce (2 numbers).
    Bounce = 8,
}

/// The number source of one texel's paths.
pub struct PathSampler {
    /// The texel's pseudo-random stream: replicate seeds, padding beyond the Sobol dimensions,
    /// and the bits below an `f32`'s precision.
    rng: ChaCha8Rng,
    /// The current replicate's scramble seed.
    seed: u32,
    /// The current path's index in its replicate.
    index: u32,
    /// The next dimension.
    dim: u32,
}

impl PathSampler {
    /// A sampler over the texel's stream `rng`.
    pub fn new(rng: ChaCha8Rng) -> Self {
        Self {
            rng,
            seed: 0,
            index: 0,
            dim: 0,
        }
    }

    /// Starts a replicate: a new scramble seed from the stream.
    pub fn start_replicate(&mut self) {
        self.seed = self.rng.random();
    }

    /// Starts path `index` (`< MAX_REPLICATE_PATHS`) of the current replicate.
    pub fn start_path(&mut self, index: u32) {
        debug_assert!(index < MAX_REPLICATE_PATHS);
        self.index = index;
        self.dim = 0;
    }

    /// Moves to `slot` of path vertex `vertex`; the next numbers are read from there on.
    pub fn at(&mut self, vertex: u32, slot: Slot) {
        self.dim = vertex
            .saturating_mul(VERTEX_DIMENSIONS)
            .saturating_add(slot as u32);
    }

    /// The next number, uniform on `[0, 1)`.
    pub fn uniform(&mut self) -> f64 {
        let d = self.dim;
        self.dim = self.dim.saturating_add(1);
        if d < QMC_DIMENSIONS {
            // 24 bits from the scrambled point, the bits below them from the stream: the sum
            // is uniform on [0, 1) when the point is uniform on the grid of 2⁻²⁴.
            let coarse = f64::from(sobol_burley::sample(self.index, d, self.seed));
            let fine = self.rng.random::<f64>() * (1.0 / (1u32 << 24) as f64);
            (coarse + fine).min(1.0 - f64::EPSILON / 2.0)
        } else {
            self.rng.random()
        }
    }

    /// [`PathSampler::uniform`] as `f32`, on `[0, 1)`.
    pub fn uniform_f32(&mut self) -> f32 {
        (self.uniform() as f32).min(1.0 - f32::EPSILON / 2.0)
    }
}

/// The mean of `replicates × per_replicate` samples of `path` (each called after
/// [`PathSampler::start_path`]; `None` stops the estimate and is returned) and its standard
/// error, from the spread of the replicates' means:
/// `sqrt(Σ_r (m_r − m)² / (R (R − 1)))` (0 for one replicate).
pub fn replicated_mean(
    sampler: &mut PathSampler,
    replicates: u32,
    per_replicate: u32,
    mut path: impl FnMut(&mut PathSampler) -> Option<DVec3>,
) -> Option<(DVec3, DVec3)> {
    let (mut sum, mut sum2) = (DVec3::ZERO, DVec3::ZERO);
    for _ in 0..replicates {
        sampler.start_replicate();
        let mut replicate = DVec3::ZERO;
        for k in 0..per_replicate {
            sampler.start_path(k);
            replicate += path(sampler)?;
        }
        let m = replicate / f64::from(per_replicate);
        sum += m;
        sum2 += m * m;
    }
    let r = f64::from(replicates);
    let mean = sum / r;
    let var = if replicates > 1 {
        ((sum2 - sum * mean) / (r - 1.0)).max(DVec3::ZERO)
    } else {
        DVec3::ZERO
    };
    Some((mean, (var / r).sqrt()))
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;

    /// The standard error is honest for stratified points: over many independent estimates of
    /// a known integral (a smooth function of a vertex's bounce numbers and a step function of
    /// its light numbers), the mean squared standard error matches the mean squared error
    /// within their sampling spread, and both lie far below independent paths' — the sample
    /// variance over all paths, which ignores the stratification, would overstate it.
    #[test]
    fn replicate_spread_is_the_standard_error_of_stratified_paths() {
        let f = |s: &mut PathSampler| {
            s.at(0, Slot::Bounce);
            let (u, v) = (s.uniform(), s.uniform());
            s.at(0, Slot::Light);
            let w = s.uniform();
            let smooth = u.exp() * (std::f64::consts::PI * v).sin();
            let step = if w < 0.3 { 1.0 } else { 0.0 };
            Some(DVec3::new(smooth, step, smooth + step))
        };
        let exact_smooth = (std::f64::consts::E - 1.0) * 2.0 / std::f64::consts::PI;
        let exact = DVec3::new(exact_smooth, 0.3, exact_smooth + 0.3);
        let runs = 400;
        for (replicates, per_replicate, max_ratio_to_iid) in [(16, 16, 0.5), (8, 64, 0.2)] {
            let (mut err2, mut se2, mut naive2) = (DVec3::ZERO, DVec3::ZERO, DVec3::ZERO);
            for run in 0..runs {
                let mut s = PathSampler::new(ChaCha8Rng::seed_from_u64(run));
                let mut all = Vec::new();
                let (mean, se) = replicated_mean(&mut s, replicates, per_replicate, |s| {
                    let v = f(s)?;
                    all.push(v);
                    Some(v)
                })
                .expect("never stopped");
                err2 += (mean - exact) * (mean - exact);
                se2 += se * se;
                let n = all.len() as f64;
                let var = all.iter().map(|v| (*v - mean) * (*v - mean)).sum::<DVec3>() / (n - 1.0);
                naive2 += var / n;
            }
            for c in 0..3 {
                let ratio = se2[c] / err2[c];
                // 400 runs: the mean of squared errors has a relative spread of ~√(2/400) ≈ 7 %
                // for Gaussian errors (more with heavier tails); allow ±35 %.
                assert!(
                    (0.65..1.5).contains(&ratio),
                    "{replicates}×{per_replicate}, channel {c}: E[se²]/E[err²] = {ratio:.3}"
                );
                let gain = err2[c] / naive2[c];
                assert!(
                    gain < max_ratio_to_iid,
                    "{replicates}×{per_replicate}, channel {c}: stratified/independent variance {gain:.3}"
                );
            }
        }
    }

    /// Edge cases of [`replicated_mean`]: one replicate gives a zero standard error, and a
    /// stop is passed on.
    #[test]
    fn one_replicate_has_no_standard_error_and_a_stop_stops() {
        let mut s = PathSampler::new(ChaCha8Rng::seed_from_u64(1));
        let (mean, se) =
            replicated_mean(&mut s, 1, 8, |s| Some(DVec3::splat(s.uniform()))).expect("ran");
        assert_eq!(se, DVec3::ZERO);
        assert!((0.0..1.0).contains(&mean.x));
        let mut calls = 0;
        let stopped = replicated_mean(&mut s, 4, 4, |_| {
            calls += 1;
            (calls < 6).then_some(DVec3::ONE)
        });
        assert!(stopped.is_none());
        assert_eq!(calls, 6);
    }

    /// Every dimension is uniform, quasi-random and padded alike: the mean of `u` and `u²`
    /// over many replicates match ½ and ⅓, and a replicate's points of one dimension are
    /// stratified (one in each of `n` equal intervals) where they come from the Sobol sequence.
    #[test]
    fn numbers_are_uniform_and_stratified_in_the_sobol_dimensions() {
        let mut s = PathSampler::new(ChaCha8Rng::seed_from_u64(3));
        let n = 64u32;
        let dims = QMC_DIMENSIONS + 4;
        let replicates = 200;
        let mut m1 = vec![0.0f64; dims as usize];
        let mut m2 = vec![0.0f64; dims as usize];
        let mut stratified = vec![true; dims as usize];
        for _ in 0..replicates {
            s.start_replicate();
            let mut seen = vec![vec![false; n as usize]; dims as usize];
            for i in 0..n {
                s.start_path(i);
                for d in 0..dims {
                    let u = s.uniform();
                    assert!((0.0..1.0).contains(&u));
                    m1[d as usize] += u;
                    m2[d as usize] += u * u;
                    let cell = (u * n as f64) as usize;
                    if seen[d as usize][cell] {
                        stratified[d as usize] = false;
                    }
                    seen[d as usize][cell] = true;
                }
            }
        }
        let count = f64::from(n * replicates);
        for d in 0..dims as usize {
            let (mean, second) = (m1[d] / count, m2[d] / count);
            // Independent uniforms: σ(mean) = 0.29/√count ≈ 0.0023; the Sobol ones far less.
            assert!((mean - 0.5).abs() < 0.01, "dimension {d}: mean {mean}");
            assert!((second - 1.0 / 3.0).abs() < 0.01, "dimension {d}: {second}");
            assert_eq!(
                stratified[d],
                d < QMC_DIMENSIONS as usize,
                "dimension {d}: stratified {}",
                stratified[d]
            );
        }
    }

    /// `at` moves to a fixed dimension: the same vertex and slot give the same number for the
    /// same path, whatever was read before.
    #[test]
    fn slots_fix_the_dimension() {
        let mut s = PathSampler::new(ChaCha8Rng::seed_from_u64(5));
        s.start_replicate();
        s.start_path(3);
        s.at(1, Slot::Bounce);
        let a = s.uniform();
        s.start_path(3);
        for _ in 0..7 {
            s.uniform();
        }
        s.at(1, Slot::Bounce);
        let b = s.uniform();
        // Equal up to the stream's bits below 2⁻²⁴.
        assert!((a - b).abs() < 1e-7, "{a} {b}");
    }
}
