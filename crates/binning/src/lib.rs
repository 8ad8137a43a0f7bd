//! Power-of-two slice binning of rectangles into texture atlases (Sunshine-Hill & Faloutsos,
//! *Offset Radiance Transfer Mapping*, I3D 2006, Sec. 5.2).
//!
//! # Purpose and data flow
//! The renderer draws one transfer map per offset; binding one texture per map would flush the
//! pipeline every draw, so the maps are cut into pieces and packed into a few fixed-size atlases.
//! [`pack`] takes the source rectangles ([`SourceRect`]: an id and a size in texels) and an atlas
//! size, and returns a [`Packing`]: a list of [`Placement`]s, each copying a sub-rectangle of one
//! source into one atlas. [`blit`] / [`blit_atlas`] then copy texel data (any `T: Copy + Default`,
//! e.g. `[f32; 3]`) from the sources into the atlases bit-exactly. This crate knows nothing about
//! GPUs or file formats; units are texels throughout.
//!
//! # Coordinates
//! Every image is row-major, row 0 first: `x` grows to the right, `y` grows *down* (row 0 is the
//! top row, `v = 1` in the lightmap convention of the main crate). A placement's `src_x, src_y`
//! are relative to its source rectangle's origin; `dst_x, dst_y` are relative to its atlas.
//!
//! # Algorithm
//! 1. **Slicing.** A map of width `w` is cut into vertical slices whose widths are the binary
//!    digits of `w`, widest on the left, e.g. `300 = 256 + 32 + 8 + 4`. A map wider than the
//!    atlas first gives up whole atlas-width slices (`w = q·W + r`, then the digits of `r`).
//!    Slices keep the map's full height; a slice taller than the atlas is simply split when it is
//!    placed (step 2). Slicing loses no texel and adds none.
//! 2. **Filling.** Unbinned slices are kept in one pool per width class (`2^k`). Free *areas* of
//!    the atlases are kept on a stack; a fresh atlas contributes one `W×H` area, opened only when
//!    the stack is empty. For a free area of width `a` and height `b`:
//!    - some slice of width `a` has height `≤ b`: take the best fit (the tallest such slice), put
//!      it at the top of the area and return the `a × (b − h)` remainder below it to the stack;
//!    - all slices of width `a` are taller than `b`: take the tallest one, place its top `b` rows
//!      (filling the area) and return the rest of the slice (same width, `h − b` rows) to the pool;
//!    - no slice has width `a`: subdivide the area into its left and right halves (`a/2` wide,
//!      still powers of two) and push both, the left one on top.
//!
//!    Refinement (on by default, [`PackOptions::exact_fill`]): before the best-fit rule, look
//!    for a set of whole slices of width `a` whose heights sum to exactly `b` (a bitset
//!    subset-sum over the [`EXACT_FILL_CANDIDATES`] tallest slices no taller than `b`,
//!    preferring taller ones) and stack them in the area. Such an area ends without a split; the
//!    paper's greedy rule almost always ends a column with one. The bin count is unchanged.
//!
//! ```text
//!   W×H = 8×8.  Maps: A 8×5 -> slice A8;  B 6×3 -> B4 | B2;  C 5×4 -> C4 | C1.
//!
//!   atlas 0    (x right, y down)         atlas 1
//!   AAAAAAAA   A8 best-fits the 8×8      CCCC....   C4's last row (best fit); the 4×7
//!   AAAAAAAA   area; 8×3 remainder:      BB......     below: no 4-wide slice left, so
//!   AAAAAAAA   no 8-wide slice left,     BB......     halves 2×7 | 2×7. B2 best-fits
//!   AAAAAAAA   so halves 4×3 | 4×3.      BB......     the left; the 2×4 below: halves
//!   AAAAAAAA                             C.......     1×4 | 1×4, C1 fits exactly.
//!   BBBBCCCC   B4 fills the left half;   C.......   The other areas stay empty:
//!   BBBBCCCC   C4 (4 rows) is taller     C.......     nothing is left to place.
//!   BBBBCCCC   than the right one: its   C.......
//!              top 3 rows go there, its last row back to the pool (a split).
//! ```
//!
//! 3. **Merging.** Finally, two pieces of the same source that are adjacent both in the source and
//!    in the atlas (side by side with the same rows, or one above the other with the same columns)
//!    are merged into one placement. This is rare with the rule above, but free.
//!
//! # Bin count: exactly optimal
//! Let `A` be the total number of texels of all maps (= the total sliced area, slicing adds
//! nothing). Then `pack` uses exactly `⌈A / (W·H)⌉` atlases, which is the lower bound for any
//! packing. Proof sketch:
//! - *Invariant:* whenever a free area of width `a` exists, no unbinned slice is wider than `a`.
//!   The first area is `W` wide and no slice is wider than `W`. A narrower area only appears by
//!   subdividing an area of width `2a`, which happens only when no slice of width `2a` is left,
//!   and (by induction) none wider was left either; remainders keep their parent's width. The
//!   pool never gains a new width (splitting a slice keeps its width), so the invariant persists.
//! - Every popped area is either covered completely (best fit + remainder area pushed; split
//!   fills it) or subdivided into two areas that cover it. An area is dropped only if it is 1
//!   wide and no 1-wide slice is left, which by the invariant means no slice is left at all.
//! - So a new atlas is opened only after the previous ones are fully covered: every atlas but
//!   the last is 100 % full, hence `(n − 1)·W·H < A ≤ n·W·H`.
//!
//! The paper's nominal figures (e.g. 100 maps of 256² into 6 atlases of 1024², 200 of 512² into
//! 43) imply maps smaller than their nominal size (cropped), since `⌈100·256²/1024²⌉ = 7`; this
//! bound is exact for the sizes actually passed in.
//!
//! # Pieces per map
//! A map of width `w` gives `⌊w/W⌋ + popcount(w mod W)` slices, and each split adds one piece
//! (merges remove some). A split happens at most once per free area that ends a column, so with
//! atlases much taller than the maps there are few. The best-fit / split-the-tallest rule keeps
//! slices whole where possible (the tallest fitting slice goes first into a fresh column, and a
//! split leaves the largest possible remainder, more likely to fit whole elsewhere); exact fill
//! removes most of the remaining splits. On synthetic sets (1024² atlases, sides uniform;
//! printed by `cargo test -p binning --test cases synthetic_sets_figures -- --nocapture`):
//! 100 maps of 20..256: 4.5–4.7 pieces/map with the paper's rule, 4.0–4.3 with exact fill;
//! 200 maps of 256..512: 6.6 and 5.8 (the paper reports 7–9). Splits remain mostly where a
//! width class runs out part-way down a column and the narrower slices are all taller than the
//! rows left. [`PackStats`] reports the pieces per source and the fill ratio.
//!
//! # Complexity and limits
//! With `s` slices and `p` pieces, packing costs `O((s + p + q) log s)` where `q ≤ 2p·log₂W` is
//! the number of subdivided areas, plus, with exact fill, one subset-sum search of
//! `O(k·b/64)` word operations (`k` = [`EXACT_FILL_CANDIDATES`]) per fresh or subdivided area
//! of height `b`; memory is `O(s + p + k·b/64)`. Atlas sides must be powers of two in
//! `1..=65536` (beyond any GPU texture limit), and a packing that could need more than
//! [`MAX_PIECES`] pieces is refused up front (the bound used is
//! `slices + atlases·W`: split pieces in one atlas all reach its bottom row and are disjoint).
//! Maps with zero width or height are accepted and get no pieces. Ids must be unique.
//! Output is deterministic: ties are broken by input order (earlier map, then leftmost slice).

