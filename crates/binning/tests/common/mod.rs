//! Shared checks for the binning integration tests: an independent, texel-by-texel validation of
//! a [`Packing`] (bounds, overlaps, coverage, bit-exact copy, bin count) and a tiny seeded RNG.

#![allow(
    dead_code,
    reason = "shared by several test crates, each of which uses a subset"
)]

use binning::{Packing, SourceRect, blit};

/// SplitMix64: a small, seeded, dependency-free generator for synthetic inputs.
pub struct SplitMix(pub u64);

impl SplitMix {
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform integer in `lo..=hi`.
    pub fn range(&mut self, lo: u32, hi: u32) -> u32 {
        lo + (self.next_u64() % u64::from(hi - lo + 1)) as u32
    }
}

/// Validates `packing` against its input `rects` texel by texel; panics with a message on the
/// first violation:
/// - every placement is non-empty and lies inside its atlas and its source;
/// - no two placements overlap in an atlas;
/// - every texel of every source is placed exactly once;
/// - the atlas count equals ⌈texels / atlas area⌉ and every atlas but the last is full;
/// - blitting puts every source texel where its placement says (tagged data, then random f32
///   bit patterns, copied bit-exactly) and leaves every other atlas texel at the default.
pub fn check_packing(rects: &[SourceRect], packing: &Packing, seed: u64) {
    let atlas_cov = check_geometry(rects, packing);
    check_blit(rects, packing, &atlas_cov, seed);
}

/// The geometric half of [`check_packing`] (no blit); returns the per-atlas coverage maps.
pub fn check_geometry(rects: &[SourceRect], packing: &Packing) -> Vec<Vec<u8>> {
    let (aw, ah) = (packing.atlas_w as usize, packing.atlas_h as usize);
    assert_eq!(packing.sources, rects);
    let n_atlas = packing.atlas_count as usize;
    let mut atlas_cov = vec![vec![0u8; aw * ah]; n_atlas];
    let mut src_cov: Vec<Vec<u8>> = rects
        .iter()
        .map(|r| vec![0u8; r.w as usize * r.h as usize])
        .collect();
    let index = |id: u32| {
        rects
            .iter()
            .position(|r| r.id == id)
            .expect("unknown source id")
    };

    for (i, p) in packing.placements.iter().enumerate() {
        assert!(p.w > 0 && p.h > 0, "placement {i} is empty: {p:?}");
        assert!(
            (p.atlas as usize) < n_atlas,
            "placement {i} atlas out of range: {p:?}"
        );
        assert!(
            p.dst_x as usize + p.w as usize <= aw,
            "placement {i} leaves the atlas: {p:?}"
        );
        assert!(
            p.dst_y as usize + p.h as usize <= ah,
            "placement {i} leaves the atlas: {p:?}"
        );
        let s = index(p.source);
        let r = rects[s];
        assert!(
            p.src_x + p.w <= r.w && p.src_y + p.h <= r.h,
            "placement {i} leaves its source"
        );
        for y in 0..p.h as usize {
            for x in 0..p.w as usize {
                let a = &mut atlas_cov[p.atlas as usize]
                    [(p.dst_y as usize + y) * aw + p.dst_x as usize + x];
                *a += 1;
                assert_eq!(*a, 1, "placement {i} overlaps another one: {p:?}");
                let c =
                    &mut src_cov[s][(p.src_y as usize + y) * r.w as usize + p.src_x as usize + x];
                *c += 1;
                assert_eq!(*c, 1, "placement {i} copies a source texel twice: {p:?}");
            }
        }
    }
    for (s, cov) in src_cov.iter().enumerate() {
        assert!(cov.iter().all(|&c| c == 1), "source #{s} not fully placed");
    }

    // Bin count: exactly the lower bound, and all atlases but the last are full.
    let texels: u64 = rects.iter().map(|r| u64::from(r.w) * u64::from(r.h)).sum();
    let area = (aw * ah) as u64;
    assert_eq!(
        u64::from(packing.atlas_count),
        texels.div_ceil(area),
        "bin count"
    );
    assert_eq!(packing.stats.texels, texels);
    for cov in atlas_cov.iter().take(n_atlas.saturating_sub(1)) {
        assert!(cov.iter().all(|&c| c == 1), "a non-last atlas is not full");
    }
    let pieces: u32 = packing.stats.pieces_per_source.iter().sum();
    assert_eq!(pieces as usize, packing.placements.len());
    atlas_cov
}

