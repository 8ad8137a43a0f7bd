//! CPU mirror of the blend path of the transfer pass (`shaders/transfer.wgsl`).
//!
//! Same order of operations as the GPU: the final map starts as a copy of the first-order
//! map (`fs_copy`), then every atlas batch in order, every piece in order, every texel of
//! the piece adds `atlas[src + (i,j)] · P_ℓ(⌊t / 2^ℓ⌋ + Δ)` (`fs_piece`; `t = dst + (i,j)`,
//! `P_0` = the first-order map, `P_ℓ` for `ℓ ≥ 1` the given pyramid levels, see
//! [`super::pyramid::read`]), read as zero outside the level. Alpha (coverage) is copied, never
//! added to. Arithmetic is `f32`; the RGBA16F accumulation option of the GPU rounds after every
//! blend and is compared against this mirror with a derived bound.
//!
//! With receiver blocks ([`crate::schedule`], "Receiver blocks") the accumulation target is
//! the lightmap with the grids `G_r` below it (the copy fills only the lightmap, the rest
//! starts at 0), and [`resolve`] (`shaders/transfer_resolve.wgsl`) gives the final map:
//! `acc[t] + Σ_r acc[block_origin(r) + ⌊t/2^r⌋]` at covered texels (alpha > 0), summed in
//! `r` order in `f32`.

use super::pyramid::read;
use crate::gpu::f16_to_f32;
use crate::pairing::PairedSchedule;
use crate::pyramid::level_size;
use crate::schedule::{FrameSchedule, PieceInstance, block_origin, target_size};
use crate::types::{AtlasData, TexelImage};

/// What instance `inst` reads at target texel `t` (`fs_piece`, `cs_gather`): `P_ℓ` at
/// `⌊(t − block_origin)/2^(ℓ−r)⌋ + Δ` (for `r = 0`: `⌊t/2^ℓ⌋ + Δ`), 0 outside level `ℓ`.
pub(crate) fn piece_read(
    first_order: &TexelImage,
    levels: &[TexelImage],
    inst: &PieceInstance,
    t: [u32; 2],
) -> [f32; 4] {
    let shift = inst.level - inst.receiver_level;
    let c = [t[0] - inst.block_origin[0], t[1] - inst.block_origin[1]];
    read(
        first_order,
        levels,
        inst.level,
        (c[0] >> shift) as i32 + inst.offset[0],
        (c[1] >> shift) as i32 + inst.offset[1],
    )
}

/// The accumulation target before any piece: the first-order map (RGBA) at the top left of a
/// `target_size(lightmap, receiver_levels)` image, 0 elsewhere (`fs_copy` / `cs_init`).
pub(crate) fn init_target(first_order: &TexelImage, receiver_levels: u32) -> TexelImage {
    let size = [first_order.width, first_order.height];
    if receiver_levels == 0 {
        return first_order.clone();
    }
    let [tw, th] = target_size(size, receiver_levels);
    let mut acc = TexelImage::new(tw, th);
    for y in 0..size[1] {
        for x in 0..size[0] {
            *acc.at_mut(x, y) = first_order.get(x, y);
        }
    }
    acc
}

/// The final lightmap (`lightmap_size`) from an accumulation target holding receiver levels
/// `1..=receiver_levels` (`shaders/transfer_resolve.wgsl`, `cs_resolve`): `acc[t]`, plus at
/// covered texels (alpha > 0) `Σ_r acc[block_origin(r) + ⌊t/2^r⌋]`, in `r` order, `f32`.
pub fn resolve(lightmap_size: [u32; 2], receiver_levels: u32, acc: &TexelImage) -> TexelImage {
    let [w, h] = lightmap_size;
    if receiver_levels == 0 && (acc.width, acc.height) == (w, h) {
        return acc.clone();
    }
    let mut out = TexelImage::new(w, h);
    for y in 0..h {
        for x in 0..w {
            let own = acc.get(x, y);
            let mut v = own;
            if own[3] > 0.0 {
                for r in 1..=receiver_levels {
                    let o = block_origin(lightmap_size, r);
                    let g = acc.get(o[0] + (x >> r), o[1] + (y >> r));
                    for c in 0..3 {
                        v[c] += g[c];
                    }
                }
            }
            *out.at_mut(x, y) = v;
        }
    }
    out
}