use std::cmp::Reverse;
use std::collections::{BTreeSet, HashMap};

/// Largest accepted atlas side, in texels.
pub const MAX_ATLAS_SIDE: u32 = 1 << 16;

/// How many of the tallest fitting slices the exact-fill search considers (see [`PackOptions`]).
pub const EXACT_FILL_CANDIDATES: usize = 64;

/// Upper limit on the number of placements a packing may produce (see the crate docs).
pub const MAX_PIECES: u64 = 1 << 24;

/// Default atlas side of [`fitting_atlas_side`]'s cap: the paper's 1024² atlases.
pub const DEFAULT_MAX_FIT_SIDE: u32 = 1024;

/// Smallest atlas side [`fitting_atlas_side`] chooses.
pub const MIN_FIT_SIDE: u32 = 16;

/// The atlas side that fits `texels` (the sum of the sources' areas) into one square atlas:
/// the smallest power of two `s` in `[MIN_FIT_SIDE, max_side]` with `s² ≥ texels` (the bin
/// count is exactly `⌈texels / s²⌉`, see the crate docs, so this is one atlas); `max_side`
/// (a power of two) when even that is too small — then several atlases of `max_side²`.
pub fn fitting_atlas_side(texels: u64, max_side: u32) -> u32 {
    let mut side = MIN_FIT_SIDE.min(max_side);
    while side < max_side && u64::from(side) * u64::from(side) < texels {
        side *= 2;
    }
    side
}

/// A source rectangle (one map) to be packed: its id and size in texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct SourceRect {
    /// Caller-chosen identifier, unique within one [`pack`] call; copied into [`Placement::source`].
    pub id: u32,
    /// Width in texels (may be 0: such a map gets no pieces).
    pub w: u32,
    /// Height in texels (may be 0: such a map gets no pieces).
    pub h: u32,
}

