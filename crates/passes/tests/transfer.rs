//! GPU-vs-CPU tests of the transfer pass (blend path in RGBA32F and RGBA16F, compute path)
//! on random atlases, pieces and first-order maps, and of the CPU mirrors against a direct
//! per-texel evaluation of paper Eq. 9.

mod common;

use common::{Rng, gpu};
use passes::cpu;
use passes::pairing::{PairedSchedule, pair_schedule};
use passes::schedule::{build_schedule, build_tiles};
use passes::transfer::{AccumFormat, TransferInputs, TransferOptions, TransferPass, TransferPath};
use passes::util::TexelReads;
use passes::{AtlasData, TexelImage, TransferPiece};

struct Case {
    size: [u32; 2],
    atlases: Vec<AtlasData>,
    pieces: Vec<TransferPiece>,
    first_order: TexelImage,
}

fn random_case(seed: u64) -> Case {
    let mut r = Rng::new(seed);
    let size = [61u32, 47u32];
    let mut first_order = TexelImage::new(size[0], size[1]);
    for px in &mut first_order.rgba {
        let covered = r.f32() < 0.8;
        *px = if covered {
            [10.0 * r.f32(), 5.0 * r.f32(), r.f32(), 1.0]
        } else {
            [0.0; 4]
        };
    }
    let atlas_sizes = [[32u32, 32u32], [16, 40], [24, 8]];
    let atlases: Vec<AtlasData> = atlas_sizes
        .iter()
        .map(|&[w, h]| AtlasData {
            width: w,
            height: h,
            rgb: (0..w * h)
                .map(|_| [0.2 * r.f32(), 0.2 * r.f32(), 0.2 * r.f32()])
                .collect(),
        })
        .collect();
    let mut pieces = Vec::new();
    for _ in 0..60 {
        let a = r.range(0, 2) as usize;
        let [aw, ah] = atlas_sizes[a];
        let w = r.range(1, aw.min(size[0]) as i64) as u32;
        let h = r.range(1, ah.min(size[1]) as i64) as u32;
        pieces.push(TransferPiece {
            atlas: a as u32,
            src_x: r.range(0, (aw - w) as i64) as u32,
            src_y: r.range(0, (ah - h) as i64) as u32,
            w,
            h,
            dst_x: r.range(0, (size[0] - w) as i64) as u32,
            dst_y: r.range(0, (size[1] - h) as i64) as u32,
            offset: [r.range(-30, 30) as i32, r.range(-30, 30) as i32],
            level: 0,
            receiver_level: 0,
        });
    }
    Case {
        size,
        atlases,
        pieces,
        first_order,
    }
}

/// Eq. 9 evaluated texel by texel, independent of the schedule: for each t, the sum over
/// all pieces containing t. Also returns, per texel, Σ|terms| (incl. first order) and the
/// number of pieces touching it, for the half-float bound.
fn reference(c: &Case) -> (TexelImage, Vec<(f32, u32)>) {
    let mut out = c.first_order.clone();
    let mut mag = Vec::new();
    for y in 0..c.size[1] {
        for x in 0..c.size[0] {
            let mut abs_sum = c.first_order.get(x, y)[..3]
                .iter()
                .cloned()
                .fold(0.0, f32::max);
            let mut n = 0;
            for p in &c.pieces {
                if x < p.dst_x || y < p.dst_y || x >= p.dst_x + p.w || y >= p.dst_y + p.h {
                    continue;
                }
                let at = &c.atlases[p.atlas as usize];
                let s = (p.src_y + y - p.dst_y) * at.width + p.src_x + x - p.dst_x;
                let a = at.rgb[s as usize];
                let fo = c
                    .first_order
                    .get_or_zero(x as i32 + p.offset[0], y as i32 + p.offset[1]);
                let o = out.at_mut(x, y);
                for ch in 0..3 {
                    o[ch] += a[ch] * fo[ch];
                    abs_sum = abs_sum.max(o[ch].abs());
                }
                n += 1;
            }
            mag.push((abs_sum, n));
        }
    }
    (out, mag)
}

