//! Multi-resolution maps: the pyramid pass against its CPU mirror (derived f32 bound), every
//! transfer path (blend, paired blend, compute, rows) with pieces of levels 0..3, with and without
//! receiver blocks, against their CPU mirrors, the mirrors against the formula written out
//! here (no schedule, no reduction, no accumulation target),
//! the renderer end to end, and the errors (level > 0 without weights, bad weights, level
//! beyond the maximum).

mod common;

use common::demo::{blur_transfer, demo_lights, floor_and_box};
use common::{Rng, gpu};
use passes::frame::Renderer;
use passes::pyramid::{PyramidInputs, PyramidPass, level_size, unpack_levels};
use passes::rows::build_rows;
use passes::schedule::{build_schedule, build_tiles};
use passes::transfer::{AccumFormat, TransferInputs, TransferOptions, TransferPass, TransferPath};
use passes::util::TexelReads;
use passes::{AtlasData, Gpu, TexelImage, TexelWeights, TransferPiece, cpu};

/// f32 unit roundoff.
const U: f64 = 1.0 / (1u64 << 24) as f64;

struct Case {
    size: [u32; 2],
    atlases: Vec<AtlasData>,
    pieces: Vec<TransferPiece>,
    first_order: TexelImage,
    weights: TexelWeights,
}

/// Random first order (20 % uncovered: RGB 0, weight 0), random texel areas (some covered
/// texels weigh 0 too), and pieces of levels `0..=max_piece_level` with offsets in blocks;
/// with `blocks`, every other piece of level ℓ ≥ 1 has a receiver level `1..=ℓ` (its
/// rectangle in that level's block grid).
fn random_case(seed: u64, size: [u32; 2], max_piece_level: u32, blocks: bool) -> Case {
    let mut r = Rng::new(seed);
    let n = (size[0] * size[1]) as usize;
    let mut first_order = TexelImage::new(size[0], size[1]);
    let mut weights = vec![0.0f32; n];
    for (px, w) in first_order.rgba.iter_mut().zip(&mut weights) {
        if r.f32() < 0.8 {
            *px = [10.0 * r.f32(), 5.0 * r.f32(), r.f32(), 1.0];
            *w = if r.f32() < 0.05 {
                0.0
            } else {
                1e-4 * (0.5 + r.f32())
            };
        }
    }
    let atlas_sizes = [[32u32, 32u32], [16, 40]];
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
    for k in 0..48 {
        let a = r.range(0, 1) as usize;
        let [aw, ah] = atlas_sizes[a];
        // Every level appears; offsets span a little beyond each level's size.
        let level = (k % (max_piece_level + 1) as usize) as u32;
        let receiver_level =
            if blocks && level > 0 && (k / (max_piece_level as usize + 1)).is_multiple_of(2) {
                1 + (k as u32 / 2) % level
            } else {
                0
            };
        let grid = level_size(size, receiver_level);
        let w = r.range(1, aw.min(grid[0]) as i64) as u32;
        let h = r.range(1, ah.min(grid[1]) as i64) as u32;
        let [lw, lh] = level_size(size, level);
        pieces.push(TransferPiece {
            atlas: a as u32,
            src_x: r.range(0, (aw - w) as i64) as u32,
            src_y: r.range(0, (ah - h) as i64) as u32,
            w,
            h,
            dst_x: r.range(0, (grid[0] - w) as i64) as u32,
            dst_y: r.range(0, (grid[1] - h) as i64) as u32,
            offset: [
                r.range(-(lw as i64) / 2, lw as i64 / 2) as i32,
                r.range(-(lh as i64) / 2, lh as i64 / 2) as i32,
            ],
            level,
            receiver_level,
        });
    }
    Case {
        size,
        atlases,
        pieces,
        first_order,
        weights: TexelWeights {
            width: size[0],
            height: size[1],
            weights,
        },
    }
}