/// One piece: a `w × h` sub-rectangle of a source copied to an atlas.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Placement {
    /// Index of the destination atlas, `0..atlas_count`.
    pub atlas: u32,
    /// Left column of the piece in the atlas.
    pub dst_x: u32,
    /// Top row of the piece in the atlas (row 0 first, `y` down).
    pub dst_y: u32,
    /// Width of the piece in texels.
    pub w: u32,
    /// Height of the piece in texels.
    pub h: u32,
    /// Id of the source rectangle ([`SourceRect::id`]).
    pub source: u32,
    /// Left column of the piece in the source, relative to the source's origin.
    pub src_x: u32,
    /// Top row of the piece in the source, relative to the source's origin.
    pub src_y: u32,
}

/// Figures about a packing.
#[derive(Clone, Debug, PartialEq)]
pub struct PackStats {
    /// Number of placements of each source, in the order the sources were given to [`pack`].
    pub pieces_per_source: Vec<u32>,
    /// Number of power-of-two slices the maps were cut into (before any split).
    pub slices: usize,
    /// Number of times a slice was split vertically because it did not fit a free area.
    pub splits: usize,
    /// Number of merges of adjacent pieces done by the final pass.
    pub merges: usize,
    /// Total texels of all sources (= texels written into the atlases).
    pub texels: u64,
    /// `texels / (atlas_count · W · H)`, in `[0, 1]`; 0 when there is no atlas.
    pub fill_ratio: f64,
}

impl PackStats {
    /// Mean number of pieces over the sources that have at least one texel (0 if none has).
    pub fn mean_pieces(&self) -> f64 {
        let non_empty: Vec<u32> = self
            .pieces_per_source
            .iter()
            .copied()
            .filter(|&n| n > 0)
            .collect();
        if non_empty.is_empty() {
            0.0
        } else {
            non_empty.iter().map(|&n| f64::from(n)).sum::<f64>() / non_empty.len() as f64
        }
    }

    /// Largest number of pieces of any source (0 if there is none).
    pub fn max_pieces(&self) -> u32 {
        self.pieces_per_source.iter().copied().max().unwrap_or(0)
    }
}

/// The result of [`pack`].
#[derive(Clone, Debug, PartialEq)]
pub struct Packing {
    /// Atlas width in texels (a power of two).
    pub atlas_w: u32,
    /// Atlas height in texels (a power of two).
    pub atlas_h: u32,
    /// Number of atlases used; exactly `⌈texels / (atlas_w · atlas_h)⌉`.
    pub atlas_count: u32,
    /// The pieces, sorted by atlas, then top row, then left column.
    pub placements: Vec<Placement>,
    /// The source rectangles, as given to [`pack`] (same order).
    pub sources: Vec<SourceRect>,
    /// Figures about the packing.
    pub stats: PackStats,
}

/// What can go wrong when packing or blitting.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
pub enum BinError {
    /// An atlas side is zero, not a power of two, or larger than [`MAX_ATLAS_SIDE`].
    #[error(
        "atlas size {width}x{height} is invalid: both sides must be powers of two from 1 to 65536 \
         (e.g. 1024x1024)"
    )]
    AtlasSize {
        /// Requested atlas width.
        width: u32,
        /// Requested atlas height.
        height: u32,
    },
    /// Two source rectangles share an id.
    #[error(
        "source rectangles #{first} and #{second} share the id {id}: give every map a unique id"
    )]
    DuplicateId {
        /// The repeated id.
        id: u32,
        /// Index of the first rectangle with this id.
        first: usize,
        /// Index of the second rectangle with this id.
        second: usize,
    },
    /// The packing could need more than [`MAX_PIECES`] placements.
    #[error(
        "packing could produce up to {bound} pieces, over the limit of {limit}: use a larger atlas \
         or fewer / smaller maps"
    )]
    TooManyPieces {
        /// Upper bound on the number of pieces for this input.
        bound: u128,
        /// The limit, [`MAX_PIECES`].
        limit: u64,
    },
    /// [`blit`] got a different number of data slices than the packing has sources.
    #[error(
        "blit got texel data for {got} sources but the packing has {expected}: pass one slice per \
         source, in the order given to pack()"
    )]
    SourceCount {
        /// Number of sources in the packing.
        expected: usize,
        /// Number of data slices passed.
        got: usize,
    },
    /// A source's texel data does not have `w · h` elements.
    #[error(
        "texel data of source id {id} has {got} elements but the rectangle is {w}x{h} \
         ({expected} texels): pass row-major data of exactly w*h texels"
    )]
    SourceDataLength {
        /// Id of the source.
        id: u32,
        /// Source width.
        w: u32,
        /// Source height.
        h: u32,
        /// `w · h`.
        expected: u128,
        /// Length of the data passed.
        got: usize,
    },
    /// [`blit_atlas`] was asked for an atlas the packing does not have.
    #[error("atlas index {atlas} is out of range: the packing has {count} atlases")]
    AtlasIndex {
        /// Requested atlas.
        atlas: u32,
        /// Number of atlases in the packing.
        count: u32,
    },
    /// A placement names an unknown source or lies outside its atlas or source.
    #[error(
        "placement #{index} names an unknown source or lies outside its atlas or source: the \
         Packing was modified after pack(); re-run pack()"
    )]
    BadPlacement {
        /// Index into [`Packing::placements`].
        index: usize,
    },
}

