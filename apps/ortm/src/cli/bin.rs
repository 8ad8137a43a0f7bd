//! `ortm bin DIR [--atlas N] [-o OUT]`: packs a bake's transfer maps into texture atlases
//! (paper Sec. 5.2). Without `--atlas`, the atlas side is the smallest power of two that holds
//! every stored texel in one atlas, capped at 1024 ([`binning::fitting_atlas_side`]).
//!
//! Data flow: `DIR/index.json` and the map files ([`ortm::bake_dir::BakeIndex`]); every crop
//! rectangle packed by the `binning` crate ([`ortm::atlas::build_atlas_set_with_stats`]);
//! `OUT/atlas_NNN.exr` and `OUT/atlases.json` ([`ortm::atlas::write_atlas_set`], format in
//! `docs/atlas-format.md`); pictures `OUT/atlas_NNN.png` (the packing: one colour per map,
//! labelled with the map index) and `OUT/atlas_NNN_values.png` (tone-mapped values). Prints the
//! atlas count, pieces per map, fill ratio and texels, with the paper's Table 1 figures where the
//! configuration matches (1024² atlases, same lightmap size and map count). Errors (missing
//! index, corrupt map file, bad atlas size) name the file or argument and the fix.

use std::path::PathBuf;

use anyhow::{Context, Result, bail};
use ortm::atlas::{self, AtlasSet};
use ortm::bake_dir::{BakeIndex, INDEX_FILE_NAME};

/// Paper Table 1 (1024² atlases): (map side, number of offsets, number of bins).
const PAPER_TABLE: [(u32, usize, usize); 8] = [
    (256, 50, 3),
    (256, 100, 6),
    (256, 200, 10),
    (256, 400, 19),
    (384, 100, 13),
    (384, 200, 24),
    (512, 100, 22),
    (512, 200, 43),
];

/// An atlas size `W×H` parsed from `N` (square) or `WxH`.
#[derive(Clone, Copy, Debug)]
pub struct AtlasSize(u32, u32);

fn parse_atlas_size(s: &str) -> Result<AtlasSize, String> {
    let side = |t: &str| -> Result<u32, String> {
        let v: u32 = t
            .trim()
            .parse()
            .map_err(|_| format!("'{t}' is not a whole number of texels"))?;
        if v.is_power_of_two() && v <= binning::MAX_ATLAS_SIDE {
            Ok(v)
        } else {
            Err(format!(
                "{v} is not a power of two from 1 to {}: use e.g. 1024",
                binning::MAX_ATLAS_SIDE
            ))
        }
    };
    match s.split_once(['x', 'X']) {
        Some((w, h)) => Ok(AtlasSize(side(w)?, side(h)?)),
        None => {
            let n = side(s)?;
            Ok(AtlasSize(n, n))
        }
    }
}

/// Arguments of `ortm bin`.
#[derive(clap::Args, Debug)]
pub struct Args {
    /// Bake directory (holds index.json and the map_*.exr files).
    dir: PathBuf,
    /// Atlas size in texels: `N` for N×N, or `WxH`; powers of two. Default: the smallest
    /// square that holds every stored texel in one atlas, at most 1024² (the paper's).
    #[arg(long, value_parser = parse_atlas_size)]
    atlas: Option<AtlasSize>,
    /// Output directory for the atlases, atlases.json and pictures (default: the bake directory).
    #[arg(short, long)]
    output: Option<PathBuf>,
}

