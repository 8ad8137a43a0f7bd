//! Every limit ortm applies to what it reads and what it is asked to allocate, in one place
//! (documented in `docs/limits.md`).
//!
//! Scene files, meshes, bake directories and atlas directories come from users and other
//! machines: sizes declared inside a file are checked against these limits *before* anything of
//! that size is allocated, and files are checked against a byte limit before they are read
//! ([`crate::io::read_bounded`]).
//! Settings that would need more memory than the machine has (a bake's coarse transport solve)
//! are refused up front with the number of bytes they would need. Every error built here names
//! the limit, the value found and the value it would need.
//!
//! | limit | value | applies to |
//! |---|---|---|
//! | [`MAX_TEXELS`] | 2²⁸ texels | lightmaps, map files' display windows, atlases |
//! | [`MAX_LIGHTMAP_SIDE`] | 8192 texels | scene files' `[lightmap]`, `--size` |
//! | [`MAX_SCENE_BYTES`] | 16 MiB | scene TOML files |
//! | [`MAX_OBJ_BYTES`] | 512 MiB | OBJ meshes |
//! | [`MAX_TEXTURE_SIDE`], [`MAX_TEXTURE_DECODE_BYTES`] | 8192 px, 512 MiB | albedo PNG textures |
//! | [`MAX_JSON_BYTES`] | 256 MiB | `index.json`, `atlases.json`, `selection.json` |
//! | [`MAX_EXR_BYTES`] | 4 GiB | map and atlas OpenEXR files |
//! | [`MAX_EXR_EXPANSION`] | 1100 | decoded pixel bytes per byte of an OpenEXR file |
//! | [`MAX_OFFSETS`] | 65,536 | offsets (transfer maps) of a bake |
//! | [`MAX_REFINEMENT_ITERATIONS`] | 100,000 | `ortm bake --iterations` |
//! | [`MAX_COARSE_BLOCK`] | 8192 texels | `ortm bake --coarse-block` (1 or more) |
//! | memory | physical memory, or `ORTM_MEMORY_LIMIT_BYTES` | a lightmap's rasterization ([`check_lightmap_memory`], before it), a bake's transport and cell values ([`bake_memory_bytes`]), `ortm bin`'s atlases ([`atlas_memory_bytes`]) |

use std::fs;

/// Largest lightmap, map or atlas, in texels (`width·height`). At 12 bytes per texel (RGB f32)
/// one such image is 3 GiB; the limit also keeps texel indices and counts inside `u32`.
pub const MAX_TEXELS: u64 = 1 << 28;

/// Largest lightmap side a scene file or `--size` may ask for, texels.
pub const MAX_LIGHTMAP_SIDE: u32 = 8192;

/// Largest scene file (TOML), bytes.
pub const MAX_SCENE_BYTES: u64 = 16 * 1024 * 1024;

/// Largest OBJ mesh file, bytes (the 17,684-triangle head is 2.7 MB).
pub const MAX_OBJ_BYTES: u64 = 512 * 1024 * 1024;

/// Largest albedo texture side, pixels (checked by the PNG decoder before it allocates).
pub const MAX_TEXTURE_SIDE: u32 = 8192;

/// Most bytes the PNG decoder may allocate for one albedo texture (an 8192² RGBA16 image).
pub const MAX_TEXTURE_DECODE_BYTES: u64 = 8192 * 8192 * 8;

/// Largest JSON file of a bake or atlas directory (`index.json`, `atlases.json`,
/// `selection.json`), bytes. An index entry takes about 300 bytes, so this is far above any
/// index of [`MAX_OFFSETS`] maps.
pub const MAX_JSON_BYTES: u64 = 256 * 1024 * 1024;

/// Largest map or atlas OpenEXR file, bytes: one uncompressed image of [`MAX_TEXELS`] RGB f32
/// texels (3 GiB) plus headers and offset tables fits.
pub const MAX_EXR_BYTES: u64 = 4 * 1024 * 1024 * 1024;

/// Largest ratio of decoded pixel bytes (12 per texel, RGB f32) to the size of the OpenEXR file
/// that declares them. The files ortm writes use ZIP (deflate), whose expansion is at most
/// 1032:1, so no valid file comes near this; a small corrupt file that declares a huge data
/// window is refused before its pixels are allocated.
pub const MAX_EXR_EXPANSION: u64 = 1100;

