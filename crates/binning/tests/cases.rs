//! Exact small cases worked out by hand from the algorithm's rules, edge cases (no maps, 1×1
//! maps, maps wider / taller than the atlas, empty maps, bad input), and the figures on
//! realistic synthetic sets (pieces per map, fill ratio, bin count).

mod common;

use binning::{
    BinError, MAX_PIECES, PackOptions, Packing, Placement, SourceRect, blit, blit_atlas, pack,
    pack_with,
};
use common::{SplitMix, check_geometry, check_packing};

fn rect(id: u32, w: u32, h: u32) -> SourceRect {
    SourceRect { id, w, h }
}

#[expect(
    clippy::too_many_arguments,
    reason = "mirrors the Placement fields one to one"
)]
fn pl(
    atlas: u32,
    dst_x: u32,
    dst_y: u32,
    w: u32,
    h: u32,
    source: u32,
    src_x: u32,
    src_y: u32,
) -> Placement {
    Placement {
        atlas,
        dst_x,
        dst_y,
        w,
        h,
        source,
        src_x,
        src_y,
    }
}

fn packed(rects: &[SourceRect], w: u32, h: u32) -> Packing {
    let p = pack(rects, w, h).expect("pack");
    check_packing(rects, &p, 1);
    p
}

#[test]
fn best_fit_takes_the_tallest_slice_that_fits() {
    // 4×4 atlas, three 4-wide maps of heights 3, 2, 1: the fresh column takes the 3 (tallest
    // fitting), the 1-row remainder takes the 1; the 2 opens atlas 1.
    let rects = [rect(10, 4, 3), rect(11, 4, 2), rect(12, 4, 1)];
    let p = packed(&rects, 4, 4);
    assert_eq!(p.atlas_count, 2);
    assert_eq!(
        p.placements,
        vec![
            pl(0, 0, 0, 4, 3, 10, 0, 0),
            pl(0, 0, 3, 4, 1, 12, 0, 0),
            pl(1, 0, 0, 4, 2, 11, 0, 0)
        ]
    );
    assert_eq!(p.stats.splits, 0);
    assert_eq!(p.stats.pieces_per_source, vec![1, 1, 1]);
}

#[test]
fn all_taller_splits_the_tallest() {
    // Two 4×3 maps in a 4×4 atlas: the second does not fit the 1-row remainder, so its top row
    // goes there and its remaining 2 rows open atlas 1.
    let rects = [rect(0, 4, 3), rect(1, 4, 3)];
    let p = packed(&rects, 4, 4);
    assert_eq!(
        p.placements,
        vec![
            pl(0, 0, 0, 4, 3, 0, 0, 0),
            pl(0, 0, 3, 4, 1, 1, 0, 0),
            pl(1, 0, 0, 4, 2, 1, 0, 1)
        ]
    );
    assert_eq!(p.stats.splits, 1);
    assert_eq!(p.stats.pieces_per_source, vec![1, 2]);

    // Heights 2 and 3 into a 1-row area: the tallest (3) is split, not the first in input order.
    let rects = [rect(0, 2, 3), rect(1, 2, 2), rect(2, 2, 3)];
    let p = packed(&rects, 2, 4);
    // Column 0: best fit 3 (id 0, first of the equal-height ones), remainder 1 row: split id 2.
    assert_eq!(p.placements[0], pl(0, 0, 0, 2, 3, 0, 0, 0));
    assert_eq!(p.placements[1], pl(0, 0, 3, 2, 1, 2, 0, 0));
    // Atlas 1: ids 2 (rest, 2 rows) and 1 (2 rows) both fit exactly; tie broken by input order.
    assert_eq!(p.placements[2], pl(1, 0, 0, 2, 2, 1, 0, 0));
    assert_eq!(p.placements[3], pl(1, 0, 2, 2, 2, 2, 0, 1));
}