/// The pyramid written out from its definition (module docs of `passes::pyramid`): block `b`
/// of level ℓ = the `f64` area-weighted mean of the level-0 texels `[b·2^ℓ, (b+1)·2^ℓ)` in the
/// map, 0 where they weigh nothing. Also the absolute mean `Σ w·|B| / Σ w` and `Σ w` per block
/// (for the f32 bound). Index `ℓ` = level ℓ (level 0 included).
#[allow(clippy::type_complexity, reason = "three parallel per-block results")]
fn direct_pyramid(c: &Case, max_level: u32) -> Vec<(Vec<[f64; 3]>, Vec<f64>, Vec<f64>)> {
    let [w, h] = c.size;
    (0..=max_level)
        .map(|l| {
            let [bw, bh] = level_size(c.size, l);
            let (mut mean, mut abs_mean, mut area) = (Vec::new(), Vec::new(), Vec::new());
            for by in 0..bh {
                for bx in 0..bw {
                    let (mut s, mut sa, mut a) = ([0.0f64; 3], 0.0f64, 0.0f64);
                    for y in (by << l)..((by + 1) << l).min(h) {
                        for x in (bx << l)..((bx + 1) << l).min(w) {
                            let wt = c.weights.weights[(y * w + x) as usize] as f64;
                            let f = c.first_order.get(x, y);
                            for ch in 0..3 {
                                s[ch] += wt * f[ch] as f64;
                            }
                            sa += wt * f[..3].iter().map(|v| v.abs() as f64).fold(0.0, f64::max);
                            a += wt;
                        }
                    }
                    let m = if a > 0.0 { s.map(|v| v / a) } else { [0.0; 3] };
                    mean.push(m);
                    abs_mean.push(if a > 0.0 { sa / a } else { 0.0 });
                    area.push(a);
                }
            }
            (mean, abs_mean, area)
        })
        .collect()
}

/// Eq. 9 with levels written out per texel from (1): `final[t] = B_o(t) + Σ_{pieces ∋ c}
/// atlas[src + c − dst] · P_ℓ(⌊c/2^(ℓ−r)⌋ + Δ)`, `c = ⌊t/2^r⌋` the piece's receiver (the
/// texel itself for `r = 0`; for `r > 0` only covered texels, alpha > 0, receive), `P` from
/// [`direct_pyramid`], 0 outside level ℓ.
fn direct_final(c: &Case) -> TexelImage {
    let max_level = c.pieces.iter().map(|p| p.level).max().unwrap_or(0);
    let pyr = direct_pyramid(c, max_level);
    let mut out = c.first_order.clone();
    for y in 0..c.size[1] {
        for x in 0..c.size[0] {
            let mut acc = [0.0f64; 3];
            let covered = c.first_order.get(x, y)[3] > 0.0;
            for p in &c.pieces {
                let rl = p.receiver_level;
                if rl > 0 && !covered {
                    continue;
                }
                let (cx, cy) = (x >> rl, y >> rl);
                if cx < p.dst_x || cy < p.dst_y || cx >= p.dst_x + p.w || cy >= p.dst_y + p.h {
                    continue;
                }
                let at = &c.atlases[p.atlas as usize];
                let a =
                    at.rgb[((p.src_y + cy - p.dst_y) * at.width + p.src_x + cx - p.dst_x) as usize];
                let l = p.level;
                let [bw, bh] = level_size(c.size, l);
                let bx = (cx >> (l - rl)) as i64 + p.offset[0] as i64;
                let by = (cy >> (l - rl)) as i64 + p.offset[1] as i64;
                if bx < 0 || by < 0 || bx >= bw as i64 || by >= bh as i64 {
                    continue;
                }
                // P_0 is the first-order map itself (whatever the weights); P_ℓ≥1 the means.
                let v = if l == 0 {
                    c.first_order.get(bx as u32, by as u32)[..3]
                        .iter()
                        .map(|&v| v as f64)
                        .collect::<Vec<_>>()
                } else {
                    pyr[l as usize].0[(by * bw as i64 + bx) as usize].to_vec()
                };
                for ch in 0..3 {
                    acc[ch] += a[ch] as f64 * v[ch];
                }
            }
            let o = out.at_mut(x, y);
            for ch in 0..3 {
                o[ch] = (o[ch] as f64 + acc[ch]) as f32;
            }
        }
    }
    out
}

