//! Gutter dilation (nearest-texel copy from a per-scene plan): the plan's sources against a
//! brute-force search over every covered texel; the GPU pass against its CPU mirror (exact);
//! and the properties that matter, checked without the plan: covered texels are never
//! changed, every texel a bilinear lookup inside a covered texel's footprint touches is
//! non-empty, filled texels copy a nearest covered texel, texels farther than `rings` from
//! coverage stay empty. Also the frame script: its plan is the first-order pass's coverage.

mod common;

use common::{Rng, gpu};
use passes::dilate::{
    DilateInputs, DilateOptions, DilatePass, DilatePath, DilatePlan, FILLED_ALPHA, NO_SOURCE,
    dilation_sources,
};
use passes::{Gpu, TexelImage, cpu};

/// The rule, by brute force over all covered texels: itself if covered; else the covered
/// texel within Chebyshev distance `rings` with the smallest (squared Euclidean distance,
/// index); else none.
fn brute_force_sources(w: u32, h: u32, covered: &[bool], rings: u32) -> Vec<u32> {
    let (w, h) = (w as i64, h as i64);
    let cov: Vec<(i64, i64, u32)> = (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .filter(|&(x, y)| covered[(y * w + x) as usize])
        .map(|(x, y)| (x, y, (y * w + x) as u32))
        .collect();
    (0..h)
        .flat_map(|y| (0..w).map(move |x| (x, y)))
        .map(|(x, y)| {
            let i = (y * w + x) as usize;
            if covered[i] {
                return i as u32;
            }
            cov.iter()
                .filter(|&&(cx, cy, _)| (cx - x).abs().max((cy - y).abs()) <= rings as i64)
                .min_by_key(|&&(cx, cy, j)| ((cx - x).pow(2) + (cy - y).pow(2), j))
                .map_or(NO_SOURCE, |&(_, _, j)| j)
        })
        .collect()
}

/// Random rectangular "charts" of random values (alpha 1) on an empty map.
fn random_charts(r: &mut Rng, w: u32, h: u32, charts: u32) -> TexelImage {
    let mut img = TexelImage::new(w, h);
    for _ in 0..charts {
        let (x0, y0) = (
            r.range(0, w as i64 - 1) as u32,
            r.range(0, h as i64 - 1) as u32,
        );
        let (cw, ch) = (r.range(1, 8) as u32, r.range(1, 8) as u32);
        for y in y0..(y0 + ch).min(h) {
            for x in x0..(x0 + cw).min(w) {
                *img.at_mut(x, y) = [r.f32() * 4.0, r.f32(), r.f32() * 2.0, 1.0];
            }
        }
    }
    img
}

/// Uploads `src`, dilates it on the GPU with `plan` by `path`, reads the result back.
fn dilate_on_gpu(
    gpu: &Gpu,
    pass: &DilatePass,
    plan: &DilatePlan,
    src: &TexelImage,
    path: DilatePath,
) -> TexelImage {
    let targets = pass.prepare(gpu, plan).unwrap();
    // The pass copies the input when it can (RGBA32F with COPY_SRC).
    let usage = match path {
        DilatePath::CopyAndGutter => {
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_SRC
        }
        DilatePath::FullScreen => wgpu::TextureUsages::TEXTURE_BINDING,
    };
    let tex = gpu
        .create_rgba32f_texture("test.src", src.width, src.height, &src.rgba, usage)
        .unwrap();
    let view = tex.create_view(&Default::default());
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let out = pass.encode(
        gpu,
        &mut enc,
        &DilateInputs {
            targets: &targets,
            source: &view,
        },
    );
    assert_eq!(out.path, path);
    gpu.submit_and_wait("test.dilate", enc).unwrap();
    gpu.read_texel_image("test.dilated", &out.dilated_tex)
        .unwrap()
}

#[test]
fn sources_match_brute_force_on_random_masks() {
    let mut r = Rng::new(11);
    let mut filled = 0;
    for case in 0..300 {
        let (w, h) = (r.range(1, 24) as u32, r.range(1, 24) as u32);
        let rings = r.range(1, 5) as u32;
        // Sparse to dense masks, some all-empty or all-covered.
        let density = [0.0, 0.01, 0.05, 0.15, 0.4, 0.8, 1.0][case % 7];
        let covered: Vec<bool> = (0..w * h).map(|_| r.f32() < density).collect();
        let got = dilation_sources(w, h, &covered, rings).unwrap();
        let want = brute_force_sources(w, h, &covered, rings);
        assert_eq!(got, want, "case {case}: {w}×{h}, rings {rings}");
        filled += got
            .iter()
            .enumerate()
            .filter(|&(i, &s)| s != NO_SOURCE && s as usize != i)
            .count();
    }
    assert!(filled > 5000, "too few filled texels tested: {filled}");
}

#[test]
fn gutter_rects_hold_every_uncovered_texel_once() {
    let mut r = Rng::new(21);
    for case in 0..200 {
        let (w, h) = (r.range(1, 40) as u32, r.range(1, 40) as u32);
        let density = [0.0, 0.05, 0.3, 0.7, 0.95, 1.0][case % 6];
        let covered: Vec<bool> = (0..w * h).map(|_| r.f32() < density).collect();
        let plan = DilatePlan::new(w, h, &covered, r.range(1, 4) as u32).unwrap();
        let block = r.range(1, 9) as u32;
        let mut count = vec![0u32; (w * h) as usize];
        for &[x0, y0, x1, y1] in &plan.gutter_rects(block) {
            assert!(
                x0 < x1 && y0 < y1 && x1 <= w && y1 <= h,
                "{w}×{h}: bad rect"
            );
            for y in y0..y1 {
                for x in x0..x1 {
                    count[(y * w + x) as usize] += 1;
                }
            }
        }
        for (i, &c) in count.iter().enumerate() {
            assert!(c <= 1, "case {case}: texel {i} in {c} rectangles");
            if !covered[i] {
                assert_eq!(c, 1, "case {case}: uncovered texel {i} in no rectangle");
            }
        }
        if block == 1 {
            // Cells of one texel: exactly the uncovered texels.
            let n = count.iter().filter(|&&c| c == 1).count();
            assert_eq!(n, covered.iter().filter(|&&c| !c).count());
        }
    }
}

#[test]
fn gpu_matches_mirror_exactly_and_never_overwrites_coverage() {
    let gpu = gpu();
    let mut r = Rng::new(5);
    for (w, h, rings) in [(45u32, 38u32, 3u32), (31, 17, 1), (64, 9, 4)] {
        let src = random_charts(&mut r, w, h, 6);
        let pass = DilatePass::new(&gpu, &DilateOptions { rings }).unwrap();
        let plan = pass.plan(&src).unwrap();
        let want = cpu::dilate::dilate(&src, &plan).unwrap();
        let got = dilate_on_gpu(&gpu, &pass, &plan, &src, DilatePath::FullScreen);
        assert_eq!(
            got, want,
            "{w}×{h}: full-screen path differs from the CPU mirror"
        );
        let got = dilate_on_gpu(&gpu, &pass, &plan, &src, DilatePath::CopyAndGutter);
        assert_eq!(
            got, want,
            "{w}×{h}: copy + gutter path differs from the CPU mirror"
        );

        // Properties, from the input alone.
        let covered: Vec<(i64, i64)> = (0..h as i64)
            .flat_map(|y| (0..w as i64).map(move |x| (x, y)))
            .filter(|&(x, y)| src.get(x as u32, y as u32)[3] == 1.0)
            .collect();
        let mut filled = 0;
        for y in 0..h as i64 {
            for x in 0..w as i64 {
                let s = src.get(x as u32, y as u32);
                let g = got.get(x as u32, y as u32);
                if s[3] == 1.0 {
                    assert_eq!(g, s, "covered texel ({x}, {y}) was overwritten");
                    continue;
                }
                let cheb = |&(cx, cy): &(i64, i64)| (cx - x).abs().max((cy - y).abs());
                let near: Vec<(i64, i64)> = covered
                    .iter()
                    .filter(|c| cheb(c) <= rings as i64)
                    .copied()
                    .collect();
                if near.is_empty() {
                    assert_eq!(
                        g, [0.0; 4],
                        "({x}, {y}) is farther than {rings} from coverage"
                    );
                    continue;
                }
                assert_eq!(g[3], FILLED_ALPHA, "({x}, {y}) must be filled");
                // Copies one of the Euclidean-nearest covered texels.
                let d2 = |&(cx, cy): &(i64, i64)| (cx - x).pow(2) + (cy - y).pow(2);
                let best = near.iter().map(d2).min().unwrap();
                assert!(
                    near.iter().filter(|c| d2(c) == best).any(|&(cx, cy)| {
                        let v = src.get(cx as u32, cy as u32);
                        v[..3] == g[..3]
                    }),
                    "({x}, {y}) = {g:?} is not the value of a nearest covered texel"
                );
                filled += 1;
            }
        }
        assert!(filled > 50, "test data too sparse: {filled} filled texels");
        // Bilinear filtering inside a covered texel's footprint reads only its 3×3
        // neighbourhood; none of those taps may be empty (black).
        for &(x, y) in &covered {
            for (dx, dy) in (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))) {
                let (qx, qy) = (x + dx, y + dy);
                if qx >= 0 && qy >= 0 && qx < w as i64 && qy < h as i64 {
                    assert!(
                        got.get(qx as u32, qy as u32)[3] > 0.0,
                        "bilinear tap ({qx}, {qy}) next to covered ({x}, {y}) is empty"
                    );
                }
            }
        }
    }
}

