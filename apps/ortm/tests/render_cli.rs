//! `ortm render` end to end through the binary: bake the Cornell box, render it (maps packed
//! in memory, then from `ortm bin`'s atlases), check that the written final lightmap is the
//! CPU reference of Eq. 9 applied to the written first-order lightmap, and that bad input
//! gives clear errors. Runs on lavapipe like the other GPU tests.

mod common;

use std::path::Path;

use common::{fails, ok, ortm, tiny_cornell_bake};
use ortm::bake_dir::BakeIndex;
use ortm::maps::apply;
use ortm::render::read_lightmap_exr;

/// `final.exr` must equal `maps::apply(maps, input.exr)` started from `first.exr`
/// ([`common::started_from`]; the default `--first-order-samples 3` averages the input): 1e-3 relative plus 1e-6 of the
/// map's maximum (the Cornell maps are all non-negative, so the GPU's f32 sums of ≤ 13 terms
/// stay within ~1e-6 relative; the floor covers near-black texels).
fn check_outputs(dir: &Path) {
    let first = read_lightmap_exr(&dir.join("first.exr")).unwrap();
    let input = read_lightmap_exr(&dir.join("input.exr")).unwrap();
    let fin = read_lightmap_exr(&dir.join("final.exr")).unwrap();
    let bake = dir.join("bake");
    let maps = BakeIndex::read(&bake).unwrap().load_maps(&bake).unwrap();
    let want = common::started_from(&apply(&maps, &input).unwrap(), &first, &input);
    let max = want.data.iter().flatten().fold(0f32, |a, &b| a.max(b));
    assert!(max > 1.0, "the box is lit");
    for (i, (g, c)) in fin.data.iter().zip(&want.data).enumerate() {
        for ch in 0..3 {
            assert!(
                (g[ch] - c[ch]).abs() <= 1e-3 * c[ch].abs() + 1e-6 * max,
                "texel {i} ch {ch}: final.exr {} vs CPU apply {}",
                g[ch],
                c[ch]
            );
        }
    }
    let sum = |m: &ortm::Lightmap| m.data.iter().map(|v| v[0] as f64).sum::<f64>();
    assert!(sum(&fin) > 1.2 * sum(&first), "interreflection adds light");
}

/// One bake directory taken through render, bin, render again and the error cases in order:
/// each step reads what the steps before it wrote.
#[test]
fn render_writes_frame_and_lightmaps_consistent_with_cpu_reference() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    tiny_cornell_bake(dir, "bake");
    let render = [
        "render",
        "bake",
        "--scene",
        "cornell",
        "--size",
        "96x64",
        "--side-by-side",
        "--shadow-size",
        "512",
        "-o",
        "frame.png",
        "--lightmap-out",
        "final.exr",
        "--first-order-out",
        "first.exr",
        "--transfer-input-out",
        "input.exr",
    ];
    let text = ok(ortm(&render, dir));
    assert!(text.contains("packed from the maps"), "{text}");
    let img = image::open(dir.join("frame.png")).unwrap();
    assert_eq!((img.width(), img.height()), (96, 64));
    check_outputs(dir);

    // With atlases from `ortm bin`, and the compute path: the same answer.
    ok(ortm(&["bin", "bake", "--atlas", "256"], dir));
    let mut compute = render.to_vec();
    compute.extend(["--path", "compute"]);
    let text = ok(ortm(&compute, dir));
    assert!(text.contains("from atlases.json"), "{text}");
    check_outputs(dir);
    // No temporary files are left behind.
    for e in std::fs::read_dir(dir).unwrap() {
        let name = e.unwrap().file_name().to_string_lossy().into_owned();
        assert!(!name.starts_with('.'), "left-over temporary {name}");
    }

    // Bad input: clear messages, no panic.
    let e = fails(ortm(&["render", "."], dir));
    assert!(e.contains("not a bake directory"), "{e}");
    // `ortm bake` records its scene argument, so `--scene` may be left out.
    let out = ortm(&["render", "bake", "-o", "frame_default_scene.png"], dir);
    assert!(
        out.status.success(),
        "render without --scene: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(dir.join("frame_default_scene.png").exists());
    let quads = common::data("scene/two_quads.toml");
    let quads = quads.to_str().unwrap();
    let e = fails(ortm(&["render", "bake", "--scene", quads], dir));
    assert!(e.contains("different scene"), "{e}");
    let e = fails(ortm(
        &[
            "render",
            "bake",
            "--scene",
            "cornell",
            "--light",
            "point:1,2:3",
        ],
        dir,
    ));
    assert!(e.contains("--light") && e.contains("expected 3"), "{e}");
    let e = fails(ortm(
        &["render", "bake", "--scene", "cornell", "--size", "12"],
        dir,
    ));
    assert!(e.contains("--size"), "{e}");
    for tau in ["-0.1", "1", "nan"] {
        let flag = format!("--rows-prune={tau}");
        let e = fails(ortm(&["render", "bake", &flag], dir));
        assert!(
            e.contains("--rows-prune") && e.contains("keep every entry"),
            "{tau}: {e}"
        );
    }

    // No usable adapter (only a backend this build lacks) and a GPU transfer path asked for
    // (`--path auto` falls back to the CPU, see tests/frictions.rs): the error says how to get
    // one.
    if cfg!(target_os = "linux") {
        let out = common::ortm_command()
            .args(["render", "bake", "-o", "no_adapter.png", "--path", "blend"])
            .env("WGPU_BACKEND", "metal")
            .current_dir(dir)
            .output()
            .expect("the ortm binary runs");
        let e = fails(out);
        assert!(
            e.contains("no GPU adapter") && e.contains("mesa-vulkan-drivers"),
            "{e}"
        );
        assert!(!dir.join("no_adapter.png").exists());
    }

    // A damaged atlas: an error naming the file, no image.
    let atlas = dir.join("bake").join("atlas_000.exr");
    let bytes = std::fs::read(&atlas).unwrap();
    std::fs::write(&atlas, &bytes[..bytes.len() / 2]).unwrap();
    let e = fails(ortm(&["render", "bake", "-o", "bad_atlas.png"], dir));
    assert!(e.contains("atlas_000.exr"), "{e}");
    assert!(!dir.join("bad_atlas.png").exists());
}