/// `|got − want| ≤ rel·max(|want|, floor)` per texel and channel.
fn assert_close(got: &TexelImage, want: &TexelImage, rel: f32, floor: f32, what: &str) {
    assert_eq!((got.width, got.height), (want.width, want.height));
    for (i, (g, w)) in got.rgba.iter().zip(&want.rgba).enumerate() {
        for ch in 0..4 {
            assert!(
                (g[ch] - w[ch]).abs() <= rel * w[ch].abs().max(floor),
                "{what}: texel {i} channel {ch}: got {} want {}",
                g[ch],
                w[ch]
            );
        }
    }
}

fn first_order_texture(gpu: &Gpu, c: &Case, reads: TexelReads) -> wgpu::TextureView {
    gpu.create_rgba32f_texture(
        "test.first_order",
        c.size[0],
        c.size[1],
        &c.first_order.rgba,
        wgpu::TextureUsages::TEXTURE_BINDING | reads.usage(),
    )
    .unwrap()
    .create_view(&Default::default())
}

/// Runs the pyramid pass on the GPU; returns levels `1..=max_level` read back.
fn gpu_pyramid(gpu: &Gpu, c: &Case, max_level: u32) -> Vec<TexelImage> {
    let pass = PyramidPass::new(gpu).unwrap();
    let scene = pass.prepare(gpu, c.size, &c.weights, max_level).unwrap();
    let fo = first_order_texture(gpu, c, TexelReads::Sampled);
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    encode_pyramid(gpu, &pass, &mut enc, &scene, &fo);
    gpu.submit_and_wait("test.pyramid", enc).unwrap();
    let packed = gpu
        .read_texel_image("test.pyramid", scene.texture())
        .unwrap();
    unpack_levels(&packed, c.size, max_level)
}

/// The f32 bound of the pyramid pass (derived in `pyramid_pass_matches_mirror_within_f32_bound`).
fn check_pyramid(c: &Case, max_level: u32, got: &[TexelImage], what: &str) {
    let mirror = cpu::pyramid::pyramid(&c.first_order, &c.weights, max_level);
    let direct = direct_pyramid(c, max_level);
    assert_eq!(got.len(), max_level as usize);
    for l in 1..=max_level {
        let (g, m) = (&got[l as usize - 1], &mirror[l as usize - 1]);
        let (_, abs_mean, area) = &direct[l as usize];
        assert_eq!([g.width, g.height], level_size(c.size, l));
        assert_eq!([m.width, m.height], level_size(c.size, l));
        let lf = l as f64;
        for (i, ((gv, mv), (am, a))) in g
            .rgba
            .iter()
            .zip(&m.rgba)
            .zip(abs_mean.iter().zip(area))
            .enumerate()
        {
            let bound = (6.0 * lf + 8.0) * U * am;
            for ch in 0..3 {
                let err = (gv[ch] as f64 - mv[ch] as f64).abs();
                assert!(
                    err <= bound,
                    "{what}: level {l} block {i} ch {ch}: gpu {} mirror {} bound {bound:e}",
                    gv[ch],
                    mv[ch]
                );
            }
            let abound = (3.0 * lf + 1.0) * U * a * 1.001;
            assert!(
                (gv[3] as f64 - mv[3] as f64).abs() <= abound,
                "{what}: level {l} block {i} weight: gpu {} mirror {}",
                gv[3],
                mv[3]
            );
            if *a == 0.0 {
                assert_eq!(*gv, [0.0; 4], "{what}: weightless block {i} of level {l}");
            }
        }
    }
}