/// A power-of-two-wide vertical strip of a source, not yet (fully) placed.
#[derive(Clone, Copy, Debug)]
struct Slice {
    /// Index of the source in the input.
    source: usize,
    src_x: u32,
    src_y: u32,
    w: u32,
    h: u32,
}

/// A free area of an atlas; it always reaches the atlas's bottom row.
#[derive(Clone, Copy, Debug)]
struct Area {
    atlas: u32,
    x: u32,
    y: u32,
    w: u32,
    h: u32,
    /// Whether an exact-fill search may still succeed here (false below a failed search).
    exact: bool,
}

/// The placement of the top `h` rows of slice `s` at row `y` of `area`.
fn place(area: &Area, y: u32, h: u32, s: &Slice, rects: &[SourceRect]) -> Placement {
    Placement {
        atlas: area.atlas,
        dst_x: area.x,
        dst_y: y,
        w: s.w,
        h,
        source: rects[s.source].id,
        src_x: s.src_x,
        src_y: s.src_y,
    }
}

/// Pool key of a slice: (height, Reverse(slice index)).
type Key = (u32, Reverse<usize>);

/// Looks for a set of whole slices, among the [`EXACT_FILL_CANDIDATES`] tallest ones no taller
/// than `target`, whose heights sum to exactly `target`. Prefers taller slices: the search adds
/// candidates tallest first and stops at the first prefix that reaches the target; the
/// reconstruction then skips the shortest slices it can. Returns the keys, tallest first.
///
/// Cost: `O(k · target / 64)` word operations and as many words of memory, `k ≤ 64`.
fn exact_subset(pool: &BTreeSet<Key>, target: u32, slices: &[Slice]) -> Option<Vec<Key>> {
    let cands: Vec<Key> = pool
        .range(..=(target, Reverse(0)))
        .rev()
        .take(EXACT_FILL_CANDIDATES)
        .copied()
        .collect();
    let t = target as usize;
    let words = t / 64 + 1;
    let bit = |set: &[u64], i: usize| set[i / 64] >> (i % 64) & 1 == 1;
    // stages[i]: the sums reachable with candidates 0..i (stages[0] = {0}).
    let mut stages: Vec<Vec<u64>> = Vec::with_capacity(cands.len() + 1);
    let mut reach = vec![0u64; words];
    reach[0] = 1;
    stages.push(reach.clone());
    let mut found = None;
    for (i, key) in cands.iter().enumerate() {
        let h = slices[key.1.0].h as usize;
        let (ws, bs) = (h / 64, h % 64);
        let prev = &stages[i];
        for w in (ws..words).rev() {
            let lo = prev[w - ws] << bs;
            let hi = if bs > 0 && w > ws {
                prev[w - ws - 1] >> (64 - bs)
            } else {
                0
            };
            reach[w] |= lo | hi;
        }
        // Keep only sums 0..=target.
        let top = t % 64;
        if top < 63 {
            reach[words - 1] &= (1u64 << (top + 1)) - 1;
        }
        stages.push(reach.clone());
        if bit(&reach, t) {
            found = Some(i + 1);
            break;
        }
    }
    let n = found?;
    let mut chosen = Vec::new();
    let mut s = t;
    for i in (0..n).rev() {
        if bit(&stages[i], s) {
            continue; // reachable without candidate i: skip it (keep taller ones)
        }
        let h = slices[cands[i].1.0].h as usize;
        chosen.push(cands[i]);
        s -= h;
    }
    chosen.reverse();
    Some(chosen)
}

/// The slice widths of a map of width `w` in an atlas `atlas_w` wide, left to right: `⌊w/W⌋`
/// atlas-wide slices, then the binary digits of `w mod W`, widest first.
fn slice_widths(w: u32, atlas_w: u32) -> impl Iterator<Item = u32> {
    let full = w / atlas_w;
    let rest = w % atlas_w;
    let digits = (0..32u32)
        .rev()
        .map(|k| 1u32 << k)
        .filter(move |&bit| rest & bit != 0);
    std::iter::repeat_n(atlas_w, full as usize).chain(digits)
}

fn valid_side(side: u32) -> bool {
    side.is_power_of_two() && side <= MAX_ATLAS_SIDE
}