#[test]
fn no_slice_of_the_area_width_subdivides_it() {
    // 4×4 atlas, maps 2×4, 1×4, 1×4: no 4-wide slice, so the atlas splits into two 2-wide
    // halves; the left takes the 2×4, the right splits again into two 1-wide columns.
    let rects = [rect(5, 2, 4), rect(6, 1, 4), rect(7, 1, 4)];
    let p = packed(&rects, 4, 4);
    assert_eq!(p.atlas_count, 1);
    assert_eq!(
        p.placements,
        vec![
            pl(0, 0, 0, 2, 4, 5, 0, 0),
            pl(0, 2, 0, 1, 4, 6, 0, 0),
            pl(0, 3, 0, 1, 4, 7, 0, 0)
        ]
    );
}

#[test]
fn non_power_of_two_width_becomes_binary_slices() {
    // A 7×2 map in an 8×2 atlas: slices 4, 2, 1 land side by side at x = 0, 4, 6 in the same
    // rows, matching their source columns, so the merge pass joins them back into one piece.
    let rects = [rect(0, 7, 2)];
    let p = packed(&rects, 8, 2);
    assert_eq!(p.stats.slices, 3);
    assert_eq!(p.stats.merges, 2);
    assert_eq!(p.placements, vec![pl(0, 0, 0, 7, 2, 0, 0, 0)]);
    // Two maps 3×2 and 1×2 in a 4×2 atlas: slices 2, 1 (map 0) and 1 (map 1). The 2 goes left;
    // the right half splits into map 0's 1 (first in input order) at x = 2, then map 1's.
    let rects = [rect(0, 3, 2), rect(1, 1, 2)];
    let p = packed(&rects, 4, 2);
    assert_eq!(
        p.placements,
        vec![pl(0, 0, 0, 3, 2, 0, 0, 0), pl(0, 3, 0, 1, 2, 1, 0, 0)]
    );
}

#[test]
fn exact_fill_avoids_the_split_of_best_fit() {
    // Heights 3, 2, 2 of width 4 in a 4×4 atlas. Paper rule: 3 on top, then the 1-row rest
    // forces a split of a 2. Exact fill: 2 + 2 = 4 fills the first atlas; 3 opens the second.
    let rects = [rect(0, 4, 3), rect(1, 4, 2), rect(2, 4, 2)];
    let paper = pack_with(&rects, 4, 4, PackOptions { exact_fill: false }).expect("pack");
    check_packing(&rects, &paper, 2);
    assert_eq!(paper.stats.splits, 1);
    assert_eq!(paper.placements.len(), 4);
    let exact = packed(&rects, 4, 4);
    assert_eq!(exact.stats.splits, 0);
    assert_eq!(
        exact.placements,
        vec![
            pl(0, 0, 0, 4, 2, 1, 0, 0),
            pl(0, 0, 2, 4, 2, 2, 0, 0),
            pl(1, 0, 0, 4, 3, 0, 0, 0)
        ]
    );
    assert_eq!(exact.atlas_count, paper.atlas_count);
    // Prefers taller slices: heights 5, 4, 3, 2, 2 into 8 rows → {5, 3} (not {4, 2, 2}); the
    // second atlas then takes {4, 2, 2} exactly (the equal 2s in input order): no split.
    let rects: Vec<SourceRect> = [2, 5, 4, 3, 2]
        .iter()
        .enumerate()
        .map(|(i, &h)| rect(i as u32, 1, h))
        .collect();
    let p = packed(&rects, 1, 8);
    assert_eq!(p.atlas_count, 2);
    assert_eq!(
        p.placements,
        vec![
            pl(0, 0, 0, 1, 5, 1, 0, 0),
            pl(0, 0, 5, 1, 3, 3, 0, 0),
            pl(1, 0, 0, 1, 4, 2, 0, 0),
            pl(1, 0, 4, 1, 2, 0, 0, 0),
            pl(1, 0, 6, 1, 2, 4, 0, 0),
        ]
    );
    assert_eq!(p.stats.splits, 0);
}