/// GPU pyramid vs mirror per block. Bound (f32, `u = 2⁻²⁴`, level ℓ, `T = Σ w·|B|`, `A = Σ w`
/// over the block, `M = T/A`): the GPU rounds each product `w·B` once and each 2×2 node adds
/// 4 values with 3 roundings, so `|S̃ − S| ≤ (3ℓ + 1)·u·T` and `|Ã − A| ≤ 3ℓ·u·A` (weights
/// are exact f32, all terms of `A` are ≥ 0); the division is within 2.5 ulp `= 5u`, so
/// `|S̃/Ã − S/A| ≤ (6ℓ + 1)·u·M + 5u·M` to first order; the mirror rounds its f64 mean once
/// (`u·M`): `(6ℓ + 8)·u·M` covers the rest. Weightless blocks are exactly 0.
#[test]
fn pyramid_pass_matches_mirror_within_f32_bound() {
    let gpu = gpu();
    for (seed, size, max_level) in [
        (1, [37, 29], 7),
        (2, [64, 64], 7),
        (3, [5, 130], 9),
        (4, [1, 1], 2),
    ] {
        let c = random_case(seed, size, 0, false);
        let got = gpu_pyramid(&gpu, &c, max_level);
        check_pyramid(&c, max_level, &got, &format!("{size:?}"));
        // The top level of a map of one block is the whole map's mean.
        let top = &got[max_level as usize - 1];
        assert_eq!([top.width, top.height], [1, 1]);
    }
}

/// The mirrors against the formula of (1)–(2) written out in this file: the pyramid mirror
/// (2×2 reductions) against the direct block means, and the blend / gather mirrors (schedule,
/// crops, tiles) against the per-texel sum, for levels 0..3 on a non-power-of-two and a
/// power-of-two map.
#[test]
fn mirrors_match_the_direct_formula() {
    for (seed, size, blocks) in [
        (5, [37u32, 29u32], false),
        (6, [32, 32], false),
        (15, [37, 29], true),
        (16, [32, 32], true),
    ] {
        let c = random_case(seed, size, 3, blocks);
        let mirror = cpu::pyramid::pyramid(&c.first_order, &c.weights, 3);
        let direct = direct_pyramid(&c, 3);
        for l in 1..=3usize {
            for (i, (m, d)) in mirror[l - 1].rgba.iter().zip(&direct[l].0).enumerate() {
                for ch in 0..3 {
                    // f64 sums in a different order, rounded once to f32.
                    assert!(
                        (m[ch] as f64 - d[ch]).abs() <= 2.0 * U * d[ch].abs() + 1e-30,
                        "{size:?} level {l} block {i}: mirror {} direct {}",
                        m[ch],
                        d[ch]
                    );
                }
            }
        }
        let want = direct_final(&c);
        let sizes: Vec<[u32; 2]> = c.atlases.iter().map(|a| [a.width, a.height]).collect();
        let s = build_schedule(c.size, &sizes, &c.pieces).unwrap();
        assert_eq!(s.max_level(), 3);
        assert_eq!(s.receiver_levels, if blocks { 3 } else { 0 });
        let blend = cpu::transfer::transfer_levels(&s, &c.atlases, &c.first_order, &mirror);
        let gather = cpu::transfer_gather::transfer_gather_levels(
            &build_tiles(&s),
            &c.atlases,
            &c.first_order,
            &mirror,
            s.receiver_levels,
        );
        let rows = cpu::transfer_rows::transfer_rows(
            &build_rows(&s, &c.atlases).unwrap(),
            &c.first_order,
            None,
            &mirror,
        );
        assert_close(&blend, &want, 1e-5, 1e-3, "cpu blend vs direct");
        assert_close(&gather, &want, 1e-5, 1e-3, "cpu gather vs direct");
        assert_close(&rows, &want, 1e-5, 1e-3, "cpu rows vs direct");
    }
}

/// Records the pyramid pass building `scene` from `first_order`.
fn encode_pyramid(
    gpu: &Gpu,
    pass: &PyramidPass,
    enc: &mut wgpu::CommandEncoder,
    scene: &passes::pyramid::PyramidScene,
    first_order: &wgpu::TextureView,
) {
    pass.encode(gpu, enc, &PyramidInputs { scene, first_order });
}