/// Choices for [`pack_with`].
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PackOptions {
    /// Before the paper's best-fit rule, look for a set of whole slices of the area's width
    /// whose heights add up to exactly the area's height (subset sum over the
    /// [`EXACT_FILL_CANDIDATES`] tallest fitting ones) and stack them there: the area is filled
    /// without a split. When there is none, fall back to best fit / split the tallest. Fewer
    /// pieces, same (optimal) bin count. `false` gives the paper's rule alone.
    pub exact_fill: bool,
}

impl Default for PackOptions {
    fn default() -> Self {
        Self { exact_fill: true }
    }
}

/// [`pack_with`] with the default [`PackOptions`] (exact fill on).
///
/// # Errors
/// As [`pack_with`].
pub fn pack(rects: &[SourceRect], atlas_w: u32, atlas_h: u32) -> Result<Packing, BinError> {
    pack_with(rects, atlas_w, atlas_h, PackOptions::default())
}

/// Packs `rects` into as few `atlas_w × atlas_h` atlases as possible (exactly
/// `⌈Σ w·h / (atlas_w·atlas_h)⌉`), cutting them into power-of-two-wide vertical slices that are
/// split vertically only when needed. See the crate docs for the algorithm.
///
/// # Errors
/// [`BinError::AtlasSize`] if a side is not a power of two in `1..=65536`,
/// [`BinError::DuplicateId`] if two rectangles share an id, [`BinError::TooManyPieces`] if the
/// result could exceed [`MAX_PIECES`] placements.
pub fn pack_with(
    rects: &[SourceRect],
    atlas_w: u32,
    atlas_h: u32,
    options: PackOptions,
) -> Result<Packing, BinError> {
    if !valid_side(atlas_w) || !valid_side(atlas_h) {
        return Err(BinError::AtlasSize {
            width: atlas_w,
            height: atlas_h,
        });
    }
    let seen = source_indices(rects)?;
    let (texels, slice_count) = problem_size(rects, atlas_w, atlas_h)?;
    let (mut slices, mut pools) = slice_sources(rects, atlas_w, slice_count);
    let filled = fill(&mut slices, &mut pools, rects, atlas_w, atlas_h, options);

    // 3. Merging, then a canonical order.
    let (mut placements, merges) = merge_adjacent(filled.placements);
    placements.sort_by_key(|p| (p.atlas, p.dst_y, p.dst_x));

    let mut pieces_per_source = vec![0u32; rects.len()];
    for p in &placements {
        pieces_per_source[seen[&p.source]] += 1;
    }
    let atlas_count = filled.atlas_count;
    let atlas_area = u128::from(atlas_w) * u128::from(atlas_h);
    let fill_ratio = if atlas_count == 0 {
        0.0
    } else {
        texels as f64 / (f64::from(atlas_count) * atlas_area as f64)
    };
    Ok(Packing {
        atlas_w,
        atlas_h,
        atlas_count,
        placements,
        sources: rects.to_vec(),
        stats: PackStats {
            pieces_per_source,
            slices: slices.len(),
            splits: filled.splits,
            merges,
            texels,
            fill_ratio,
        },
    })
}

/// Id → input index of every rectangle; [`BinError::DuplicateId`] if two share an id.
fn source_indices(rects: &[SourceRect]) -> Result<HashMap<u32, usize>, BinError> {
    let mut seen: HashMap<u32, usize> = HashMap::with_capacity(rects.len());
    for (i, r) in rects.iter().enumerate() {
        if let Some(&first) = seen.get(&r.id) {
            return Err(BinError::DuplicateId {
                id: r.id,
                first,
                second: i,
            });
        }
        seen.insert(r.id, i);
    }
    Ok(seen)
}

/// Sizes the problem before anything proportional to it is allocated: the texels to pack and
/// the number of slices; [`BinError::TooManyPieces`] if the result could exceed
/// [`MAX_PIECES`] placements.
fn problem_size(rects: &[SourceRect], atlas_w: u32, atlas_h: u32) -> Result<(u64, u128), BinError> {
    let atlas_area = u128::from(atlas_w) * u128::from(atlas_h);
    let mut texels: u128 = 0;
    let mut slice_count: u128 = 0;
    for r in rects.iter().filter(|r| r.w > 0 && r.h > 0) {
        texels += u128::from(r.w) * u128::from(r.h);
        slice_count += u128::from(r.w / atlas_w) + u128::from((r.w % atlas_w).count_ones());
    }
    let atlas_bound = texels.div_ceil(atlas_area);
    let piece_bound = slice_count + atlas_bound * u128::from(atlas_w);
    if piece_bound > u128::from(MAX_PIECES) {
        return Err(BinError::TooManyPieces {
            bound: piece_bound,
            limit: MAX_PIECES,
        });
    }
    // Both fit comfortably now: texels ≤ pieces · 2^32 ≤ 2^56.
    Ok((texels as u64, slice_count))
}