/// `options` with [`TexelReads::Storage`], when the adapter supports it (lavapipe does; a
/// failure where the adapter can but the device says it cannot, a note where it cannot).
fn storage_reads(options: TransferOptions) -> Option<TransferOptions> {
    common::has_storage_reads(&gpu(), "transfer storage reads").then_some(TransferOptions {
        texel_reads: TexelReads::Storage,
        ..options
    })
}

fn run_gpu(c: &Case, options: TransferOptions) -> TexelImage {
    run_gpu_paired(c, options).0
}

/// [`run_gpu`], also returning the paired schedule when the options pair pieces.
fn run_gpu_paired(c: &Case, options: TransferOptions) -> (TexelImage, Option<PairedSchedule>) {
    let gpu = gpu();
    let pass = TransferPass::new(&gpu, &options).unwrap();
    let scene = pass.prepare(&gpu, c.size, &c.atlases, &c.pieces).unwrap();
    let fo_tex = gpu
        .create_rgba32f_texture(
            "test.first_order",
            c.size[0],
            c.size[1],
            &c.first_order.rgba,
            wgpu::TextureUsages::TEXTURE_BINDING | options.texel_reads.usage(),
        )
        .unwrap();
    let fo_view = fo_tex.create_view(&Default::default());
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let out = pass
        .encode(
            &gpu,
            &mut enc,
            &TransferInputs {
                scene: &scene,
                first_order: &fo_view,
                base: None,
                pyramid: None,
            },
        )
        .unwrap();
    gpu.submit_and_wait("test.transfer", enc).unwrap();
    let img = gpu
        .read_texel_image("test.final", &out.final_lightmap_tex)
        .unwrap();
    // The scene keeps no pair texels once uploaded; rebuild them (deterministic) for the
    // mirror, and check the rebuilt pairing is the one drawn.
    let paired = scene.paired.as_ref().map(|drawn| {
        let limit = gpu.device.limits().max_texture_dimension_2d;
        let p = pair_schedule(&scene.schedule, &c.atlases, limit).unwrap();
        assert_eq!(p.singles, drawn.singles);
        let inst = |q: &PairedSchedule| {
            q.pages
                .iter()
                .map(|pg| pg.instances.clone())
                .collect::<Vec<_>>()
        };
        assert_eq!(inst(&p), inst(drawn));
        assert!(drawn.pages.iter().all(|pg| pg.texels.is_empty()));
        p
    });
    (img, paired)
}

/// Max over texels/channels of |a − b| / max(|b|, floor).
fn assert_close(got: &TexelImage, want: &TexelImage, rel: f32, floor: f32, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height));
    for (i, (g, w)) in got.rgba.iter().zip(&want.rgba).enumerate() {
        for ch in 0..4 {
            let err = (g[ch] - w[ch]).abs();
            assert!(
                err <= rel * w[ch].abs().max(floor),
                "{what}: texel {i} channel {ch}: got {} want {}",
                g[ch],
                w[ch]
            );
        }
    }
}

#[test]
fn cpu_mirrors_match_direct_eq9() {
    for seed in 1..4 {
        let c = random_case(seed);
        let (want, _) = reference(&c);
        let sizes: Vec<[u32; 2]> = c.atlases.iter().map(|a| [a.width, a.height]).collect();
        let s = build_schedule(c.size, &sizes, &c.pieces).unwrap();
        let blend = cpu::transfer::transfer(&s, &c.atlases, &c.first_order);
        let gather =
            cpu::transfer_gather::transfer_gather(&build_tiles(&s), &c.atlases, &c.first_order);
        assert_close(&blend, &want, 1e-5, 1e-3, "cpu blend");
        assert_close(&gather, &want, 1e-5, 1e-3, "cpu gather");
    }
}