#[test]
fn map_with_other_coverage_than_the_plan_keeps_its_covered_texels() {
    let gpu = gpu();
    let mut r = Rng::new(9);
    let (w, h) = (40, 30);
    let planned = random_charts(&mut r, w, h, 8);
    let pass = DilatePass::new(&gpu, &DilateOptions::default()).unwrap();
    let plan = pass.plan(&planned).unwrap();
    // The map shown: the same charts with ~10 % of the texels' coverage flipped (and some
    // garbage RGB under alpha 0, which a texel covered in the plan keeps).
    let mut src = planned.clone();
    let mut flipped = 0;
    for t in &mut src.rgba {
        if r.f32() < 0.1 {
            *t = if t[3] > 0.0 {
                [r.f32(), 0.0, 0.0, 0.0]
            } else {
                [r.f32(), r.f32(), r.f32(), 1.0]
            };
            flipped += 1;
        }
    }
    assert!(flipped > 50);
    let got = dilate_on_gpu(&gpu, &pass, &plan, &src, DilatePath::CopyAndGutter);
    assert_eq!(got, cpu::dilate::dilate(&src, &plan).unwrap());
    let full = dilate_on_gpu(&gpu, &pass, &plan, &src, DilatePath::FullScreen);
    assert_eq!(full, got, "the two GPU paths differ");
    for y in 0..h {
        for x in 0..w {
            let (s, g) = (src.get(x, y), got.get(x, y));
            if s[3] > 0.0 || plan.source(x, y) == Some((x, y)) {
                assert_eq!(g, s, "covered ({x}, {y}) was changed");
                continue;
            }
            match plan.source(x, y) {
                Some((sx, sy)) if src.get(sx, sy)[3] > 0.0 => {
                    let v = src.get(sx, sy);
                    assert_eq!(g, [v[0], v[1], v[2], FILLED_ALPHA], "({x}, {y})");
                }
                // No source, or a source that is empty in this map: stays empty.
                _ => assert_eq!(g, [0.0; 4], "({x}, {y})"),
            }
        }
    }
}