#[test]
fn no_maps_gives_no_atlas() {
    let p = packed(&[], 1024, 1024);
    assert_eq!(p.atlas_count, 0);
    assert!(p.placements.is_empty());
    assert_eq!(p.stats.fill_ratio, 0.0);
    assert_eq!(p.stats.mean_pieces(), 0.0);
    let empty: Vec<&[f32]> = Vec::new();
    assert!(blit(&p, &empty).expect("blit").is_empty());
}

#[test]
fn empty_maps_get_no_pieces() {
    let rects = [rect(0, 0, 5), rect(1, 5, 0), rect(2, 3, 3)];
    let p = packed(&rects, 4, 4);
    assert_eq!(p.stats.pieces_per_source[..2], [0, 0]);
    assert_eq!(p.atlas_count, 1);
}

#[test]
fn one_by_one_maps() {
    // 37 single texels into 2×4 atlases: ⌈37/8⌉ = 5 atlases, one piece each.
    let rects: Vec<SourceRect> = (0..37).map(|i| rect(i * 3 + 1, 1, 1)).collect();
    let p = packed(&rects, 2, 4);
    assert_eq!(p.atlas_count, 5);
    assert!(p.stats.pieces_per_source.iter().all(|&n| n == 1));
    // 1×1 atlas: every texel is its own atlas.
    let rects = [rect(0, 2, 3)];
    let p = packed(&rects, 1, 1);
    assert_eq!(p.atlas_count, 6);
}

#[test]
fn maps_wider_or_taller_than_the_atlas_are_split() {
    // 20×5 into 8×8: slices 8, 8, 4 (⌊20/8⌋ = 2 full-width ones).
    let rects = [rect(0, 20, 5)];
    let p = packed(&rects, 8, 8);
    assert_eq!(p.stats.slices, 3);
    assert_eq!(p.atlas_count, 2);
    // 3×50 into 4×16 and 64×64 into 16×16: split at every atlas bottom.
    packed(&[rect(0, 3, 50)], 4, 16);
    let p = packed(&[rect(9, 64, 64)], 16, 16);
    assert_eq!(p.atlas_count, 16);
    assert!(p.stats.fill_ratio == 1.0);
}

#[test]
fn bad_input_is_an_error() {
    for (w, h) in [(0, 8), (8, 0), (12, 16), (16, 12), (1 << 17, 4)] {
        assert_eq!(
            pack(&[], w, h),
            Err(BinError::AtlasSize {
                width: w,
                height: h
            })
        );
    }
    assert_eq!(
        pack(&[rect(4, 1, 1), rect(5, 1, 1), rect(4, 2, 2)], 8, 8),
        Err(BinError::DuplicateId {
            id: 4,
            first: 0,
            second: 2
        })
    );
    // 2^20 × 2^10 texels into 1×1 atlases: far over MAX_PIECES; refused before allocating.
    match pack(&[rect(0, 1 << 20, 1 << 10)], 1, 1) {
        Err(BinError::TooManyPieces { bound, limit }) => {
            assert!(bound > u128::from(MAX_PIECES));
            assert_eq!(limit, MAX_PIECES);
        }
        other => panic!("expected TooManyPieces, got {other:?}"),
    }
    let msg = BinError::AtlasSize {
        width: 3,
        height: 4,
    }
    .to_string();
    assert!(
        msg.contains("3x4") && msg.contains("powers of two"),
        "{msg}"
    );
}

