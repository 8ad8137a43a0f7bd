//! Benchmark data for `ortm bench` (the tables themselves are printed by `src/cli/bench*.rs`).

pub mod synthetic;