/// Multi-resolution maps end to end, one value per receiver and with receiver blocks
/// (`--receiver-blocks on`: maps of receiver level > 0, drawn into the block grids and
/// resolved on the GPU): `ortm bake --levels`, then `ortm render` packing in memory (blend
/// path), then from `ortm bin`'s atlases (compute path). Each written `final.exr` equals the
/// CPU reference of the level maps ([`ortm::maps::levels::apply_levels`]) applied to the
/// written transfer input and started from the written `first.exr`
/// ([`common::started_from`]), within the GPU's f32 sums (1e-4 relative + 1e-5 of the
/// maximum: up to a few hundred terms of mixed sign per texel, whose inputs reach the
/// averaged light of the ceiling beside the lamp: 1e-6 of the maximum held with the centres'
/// input; with the averaged one a 57.69 W/m² texel read 7.2e-3 W/m² off).
#[test]
fn render_applies_multi_resolution_maps_like_the_cpu() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let grid =
        ortm::bake::texels::TexelGrid::build(&ortm::scene::cornell::cornell_box(32)).unwrap();
    for (name, blocks) in [("bake", "off"), ("blocks", "on")] {
        ok(ortm(
            &[
                "bake",
                "cornell",
                "--size",
                "32",
                "--levels",
                "3e-3",
                "--coarse-block",
                "1",
                "--receiver-blocks",
                blocks,
                "-o",
                name,
            ],
            dir,
        ));
        let bake = dir.join(name);
        let maps = BakeIndex::read(&bake).unwrap().load_maps(&bake).unwrap();
        assert!(maps.iter().any(|m| m.level() >= 2), "coarse levels in use");
        assert_eq!(
            maps.iter().any(|m| m.receiver_level() > 0),
            blocks == "on",
            "receiver blocks {blocks}"
        );
        let check = || {
            let first = read_lightmap_exr(&dir.join("first.exr")).unwrap();
            let input = read_lightmap_exr(&dir.join("input.exr")).unwrap();
            let fin = read_lightmap_exr(&dir.join("final.exr")).unwrap();
            let applied =
                ortm::maps::levels::apply_levels(&maps, &input, &grid.area_map()).unwrap();
            let want = common::started_from(&applied, &first, &input);
            let max = want.data.iter().flatten().fold(0f32, |a, &b| a.max(b));
            assert!(max > 1.0, "the box is lit");
            for t in &grid.texels {
                let i = (t.y * grid.width + t.x) as usize;
                for ch in 0..3 {
                    let (g, c) = (fin.data[i][ch], want.data[i][ch]);
                    assert!(
                        (g - c).abs() <= 1e-4 * c.abs() + 1e-5 * max,
                        "{name}: texel ({}, {}) ch {ch}: final.exr {g} vs CPU {c}",
                        t.x,
                        t.y
                    );
                }
            }
        };
        let render = |path: &str| {
            ok(ortm(
                &[
                    "render",
                    name,
                    "--size",
                    "64x48",
                    "--path",
                    path,
                    "-o",
                    "frame.png",
                    "--lightmap-out",
                    "final.exr",
                    "--first-order-out",
                    "first.exr",
                    "--transfer-input-out",
                    "input.exr",
                ],
                dir,
            ))
        };
        render("blend");
        check();
        ok(ortm(&["bin", name, "--atlas", "256"], dir));
        render("compute");
        check();
    }
}