#[test]
fn blit_rejects_mismatched_data() {
    let rects = [rect(0, 2, 2), rect(1, 3, 1)];
    let p = pack(&rects, 4, 4).expect("pack");
    let a = [1u8; 4];
    let b = [2u8; 3];
    assert_eq!(
        blit(&p, &[&a[..]]),
        Err(BinError::SourceCount {
            expected: 2,
            got: 1
        })
    );
    assert!(matches!(
        blit(&p, &[&a[..], &a[..]]),
        Err(BinError::SourceDataLength {
            id: 1,
            expected: 3,
            got: 4,
            ..
        })
    ));
    assert_eq!(
        blit_atlas(&p, 1, &[&a[..], &b[..]]),
        Err(BinError::AtlasIndex { atlas: 1, count: 1 })
    );
    let mut bad = p.clone();
    bad.placements[0].dst_x = 3;
    assert_eq!(
        blit(&bad, &[&a[..], &b[..]]),
        Err(BinError::BadPlacement { index: 0 })
    );
    let mut bad = p.clone();
    bad.placements[1].source = 99;
    assert_eq!(
        blit(&bad, &[&a[..], &b[..]]),
        Err(BinError::BadPlacement { index: 1 })
    );
}

#[test]
fn deterministic() {
    let mut rng = SplitMix(7);
    let rects: Vec<SourceRect> = (0..60)
        .map(|i| rect(i, rng.range(1, 200), rng.range(1, 200)))
        .collect();
    assert_eq!(pack(&rects, 512, 512), pack(&rects, 512, 512));
}

/// `n` maps with sides uniform in `lo..=hi`.
fn synthetic(seed: u64, n: u32, lo: u32, hi: u32) -> Vec<SourceRect> {
    let mut rng = SplitMix(seed);
    (0..n)
        .map(|i| rect(i, rng.range(lo, hi), rng.range(lo, hi)))
        .collect()
}

fn report(name: &str, rects: &[SourceRect], p: &Packing) {
    let texels: u64 = rects.iter().map(|r| u64::from(r.w) * u64::from(r.h)).sum();
    println!(
        "{name}: {} maps -> {} atlases of {}x{} (bound {}), pieces/map mean {:.2} max {}, \
         slices {} splits {} merges {}, fill {:.4}",
        rects.len(),
        p.atlas_count,
        p.atlas_w,
        p.atlas_h,
        texels.div_ceil(u64::from(p.atlas_w) * u64::from(p.atlas_h)),
        p.stats.mean_pieces(),
        p.stats.max_pieces(),
        p.stats.slices,
        p.stats.splits,
        p.stats.merges,
        p.stats.fill_ratio,
    );
}

#[test]
fn synthetic_sets_figures() {
    // The realistic set: 100 maps with sides 20..256 into 1024² atlases.
    let mut means = Vec::new();
    for seed in 0..5 {
        let rects = synthetic(seed, 100, 20, 256);
        let paper = pack_with(&rects, 1024, 1024, PackOptions { exact_fill: false }).expect("pack");
        check_packing(&rects, &paper, seed);
        report(
            &format!("paper rule, sides 20..256, seed {seed}"),
            &rects,
            &paper,
        );
        let p = pack(&rects, 1024, 1024).expect("pack");
        check_packing(&rects, &p, seed);
        report(
            &format!("exact fill, sides 20..256, seed {seed}"),
            &rects,
            &p,
        );
        means.push(p.stats.mean_pieces());
    }
    // Goal from the issue (paper: 7–9 pieces per map on average).
    assert!(
        means.iter().all(|&m| m <= 7.0),
        "mean pieces per map above 7: {means:?}"
    );

    // Paper-like sets: maps up to their nominal size, packed into 1024².
    for (n, hi) in [(100u32, 256u32), (200, 256), (100, 512), (200, 512)] {
        let rects = synthetic(u64::from(n + hi), n, hi / 2, hi);
        let paper = pack_with(&rects, 1024, 1024, PackOptions { exact_fill: false }).expect("pack");
        report(
            &format!("paper rule, sides {}..{hi}", hi / 2),
            &rects,
            &paper,
        );
        let p = pack(&rects, 1024, 1024).expect("pack");
        check_geometry(&rects, &p); // no blit: up to 28 atlases of 1024², too slow in a test
        report(&format!("exact fill, sides {}..{hi}", hi / 2), &rects, &p);
        assert!(p.stats.mean_pieces() <= 7.0);
    }
}