/// Where the placement rules put each atlas texel: `Some((source index, x, y))` for a texel that
/// placement `p` covers — source texel `(p.src_x + i, p.src_y + j)` goes to atlas texel
/// `(p.dst_x + i, p.dst_y + j)` of atlas `p.atlas`, unrotated and unflipped (the `Placement`
/// docs) — and `None` for a texel no placement covers. Built from the placements alone, never
/// from the blit's output, so the blit check below is independent of the code it checks.
fn expected_sources(
    rects: &[SourceRect],
    packing: &Packing,
) -> Vec<Vec<Option<(usize, u32, u32)>>> {
    let (aw, ah) = (packing.atlas_w as usize, packing.atlas_h as usize);
    let mut expect = vec![vec![None; aw * ah]; packing.atlas_count as usize];
    for p in &packing.placements {
        let s = rects
            .iter()
            .position(|r| r.id == p.source)
            .expect("unknown source id");
        for j in 0..p.h {
            for i in 0..p.w {
                let t = (p.dst_y + j) as usize * aw + (p.dst_x + i) as usize;
                expect[p.atlas as usize][t] = Some((s, p.src_x + i, p.src_y + j));
            }
        }
    }
    expect
}

/// The blit half of [`check_packing`], given the coverage maps from [`check_geometry`]: every
/// atlas texel must hold the source texel [`expected_sources`] assigns it, so a piece written
/// transposed, flipped, shifted or from the wrong source fails.
fn check_blit(rects: &[SourceRect], packing: &Packing, atlas_cov: &[Vec<u8>], seed: u64) {
    let aw = packing.atlas_w as usize;
    let n_atlas = packing.atlas_count as usize;
    let expect = expected_sources(rects, packing);

    // Tagged blit: each source texel holds `[source + 1, x, y]` (0 is the default, so an
    // uncovered atlas texel must stay `[0, 0, 0]`); each atlas texel must decode to the source
    // texel the placements assign it.
    let tags: Vec<Vec<[u32; 3]>> = rects
        .iter()
        .enumerate()
        .map(|(s, r)| {
            (0..r.h)
                .flat_map(|y| (0..r.w).map(move |x| [s as u32 + 1, x, y]))
                .collect()
        })
        .collect();
    let tag_refs: Vec<&[[u32; 3]]> = tags.iter().map(Vec::as_slice).collect();
    let tagged = blit(packing, &tag_refs).expect("blit tags");
    assert_eq!(tagged.len(), n_atlas);
    for (a, img) in tagged.iter().enumerate() {
        assert_eq!(img.len(), expect[a].len());
        for (t, tag) in img.iter().enumerate() {
            let want = expect[a][t].map_or([0, 0, 0], |(s, x, y)| [s as u32 + 1, x, y]);
            // The geometry check's coverage agrees with the placements (same rule, two codes).
            assert_eq!(
                atlas_cov[a][t] == 1,
                expect[a][t].is_some(),
                "coverage of atlas {a} texel {t}"
            );
            assert_eq!(
                *tag,
                want,
                "atlas {a} texel ({}, {}) holds [source + 1, x, y] = {tag:?}, the placements \
                 put {want:?} there",
                t % aw,
                t / aw
            );
        }
    }

    // Bit-exact copy of arbitrary f32 RGB data (any bit pattern, NaNs included), expected texel
    // by texel from the placements.
    let mut rng = SplitMix(seed);
    let data: Vec<Vec<[f32; 3]>> = rects
        .iter()
        .map(|r| {
            (0..r.w as usize * r.h as usize)
                .map(|_| std::array::from_fn(|_| f32::from_bits(rng.next_u64() as u32)))
                .collect()
        })
        .collect();
    let refs: Vec<&[[f32; 3]]> = data.iter().map(Vec::as_slice).collect();
    let atlases = blit(packing, &refs).expect("blit data");
    for (a, img) in atlases.iter().enumerate() {
        for (t, v) in img.iter().enumerate() {
            let want = expect[a][t].map_or([0.0f32; 3], |(s, x, y)| {
                data[s][y as usize * rects[s].w as usize + x as usize]
            });
            assert_eq!(
                v.map(f32::to_bits),
                want.map(f32::to_bits),
                "atlas {a} texel ({}, {}) not a bit-exact copy of its source texel",
                t % aw,
                t / aw
            );
        }
    }
}