#[test]
fn exact_single_piece() {
    // 3×2 map, one 2×1 piece at dst (1,0) reading Δt = (−1, 1), and one piece reading
    // outside the map (must add nothing).
    let mut fo = TexelImage::new(3, 2);
    for (i, px) in fo.rgba.iter_mut().enumerate() {
        *px = [i as f32 + 1.0, 2.0 * i as f32, 1.0, 1.0];
    }
    let atlas = AtlasData {
        width: 2,
        height: 1,
        rgb: vec![[0.5, 0.25, 1.0], [2.0, 1.0, 0.0]],
    };
    let pieces = [
        TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w: 2,
            h: 1,
            dst_x: 1,
            dst_y: 0,
            offset: [-1, 1],
            level: 0,
            receiver_level: 0,
        },
        TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w: 1,
            h: 1,
            dst_x: 0,
            dst_y: 0,
            offset: [0, 5],
            level: 0,
            receiver_level: 0,
        },
    ];
    let c = Case {
        size: [3, 2],
        atlases: vec![atlas],
        pieces: pieces.to_vec(),
        first_order: fo.clone(),
    };
    let mut want = fo.clone();
    // t=(1,0) reads (0,1) = index 3 → [4,6,1]; atlas (0,0) = [0.5,0.25,1].
    want.at_mut(1, 0)[0] += 0.5 * 4.0;
    want.at_mut(1, 0)[1] += 0.25 * 6.0;
    want.at_mut(1, 0)[2] += 1.0;
    // t=(2,0) reads (1,1) = index 4 → [5,8,1]; atlas (1,0) = [2,1,0].
    want.at_mut(2, 0)[0] += 10.0;
    want.at_mut(2, 0)[1] += 8.0;
    for path in [TransferPath::Blend, TransferPath::Compute] {
        let options = TransferOptions {
            path,
            accum_format: AccumFormat::Rgba32Float,
            pair_pieces: false,
            texel_reads: TexelReads::Sampled,
            rows_prune: 0.0,
        };
        assert_eq!(run_gpu(&c, options), want, "{path:?}");
        if let Some(options) = storage_reads(options) {
            assert_eq!(run_gpu(&c, options), want, "{path:?}, storage reads");
        }
    }
}

#[test]
fn blend_rgba32f_matches_cpu() {
    let c = random_case(7);
    let (want, _) = reference(&c);
    let options = TransferOptions {
        path: TransferPath::Blend,
        accum_format: AccumFormat::Rgba32Float,
        pair_pieces: false,
        texel_reads: TexelReads::Sampled,
        rows_prune: 0.0,
    };
    let got = run_gpu(&c, options);
    assert_close(&got, &want, 1e-3, 1e-3, "blend rgba32f");
    if let Some(options) = storage_reads(options) {
        assert_eq!(
            run_gpu(&c, options),
            got,
            "storage and sampled reads must agree bit for bit"
        );
    }
}

#[test]
fn compute_path_matches_cpu_and_blend() {
    let c = random_case(11);
    let (want, _) = reference(&c);
    let got = run_gpu(
        &c,
        TransferOptions {
            path: TransferPath::Compute,
            accum_format: AccumFormat::Rgba32Float,
            pair_pieces: false,
            texel_reads: TexelReads::Sampled,
            rows_prune: 0.0,
        },
    );
    assert_close(&got, &want, 1e-3, 1e-3, "compute");
    let blend = run_gpu(
        &c,
        TransferOptions {
            path: TransferPath::Blend,
            accum_format: AccumFormat::Rgba32Float,
            pair_pieces: false,
            texel_reads: TexelReads::Sampled,
            rows_prune: 0.0,
        },
    );
    assert_close(&got, &blend, 1e-5, 1e-3, "compute vs blend");
}

