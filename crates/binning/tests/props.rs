//! Property tests over random map sets and atlas sizes, both with and without exact fill: no
//! two pieces overlap, every texel of every map is placed exactly once and copied bit-exactly,
//! everything lies inside the atlases, and the atlas count is exactly ⌈texels / atlas area⌉
//! with every atlas but the last full (see `common::check_packing`).

mod common;

use binning::{PackOptions, SourceRect, pack_with};
use common::check_packing;
use proptest::prelude::*;

/// Random map sets: up to 10 maps with sides 0..40 (so 0-sized maps, 1×1 maps and maps wider
/// or taller than the small atlases below all occur), ids unique but not in index order.
fn map_sets() -> impl Strategy<Value = Vec<SourceRect>> {
    prop::collection::vec((0u32..40, 0u32..40), 0..10).prop_map(|sizes| {
        sizes
            .into_iter()
            .enumerate()
            .map(|(i, (w, h))| SourceRect {
                id: (i as u32).wrapping_mul(2_654_435_761) ^ 0x5555,
                w,
                h,
            })
            .collect()
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn packing_is_exact_and_optimal(
        rects in map_sets(),
        log_w in 0u32..6,
        log_h in 0u32..6,
        exact_fill in any::<bool>(),
        seed in any::<u64>(),
    ) {
        let p = pack_with(&rects, 1 << log_w, 1 << log_h, PackOptions { exact_fill })
            .expect("valid input");
        check_packing(&rects, &p, seed);
    }

    #[test]
    fn many_similar_maps_in_a_larger_atlas(
        sizes in prop::collection::vec((1u32..70, 1u32..70), 1..40),
        exact_fill in any::<bool>(),
    ) {
        // Many maps of comparable size, as in real use: exercises long best-fit / exact-fill
        // columns and splits.
        let rects: Vec<SourceRect> = sizes
            .into_iter()
            .enumerate()
            .map(|(i, (w, h))| SourceRect { id: i as u32, w, h })
            .collect();
        let p = pack_with(&rects, 128, 64, PackOptions { exact_fill }).expect("valid input");
        check_packing(&rects, &p, 11);
        // Both rules are exactly optimal in the bin count, so they must agree on it.
        let paper = pack_with(&rects, 128, 64, PackOptions { exact_fill: false }).expect("valid");
        prop_assert_eq!(p.atlas_count, paper.atlas_count);
    }
}