/// Runs the transfer pass (with the pyramid pass first when needed) on the GPU; returns the
/// final map, the pyramid levels it read (read back) and the pass's scene pieces.
fn run_transfer(
    gpu: &Gpu,
    c: &Case,
    options: TransferOptions,
) -> (TexelImage, Vec<TexelImage>, passes::transfer::TransferScene) {
    let pass = TransferPass::new(gpu, &options).unwrap();
    let scene = pass.prepare(gpu, c.size, &c.atlases, &c.pieces).unwrap();
    let fo = first_order_texture(gpu, c, options.texel_reads);
    let max_level = scene.max_level();
    let pyr_pass = PyramidPass::new(gpu).unwrap();
    let pyr = (max_level > 0).then(|| {
        pyr_pass
            .prepare(gpu, c.size, &c.weights, max_level)
            .unwrap()
    });
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    if let Some(p) = &pyr {
        encode_pyramid(gpu, &pyr_pass, &mut enc, p, &fo);
    }
    let out = pass
        .encode(
            gpu,
            &mut enc,
            &TransferInputs {
                scene: &scene,
                first_order: &fo,
                base: None,
                pyramid: pyr.as_ref(),
            },
        )
        .unwrap();
    gpu.submit_and_wait("test.transfer", enc).unwrap();
    let img = gpu
        .read_texel_image("test.final", &out.final_lightmap_tex)
        .unwrap();
    let levels = match &pyr {
        Some(p) => {
            let packed = gpu.read_texel_image("test.pyramid", p.texture()).unwrap();
            unpack_levels(&packed, c.size, max_level)
        }
        None => Vec::new(),
    };
    (img, levels, scene)
}

fn options(path: TransferPath, pair_pieces: bool, texel_reads: TexelReads) -> TransferOptions {
    TransferOptions {
        path,
        accum_format: AccumFormat::Rgba32Float,
        pair_pieces,
        texel_reads,
        rows_prune: 0.0,
    }
}

/// Every transfer path (blend, paired blend, compute, rows; sampled and storage reads) with pieces
/// of levels 0..3 equal their CPU mirrors per texel (the mirrors read the pyramid the GPU
/// built, so only the transfer is compared: the bounds of `tests/transfer.rs`), and the
/// direct formula within its 1e-3 bound, on a non-power-of-two and a power-of-two map.
#[test]
fn transfer_paths_with_levels_match_mirrors() {
    let gpu = gpu();
    let storage = common::has_storage_reads(&gpu, "levels storage reads");
    for (seed, size, blocks) in [
        (7, [37u32, 29u32], false),
        (8, [64, 64], false),
        (17, [37, 29], true),
        (18, [64, 64], true),
    ] {
        let c = random_case(seed, size, 3, blocks);
        let want = direct_final(&c);
        let mut reads = vec![TexelReads::Sampled];
        if storage {
            reads.push(TexelReads::Storage);
        }
        for &r in &reads {
            for (path, paired) in [
                (TransferPath::Blend, false),
                (TransferPath::Blend, true),
                (TransferPath::Compute, false),
                (TransferPath::Rows, false),
            ] {
                let what = format!("{size:?} blocks {blocks} {path:?} paired {paired} {r:?}");
                let (got, levels, scene) = run_transfer(&gpu, &c, options(path, paired, r));
                check_pyramid(&c, 3, &levels, &what);
                let s = &scene.schedule;
                assert_eq!(s.receiver_levels > 0, blocks, "{what}");
                let mirror = match (path, paired) {
                    (TransferPath::Rows, _) => cpu::transfer_rows::transfer_rows(
                        &build_rows(s, &c.atlases).unwrap(),
                        &c.first_order,
                        None,
                        &levels,
                    ),
                    (TransferPath::Compute, _) => cpu::transfer_gather::transfer_gather_levels(
                        &build_tiles(s),
                        &c.atlases,
                        &c.first_order,
                        &levels,
                        s.receiver_levels,
                    ),
                    (_, false) => {
                        cpu::transfer::transfer_levels(s, &c.atlases, &c.first_order, &levels)
                    }
                    (_, true) => {
                        let limit = gpu.device.limits().max_texture_dimension_2d;
                        let p = passes::pairing::pair_schedule(s, &c.atlases, limit).unwrap();
                        let coarse_pairs = p
                            .pages
                            .iter()
                            .flat_map(|pg| &pg.instances)
                            .filter(|i| i.level > 0)
                            .count();
                        assert!(coarse_pairs > 0 || blocks, "{what}: no pair of level > 0");
                        let block_pairs = p.singles.batches.iter().flat_map(|b| &b.instances);
                        assert_eq!(
                            block_pairs.filter(|i| i.receiver_level > 0).count(),
                            s.batches
                                .iter()
                                .flat_map(|b| &b.instances)
                                .filter(|i| i.receiver_level > 0)
                                .count(),
                            "{what}: every receiver-block piece stays single"
                        );
                        cpu::transfer::transfer_paired_levels(
                            &p,
                            &c.atlases,
                            &c.first_order,
                            &levels,
                        )
                    }
                };
                assert_close(&got, &mirror, 1e-5, 1e-3, &format!("{what}: gpu vs mirror"));
                // Binary16 pairs err by ≤ 2⁻¹¹ relative per term: within 1e-3 too.
                assert_close(&got, &want, 1e-3, 1e-3, &format!("{what}: gpu vs direct"));
            }
        }
    }
}

