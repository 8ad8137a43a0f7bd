//! Memory before allocation (issue 19, item 5): a 300-byte scene asking for an 8192² lightmap
//! made `ortm inspect` peak at 6.1 GB and `ortm bake` at 6.9 GB before any memory check. Now
//! the rasterizer's memory (`limits::LIGHTMAP_BYTES_PER_TEXEL` per texel, measured) is checked
//! against `ORTM_MEMORY_LIMIT_BYTES` before rasterizing, so under a 1 GB limit both are refused
//! with the bytes needed, and their peak resident memory (`VmHWM`, which the binary prints at
//! exit under the test hook `ORTM_TEST_REPORT_PEAK`) stays under the limit + 10 %; measured
//! here: 8–10 MB (`ORTM_TEST_REPORT_PEAK=1 ortm inspect scene.toml`: 9494528 bytes).

mod common;

use std::fs;

use common::{ortm_command, reported_peak as peak};

#[test]
fn huge_lightmap_is_refused_before_rasterizing_under_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    let text = fs::read_to_string(common::data("scene/two_quads.toml")).unwrap();
    let text = text
        .replace("width = 64", "width = 8192")
        .replace("height = 32", "height = 8192");
    assert!(text.contains("width = 8192") && text.contains("height = 8192"));
    fs::write(dir.path().join("scene.toml"), text).unwrap();
    fs::copy(
        common::data("scene/two_quads.obj"),
        dir.path().join("two_quads.obj"),
    )
    .unwrap();
    let limit: u64 = 1_000_000_000;
    for args in [
        &["inspect", "scene.toml"][..],
        &["bake", "scene.toml", "-o", "out"][..],
        &["bake", "cornell", "--size", "8192", "-o", "out"][..],
    ] {
        let out = ortm_command()
            .args(args)
            .current_dir(dir.path())
            .env(ortm::io::limits::MEMORY_LIMIT_ENV, limit.to_string())
            .env("ORTM_TEST_REPORT_PEAK", "1")
            .output()
            .unwrap();
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{args:?}: {err}");
        // 8192² texels × LIGHTMAP_BYTES_PER_TEXEL bytes.
        let need = 8192u64 * 8192 * ortm::io::limits::LIGHTMAP_BYTES_PER_TEXEL;
        assert!(
            err.contains(&format!("{need} bytes")) && err.contains("1000000000 bytes"),
            "{args:?}: {err}"
        );
        let p = peak(&err);
        assert!(p < limit + limit / 10, "{args:?}: peak {p} bytes");
        assert!(!dir.path().join("out").exists(), "{args:?} wrote output");
    }
}

/// The integrated cell rule holds one RGB value per covered texel and map while the transport
/// is alive (`limits::CELL_VALUE_BYTES`): the Cornell box at 512² with 400 maps needs 1.40 GiB
/// (the coarse solve's 0.57 GB + 512 bytes per covered texel + 176,120 covered texels × 400 ×
/// 12 bytes) and is refused under a 1 GB limit before the transport is built (peak measured:
/// 25 MB). Without the cell values in the check it would be accepted (0.66 GB) and grow past
/// the limit. With 20 maps (0.70 GB estimated) the same bake runs and peaks at 823 MB (`ORTM_MEMORY_LIMIT_BYTES=1000000000
/// ORTM_TEST_REPORT_PEAK=1 ortm bake cornell --size 512 --offsets 20`, 2 min; not run here).
#[test]
fn cell_values_count_in_the_bake_memory_check() {
    let dir = tempfile::tempdir().unwrap();
    let limit: u64 = 1_000_000_000;
    let out = ortm_command()
        .args([
            "bake",
            "cornell",
            "--size",
            "512",
            "--offsets",
            "400",
            "-o",
            "out",
        ])
        .current_dir(dir.path())
        .env(ortm::io::limits::MEMORY_LIMIT_ENV, limit.to_string())
        .env("ORTM_TEST_REPORT_PEAK", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    let covered = ortm::bake::texels::TexelGrid::build(&ortm::scene::cornell::cornell_box(512))
        .unwrap()
        .texels
        .len() as u64;
    let cell_values = covered * 400;
    assert!(
        err.contains(&format!("{cell_values} cell values")) && err.contains("--offsets"),
        "{err}"
    );
    let p = peak(&err);
    assert!(p < limit + limit / 10, "peak {p} bytes");
}

/// CRC-32 (IEEE, as PNG chunks use), bit by bit.
fn crc32(bytes: &[u8]) -> u32 {
    let mut c = 0xffff_ffffu32;
    for &b in bytes {
        c ^= u32::from(b);
        for _ in 0..8 {
            c = if c & 1 == 1 {
                0xedb8_8320 ^ (c >> 1)
            } else {
                c >> 1
            };
        }
    }
    !c
}

/// A tiny 16-bit RGB PNG whose header declares `side`² pixels (its data is for 1×1, so only a
/// reader that trusts the header before checking would allocate for it).
fn png_declaring(side: u32) -> Vec<u8> {
    let img = image::ImageBuffer::<image::Rgb<u16>, _>::from_pixel(1, 1, image::Rgb([1, 2, 3]));
    let mut png = std::io::Cursor::new(Vec::new());
    img.write_to(&mut png, image::ImageFormat::Png).unwrap();
    let mut b = png.into_inner();
    assert_eq!(&b[12..16], b"IHDR");
    b[16..20].copy_from_slice(&side.to_be_bytes());
    b[20..24].copy_from_slice(&side.to_be_bytes());
    let crc = crc32(&b[12..29]);
    b[29..33].copy_from_slice(&crc.to_be_bytes());
    b
}

#[test]
fn huge_texture_is_refused_before_decoding_under_the_memory_limit() {
    let dir = tempfile::tempdir().unwrap();
    // 8000² pixels × 32 bytes (decoded, RGB f32, linear RGB) = 2.048 GB > 1 GB.
    fs::write(dir.path().join("big.png"), png_declaring(8000)).unwrap();
    let text = fs::read_to_string(common::data("scene/two_quads.toml")).unwrap();
    let text = text.replace(
        "albedo = [0.5, 0.25, 0.125]",
        "albedo_texture = \"big.png\"",
    );
    assert!(text.contains("big.png"));
    fs::write(dir.path().join("scene.toml"), text).unwrap();
    fs::copy(
        common::data("scene/two_quads.obj"),
        dir.path().join("two_quads.obj"),
    )
    .unwrap();
    let limit: u64 = 1_000_000_000;
    let out = ortm_command()
        .args(["inspect", "scene.toml"])
        .current_dir(dir.path())
        .env(ortm::io::limits::MEMORY_LIMIT_ENV, limit.to_string())
        .env("ORTM_TEST_REPORT_PEAK", "1")
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert_eq!(out.status.code(), Some(1), "{err}");
    assert!(
        err.contains("8000×8000 image whose decoding needs 2048000000 bytes"),
        "{err}"
    );
    let p = peak(&err);
    assert!(p < limit + limit / 10, "peak {p} bytes");
}
