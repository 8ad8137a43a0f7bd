//! Files the tool writes for people, shared by the subcommands and the viewer.

use std::path::Path;

use anyhow::{Context, Result};

/// Saves a PNG atomically ([`ortm::io::write_png_atomic`]), naming the file on failure.
pub fn save_png_atomic(img: &image::RgbaImage, path: &Path) -> Result<()> {
    ortm::io::write_png_atomic(img, path)
        .with_context(|| format!("cannot write image '{}'", path.display()))
}