/// Level-0 pieces read exactly what they read before levels existed: a pyramid given with
/// them changes nothing, bit for bit, on every path.
#[test]
fn level_zero_ignores_the_pyramid_bit_for_bit() {
    let gpu = gpu();
    let c = random_case(9, [37, 29], 0, false);
    for (path, paired) in [
        (TransferPath::Blend, false),
        (TransferPath::Blend, true),
        (TransferPath::Compute, false),
        (TransferPath::Rows, false),
    ] {
        let o = options(path, paired, TexelReads::Sampled);
        let (plain, levels, scene) = run_transfer(&gpu, &c, o);
        assert!(levels.is_empty() && scene.max_level() == 0);
        let sizes: Vec<[u32; 2]> = c.atlases.iter().map(|a| [a.width, a.height]).collect();
        let s = build_schedule(c.size, &sizes, &c.pieces).unwrap();
        // The level-0 mirror is the original mirror.
        if path == TransferPath::Blend && !paired {
            let mirror = cpu::transfer::transfer(&s, &c.atlases, &c.first_order);
            assert_close(&plain, &mirror, 1e-5, 1e-3, "level 0 blend");
        }
        // With a (needless) pyramid bound: identical.
        let pass = TransferPass::new(&gpu, &o).unwrap();
        let scene = pass.prepare(&gpu, c.size, &c.atlases, &c.pieces).unwrap();
        let pyr_pass = PyramidPass::new(&gpu).unwrap();
        let pyr = pyr_pass.prepare(&gpu, c.size, &c.weights, 2).unwrap();
        let fo = first_order_texture(&gpu, &c, TexelReads::Sampled);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        encode_pyramid(&gpu, &pyr_pass, &mut enc, &pyr, &fo);
        let out = pass
            .encode(
                &gpu,
                &mut enc,
                &TransferInputs {
                    scene: &scene,
                    first_order: &fo,
                    base: None,
                    pyramid: Some(&pyr),
                },
            )
            .unwrap();
        gpu.submit_and_wait("test.transfer", enc).unwrap();
        let with = gpu
            .read_texel_image("test.final", &out.final_lightmap_tex)
            .unwrap();
        assert_eq!(with, plain, "{path:?} paired {paired}");
    }
}