/// `final = first_order + Σ pieces` in blend order, every piece of level 0.
pub fn transfer(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
) -> TexelImage {
    transfer_levels(schedule, atlases, first_order, &[])
}

/// [`transfer`] with pieces of any level: `levels[ℓ − 1]` is pyramid level `ℓ` (as
/// [`super::pyramid::pyramid`] returns or read back from the GPU, e.g. with
/// [`crate::pyramid::unpack_levels`]). Panics when a piece's level is beyond `levels`.
pub fn transfer_levels(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
    levels: &[TexelImage],
) -> TexelImage {
    let acc = accumulate(schedule, atlases, first_order, levels);
    resolve(schedule.lightmap_size, schedule.receiver_levels, &acc)
}

/// The accumulation target after the copy and every piece of `schedule` (before the resolve).
fn accumulate(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
    levels: &[TexelImage],
) -> TexelImage {
    // fs_copy: the accumulation target starts as the first-order map (alpha = coverage).
    let mut out = init_target(first_order, schedule.receiver_levels);
    for batch in &schedule.batches {
        let atlas = &atlases[batch.atlas as usize];
        for inst in &batch.instances {
            for j in 0..inst.size[1] {
                for i in 0..inst.size[0] {
                    // fs_piece: texel of the quad, its atlas texel and the offset read.
                    let t = [inst.dst[0] + i, inst.dst[1] + j];
                    let s = [inst.src[0] + i, inst.src[1] + j];
                    let a = atlas.rgb[(s[1] * atlas.width + s[0]) as usize];
                    let fo = piece_read(first_order, levels, inst, t);
                    // Additive blend, alpha untouched.
                    let o = out.at_mut(t[0], t[1]);
                    for c in 0..3 {
                        o[c] += a[c] * fo[c];
                    }
                }
            }
        }
    }
    out
}

/// Mirror of the paired blend path (`shaders/transfer_pair.wgsl`): the copy, the unpaired
/// pieces of `paired.singles` as in [`transfer`], then every page's pairs in order, each
/// texel adding `â·P_ℓ(⌊t/2^ℓ⌋ + Δ_A) + b̂·P_ℓ(⌊t/2^ℓ⌋ + Δ_B)` (both pieces of a pair have the
/// same level `ℓ`) with the binary16 values decoded and scaled as the shader does and the
/// reads clamped into level `ℓ`. Every piece of level 0.
pub fn transfer_paired(
    paired: &PairedSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
) -> TexelImage {
    transfer_paired_levels(paired, atlases, first_order, &[])
}

/// [`transfer_paired`] with pieces of any level (`levels` as in [`transfer_levels`]).
pub fn transfer_paired_levels(
    paired: &PairedSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
    levels: &[TexelImage],
) -> TexelImage {
    let mut out = accumulate(&paired.singles, atlases, first_order, levels);
    let read = |t: [u32; 2], off: [i32; 2], level: u32| {
        let [w, h] = level_size(paired.lightmap_size, level);
        let x = ((t[0] >> level) as i32 + off[0]).clamp(0, w as i32 - 1);
        let y = ((t[1] >> level) as i32 + off[1]).clamp(0, h as i32 - 1);
        read(first_order, levels, level, x, y)
    };
    for page in &paired.pages {
        for inst in &page.instances {
            for j in 0..inst.size[1] {
                for i in 0..inst.size[0] {
                    let t = [inst.dst[0] + i, inst.dst[1] + j];
                    let p =
                        page.texels[((inst.src[1] + j) * page.width + inst.src[0] + i) as usize];
                    let lo = |v: u32| f16_to_f32(v as u16);
                    let hi = |v: u32| f16_to_f32((v >> 16) as u16);
                    let a = [lo(p[0]), hi(p[0]), lo(p[1])].map(|v| v * inst.scale[0]);
                    let b = [hi(p[1]), lo(p[2]), hi(p[2])].map(|v| v * inst.scale[1]);
                    let (fa, fb) = (
                        read(t, inst.offset_a, inst.level),
                        read(t, inst.offset_b, inst.level),
                    );
                    let o = out.at_mut(t[0], t[1]);
                    for c in 0..3 {
                        o[c] += a[c] * fa[c] + b[c] * fb[c];
                    }
                }
            }
        }
    }
    resolve(paired.lightmap_size, paired.singles.receiver_levels, &out)
}