/// Step 1, slicing: every non-empty rectangle cut into power-of-two-wide slices
/// ([`slice_widths`]), and per width class `2^k` the pool of its slices' keys
/// (height, Reverse(slice index)), so that the last key at or below a height is the tallest
/// fitting slice, earliest in input order among equals.
fn slice_sources(
    rects: &[SourceRect],
    atlas_w: u32,
    slice_count: u128,
) -> (Vec<Slice>, Vec<BTreeSet<Key>>) {
    let classes_n = atlas_w.trailing_zeros() as usize + 1;
    let mut slices: Vec<Slice> = Vec::with_capacity(slice_count as usize);
    let mut pools: Vec<BTreeSet<Key>> = vec![BTreeSet::new(); classes_n];
    for (source, r) in rects.iter().enumerate() {
        if r.w == 0 || r.h == 0 {
            continue;
        }
        let mut x = 0;
        for w in slice_widths(r.w, atlas_w) {
            let idx = slices.len();
            slices.push(Slice {
                source,
                src_x: x,
                src_y: 0,
                w,
                h: r.h,
            });
            pools[w.trailing_zeros() as usize].insert((r.h, Reverse(idx)));
            x += w;
        }
    }
    (slices, pools)
}

/// What [`fill`] placed.
struct Filled {
    placements: Vec<Placement>,
    atlas_count: u32,
    splits: usize,
}

/// Step 2, filling (see the crate docs): free areas from a stack, new atlases when it is
/// empty, until every slice is placed. Slices split here keep their rest in `slices`.
fn fill(
    slices: &mut [Slice],
    pools: &mut [BTreeSet<Key>],
    rects: &[SourceRect],
    atlas_w: u32,
    atlas_h: u32,
    options: PackOptions,
) -> Filled {
    let mut placements: Vec<Placement> = Vec::with_capacity(slices.len());
    let mut remaining = slices.len();
    let mut stack: Vec<Area> = Vec::new();
    let mut atlas_count: u32 = 0;
    let mut splits = 0usize;
    while remaining > 0 {
        let mut area = stack.pop().unwrap_or_else(|| {
            atlas_count += 1;
            whole_atlas(atlas_count - 1, atlas_w, atlas_h)
        });
        let pool = &mut pools[area.w.trailing_zeros() as usize];
        if pool.is_empty() {
            // A 1-wide area with no 1-wide slice left is dropped; by the invariant in the crate
            // docs this only happens once every slice is placed.
            if area.w > 1 {
                let (left, right) = halves(&area);
                stack.push(right);
                stack.push(left);
            }
            continue;
        }
        if area.exact && options.exact_fill {
            if let Some(subset) = exact_subset(pool, area.h, slices) {
                // Stack the chosen slices, tallest first; they fill the area exactly.
                let mut y = area.y;
                for key in subset {
                    pool.remove(&key);
                    let s = slices[key.1.0];
                    placements.push(place(&area, y, s.h, &s, rects));
                    remaining -= 1;
                    y += s.h;
                }
                continue;
            }
            // No exact subset of the candidates: a remainder's exact subset plus the slice put
            // above it would have been one (up to the candidate cap), so do not search again
            // below this area.
            area.exact = false;
        }
        let best_fit = pool.range(..=(area.h, Reverse(0))).next_back().copied();
        if let Some(key) = best_fit {
            pool.remove(&key);
            let s = slices[key.1.0];
            placements.push(place(&area, area.y, s.h, &s, rects));
            remaining -= 1;
            if area.h > s.h {
                stack.push(Area {
                    y: area.y + s.h,
                    h: area.h - s.h,
                    ..area
                });
            }
        } else if let Some(key) = pool.pop_last() {
            // Every slice of this width is taller than the area: split the tallest.
            let s = &mut slices[key.1.0];
            placements.push(place(&area, area.y, area.h, s, rects));
            s.src_y += area.h;
            s.h -= area.h;
            pool.insert((s.h, key.1));
            splits += 1;
        }
    }
    Filled {
        placements,
        atlas_count,
        splits,
    }
}

/// The free area of a new, empty atlas.
fn whole_atlas(atlas: u32, w: u32, h: u32) -> Area {
    Area {
        atlas,
        x: 0,
        y: 0,
        w,
        h,
        exact: true,
    }
}

/// The left and right halves of a free `area` at least 2 wide, both open to an exact-fill
/// search again.
fn halves(area: &Area) -> (Area, Area) {
    let half = area.w / 2;
    let left = Area {
        w: half,
        exact: true,
        ..*area
    };
    let right = Area {
        x: area.x + half,
        ..left
    };
    (left, right)
}

