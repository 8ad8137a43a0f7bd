//! The bake: from a scene to a directory of offset transfer maps (paper Sec. 3, 3.1, 5.1).
//!
//! # Data flow
//! scene → [`TexelGrid`](texels::TexelGrid) → [`Transport`](transport::Transport) (BVH, coarse remainder) → offset selection
//! ([`crate::bake::offsets`], importance-sampled or jittered grid) → Voronoi cells and `TVA` →
//! one transfer map per offset, `TR(t, t+Δt)·TVA(t, Δt)` (Eq. 10) → cropped OpenEXR files and
//! `index.json` ([`crate::bake_dir`]).
//!
//! # Transfer map values
//! With `R(t, t')` the transfer of [`crate::bake::transport`] (dimensionless, it already contains the
//! sender's area `A(t')`), the per-unit-area transfer is `TR(t, t') = R(t, t') / A(t')` and the
//! map of offset `Δt` holds, for every receiver `t` whose sender `t + Δt` is covered,
//! `TR(t, t + Δt) · TVA(t, Δt)`, `TVA(t, Δt) = Σ_{v ∈ V(Δt)} A(t + v)` (Eq. 8). The
//! subsurface term's point mass at `t' = t` (the `−1` of `X ρ̄⁻¹ − I`, light that leaves elsewhere)
//! is not per unit area: it is added as is to the map of `Δt = (0, 0)`, whose Voronoi cell holds
//! the zero offset. When every integer offset is selected each cell is `{Δt}`, `TVA = A(t + Δt)`,
//! and the maps reproduce `R` exactly (tested).
//!
//! # Importance
//! The transference of an offset (the data points of the importance density) is the maximum
//! (or average, [`ImportanceMetric`](offsets::ImportanceMetric)) over receivers of the largest channel of `|R(t, t+Δt)|`,
//! evaluated on an evenly strided subset of at most [`BakeSettings::selection_receivers`]
//! receivers.
//!
//! # Resuming
//! Maps are written one by one, atomically, stamped with the bake key (scene hash + settings);
//! the selected offsets are saved in `selection.json`. A rerun with the same scene and settings
//! keeps every valid finished map and recomputes only the rest; `index.json` is written last, so
//! a directory with an index is a complete bake.
//!
//! # Modules
//! [`texels`] (covered texels) → [`raycast`] (visibility) → [`transport`] (`R(t, t')`) →
//! [`offsets`] (Appendix A) → [`cells`] (each map's value over its Voronoi cell) →
//! [`pipeline`] (the orchestrator, re-exported here) → [`report`] (pictures). [`lighting`] is
//! the CPU first-order lighting, [`point_grid`] the texels' neighbour queries in 3D and [`eval`]
//! the accuracy of a bake against the exact solve.

pub mod cells;
pub mod eval;
pub mod lighting;
pub mod multires;
pub mod near_field;
pub mod near_gather;
pub mod offsets;
pub mod pipeline;
pub mod point_grid;
pub mod raycast;
pub mod report;
pub mod shard;
pub mod texels;
pub mod transport;

pub use pipeline::{
    BakeError, BakeEvent, BakeSettings, BakeSummary, CellRule, EXACT_CELL_MAX, MapPlan,
    SelectionRecord, Selector, bake, bake_maps, compute_map_values, compute_map_values_exact,
    select_offsets, selection_receivers, transference,
};