/// Runs `ortm bin`.
pub fn run(a: Args) -> Result<()> {
    let dir = &a.dir;
    if std::fs::symlink_metadata(dir).is_err() {
        bail!(
            "the bake folder '{}' does not exist: pass the folder written by `ortm bake -o DIR`",
            dir.display()
        );
    }
    if !dir.join(INDEX_FILE_NAME).is_file() {
        bail!(
            "'{}' has no {INDEX_FILE_NAME}: it is not a finished bake directory; run `ortm bake` \
             first (the index is written last)",
            dir.display()
        );
    }
    let (index, index_sha256) = BakeIndex::read_with_sha256(dir)
        .with_context(|| format!("reading the bake index of '{}'", dir.display()))?;
    let stored: u64 = index
        .maps
        .iter()
        .flat_map(|m| &m.rects)
        .map(|r| r.area())
        .sum();
    let atlas_size = a.atlas.unwrap_or_else(|| {
        let side = binning::fitting_atlas_side(stored, binning::DEFAULT_MAX_FIT_SIDE);
        AtlasSize(side, side)
    });
    ortm::io::limits::check_atlas_request(atlas_size.0, atlas_size.1, stored)?;
    let maps = index
        .load_maps(dir)
        .with_context(|| format!("loading the transfer maps of '{}'", dir.display()))?;
    let AtlasSize(aw, ah) = atlas_size;
    let (set, pack) = atlas::build_atlas_set_with_stats(&maps, aw, ah)
        .with_context(|| format!("packing the maps of '{}'", dir.display()))?;

    let out = a.output.as_deref().unwrap_or(dir);
    // One writer per folder: atlases, index and pictures all under the lock.
    let lock = ortm::io::DirLock::acquire(out)?;
    let written = atlas::write_atlas_set_locked(&lock, &set, &index.bake_key, Some(&index_sha256))
        .with_context(|| format!("writing the atlases to '{}'", out.display()))?;
    write_pictures(out, &set)?;
    drop(lock);

    let (lw, lh) = set.lightmap_size;
    let crops: usize = maps.iter().map(|m| m.crops().len()).sum();
    let empty = maps.iter().filter(|m| m.crops().is_empty()).count();
    let st = set.stats();
    println!(
        "bake         {}: {} maps ({empty} empty), lightmap {lw}x{lh}, {crops} crop rectangles",
        dir.display(),
        maps.len()
    );
    let capacity = u64::from(aw) * u64::from(ah);
    let paper = PAPER_TABLE
        .iter()
        .find(|&&(side, n, _)| {
            (lw, lh) == (side, side) && maps.len() == n && (aw, ah) == (1024, 1024)
        })
        .map_or_else(String::new, |&(side, n, bins)| {
            format!("   (paper Table 1, {n} maps of {side}x{side}: {bins})")
        });
    println!(
        "atlases      {} of {aw}x{ah} (lower bound ⌈texels / atlas⌉ = {}){paper}",
        st.atlases,
        st.texels.div_ceil(capacity)
    );
    println!(
        "pieces       {}: per map mean {:.2}, max {} ({} slices, {} splits, {} merges)   \
         (paper: 7–9 per map)",
        st.pieces,
        st.mean_pieces_per_map,
        st.max_pieces_per_map,
        pack.slices,
        pack.splits,
        pack.merges
    );
    println!(
        "fill         {:.1} %{}",
        100.0 * st.fill_ratio,
        if a.atlas.is_none() {
            format!("   (atlas size chosen to fit the {stored} stored texels; --atlas N to choose)")
        } else {
            String::new()
        }
    );
    println!("texels       {}", st.texels);
    let bytes: u64 = written.atlases.iter().map(|e| e.bytes).sum();
    println!(
        "wrote        {}: {} + {} atlas files ({:.1} MiB), pictures atlas_NNN.png and \
         atlas_NNN_values.png",
        out.display(),
        atlas::ATLAS_INDEX_FILE_NAME,
        written.atlases.len(),
        bytes as f64 / (1024.0 * 1024.0)
    );
    Ok(())
}

/// Writes `atlas_NNN.png` (packing) and `atlas_NNN_values.png` (tone-mapped values) per atlas,
/// small atlases enlarged to a readable size (one square of pixels per texel).
fn write_pictures(out: &std::path::Path, set: &AtlasSet) -> Result<()> {
    for i in 0..set.atlases.len() as u32 {
        let stem = atlas::atlas_file_name(i);
        let stem = stem.trim_end_matches(".exr");
        let pictures = [
            (format!("{stem}.png"), atlas::packing_image(set, i)),
            (
                format!("{stem}_values.png"),
                atlas::atlas_values_image(set, i),
            ),
        ];
        for (name, img) in pictures {
            let img = img.context("atlas index out of range (internal error)")?;
            let img = ortm::bake::report::upscale_readable(&img);
            ortm::bake::report::save_png(&img, &out.join(&name))?;
        }
    }
    Ok(())
}
