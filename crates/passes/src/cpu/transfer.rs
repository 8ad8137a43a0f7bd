//! CPU mirror of the blend path of the transfer pass (`shaders/transfer.wgsl`).
//!
//! Same order of operations as the GPU: the final map starts as a copy of the first-order
//! map (`fs_copy`), then every atlas batch in order, every piece in order, every texel of
//! the piece adds `atlas[src + (i,j)] · first_order[dst + (i,j) + Δt]` (`fs_piece`), with
//! first-order light read as zero outside the map. Alpha (coverage) is copied, never added
//! to. Arithmetic is `f32`; the RGBA16F accumulation option of the GPU rounds after every
//! blend and is compared against this mirror with a derived bound.

use crate::gpu::f16_to_f32;
use crate::pairing::PairedSchedule;
use crate::schedule::FrameSchedule;
use crate::types::{AtlasData, TexelImage};

/// `final = first_order + Σ pieces` in blend order.
pub fn transfer(
    schedule: &FrameSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
) -> TexelImage {
    // fs_copy: the accumulation target starts as the first-order map (alpha = coverage).
    let mut out = first_order.clone();
    for batch in &schedule.batches {
        let atlas = &atlases[batch.atlas as usize];
        for inst in &batch.instances {
            for j in 0..inst.size[1] {
                for i in 0..inst.size[0] {
                    // fs_piece: texel of the quad, its atlas texel and the offset read.
                    let t = [inst.dst[0] + i, inst.dst[1] + j];
                    let s = [inst.src[0] + i, inst.src[1] + j];
                    let a = atlas.rgb[(s[1] * atlas.width + s[0]) as usize];
                    let fo = first_order
                        .get_or_zero(t[0] as i32 + inst.offset[0], t[1] as i32 + inst.offset[1]);
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
/// texel adding `â·f(t + Δt_A) + b̂·f(t + Δt_B)` with the binary16 values decoded and scaled
/// as the shader does and the reads clamped into the map.
pub fn transfer_paired(
    paired: &PairedSchedule,
    atlases: &[AtlasData],
    first_order: &TexelImage,
) -> TexelImage {
    let mut out = transfer(&paired.singles, atlases, first_order);
    let [w, h] = paired.lightmap_size;
    let read = |t: [u32; 2], off: [i32; 2]| {
        let x = (t[0] as i32 + off[0]).clamp(0, w as i32 - 1) as u32;
        let y = (t[1] as i32 + off[1]).clamp(0, h as i32 - 1) as u32;
        first_order.get(x, y)
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
                    let (fa, fb) = (read(t, inst.offset_a), read(t, inst.offset_b));
                    let o = out.at_mut(t[0], t[1]);
                    for c in 0..3 {
                        o[c] += a[c] * fa[c] + b[c] * fb[c];
                    }
                }
            }
        }
    }
    out
}
