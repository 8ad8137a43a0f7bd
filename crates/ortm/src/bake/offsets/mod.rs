//! Offset selection and Voronoi weights (paper Sec. 3, 3.1, 5.1, Appendix A).
//!
//! Pure algorithms, no file I/O and no scene knowledge; the bake orchestrator supplies a
//! closure that computes the importance (transference) of a batch of offsets.
//!
//! - [`density`]: a C⁰ piecewise-linear density over unordered weighted points (Delaunay
//!   triangulation) with an exact O(log n) sampler (Appendix A).
//! - [`select`]: importance-sampled offset selection (Sec. 3.1, 5.1) and the jittered-grid
//!   baseline.
//! - [`voronoi`]: clipped Voronoi cells of the final offsets with hull sentinels, discrete
//!   integer cells, and the `TVA` map of Eq. 8.
//!
//! # Conventions
//! Offsets are integer texel vectors `Δt = (dx, dy)` (`+dy` goes down the image); valid
//! offsets of a `W×H` map satisfy `|dx| ≤ W−1`, `|dy| ≤ H−1`. The density lives in
//! continuous texel-offset coordinates; Voronoi cells use normalised coordinates
//! `(dx/W, dy/H)` in `[−1, 1]²`.

pub mod density;
pub mod select;
pub mod voronoi;

pub use density::PiecewiseLinearDensity;
pub use select::{
    ImportanceMetric, Phase, Selection, SelectionSettings, select_importance, select_jittered_grid,
};
pub use voronoi::{
    ClippedCells, DiscreteCells, RowRun, SENTINEL_COUNT, clipped_cell_polygons, discrete_cells,
    normalise, polygon_area, sentinel_offsets, tva_map,
};

/// Errors of offset selection, density construction and Voronoi weighting.
#[derive(Debug, thiserror::Error)]
pub enum OffsetError {
    /// A density data point has a NaN or infinite coordinate.
    #[error("density data point ({x}, {y}) has a non-finite coordinate; pass finite positions")]
    NonFinitePoint {
        /// x coordinate.
        x: f64,
        /// y coordinate.
        y: f64,
    },
    /// A density weight is negative, NaN or infinite.
    #[error("density data point ({x}, {y}) has weight {value}; weights must be finite and ≥ 0")]
    InvalidWeight {
        /// x coordinate.
        x: f64,
        /// y coordinate.
        y: f64,
        /// The rejected weight.
        value: f64,
    },
    /// The triangulation library cannot represent a coordinate (too large or too close to 0).
    #[error(
        "density data point ({x}, {y}) cannot be triangulated ({reason}); keep coordinates \
         either 0 or of magnitude between ~1e-142 and ~1e201"
    )]
    UnrepresentablePoint {
        /// x coordinate.
        x: f64,
        /// y coordinate.
        y: f64,
        /// What the triangulation library reported.
        reason: String,
    },
    /// Fewer than three non-collinear data points: there is no triangle to interpolate on.
    #[error(
        "density has {points} distinct data point(s) but no triangle; provide at least three \
         points that are not all on one line"
    )]
    DegenerateDensity {
        /// Number of distinct data points.
        points: usize,
    },
    /// All weights are zero (or the mass overflowed): the density cannot be normalised.
    #[error("density has total mass {total}; at least one weight must be positive and finite")]
    ZeroMass {
        /// The computed total mass.
        total: f64,
    },
    /// The lightmap size does not allow this operation.
    #[error("lightmap size {width}×{height} is not usable: {reason}")]
    InvalidMapSize {
        /// Width in texels.
        width: u32,
        /// Height in texels.
        height: u32,
        /// What is required.
        reason: &'static str,
    },
    /// An offset can never pair two texels of the map.
    #[error(
        "offset ({dx}, {dy}) is outside the valid range |dx| ≤ {width}−1, |dy| ≤ {height}−1 \
         of a {width}×{height} map; drop it"
    )]
    OffsetOutOfRange {
        /// Column offset.
        dx: i32,
        /// Row offset.
        dy: i32,
        /// Map width.
        width: u32,
        /// Map height.
        height: u32,
    },
    /// The same offset appears twice in an offset set.
    #[error("offset ({dx}, {dy}) appears more than once; offsets must be distinct")]
    DuplicateOffset {
        /// Column offset.
        dx: i32,
        /// Row offset.
        dy: i32,
    },
    /// The texel-area slice does not match the map size.
    #[error(
        "texel area array has {got} entries but the map needs {expected} (width × height); \
         pass one area per texel, row-major"
    )]
    AreaLength {
        /// `W·H`.
        expected: usize,
        /// Length given.
        got: usize,
    },
    /// The transference closure returned the wrong number of values.
    #[error(
        "transference closure returned {got} values for a batch of {expected} offsets; \
         return exactly one value per offset, in batch order"
    )]
    TransferenceLength {
        /// Batch size.
        expected: usize,
        /// Number of values returned.
        got: usize,
    },
    /// The transference closure returned a negative or non-finite value.
    #[error(
        "transference at offset ({dx}, {dy}) is {value}; importance values must be finite \
         and ≥ 0 (check the transfer computation for that offset)"
    )]
    InvalidTransference {
        /// Column offset.
        dx: i32,
        /// Row offset.
        dy: i32,
        /// The rejected value.
        value: f64,
    },
    /// Every seed offset has zero transference, so there is nothing to importance-sample.
    #[error(
        "transference is 0 at all {seeds} seed offsets; the scene has no light transport \
         between texels (check the transport stage) or the seed grid is too coarse \
         (raise seed_grid)"
    )]
    ZeroTransference {
        /// Number of seed offsets evaluated.
        seeds: usize,
    },
    /// More offsets were requested than the map has valid offsets.
    #[error(
        "{requested} offsets requested but a {width}×{height} map has only {available} \
         valid offsets ((2W−1)(2H−1)); lower the count"
    )]
    TooManyOffsets {
        /// Requested count.
        requested: usize,
        /// `(2W−1)(2H−1)`.
        available: usize,
        /// Map width.
        width: u32,
        /// Map height.
        height: u32,
    },
    /// A selection setting is out of range.
    #[error("selection setting `{field}` {reason}")]
    InvalidSettings {
        /// Name of the setting.
        field: &'static str,
        /// What is wrong and what is allowed.
        reason: String,
    },
}
