//! Physics checks of the transport against closed forms: white furnace in a closed box,
//! reciprocity and row sums of the assembled form factors, and the dense solver against the
//! Neumann series.

use std::sync::Arc;

use glam::Vec3;
use ortm::bake::raycast::Visibility;
use ortm::bake::transport::dense::DenseTransport;
use ortm::bake::transport::{Effects, Kernels, Patch};

/// Inward-facing patches of the unit cube, `n × n` per face: texels (with footprints, so their
/// form factors are collocated at their centres) or clusters (area means, reciprocal).
fn cube_patches(n: usize, rho: Vec3, texels: bool) -> Vec<Patch> {
    let faces = [
        (Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y, -Vec3::Z),
        (Vec3::ZERO, Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::X, Vec3::Z, -Vec3::Y),
        (Vec3::ZERO, Vec3::Y, Vec3::Z, Vec3::X),
        (Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X),
    ];
    let area = 1.0 / (n * n) as f32;
    let mut v = Vec::new();
    for (o, e1, e2, nrm) in faces {
        for y in 0..n {
            for x in 0..n {
                v.push(Patch {
                    position_m: o
                        + e1 * ((x as f32 + 0.5) / n as f32)
                        + e2 * ((y as f32 + 0.5) / n as f32),
                    normal: nrm,
                    lift_normal: nrm,
                    area_m2: area,
                    rho,
                    material: 0,
                    subsurface_scale: Vec3::ONE,
                    subsurface_gather: Vec3::ONE,
                    footprint_m: texels.then(|| [e1 / n as f32, e2 / n as f32]),
                });
            }
        }
    }
    v
}

fn kernels() -> Kernels {
    Kernels::from_parts(
        Effects::default(),
        vec![None],
        Arc::new(Visibility::from_triangles(Vec::new())),
    )
}

#[test]
fn white_furnace_closed_box() {
    let rho = Vec3::new(0.3, 0.5, 0.7);
    // ρ = 0.7 amplifies the form factors' row-sum error by ρ/(1−ρ) ≈ 2.3. Measured worst
    // relative error: texels 1.36e-3, clusters 4.2e-3; bounds + 25 %.
    for (texels, bound) in [(true, 1.7e-3), (false, 5.3e-3)] {
        let patches = cube_patches(10, rho, texels);
        let dense = DenseTransport::new(&patches, &kernels());
        let b_o = vec![Vec3::splat(2.0); patches.len()];
        let b = dense.solve(&b_o);
        let mut worst = 0f32;
        for (i, bi) in b.iter().enumerate() {
            for c in 0..3 {
                let expected = 2.0 / (1.0 - rho[c]);
                let rel = (bi[c] - expected).abs() / expected;
                worst = worst.max(rel);
                assert!(
                    rel < bound,
                    "texels {texels}, patch {i} channel {c}: {} vs {expected}",
                    bi[c]
                );
            }
        }
        eprintln!("white furnace (texels {texels}): worst relative error {worst:.3e}");
    }
}

#[test]
fn assembled_form_factors_are_reciprocal_and_rows_sum_to_one() {
    // Clusters: reciprocal to rounding. A closed surface sees only itself: every row sums to 1
    // up to the quadrature error of the near-field form factors at edges and corners, measured
    // 3.1e-3 (+ 25 %).
    let patches = cube_patches(8, Vec3::splat(0.5), false);
    let dense = DenseTransport::new(&patches, &kernels());
    for i in 0..dense.n {
        for j in 0..dense.n {
            let (a, b) = (
                patches[i].area_m2 as f64 * dense.form_factors[(i, j)],
                patches[j].area_m2 as f64 * dense.form_factors[(j, i)],
            );
            assert!((a - b).abs() <= 1e-9 + 1e-6 * a.abs());
        }
    }
    let mut worst = 0f64;
    for s in dense.form_factor_row_sums() {
        worst = worst.max((s - 1.0).abs());
        assert!((s - 1.0).abs() < 3.9e-3, "row sum {s}");
    }
    eprintln!("closed cube, clusters: worst |row sum − 1| {worst:.3e}");

    // Texels, collocated at their centres: a point inside a closed surface sees all of it, so
    // each row sums to 1 up to the point kernel beyond 8 texel sizes; what a texel's radiosity
    // reaches, the column Σ_j A_j F_ji / A_i, is 1 up to the collocation's asymmetry between
    // near texels (largest at the cube's edges and corners, where a texel's centre sees its
    // neighbours across the crease differently than they see it: 8 × 8 texels per face); pairs
    // farther than 8 texel sizes are reciprocal to rounding. Measured: rows 5.9e-4, columns
    // 3.5e-2; bounds + 25 %.
    let patches = cube_patches(8, Vec3::splat(0.5), true);
    let dense = DenseTransport::new(&patches, &kernels());
    let (mut worst_row, mut worst_col) = (0f64, 0f64);
    let cols = dense.form_factor_column_sums(&patches);
    for (i, s) in dense.form_factor_row_sums().into_iter().enumerate() {
        worst_row = worst_row.max((s - 1.0).abs());
        worst_col = worst_col.max((cols[i] - 1.0).abs());
        for j in 0..dense.n {
            let d = (patches[j].position_m - patches[i].position_m).length();
            if d > 8.0 * patches[i].area_m2.sqrt() {
                let (a, b) = (
                    patches[i].area_m2 as f64 * dense.form_factors[(i, j)],
                    patches[j].area_m2 as f64 * dense.form_factors[(j, i)],
                );
                assert!((a - b).abs() <= 1e-9 + 1e-6 * a.abs(), "far pair {i}, {j}");
            }
        }
    }
    eprintln!(
        "closed cube, texels: worst |row sum − 1| {worst_row:.3e}, |column sum − 1| \
         {worst_col:.3e}"
    );
    assert!(worst_row < 7.4e-4, "row sums: {worst_row}");
    assert!(worst_col < 4.4e-2, "column sums: {worst_col}");
}

#[test]
fn transfer_equals_neumann_series() {
    // A small open configuration (two facing plates) with unequal albedo.
    let mut patches = cube_patches(3, Vec3::new(0.6, 0.4, 0.2), false);
    patches.truncate(18); // floor and ceiling only
    let dense = DenseTransport::new(&patches, &kernels());
    let r = dense.transfer();
    let n = dense.n;
    // K = ρ F; R = K + K² + … (60 terms: ρ·F ≤ 0.6·0.3 converges fast).
    for (ch, r_ch) in r.iter().enumerate() {
        let k = |i: usize, j: usize| patches[i].rho[ch] as f64 * dense.form_factors[(i, j)];
        let mut term: Vec<f64> = (0..n * n).map(|x| k(x / n, x % n)).collect();
        let mut sum = term.clone();
        for _ in 0..60 {
            let mut next = vec![0.0; n * n];
            for i in 0..n {
                for m in 0..n {
                    let kim = k(i, m);
                    for j in 0..n {
                        next[i * n + j] += kim * term[m * n + j];
                    }
                }
            }
            for (s, t) in sum.iter_mut().zip(&next) {
                *s += t;
            }
            term = next;
        }
        for i in 0..n {
            for j in 0..n {
                assert!((r_ch[(i, j)] - sum[i * n + j]).abs() < 1e-9, "R({i},{j})");
            }
        }
    }
}