/// The rows path in many bands (at most 40 entries each) equals it in one band bit for bit,
/// with a base distinct from the pieces' input both equal the mirror, and a lightmap row
/// with more entries than a band may hold is a clear error naming the row.
#[test]
fn rows_in_bands_with_a_base_match_the_mirror() {
    use passes::transfer_rows::RowsPass;
    let gpu = gpu();
    let c = random_case(27, [37, 29], 3, true);
    let sizes: Vec<[u32; 2]> = c.atlases.iter().map(|a| [a.width, a.height]).collect();
    let s = build_schedule(c.size, &sizes, &c.pieces).unwrap();
    let rows = build_rows(&s, &c.atlases).unwrap();
    let widest = (0..c.size[1])
        .map(|y| {
            rows.offsets[((y + 1) * c.size[0]) as usize] - rows.offsets[(y * c.size[0]) as usize]
        })
        .max()
        .unwrap() as u64;
    let fo = first_order_texture(&gpu, &c, TexelReads::Sampled);
    // The base: the first order scaled per texel (coverage kept), so that a path adding the
    // wrong map shows.
    let mut base = c.first_order.clone();
    for (i, px) in base.rgba.iter_mut().enumerate() {
        for v in &mut px[..3] {
            *v *= 0.5 + (i % 7) as f32 * 0.1;
        }
    }
    let base_view = gpu
        .create_rgba32f_texture(
            "test.base",
            c.size[0],
            c.size[1],
            &base.rgba,
            wgpu::TextureUsages::TEXTURE_BINDING,
        )
        .unwrap()
        .create_view(&Default::default());
    let max_level = s.max_level();
    let pyr_pass = PyramidPass::new(&gpu).unwrap();
    let pyr = pyr_pass
        .prepare(&gpu, c.size, &c.weights, max_level)
        .unwrap();
    let run = |band_entries: Option<u64>| {
        let mut pass = RowsPass::new(&gpu).unwrap();
        if let Some(n) = band_entries {
            pass = pass.with_band_entries(n);
        }
        let (scene, tex) = pass.prepare(&gpu, &rows)?;
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        encode_pyramid(&gpu, &pyr_pass, &mut enc, &pyr, &fo);
        pass.encode(
            &gpu.device,
            &mut enc,
            &scene,
            (&fo, Some(&base_view), pyr.view()),
        );
        gpu.submit_and_wait("test.rows", enc).unwrap();
        let packed = gpu.read_texel_image("test.pyramid", pyr.texture()).unwrap();
        let img = gpu.read_texel_image("test.final", &tex).unwrap();
        Ok::<_, passes::PassError>((
            img,
            scene.bands(),
            unpack_levels(&packed, c.size, max_level),
        ))
    };
    let (one, n1, levels) = run(None).unwrap();
    let (many, n40, _) = run(Some(widest.max(40))).unwrap();
    assert_eq!(n1, 1);
    assert!(n40 > 3, "{n40} bands");
    assert_eq!(one, many, "bands change nothing");
    let mirror = cpu::transfer_rows::transfer_rows(&rows, &c.first_order, Some(&base), &levels);
    assert_close(&one, &mirror, 1e-5, 1e-3, "rows with a base: gpu vs mirror");
    // The base is what the final starts from: final − base is the transfer of the first order.
    let plain = cpu::transfer_rows::transfer_rows(&rows, &c.first_order, None, &levels);
    for (i, ((m, p), (b, f))) in mirror
        .rgba
        .iter()
        .zip(&plain.rgba)
        .zip(base.rgba.iter().zip(&c.first_order.rgba))
        .enumerate()
    {
        for ch in 0..3 {
            let want = p[ch] - f[ch] + b[ch];
            assert!(
                (m[ch] - want).abs() <= 1e-5 * want.abs().max(1.0),
                "texel {i} channel {ch}: {} against {want}",
                m[ch]
            );
        }
    }
    match run(Some(widest - 1)) {
        Err(passes::PassError::TooLarge { what, .. }) => {
            assert!(what.contains("entries of lightmap row"), "{what}")
        }
        other => panic!("a row wider than a band: {:?}", other.map(|r| r.1)),
    }
}