/// Merges pieces of the same source that are adjacent in both the source and the atlas, first
/// side by side (same rows), then one above the other (same columns, by [`merge_rows`] on the
/// transposed pieces). Returns the merged list and the number of merges.
fn merge_adjacent(ps: Vec<Placement>) -> (Vec<Placement>, usize) {
    let (ps, across) = merge_rows(ps);
    let (ps, down) = merge_rows(ps.into_iter().map(transposed).collect());
    (ps.into_iter().map(transposed).collect(), across + down)
}

/// Merges pieces of the same source side by side: grouped by (atlas, source, dst_y, src_y,
/// h), walked in dst_x order. Returns them in that order and the number of merges.
fn merge_rows(mut ps: Vec<Placement>) -> (Vec<Placement>, usize) {
    let mut merges = 0;
    ps.sort_by_key(|p| (p.atlas, p.source, p.dst_y, p.src_y, p.h, p.dst_x));
    let mut out: Vec<Placement> = Vec::with_capacity(ps.len());
    for p in ps {
        if let Some(q) = out.last_mut()
            && (q.atlas, q.source, q.dst_y, q.src_y, q.h)
                == (p.atlas, p.source, p.dst_y, p.src_y, p.h)
            && q.dst_x + q.w == p.dst_x
            && q.src_x + q.w == p.src_x
        {
            q.w += p.w;
            merges += 1;
            continue;
        }
        out.push(p);
    }
    (out, merges)
}

/// `p` with x and y (and width and height) swapped, in the atlas and in the source.
fn transposed(p: Placement) -> Placement {
    Placement {
        atlas: p.atlas,
        dst_x: p.dst_y,
        dst_y: p.dst_x,
        w: p.h,
        h: p.w,
        source: p.source,
        src_x: p.src_y,
        src_y: p.src_x,
    }
}

/// Checks the texel data against the packing's sources; returns id → source index.
fn check_sources<T>(packing: &Packing, data: &[&[T]]) -> Result<HashMap<u32, usize>, BinError> {
    if data.len() != packing.sources.len() {
        return Err(BinError::SourceCount {
            expected: packing.sources.len(),
            got: data.len(),
        });
    }
    let mut index = HashMap::with_capacity(data.len());
    for (i, (r, d)) in packing.sources.iter().zip(data).enumerate() {
        let expected = u128::from(r.w) * u128::from(r.h);
        if d.len() as u128 != expected {
            return Err(BinError::SourceDataLength {
                id: r.id,
                w: r.w,
                h: r.h,
                expected,
                got: d.len(),
            });
        }
        index.insert(r.id, i);
    }
    Ok(index)
}

/// Copies one atlas: a row-major `atlas_w × atlas_h` image, `T::default()` where no piece lands.
/// `data[i]` is the row-major texel data of `packing.sources[i]` (`w · h` elements).
///
/// # Errors
/// [`BinError::AtlasIndex`] for an atlas the packing does not have, [`BinError::SourceCount`] /
/// [`BinError::SourceDataLength`] when `data` does not match the sources, and
/// [`BinError::BadPlacement`] if a placement was edited to lie outside its atlas or source.
pub fn blit_atlas<T: Copy + Default>(
    packing: &Packing,
    atlas: u32,
    data: &[&[T]],
) -> Result<Vec<T>, BinError> {
    if atlas >= packing.atlas_count {
        return Err(BinError::AtlasIndex {
            atlas,
            count: packing.atlas_count,
        });
    }
    let index = check_sources(packing, data)?;
    let (aw, ah) = (packing.atlas_w as usize, packing.atlas_h as usize);
    let mut out = vec![T::default(); aw * ah];
    for (pi, p) in packing.placements.iter().enumerate() {
        if p.atlas != atlas {
            continue;
        }
        let bad = BinError::BadPlacement { index: pi };
        let &si = index.get(&p.source).ok_or_else(|| bad.clone())?;
        let src = &packing.sources[si];
        let fits =
            |off: u32, len: u32, size: u32| u64::from(off) + u64::from(len) <= u64::from(size);
        if !(fits(p.dst_x, p.w, packing.atlas_w)
            && fits(p.dst_y, p.h, packing.atlas_h)
            && fits(p.src_x, p.w, src.w)
            && fits(p.src_y, p.h, src.h))
        {
            return Err(bad);
        }
        let (w, sw) = (p.w as usize, src.w as usize);
        for row in 0..p.h as usize {
            let s0 = (p.src_y as usize + row) * sw + p.src_x as usize;
            let d0 = (p.dst_y as usize + row) * aw + p.dst_x as usize;
            out[d0..d0 + w].copy_from_slice(&data[si][s0..s0 + w]);
        }
    }
    Ok(out)
}