/// Most offsets (transfer maps) in one bake.
pub const MAX_OFFSETS: usize = 65_536;

/// Most shards of a sharded bake (`ortm bake --plan --shards N`, `--shard I/N`).
pub const MAX_SHARDS: u32 = 10_000;

/// Most refinement draws of the importance density (`--iterations`): 100× the default of
/// 1000; each draw evaluates the transference of one offset over the selection receivers, so
/// an unbounded count would run for ever.
pub const MAX_REFINEMENT_ITERATIONS: usize = 100_000;

/// Most paths per texel of the path-traced reference (`ortm reference --spp`, the viewer's
/// `--reference-spp`, `ortm bench accuracy --spp/--max-spp`): 2²⁰, a thousand times what a 1 %
/// standard error usually needs; beyond it a run would take days.
pub const MAX_SAMPLES_PER_TEXEL: u32 = 1 << 20;

/// Largest side of the texel clusters of the coarse solve (`--coarse-block`): a block as large
/// as the largest lightmap side ([`MAX_LIGHTMAP_SIDE`]) already makes one cluster.
pub const MAX_COARSE_BLOCK: u32 = MAX_LIGHTMAP_SIDE;

/// Environment variable that lowers (or raises) the memory a bake may plan to use, in bytes;
/// without it the limit is the machine's physical memory (`MemTotal` of `/proc/meminfo`).
pub const MEMORY_LIMIT_ENV: &str = "ORTM_MEMORY_LIMIT_BYTES";

/// A limit that an input or a setting exceeds.
#[derive(Debug, thiserror::Error, Clone, PartialEq, Eq)]
#[error("{what}: {found} exceeds the limit {limit_name} = {limit}{fix}")]
pub struct LimitError {
    /// What was checked (file and field, or setting).
    pub what: String,
    /// The value found or needed, with its unit.
    pub found: String,
    /// Name of the limit ([`MAX_TEXELS`], …).
    pub limit_name: &'static str,
    /// The limit, with its unit.
    pub limit: String,
    /// How to fix it (starts with "; ", or empty).
    pub fix: String,
}

/// Checks that the pixels an OpenEXR file declares (`texels`, each 12 bytes) are plausible for
/// a file of `file_bytes` bytes ([`MAX_EXR_EXPANSION`]) and at most [`MAX_TEXELS`].
///
/// # Errors
/// A [`LimitError`] naming `what`.
pub fn check_exr_pixels(what: &str, texels: u64, file_bytes: u64) -> Result<(), LimitError> {
    if texels > MAX_TEXELS {
        return Err(LimitError {
            what: what.to_owned(),
            found: format!("{texels} texels"),
            limit_name: "MAX_TEXELS",
            limit: format!("{MAX_TEXELS} texels"),
            fix: String::new(),
        });
    }
    let decoded = texels.saturating_mul(12);
    let allowed = file_bytes
        .saturating_mul(MAX_EXR_EXPANSION)
        .saturating_add(4096);
    if decoded > allowed {
        return Err(LimitError {
            what: what.to_owned(),
            found: format!(
                "{decoded} bytes of pixels declared by a {file_bytes}-byte file (expansion {:.0}:1)",
                decoded as f64 / file_bytes.max(1) as f64
            ),
            limit_name: "MAX_EXR_EXPANSION",
            limit: format!("{MAX_EXR_EXPANSION}:1"),
            fix: "; the file is corrupt or not written by ortm: re-run the command that wrote it"
                .into(),
        });
    }
    Ok(())
}

