//! CPU mirror of the compute (gather) path of the transfer pass
//! (`shaders/transfer_gather.wgsl`).
//!
//! `cs_init` copies first-order RGBA into an accumulation buffer; then per atlas, per
//! non-empty tile, per texel of the tile, the texel sums the contributions of the tile's
//! pieces that contain it (in list order; a piece of level `ℓ` reads `P_ℓ(⌊t/2^ℓ⌋ + Δ)`,
//! level 0 the first-order map) and adds the sum to the buffer (`cs_gather`);
//! `cs_resolve` writes the buffer to the final texture.

use super::transfer::{init_target, piece_read, resolve};
use crate::schedule::{AtlasTiles, TILE_SIZE};
use crate::types::{AtlasData, TexelImage};

/// `final = first_order + Σ pieces` in gather order, every piece of level 0.
pub fn transfer_gather(
    tiles: &[AtlasTiles],
    atlases: &[AtlasData],
    first_order: &TexelImage,
) -> TexelImage {
    transfer_gather_levels(tiles, atlases, first_order, &[], 0)
}

/// [`transfer_gather`] with pieces of any level: a piece of level `ℓ` reads
/// `P_ℓ(⌊t / 2^ℓ⌋ + Δ)`, `levels[ℓ − 1]` being pyramid level `ℓ` (see
/// [`super::transfer::transfer_levels`]). `receiver_levels` is the schedule's
/// [`crate::schedule::FrameSchedule::receiver_levels`] (the tiles cover its accumulation
/// target; 0 without receiver blocks).
pub fn transfer_gather_levels(
    tiles: &[AtlasTiles],
    atlases: &[AtlasData],
    first_order: &TexelImage,
    levels: &[TexelImage],
    receiver_levels: u32,
) -> TexelImage {
    // cs_init
    let mut acc = init_target(first_order, receiver_levels);
    for at in tiles {
        let atlas = &atlases[at.atlas as usize];
        for work in &at.tiles {
            for ly in 0..TILE_SIZE {
                for lx in 0..TILE_SIZE {
                    // cs_gather: one invocation per texel of the tile.
                    let t = [work.tile[0] * TILE_SIZE + lx, work.tile[1] * TILE_SIZE + ly];
                    if t[0] >= acc.width || t[1] >= acc.height {
                        continue;
                    }
                    let mut sum = [0.0f32; 3];
                    for k in work.first..work.first + work.count {
                        let inst = at.instances[at.entries[k as usize] as usize];
                        let li = t[0] as i32 - inst.dst[0] as i32;
                        let lj = t[1] as i32 - inst.dst[1] as i32;
                        if li < 0
                            || lj < 0
                            || li >= inst.size[0] as i32
                            || lj >= inst.size[1] as i32
                        {
                            continue;
                        }
                        let s = [inst.src[0] + li as u32, inst.src[1] + lj as u32];
                        let a = atlas.rgb[(s[1] * atlas.width + s[0]) as usize];
                        let fo = piece_read(first_order, levels, &inst, t);
                        for c in 0..3 {
                            sum[c] += a[c] * fo[c];
                        }
                    }
                    let o = acc.at_mut(t[0], t[1]);
                    for c in 0..3 {
                        o[c] += sum[c];
                    }
                }
            }
        }
    }
    // cs_resolve
    resolve(
        [first_order.width, first_order.height],
        receiver_levels,
        &acc,
    )
}
