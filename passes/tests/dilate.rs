//! Gutter dilation on the GPU vs its CPU mirror, plus the properties that matter: covered
//! texels are never changed, the first ring is the mean of its covered neighbours, texels
//! farther than `iterations` from coverage stay empty.

mod common;

use common::{Rng, gpu};
use passes::dilate::{DilateInputs, DilateOptions, DilatePass, FILLED_ALPHA};
use passes::{TexelImage, cpu};

#[test]
fn dilation_matches_mirror_and_never_overwrites_coverage() {
    let (w, h) = (45u32, 38u32);
    let mut r = Rng::new(5);
    let mut src = TexelImage::new(w, h);
    // A few rectangular charts of random values.
    for _ in 0..6 {
        let (x0, y0) = (r.range(0, 40) as u32, r.range(0, 33) as u32);
        let (cw, ch) = (r.range(1, 8) as u32, r.range(1, 8) as u32);
        for y in y0..(y0 + ch).min(h) {
            for x in x0..(x0 + cw).min(w) {
                *src.at_mut(x, y) = [r.f32() * 4.0, r.f32(), r.f32() * 2.0, 1.0];
            }
        }
    }
    let iterations = 3;
    let gpu = gpu();
    let pass = DilatePass::new(&gpu, &DilateOptions { iterations }).unwrap();
    let targets = pass.prepare(&gpu, [w, h]).unwrap();
    let tex = gpu
        .create_rgba32f_texture(
            "test.src",
            w,
            h,
            &src.rgba,
            wgpu::TextureUsages::TEXTURE_BINDING,
        )
        .unwrap();
    let view = tex.create_view(&Default::default());
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let out = pass.encode(
        &gpu,
        &mut enc,
        &DilateInputs {
            targets: &targets,
            source: &view,
        },
    );
    gpu.submit_and_wait("test.dilate", enc).unwrap();
    let got = gpu
        .read_texel_image("test.dilated", &out.dilated_tex)
        .unwrap();

    let want = cpu::dilate::dilate(&src, iterations);
    for (i, (g, m)) in got.rgba.iter().zip(&want.rgba).enumerate() {
        for c in 0..4 {
            assert!(
                (g[c] - m[c]).abs() <= 1e-6 * m[c].abs().max(1.0),
                "texel {i}: {g:?} vs {m:?}"
            );
        }
    }
    // Chebyshev distance to the nearest covered texel, by brute force.
    let covered: Vec<(i32, i32)> = (0..h as i32)
        .flat_map(|y| (0..w as i32).map(move |x| (x, y)))
        .filter(|&(x, y)| src.get(x as u32, y as u32)[3] == 1.0)
        .collect();
    let mut rings = 0;
    for y in 0..h as i32 {
        for x in 0..w as i32 {
            let s = src.get(x as u32, y as u32);
            let g = got.get(x as u32, y as u32);
            if s[3] == 1.0 {
                assert_eq!(g, s, "covered texel ({x}, {y}) was overwritten");
                continue;
            }
            let d = covered
                .iter()
                .map(|&(cx, cy)| (cx - x).abs().max((cy - y).abs()))
                .min()
                .unwrap_or(i32::MAX);
            if d > iterations as i32 {
                assert_eq!(g, [0.0; 4], "({x}, {y}) is {d} texels from coverage");
            } else {
                assert_eq!(
                    g[3], FILLED_ALPHA,
                    "({x}, {y}) at distance {d} must be filled"
                );
            }
            if d == 1 {
                // First ring: exactly the mean of the covered 8-neighbours.
                let nb: Vec<[f32; 4]> = covered
                    .iter()
                    .filter(|&&(cx, cy)| (cx - x).abs().max((cy - y).abs()) == 1)
                    .map(|&(cx, cy)| src.get(cx as u32, cy as u32))
                    .collect();
                for c in 0..3 {
                    let mean = nb.iter().map(|v| v[c]).sum::<f32>() / nb.len() as f32;
                    assert!((g[c] - mean).abs() <= 1e-5 * mean.abs().max(1.0));
                }
                rings += 1;
            }
        }
    }
    assert!(
        rings > 20,
        "test data too sparse: {rings} first-ring texels"
    );
}