/// Checks a bake's lightmap size and offset count before anything is allocated: sides in
/// `1..=`[`MAX_LIGHTMAP_SIDE`], at most [`MAX_OFFSETS`] offsets, and no more offsets than the
/// `(2W−1)(2H−1)` distinct integer offsets a `W×H` lightmap has.
///
/// # Errors
/// A [`LimitError`] with the number the request would need.
pub fn check_bake_request(width: u32, height: u32, offsets: usize) -> Result<(), LimitError> {
    for (name, side) in [("width", width), ("height", height)] {
        if !(1..=MAX_LIGHTMAP_SIDE).contains(&side) {
            return Err(LimitError {
                what: format!("lightmap {name}"),
                found: format!("{side} texels"),
                limit_name: "MAX_LIGHTMAP_SIDE",
                limit: format!("1..={MAX_LIGHTMAP_SIDE} texels"),
                fix: format!("; choose --size between 1 and {MAX_LIGHTMAP_SIDE} (e.g. 256 or 512)"),
            });
        }
    }
    if offsets > MAX_OFFSETS {
        return Err(LimitError {
            what: "--offsets".into(),
            found: format!("{offsets} offsets"),
            limit_name: "MAX_OFFSETS",
            limit: format!("{MAX_OFFSETS}"),
            fix: "; the paper uses 50–400 offsets".into(),
        });
    }
    let distinct = (2 * u64::from(width) - 1) * (2 * u64::from(height) - 1);
    if offsets as u64 > distinct {
        return Err(LimitError {
            what: "--offsets".into(),
            found: format!("{offsets} offsets"),
            limit_name: "the number of distinct offsets (2W−1)(2H−1) of the lightmap",
            limit: format!("{distinct} for {width}×{height}"),
            fix: "; ask for fewer offsets or a larger lightmap".into(),
        });
    }
    Ok(())
}

/// Bytes of one cell value of the integrated cell rule (`bake/cells/mod.rs`, `CellValues`: RGB f32
/// per covered texel and map, all held while the transport is alive).
pub const CELL_VALUE_BYTES: u64 = 12;

/// Bytes the bake's transport needs for `clusters` clusters of the coarse higher-order solve
/// (`src/transport/coarse.rs`): per pair of clusters an f64 form factor, an f64 system matrix
/// and its LU factors, three f64 transfer channels, three f32 remainders and the f32 form
/// factor the multi-resolution rows' receiver gather reads (`8+8+8+24+12+4 = 64` bytes), plus `per_texel` bytes for each covered texel (patches, BVH, grid), plus
/// [`CELL_VALUE_BYTES`] per cell value the integrated cell rule holds at once (`cell_values` =
/// covered texels × maps; 0 for the sampled rule, which makes one map at a time).
pub fn bake_memory_bytes(clusters: u64, covered_texels: u64, cell_values: u64) -> u64 {
    const PER_CLUSTER_PAIR: u64 = 64;
    const PER_TEXEL: u64 = 512;
    clusters
        .saturating_mul(clusters)
        .saturating_mul(PER_CLUSTER_PAIR)
        .saturating_add(covered_texels.saturating_mul(PER_TEXEL))
        .saturating_add(cell_values.saturating_mul(CELL_VALUE_BYTES))
}

