//! `ortm unwrap IN -o OUT`: generates lightmap UVs (charts, planar projection, packing with
//! 2-texel gutters) for an OBJ or glTF mesh and writes the mesh with them (OBJ `vt`, or glTF
//! `TEXCOORD_1`). The work is the library's ([`ortm::scene::unwrap::unwrap_file`]).

use std::path::PathBuf;

use anyhow::{Context, Result};

/// Arguments of `ortm unwrap`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Mesh to unwrap: `.obj`, `.gltf` or `.glb`.
    input: PathBuf,
    /// Where to write the mesh with lightmap UVs: `.obj`, `.gltf` (+ `.bin`) or `.glb`.
    #[arg(short, long)]
    output: PathBuf,
    /// Lightmap side in texels the charts are packed for (gutters are 2 texels at this size).
    #[arg(long, default_value_t = ortm::scene::file::DEFAULT_LIGHTMAP_SIZE)]
    size: u32,
}

/// Runs `ortm unwrap`.
pub fn run(a: Args) -> Result<()> {
    let max = ortm::io::limits::MAX_LIGHTMAP_SIDE;
    if a.size < 8 || a.size > max {
        anyhow::bail!("--size {} is out of range: use 8..={max} texels", a.size);
    }
    let s = ortm::scene::unwrap::unwrap_file(&a.input, &a.output, a.size)
        .with_context(|| format!("unwrapping '{}'", a.input.display()))?;
    for w in &s.warnings {
        eprintln!("warning: {w}");
    }
    println!(
        "wrote {}: {} triangles, {} charts at {:.1} texels/m for a {}² lightmap (2-texel gutters)",
        a.output.display(),
        s.triangles,
        s.report.charts,
        s.report.texels_per_m,
        a.size
    );
    Ok(())
}
