//! The `ortm` command-line tool.
fn main() {}