/// The memory a bake may plan to use, bytes: `$ORTM_MEMORY_LIMIT_BYTES` if set, else the
/// machine's physical memory from `/proc/meminfo`, else `None` (no check).
///
/// # Errors
/// A malformed `ORTM_MEMORY_LIMIT_BYTES` (not a decimal byte count).
pub fn memory_limit_bytes() -> Result<Option<u64>, LimitError> {
    if let Ok(v) = std::env::var(MEMORY_LIMIT_ENV) {
        return v.trim().parse().map(Some).map_err(|_| LimitError {
            what: MEMORY_LIMIT_ENV.into(),
            found: format!("{v:?}"),
            limit_name: "a decimal byte count",
            limit: "e.g. 8000000000".into(),
            fix: String::new(),
        });
    }
    let info = fs::read_to_string("/proc/meminfo").ok();
    Ok(info.as_deref().and_then(|t| {
        t.lines()
            .find_map(|l| l.strip_prefix("MemTotal:"))
            .and_then(|v| v.trim().strip_suffix("kB"))
            .and_then(|kb| kb.trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
    }))
}

/// Refuses a bake whose transport and cell values would need more memory than
/// [`memory_limit_bytes`], naming the bytes it would need ([`bake_memory_bytes`]). `clusters` is
/// the number of clusters the coarse solve forms (one per `coarse_block²` tile, chart and
/// material of the covered texels); `cell_values` as [`bake_memory_bytes`].
///
/// # Errors
/// A [`LimitError`] with the bytes needed and the limit.
pub fn check_bake_memory(
    clusters: u64,
    covered_texels: u64,
    coarse_block: u32,
    cell_values: u64,
) -> Result<(), LimitError> {
    let need = bake_memory_bytes(clusters, covered_texels, cell_values);
    match memory_limit_bytes()? {
        Some(limit) if need > limit => Err(LimitError {
            what: format!(
                "bake transport ({covered_texels} covered texels in {clusters} clusters of \
                 {coarse_block}×{coarse_block}) and {cell_values} cell values"
            ),
            found: format!("{need} bytes ({:.2} GiB) needed", gib(need)),
            limit_name: "memory (physical memory or ORTM_MEMORY_LIMIT_BYTES)",
            limit: format!("{limit} bytes ({:.2} GiB)", gib(limit)),
            fix: "; use the hierarchical first bounce (--tolerance, at its default 1e-4, or \
                  --tolerance 1e-3 for a faster bake; it keeps at most 1,024 clusters, and with \
                  --levels up to 4,096 slit texels besides), a smaller \
                  lightmap (--size), larger clusters (--coarse-block) or fewer offsets (--offsets)"
                .into(),
        }),
        _ => Ok(()),
    }
}

/// Upper bound of the memory rasterizing a lightmap takes per lightmap texel, bytes: the texel
/// grid (per-texel lookup, covered-texel records, chart labels, and for charts of uneven
/// stretch the sums that average each texel's area over its square) plus `ortm inspect`'s
/// coverage picture. Measured (`/usr/bin/time -f %M ortm inspect SCENE --size N`): Cornell
/// (69 % covered, even charts) 79 MB, 296 MB and 1162 MB at 1024², 2048², 4096², i.e. 70.5
/// bytes per lightmap texel or 102 per covered texel; the head (92 % covered, uneven charts)
/// 540 MB at 2048² and 2.06 GB at 4096², 129 and 123 bytes per lightmap texel; 136 bounds them.
pub const LIGHTMAP_BYTES_PER_TEXEL: u64 = 136;

/// Checks, before a `width×height` lightmap is rasterized, that its texel grid
/// ([`LIGHTMAP_BYTES_PER_TEXEL`] per texel) fits the memory limit ([`memory_limit_bytes`]).
///
/// # Errors
/// [`LimitError`] with the bytes needed and the limit.
pub fn check_lightmap_memory(width: u32, height: u32) -> Result<(), LimitError> {
    let need = (u64::from(width) * u64::from(height)).saturating_mul(LIGHTMAP_BYTES_PER_TEXEL);
    match memory_limit_bytes()? {
        Some(limit) if need > limit => Err(LimitError {
            what: format!("rasterizing the {width}×{height} lightmap"),
            found: format!("{need} bytes ({:.2} GiB) needed", gib(need)),
            limit_name: "memory (physical memory or ORTM_MEMORY_LIMIT_BYTES)",
            limit: format!("{limit} bytes ({:.2} GiB)", gib(limit)),
            fix: "; use a smaller lightmap (--size, or [lightmap] in the scene file)".into(),
        }),
        _ => Ok(()),
    }
}

/// The process's resident memory now and its peak so far (`VmRSS`, `VmHWM` of
/// `/proc/self/status`), bytes; `None` where the file is missing (not Linux) or unreadable.
pub fn resident_memory() -> Option<(u64, u64)> {
    let text = fs::read_to_string("/proc/self/status").ok()?;
    let field = |name: &str| {
        text.lines()
            .find_map(|l| l.strip_prefix(name))
            .and_then(|v| v.trim().trim_end_matches("kB").trim().parse::<u64>().ok())
            .map(|kb| kb * 1024)
    };
    Some((field("VmRSS:")?, field("VmHWM:")?))
}

/// Test hook (`ORTM_TEST_REPORT_PEAK=1`): prints the process's peak resident memory
/// (`VmHWM` of `/proc/self/status`, in bytes) to stderr as `ORTM_TEST_PEAK_BYTES: N`, so a test
/// can check a command's peak memory; does nothing when the variable is unset.
pub fn report_peak_memory_if_asked() {
    if std::env::var_os("ORTM_TEST_REPORT_PEAK").is_none() {
        return;
    }
    if let Some((_, peak)) = resident_memory() {
        eprintln!("ORTM_TEST_PEAK_BYTES: {peak}");
    }
}

/// Bytes `ortm bin` needs to pack `stored_texels` map texels into `aw×ah` atlases: the maps
/// (12 bytes per stored texel) plus `⌈stored / (aw·ah)⌉` atlases (at least one) of 12 bytes per
/// texel (RGB f32).
pub fn atlas_memory_bytes(aw: u32, ah: u32, stored_texels: u64) -> u64 {
    let per_atlas = u64::from(aw) * u64::from(ah);
    let atlases = stored_texels.div_ceil(per_atlas.max(1)).max(1);
    atlases
        .saturating_mul(per_atlas)
        .saturating_add(stored_texels)
        .saturating_mul(12)
}

/// Refuses an atlas size whose atlases would not fit in memory ([`atlas_memory_bytes`] against
/// [`memory_limit_bytes`]) or exceed [`MAX_TEXELS`] per atlas, naming the bytes needed.
///
/// # Errors
/// A [`LimitError`] with the number needed and the limit.
pub fn check_atlas_request(aw: u32, ah: u32, stored_texels: u64) -> Result<(), LimitError> {
    let texels = u64::from(aw) * u64::from(ah);
    if texels > MAX_TEXELS {
        return Err(LimitError {
            what: format!("--atlas {aw}x{ah}"),
            found: format!("{texels} texels per atlas"),
            limit_name: "MAX_TEXELS",
            limit: format!("{MAX_TEXELS} texels"),
            fix: "; use a smaller atlas, e.g. --atlas 4096".into(),
        });
    }
    let need = atlas_memory_bytes(aw, ah, stored_texels);
    match memory_limit_bytes()? {
        Some(limit) if need > limit => Err(LimitError {
            what: format!("--atlas {aw}x{ah} for {stored_texels} stored map texels"),
            found: format!("{need} bytes ({:.2} GiB) needed", gib(need)),
            limit_name: "memory (physical memory or ORTM_MEMORY_LIMIT_BYTES)",
            limit: format!("{limit} bytes ({:.2} GiB)", gib(limit)),
            fix: "; use a smaller atlas size (--atlas)".into(),
        }),
        _ => Ok(()),
    }
}

/// `bytes` in GiB (2³⁰ bytes), for messages.
pub fn gib(bytes: u64) -> f64 {
    bytes as f64 / (1024.0 * 1024.0 * 1024.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn exr_pixel_bound_follows_the_deflate_ratio() {
        // 1000 bytes may declare up to 1000·1100 + 4096 bytes of pixels.
        let max_texels = (1000 * MAX_EXR_EXPANSION + 4096) / 12;
        check_exr_pixels("f", max_texels, 1000).unwrap();
        let e = check_exr_pixels("f", max_texels + 1, 1000).unwrap_err();
        assert_eq!(e.limit_name, "MAX_EXR_EXPANSION");
        let e = check_exr_pixels("f", MAX_TEXELS + 1, u64::MAX).unwrap_err();
        assert_eq!(e.limit_name, "MAX_TEXELS");
    }

    #[test]
    fn bake_request_limits_name_the_needed_value() {
        check_bake_request(32, 32, 8).unwrap();
        // A 2×2 lightmap has 3·3 = 9 distinct offsets.
        check_bake_request(2, 2, 9).unwrap();
        let e = check_bake_request(2, 2, 10).unwrap_err();
        assert!(e.to_string().contains("9 for 2×2"), "{e}");
        assert!(check_bake_request(0, 4, 1).is_err());
        let e = check_bake_request(8193, 8, 1).unwrap_err();
        assert!(e.to_string().contains("8193 texels"), "{e}");
        let e = check_bake_request(4096, 4096, MAX_OFFSETS + 1).unwrap_err();
        assert_eq!(e.limit_name, "MAX_OFFSETS");
    }

    #[test]
    fn atlas_memory_counts_whole_atlases() {
        // 100 texels in 8×8 atlases: 2 atlases of 64 texels + the maps, 12 bytes each.
        assert_eq!(atlas_memory_bytes(8, 8, 100), (128 + 100) * 12);
        // An empty bake still allocates one atlas.
        assert_eq!(atlas_memory_bytes(4, 4, 0), 16 * 12);
        let e = check_atlas_request(65536, 8192, 1).unwrap_err();
        assert_eq!(e.limit_name, "MAX_TEXELS");
    }

    #[test]
    fn bake_memory_is_quadratic_in_clusters() {
        assert_eq!(bake_memory_bytes(1000, 0, 0), 64_000_000);
        assert_eq!(bake_memory_bytes(0, 10, 0), 5120);
        assert_eq!(bake_memory_bytes(0, 0, 1000), 12_000);
        assert_eq!(bake_memory_bytes(u64::MAX, 1, 0), u64::MAX);
    }
}