#[test]
fn blend_rgba16f_within_half_float_bound() {
    // Each of the n blends (and the copy and each product) rounds to binary16 with relative
    // error ≤ u = 2⁻¹¹, so |err| ≤ (2n + 2)·u·max|partial sum| + 2⁻²⁴ per texel.
    let c = random_case(13);
    let (want, mag) = reference(&c);
    let got = run_gpu(
        &c,
        TransferOptions {
            path: TransferPath::Blend,
            accum_format: AccumFormat::Rgba16Float,
            pair_pieces: false,
            texel_reads: TexelReads::Sampled,
            rows_prune: 0.0,
        },
    );
    let u = 2f32.powi(-11);
    for (i, ((g, w), (m, n))) in got.rgba.iter().zip(&want.rgba).zip(&mag).enumerate() {
        let bound = (2 * n + 2) as f32 * u * m + 2f32.powi(-24);
        for ch in 0..3 {
            assert!(
                (g[ch] - w[ch]).abs() <= bound,
                "texel {i} ch {ch}: got {} want {} bound {bound} (n = {n})",
                g[ch],
                w[ch]
            );
        }
        assert_eq!(g[3], w[3], "coverage alpha must be copied exactly");
    }
}

/// The paired path's derived bound (`pairing` module docs) per texel and channel: every stored
/// value has `|â − a| ≤ 2⁻¹¹·|a| + 2⁻²⁹·M` (M = the piece's largest |value|; the uncropped
/// piece's maximum is ≥ the cropped one's, so using it only loosens the bound), so the sum errs
/// by ≤ `2⁻¹¹·Σ|a·f| + 2⁻²⁹·Σ M·|f|`, plus f32 rounding in a different summation order:
/// ≤ `2·(n + 2)·2⁻²⁴·(|f₀| + Σ|a·f|)·(1 + 2⁻¹¹)` for n pieces at the texel.
fn paired_bound(c: &Case) -> Vec<[f32; 3]> {
    let maxima: Vec<f32> = c
        .pieces
        .iter()
        .map(|p| {
            let at = &c.atlases[p.atlas as usize];
            let mut m = 0f32;
            for y in p.src_y..p.src_y + p.h {
                for x in p.src_x..p.src_x + p.w {
                    m = at.rgb[(y * at.width + x) as usize]
                        .iter()
                        .fold(m, |m, v| m.max(v.abs()));
                }
            }
            m
        })
        .collect();
    let mut out = Vec::new();
    for y in 0..c.size[1] {
        for x in 0..c.size[0] {
            let f0 = c.first_order.get(x, y);
            let mut s1 = [0f32; 3];
            let mut s2 = [0f32; 3];
            let mut n = 0u32;
            for (p, m) in c.pieces.iter().zip(&maxima) {
                if x < p.dst_x || y < p.dst_y || x >= p.dst_x + p.w || y >= p.dst_y + p.h {
                    continue;
                }
                let at = &c.atlases[p.atlas as usize];
                let a =
                    at.rgb[((p.src_y + y - p.dst_y) * at.width + p.src_x + x - p.dst_x) as usize];
                let f = c
                    .first_order
                    .get_or_zero(x as i32 + p.offset[0], y as i32 + p.offset[1]);
                for ch in 0..3 {
                    s1[ch] += (a[ch] * f[ch]).abs();
                    s2[ch] += m * f[ch].abs();
                }
                n += 1;
            }
            let u = 2f32.powi(-11);
            out.push(std::array::from_fn(|ch| {
                u * s1[ch]
                    + 2f32.powi(-29) * s2[ch]
                    + 2.0 * (n + 2) as f32 * 2f32.powi(-24) * (f0[ch].abs() + s1[ch]) * (1.0 + u)
            }));
        }
    }
    out
}

fn paired_options() -> TransferOptions {
    TransferOptions {
        path: TransferPath::Blend,
        accum_format: AccumFormat::Rgba32Float,
        pair_pieces: true,
        texel_reads: TexelReads::Sampled,
        rows_prune: 0.0,
    }
}