#[test]
fn plans_of_another_size_are_errors() {
    let gpu = gpu();
    let pass = DilatePass::new(&gpu, &DilateOptions::default()).unwrap();
    let plan = DilatePlan::new(4, 4, &[true; 16], 2).unwrap();
    let e = cpu::dilate::dilate(&TexelImage::new(5, 4), &plan).unwrap_err();
    assert!(e.to_string().contains("4×4"), "{e}");
    let mut bad = plan.clone();
    bad.sources[3] = 16;
    let e = pass.prepare(&gpu, &bad).unwrap_err();
    assert!(e.to_string().contains("DilatePlan.sources"), "{e}");
    assert!(DilatePass::new(&gpu, &DilateOptions { rings: 0 }).is_err());
}

#[test]
fn frame_plan_is_the_first_order_coverage_and_dilates_like_the_mirror() {
    use common::demo::{demo_lights, prepare_demo};
    use passes::frame::{FrameOptions, FrameParams, Renderer};

    let gpu = gpu();
    let size = 64;
    // The lightmap display: the frame dilates the final and the first-order maps (with
    // per-pixel direct light it dilates the transferred light instead).
    let mut options = common::demo_renderer_options(32, 16);
    options.display.direct = passes::display::DirectLight::Lightmap;
    let renderer = Renderer::new(&gpu, &options).unwrap();
    let (scene, _) = prepare_demo(&gpu, &renderer, size);
    let lights = demo_lights();
    let params = FrameParams {
        lights: &lights,
        camera: common::demo_camera(),
        exposure: 1.0,
        specular: None,
    };
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let out = renderer
        .encode_frame(&gpu, &mut enc, &scene, &params, &FrameOptions::default())
        .unwrap();
    gpu.submit_and_wait("test.frame", enc).unwrap();
    let read = |what, t| gpu.read_texel_image(what, t).unwrap();
    let fo = read("fo", &out.first_order_tex);
    let fin = read("final", &out.final_lightmap_tex);
    let plan = DilatePlan::from_alpha(&fo, DilateOptions::default().rings).unwrap();
    assert_eq!(scene.dilate_plan, plan, "plan ≠ the lit frame's coverage");
    assert!(scene.dilate_plan.filled_texels() > 100);
    let want_final = cpu::dilate::dilate(&fin, &plan).unwrap();
    assert_eq!(read("dilated final", &out.dilated_final_tex), want_final);
    let want_fo = cpu::dilate::dilate(&fo, &plan).unwrap();
    assert_eq!(
        read("dilated first order", scene.dilate_first_order.output()),
        want_fo
    );
}