/// Pieces of level > 0 without weights (renderer) or without a pyramid (transfer pass) are
/// clear errors; so are bad weights and a level beyond the maximum.
#[test]
fn levels_without_weights_and_bad_inputs_are_errors() {
    let gpu = gpu();
    let size = 32;
    let renderer = Renderer::new(&gpu, &common::demo_renderer_options(32, 32)).unwrap();
    let (mesh, albedo) = floor_and_box(size);
    let (atlases, mut pieces) = blur_transfer([size, size], 2, 1, 0.02);
    pieces[0].level = 1;
    let e = renderer
        .prepare(&gpu, &mesh, &albedo, &atlases, &pieces)
        .unwrap_err()
        .to_string();
    assert!(e.contains("texel weights") && e.contains("level 1"), "{e}");
    let mut bad = TexelWeights {
        width: size,
        height: size,
        weights: vec![1.0; (size * size) as usize],
    };
    bad.weights[5] = -1.0;
    let e = renderer
        .prepare_with_weights(&gpu, &mesh, &albedo, &atlases, &pieces, Some(&bad))
        .unwrap_err()
        .to_string();
    assert!(e.contains("weights[5]"), "{e}");
    bad.weights.pop();
    let e = renderer
        .prepare_with_weights(&gpu, &mesh, &albedo, &atlases, &pieces, Some(&bad))
        .unwrap_err()
        .to_string();
    assert!(e.contains("TexelWeights.weights"), "{e}");
    pieces[3].level = 16;
    let e = renderer
        .prepare(&gpu, &mesh, &albedo, &atlases, &pieces)
        .unwrap_err()
        .to_string();
    assert!(e.contains("pieces[3].level"), "{e}");

    // The transfer pass alone: encoding level > 0 pieces without a pyramid.
    let c = random_case(10, [37, 29], 2, false);
    let o = options(TransferPath::Blend, false, TexelReads::Sampled);
    let pass = TransferPass::new(&gpu, &o).unwrap();
    let scene = pass.prepare(&gpu, c.size, &c.atlases, &c.pieces).unwrap();
    let fo = first_order_texture(&gpu, &c, TexelReads::Sampled);
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let inputs = TransferInputs {
        scene: &scene,
        first_order: &fo,
        base: None,
        pyramid: None,
    };
    let e = pass
        .encode(&gpu, &mut enc, &inputs)
        .unwrap_err()
        .to_string();
    assert!(e.contains("pyramid"), "{e}");
    // A pyramid that stops below the pieces' level.
    let pyr = PyramidPass::new(&gpu)
        .unwrap()
        .prepare(&gpu, c.size, &c.weights, 1)
        .unwrap();
    let inputs = TransferInputs {
        pyramid: Some(&pyr),
        ..inputs
    };
    let e = pass
        .encode(&gpu, &mut enc, &inputs)
        .unwrap_err()
        .to_string();
    assert!(e.contains("level 2"), "{e}");
}

/// The renderer builds the pyramid after the first order and the transfer reads it: the
/// final map equals the mirrors run on the read-back first order.
#[test]
fn renderer_with_levels_matches_mirrors() {
    let gpu = gpu();
    let size = 48;
    let renderer = Renderer::new(&gpu, &common::demo_renderer_options(32, 32)).unwrap();
    let (mesh, albedo) = floor_and_box(size);
    let (atlases, mut pieces) = blur_transfer([size, size], 2, 1, 0.02);
    for (k, p) in pieces.iter_mut().enumerate() {
        p.level = k as u32 % 4;
    }
    let mut r = Rng::new(12);
    let weights = TexelWeights {
        width: size,
        height: size,
        weights: (0..size * size).map(|_| 0.5 + r.f32()).collect(),
    };
    let scene = renderer
        .prepare_with_weights(&gpu, &mesh, &albedo, &atlases, &pieces, Some(&weights))
        .unwrap();
    assert_eq!(scene.pyramid.as_ref().map(|p| p.max_level()), Some(3));
    let (fo, fin) = renderer
        .render_lightmaps(&gpu, &scene, &demo_lights())
        .unwrap();
    let levels = cpu::pyramid::pyramid(&fo, &weights, 3);
    let want = match &scene.transfer.paired {
        Some(_) => {
            let limit = gpu.device.limits().max_texture_dimension_2d;
            let p =
                passes::pairing::pair_schedule(&scene.transfer.schedule, &atlases, limit).unwrap();
            cpu::transfer::transfer_paired_levels(&p, &atlases, &fo, &levels)
        }
        None => cpu::transfer::transfer_levels(&scene.transfer.schedule, &atlases, &fo, &levels),
    };
    assert_close(&fin, &want, 1e-3, 1e-3, "renderer with levels");
    let brighter = fin
        .rgba
        .iter()
        .zip(&fo.rgba)
        .filter(|(f, o)| f[0] > o[0])
        .count();
    assert!(
        brighter > 500,
        "the transfer must add light ({brighter} texels)"
    );
}