/// Checks the paired GPU result against the independent Eq. 9 reference within the derived
/// bound, and against the paired CPU mirror (same binary16 values) within f32 rounding.
fn check_paired(c: &Case, what: &str) -> PairedSchedule {
    let (got, paired) = run_gpu_paired(c, paired_options());
    let paired = paired.expect("pair_pieces builds a paired schedule");
    if let Some(options) = storage_reads(paired_options()) {
        let (storage, _) = run_gpu_paired(c, options);
        assert_eq!(
            storage, got,
            "{what}: storage and sampled reads must agree bit for bit"
        );
    }
    let (want, _) = reference(c);
    let bound = paired_bound(c);
    for (i, ((g, w), b)) in got.rgba.iter().zip(&want.rgba).zip(&bound).enumerate() {
        for ch in 0..3 {
            assert!(
                (g[ch] - w[ch]).abs() <= b[ch],
                "{what}: texel {i} ch {ch}: got {} want {} bound {}",
                g[ch],
                w[ch],
                b[ch]
            );
        }
        assert_eq!(g[3], w[3], "{what}: coverage alpha must be copied exactly");
    }
    let mirror = cpu::transfer::transfer_paired(&paired, &c.atlases, &c.first_order);
    assert_close(&got, &mirror, 1e-5, 1e-3, what);
    paired
}

#[test]
fn paired_blend_within_binary16_bound() {
    for seed in [7, 11, 13] {
        let c = random_case(seed);
        let paired = check_paired(&c, &format!("paired, seed {seed}"));
        eprintln!("seed {seed}: {} pairs", paired.pairs);
        assert!(
            paired.pairs >= 2,
            "seed {seed}: only {} pairs",
            paired.pairs
        );
    }
}

#[test]
fn paired_partial_overlap_reads_outside_own_rect() {
    // 16×12 map. A: dst (2, 0), 10×10, Δt = (−2, 2): its reads stay in the map (x − 2 ≥ 0,
    // y + 2 < 12). B: dst (0, 4), 12×8, Δt = (4, −4). The pair's bounding box (0, 0)–(12, 12)
    // holds texels of A only, of B only, of both; at x < 2 A's read x − 2 leaves the map, and
    // at y ≥ 10 (rows of B only) A's read y + 2 ≥ 12 does too; at y < 4 B's read y − 4 < 0.
    let (w, h) = (16u32, 12u32);
    let mut first_order = TexelImage::new(w, h);
    for (i, px) in first_order.rgba.iter_mut().enumerate() {
        let i = i as f32;
        *px = [1.0 + i, 100.0 - 0.5 * i, 0.25 * i + 3.0, 1.0];
    }
    let mut atlas = AtlasData {
        width: 12,
        height: 18,
        rgb: (0..12 * 18)
            .map(|i| {
                let i = i as f32;
                // Values spanning several binades, none exactly representable in binary16.
                [
                    0.013 * (i + 1.0).sqrt(),
                    0.31 / (i + 3.0),
                    1e-4 * i + 1.234e-5,
                ]
            })
            .collect(),
    };
    // Values far below the piece's maximum (~0.19; scaled by 2^16): 1e-12 is stored as 0,
    // 7e-10 (scaled ≈ 4.6e-5 ∈ [2^−15, 2^−14)) as 2^−14 — never as a binary16 subnormal.
    atlas.rgb[2 * 12 + 3][1] = 1e-12;
    atlas.rgb[5 * 12 + 4][0] = 7e-10;
    let pieces = vec![
        TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 0,
            w: 10,
            h: 10,
            dst_x: 2,
            dst_y: 0,
            offset: [-2, 2],
            level: 0,
            receiver_level: 0,
        },
        TransferPiece {
            atlas: 0,
            src_x: 0,
            src_y: 10,
            w: 12,
            h: 8,
            dst_x: 0,
            dst_y: 4,
            offset: [4, -4],
            level: 0,
            receiver_level: 0,
        },
    ];
    let c = Case {
        size: [w, h],
        atlases: vec![atlas],
        pieces,
        first_order,
    };
    let paired = check_paired(&c, "partial overlap");
    assert_eq!(paired.pairs, 1);
    assert!(paired.singles.batches.is_empty());
    let inst = paired.pages[0].instances[0];
    assert_eq!((inst.dst, inst.size), ([0, 0], [12, 12]));
}