/// Copies every atlas (see [`blit_atlas`]); returns `atlas_count` row-major images.
///
/// # Errors
/// As [`blit_atlas`].
pub fn blit<T: Copy + Default>(packing: &Packing, data: &[&[T]]) -> Result<Vec<Vec<T>>, BinError> {
    check_sources(packing, data)?;
    (0..packing.atlas_count)
        .map(|a| blit_atlas(packing, a, data))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn fitting_atlas_side_is_the_smallest_power_of_two_holding_every_texel() {
        // 64² lightmap, 100 maps of ~400 texels: 40,000 texels → 256² (65,536), not 128².
        assert_eq!(fitting_atlas_side(40_000, 1024), 256);
        assert_eq!(fitting_atlas_side(16_384, 1024), 128);
        assert_eq!(fitting_atlas_side(16_385, 1024), 256);
        assert_eq!(fitting_atlas_side(0, 1024), MIN_FIT_SIDE);
        assert_eq!(fitting_atlas_side(10_000_000, 1024), 1024);
        assert_eq!(fitting_atlas_side(100, 8), 8);
        // The packing of that many texels fits one atlas of the chosen side.
        let rects: Vec<SourceRect> = (0..100).map(|id| SourceRect { id, w: 20, h: 20 }).collect();
        let side = fitting_atlas_side(100 * 400, 1024);
        assert_eq!(pack(&rects, side, side).unwrap().atlas_count, 1);
    }

    #[test]
    fn slice_widths_are_binary_digits_and_sum_to_width() {
        for atlas_w in [1u32, 2, 8, 64, 256] {
            for w in 0..600u32 {
                let ws: Vec<u32> = slice_widths(w, atlas_w).collect();
                assert_eq!(ws.iter().sum::<u32>(), w, "w={w} atlas_w={atlas_w}");
                assert!(ws.iter().all(|s| s.is_power_of_two() && *s <= atlas_w));
                assert!(ws.windows(2).all(|p| p[0] >= p[1]), "widest first: {ws:?}");
                // At most one slice of each width below the atlas width.
                let narrow: Vec<u32> = ws.iter().copied().filter(|&s| s < atlas_w).collect();
                let mut dedup = narrow.clone();
                dedup.dedup();
                assert_eq!(narrow, dedup);
            }
        }
        assert_eq!(
            slice_widths(300, 1024).collect::<Vec<_>>(),
            vec![256, 32, 8, 4]
        );
    }

    #[test]
    fn exact_subset_agrees_with_brute_force() {
        // Small random pools; brute force over all subsets of the candidates (all slices no
        // taller than the target, fewer than EXACT_FILL_CANDIDATES here) decides existence.
        let mut state = 0x1234_5678_9abc_def0u64;
        let mut next = |m: u32| {
            state ^= state << 13;
            state ^= state >> 7;
            state ^= state << 17;
            (state % u64::from(m)) as u32
        };
        for _ in 0..400 {
            let n = next(9) as usize;
            let slices: Vec<Slice> = (0..n)
                .map(|i| Slice {
                    source: i,
                    src_x: 0,
                    src_y: 0,
                    w: 1,
                    h: 1 + next(150),
                })
                .collect();
            let pool: BTreeSet<Key> = slices
                .iter()
                .enumerate()
                .map(|(i, s)| (s.h, Reverse(i)))
                .collect();
            let target = 1 + next(400);
            let exists = (0u32..1 << n).any(|mask| {
                (0..n)
                    .filter(|i| mask >> i & 1 == 1)
                    .map(|i| slices[i].h)
                    .sum::<u32>()
                    == target
            });
            let got = exact_subset(&pool, target, &slices);
            assert_eq!(got.is_some(), exists, "target {target}, pool {pool:?}");
            if let Some(keys) = got {
                let sum: u32 = keys.iter().map(|k| slices[k.1.0].h).sum();
                assert_eq!(sum, target);
                assert!(
                    keys.windows(2).all(|k| k[0] > k[1]),
                    "distinct, tallest first"
                );
                assert!(keys.iter().all(|k| pool.contains(k)));
            }
        }
    }

    #[test]
    fn merge_joins_adjacent_pieces_only() {
        let p = |atlas, dst_x, dst_y, w, h, source, src_x, src_y| Placement {
            atlas,
            dst_x,
            dst_y,
            w,
            h,
            source,
            src_x,
            src_y,
        };
        let input = vec![
            p(0, 0, 0, 4, 3, 7, 0, 0),
            p(0, 4, 0, 2, 3, 7, 4, 0), // right of the first in both: merge
            p(0, 0, 3, 6, 2, 7, 0, 3), // below the merged one in both: merge
            p(0, 8, 0, 1, 5, 7, 6, 0), // adjacent in the source but not in the atlas
            p(1, 6, 0, 1, 5, 7, 6, 0), // different atlas
            p(0, 6, 0, 2, 3, 8, 6, 0), // other source
        ];
        let (out, merges) = merge_adjacent(input);
        assert_eq!(merges, 2);
        assert_eq!(out.len(), 4);
        assert!(out.contains(&p(0, 0, 0, 6, 5, 7, 0, 0)));
    }
}
