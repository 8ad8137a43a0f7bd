//! The newcomer's frictions of issue 22 (item 4), each through the built `ortm` binary: what
//! a user types, and what the tool now answers or writes.
//!
//! - A machine without a Vulkan driver (simulated with `WGPU_BACKEND=metal`, a backend this
//!   build lacks): `ortm render` falls back to the CPU mirrors of the passes and says so; its
//!   lightmaps obey Eq. 9 against the maps of `index.json`, and its frame matches the GPU's.
//! - Scene names: `ortm bake cornel` lists the built-ins; help texts name them all.
//! - `ORTM_HEAD_OBJ`: a wrong path is named in the error with where it came from.
//! - Negative numbers in `--camera` values are accepted as the `=` form always was.
//! - `ortm render DIR` from another folder: the bake records its scene file resolved, a scene
//!   outside the bake folder is answered with `--scene` (issue 19's rule), one inside opens.
//! - Re-baking into a used folder removes the old maps and stale atlases; a rerun with the
//!   same settings still reuses every map.
//! - `ortm inspect` on overlapping UVs: reports them and draws exactly those texels red.
//! - Readable outputs: enlarged lightmap PNGs with a legend, atlas size fitted by `ortm bin`.
//! - Progress lines on stderr when it is not a terminal.
//! - A convex object (no transport between its texels) bakes, lit by a default light outside it.
//! - One `--shadow-size` default, help texts without internal names, power in W in both
//!   `render` and `solve`, "does not exist" for a missing bake folder.

mod common;

use std::path::Path;

use common::{fails, ok, ortm, ortm_command, ortm_no_gpu, tiny_cornell_bake};
use ortm::bake_dir::BakeIndex;
use ortm::render::read_lightmap_exr;

/// The three numbers after `label` in `text` (`label [r, g, b]`).
fn rgb_after(text: &str, label: &str) -> [f64; 3] {
    let rest = &text[text
        .find(label)
        .unwrap_or_else(|| panic!("{label} in {text}"))
        + label.len()..];
    let inner = &rest[rest.find('[').unwrap() + 1..rest.find(']').unwrap()];
    let v: Vec<f64> = inner
        .split(',')
        .map(|s| s.trim().parse().unwrap())
        .collect();
    [v[0], v[1], v[2]]
}

#[test]
fn without_a_gpu_adapter_render_runs_on_the_cpu_mirrors() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    tiny_cornell_bake(dir, "bake");
    let args = [
        "render",
        "bake",
        "--size",
        "96x64",
        "--side-by-side",
        "--lightmap-out",
        "final.exr",
        "--first-order-out",
        "first.exr",
        "--transfer-input-out",
        "input.exr",
    ];
    let mut cpu = args.to_vec();
    cpu.extend(["-o", "cpu.png"]);
    let text = ok(ortm_no_gpu(&cpu, dir));
    assert!(
        text.contains("CPU mirrors of the passes") && text.contains("no GPU adapter"),
        "{text}"
    );
    // Eq. 9 with the maps of index.json (not the atlas pieces the fallback applied) on the
    // transfer's input, started from the first order.
    let first = read_lightmap_exr(&dir.join("first.exr")).unwrap();
    let input = read_lightmap_exr(&dir.join("input.exr")).unwrap();
    let fin = read_lightmap_exr(&dir.join("final.exr")).unwrap();
    let bake = dir.join("bake");
    let maps = BakeIndex::read(&bake).unwrap().load_maps(&bake).unwrap();
    let want = common::started_from(&ortm::maps::apply(&maps, &input).unwrap(), &first, &input);
    let max = want.data.iter().flatten().fold(0f32, |a, &b| a.max(b));
    for (g, c) in fin.data.iter().flatten().zip(want.data.iter().flatten()) {
        assert!((g - c).abs() <= 1e-4 * c.abs() + 1e-6 * max, "{g} vs {c}");
    }
    // Its first order is the exact solve's (same ray-cast first order), in the same unit.
    let solve = ok(ortm(&["solve", "cornell", "--size", "32", "-o", "s"], dir));
    let (cpu_fo, solve_fo) = (
        rgb_after(&text, "first-order power"),
        rgb_after(&solve, "first-order power"),
    );
    for c in 0..3 {
        assert!(
            (cpu_fo[c] - solve_fo[c]).abs() <= 1e-3 * solve_fo[c],
            "{cpu_fo:?} vs {solve_fo:?}"
        );
    }
    assert!(text.contains("] W (RGB)") && solve.contains("] W (RGB)"));

    // Asking for a GPU transfer path keeps the error with its advice.
    let mut blend = args[..4].to_vec();
    blend.extend(["--path", "blend", "-o", "blend.png"]);
    let e = fails(ortm_no_gpu(&blend, dir));
    assert!(
        e.contains("no GPU adapter") && e.contains("mesa-vulkan-drivers"),
        "{e}"
    );

    // The same frame as the GPU's (lavapipe) with the display the fallback has, all light
    // from the lightmaps: shadow maps and rasterisation against ray casting differ only
    // along shadow edges and silhouettes.
    let mut gpu = args[..5].to_vec();
    gpu.extend([
        "--direct",
        "lightmap",
        "--shadow-size",
        "2048",
        "-o",
        "gpu.png",
    ]);
    ok(ortm(&gpu, dir));
    let a = image::open(dir.join("cpu.png")).unwrap().to_rgb8();
    let b = image::open(dir.join("gpu.png")).unwrap().to_rgb8();
    assert_eq!(a.dimensions(), b.dimensions());
    let differing = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 24))
        .count();
    let fraction = differing as f64 / (96.0 * 64.0);
    println!(
        "pixels differing by more than 24/255: {:.2} %",
        100.0 * fraction
    );
    // Measured: 10 of 6,144 pixels (0.16 %), along the boxes' silhouettes; 25 % margin.
    assert!(differing <= 13, "{differing} pixels differ");
}

#[test]
fn unknown_scene_names_are_answered_with_the_built_in_names() {
    let tmp = tempfile::tempdir().unwrap();
    let e = fails(ortm(&["bake", "cornel", "-o", "b"], tmp.path()));
    assert!(e.contains("did you mean `cornell`"), "{e}");
    for name in ["`cornell`", "`maze`", "`head`", "`head-exponential`"] {
        assert!(e.contains(name), "{name}: {e}");
    }
    assert!(!tmp.path().join("b").exists());
    // Far from every name: no guess, still the list.
    let e = fails(ortm(&["inspect", "teapot"], tmp.path()));
    assert!(!e.contains("did you mean") && e.contains("`maze`"), "{e}");
    for cmd in ["bake", "inspect", "solve", "reference", "compare"] {
        let help = ok(ortm(&[cmd, "--help"], tmp.path()));
        for name in ["`cornell`", "`maze`", "`head`", "`head-exponential`"] {
            assert!(
                help.contains(name),
                "ortm {cmd} --help lacks {name}:\n{help}"
            );
        }
    }
}

/// The bench's lists take spaces as their help's defaults show them, as well as commas: the
/// second case is parsed, the first (unknown) one named.
#[test]
fn bench_lists_take_spaces_as_well_as_commas() {
    let tmp = tempfile::tempdir().unwrap();
    for cases in [&["nosuch-32", "other-32"][..], &["nosuch-32,other-32"]] {
        let args = [&["bench", "accuracy", "--cases"][..], cases].concat();
        let e = fails(ortm(&args, tmp.path()));
        assert!(e.contains("unknown scene 'nosuch'"), "{cases:?}: {e}");
    }
}

#[test]
fn a_wrong_ortm_head_obj_is_named_in_the_error() {
    let tmp = tempfile::tempdir().unwrap();
    let missing = tmp.path().join("nowhere").join("head.obj");
    let out = ortm_command()
        .args(["inspect", "head", "-o", "h.png"])
        .current_dir(tmp.path())
        .env("ORTM_HEAD_OBJ", &missing)
        .output()
        .unwrap();
    let e = fails(out);
    assert!(
        e.contains(&missing.display().to_string()) && e.contains("from $ORTM_HEAD_OBJ"),
        "{e}"
    );
    let help = ok(ortm(&["inspect", "--help"], tmp.path()));
    assert!(help.contains("ORTM_HEAD_OBJ"), "{help}");
}

#[test]
fn negative_camera_values_are_accepted_after_a_space() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    tiny_cornell_bake(dir, "bake");
    let spec = "-0.3,0.3,-0.6:0.278,0.278,0.278:50";
    let base = ["render", "bake", "--size", "64x48"];
    let mut spaced = base.to_vec();
    spaced.extend(["--camera", spec, "-o", "spaced.png"]);
    ok(ortm_no_gpu(&spaced, dir));
    let equals = format!("--camera={spec}");
    let mut joined = base.to_vec();
    joined.extend([equals.as_str(), "-o", "joined.png"]);
    ok(ortm_no_gpu(&joined, dir));
    assert_eq!(
        std::fs::read(dir.join("spaced.png")).unwrap(),
        std::fs::read(dir.join("joined.png")).unwrap()
    );
}

/// Copies the two-quads scene (TOML + OBJ) into `dir`.
fn copy_two_quads(dir: &Path) {
    for f in ["two_quads.toml", "two_quads.obj"] {
        std::fs::copy(common::data(&format!("scene/{f}")), dir.join(f)).unwrap();
    }
}

#[test]
fn render_from_another_folder_finds_or_names_the_recorded_scene() {
    let tmp = tempfile::tempdir().unwrap();
    let root = tmp.path();
    let work = root.join("work");
    std::fs::create_dir_all(work.join("inside")).unwrap();
    copy_two_quads(&work);
    let bake = |scene: &str, out: &str| {
        ok(ortm(
            &[
                "bake",
                scene,
                "-o",
                out,
                "--size",
                "16",
                "--offsets",
                "4",
                "--effects",
                "radiosity",
            ],
            &work,
        ))
    };
    bake("two_quads.toml", "bake");
    let index = BakeIndex::read(&work.join("bake")).unwrap();
    let recorded = index.settings["scene"].as_str().unwrap().to_owned();
    let real = std::fs::canonicalize(work.join("two_quads.toml")).unwrap();
    assert_eq!(Path::new(&recorded), real);
    // From the parent folder: the scene lies outside the bake folder, so it must be named.
    let e = fails(ortm_no_gpu(&["render", "work/bake", "-o", "f.png"], root));
    assert!(
        e.contains("--scene") && e.contains("outside the bake directory"),
        "{e}"
    );
    ok(ortm_no_gpu(
        &[
            "render",
            "work/bake",
            "--scene",
            "work/two_quads.toml",
            "-o",
            "f.png",
        ],
        root,
    ));
    // A scene kept inside the bake folder opens from anywhere.
    copy_two_quads(&work.join("inside"));
    bake("inside/two_quads.toml", "inside");
    ok(ortm_no_gpu(&["render", "work/inside", "-o", "g.png"], root));
    // Moved away: the message names the recorded scene and --scene.
    std::fs::remove_file(work.join("inside/two_quads.toml")).unwrap();
    let e = fails(ortm_no_gpu(&["render", "work/inside", "-o", "h.png"], root));
    assert!(
        e.contains("recorded by the bake") && e.contains("--scene"),
        "{e}"
    );
    // A bake folder that does not exist is named as such.
    let e = fails(ortm_no_gpu(&["render", "work/nowhere"], root));
    assert!(e.contains("does not exist"), "{e}");
    let e = fails(ortm(&["bin", "work/nowhere"], root));
    assert!(e.contains("does not exist"), "{e}");
}

/// The `map_*.exr` files of `dir`, sorted.
fn map_files(dir: &Path) -> Vec<String> {
    let mut v: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .filter(|n| n.starts_with("map_") && n.ends_with(".exr"))
        .collect();
    v.sort();
    v
}

#[test]
fn rebaking_into_a_used_folder_leaves_only_the_new_maps() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let bake = |offsets: &str| {
        ok(ortm(
            &[
                "bake",
                "cornell",
                "--size",
                "32",
                "--offsets",
                offsets,
                "--selector",
                "jittered-grid",
                "-o",
                "b",
            ],
            dir,
        ))
    };
    bake("12");
    ok(ortm(&["bin", "b", "--atlas", "64"], dir));
    assert_eq!(map_files(&dir.join("b")).len(), 12);
    let text = bake("6");
    let index = BakeIndex::read(&dir.join("b")).unwrap();
    let mut named: Vec<String> = index.maps.iter().map(|m| m.file.clone()).collect();
    named.sort();
    assert_eq!(map_files(&dir.join("b")), named);
    assert_eq!(named.len(), 6);
    assert!(!dir.join("b/atlases.json").exists() && !dir.join("b/atlas_000.exr").exists());
    assert!(text.contains("removed"), "{text}");
    // The same settings again: every map reused, nothing removed.
    let text = bake("6");
    assert!(
        text.contains("(6 reused)") && !text.contains("removed"),
        "{text}"
    );
    assert_eq!(map_files(&dir.join("b")), named);
}

#[test]
fn inspect_reports_overlapping_uvs_and_draws_them_red() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    // The two quads with the right one mapped onto the left one's UVs, at 8×8: the left half
    // (4 columns × 8 rows of texel centres) is covered twice.
    let obj = std::fs::read_to_string(common::data("scene/two_quads.obj")).unwrap();
    std::fs::write(
        dir.join("two_quads.obj"),
        obj.replace("f 2/5 3/6 6/7 5/8", "f 2/1 3/2 6/3 5/4"),
    )
    .unwrap();
    let toml = std::fs::read_to_string(common::data("scene/two_quads.toml")).unwrap();
    std::fs::write(
        dir.join("overlap.toml"),
        toml.replace("width = 64\nheight = 32", "width = 8\nheight = 8"),
    )
    .unwrap();
    // As they are, the UVs are replaced by generated ones (docs/scene-format.md): the bake
    // runs and says so, and inspect shows the layout the bake uses.
    let baked = ok(ortm(
        &["bake", "overlap.toml", "-o", "b", "--offsets", "4"],
        dir,
    ));
    assert!(baked.contains("its UVs overlap (32 of 32"), "{baked}");
    assert!(baked.contains("generated lightmap UVs"), "{baked}");
    let text = ok(ortm(&["inspect", "overlap.toml", "-o", "gen.png"], dir));
    assert!(text.contains("overlaps     0 texel(s)"), "{text}");
    // Kept with `allow_uv_overlap = true`: inspect reports the overlap and draws it red.
    let toml = std::fs::read_to_string(dir.join("overlap.toml")).unwrap();
    std::fs::write(
        dir.join("overlap.toml"),
        toml.replace("mesh = ", "allow_uv_overlap = true\nmesh = "),
    )
    .unwrap();
    let text = ok(ortm(&["inspect", "overlap.toml", "-o", "cov.png"], dir));
    assert!(text.contains("overlaps     32 texel(s)"), "{text}");
    let img = image::open(dir.join("cov.png")).unwrap().to_rgb8();
    // 8 texels enlarged to 512 px: 64 px per texel; a legend below.
    assert_eq!(img.width(), 512);
    assert!(img.height() > 512);
    let red = |x: u32, y: u32| img.get_pixel(x, y).0 == [255, 0, 0];
    let red_texels = (0..8u32)
        .flat_map(|ty| (0..8u32).map(move |tx| (tx, ty)))
        .filter(|&(tx, ty)| red(tx * 64 + 32, ty * 64 + 32))
        .collect::<Vec<_>>();
    assert_eq!(red_texels.len(), 32);
    assert!(red_texels.iter().all(|&(tx, _)| tx < 4), "{red_texels:?}");
}

#[test]
fn pictures_are_enlarged_with_a_legend_and_atlases_fit_the_maps() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    ok(ortm(&["solve", "cornell", "--size", "32", "-o", "s"], dir));
    let exr = read_lightmap_exr(&dir.join("s/final.exr")).unwrap();
    let png = image::open(dir.join("s/final.png")).unwrap().to_rgb8();
    // 32 texels → 16 px each; every texel one uniform square; uncovered texels black.
    assert_eq!(png.width(), 512);
    assert!(png.height() > 512 + 30, "a legend strip below the map");
    for ty in 0..32u32 {
        for tx in 0..32u32 {
            let c = *png.get_pixel(tx * 16, ty * 16);
            for (dx, dy) in [(15, 0), (0, 15), (15, 15), (7, 9)] {
                assert_eq!(*png.get_pixel(tx * 16 + dx, ty * 16 + dy), c);
            }
            if exr.get(tx, ty) == [0.0; 3] {
                assert_eq!(c.0, [0, 0, 0]);
            }
        }
    }

    // `ortm bin` without --atlas: the smallest power-of-two square holding every stored texel,
    // one atlas.
    tiny_cornell_bake(dir, "bake");
    let text = ok(ortm(&["bin", "bake"], dir));
    let index = BakeIndex::read(&dir.join("bake")).unwrap();
    let stored: u64 = index
        .maps
        .iter()
        .flat_map(|m| &m.rects)
        .map(|r| r.area())
        .sum();
    let set = ortm::atlas::read_atlas_set(&dir.join("bake")).unwrap();
    let side = u64::from(set.atlas_size.0);
    assert_eq!(set.atlas_size.0, set.atlas_size.1);
    assert!(
        side * side >= stored && (side / 2) * (side / 2) < stored,
        "{side} for {stored}"
    );
    assert_eq!(set.atlases.len(), 1);
    assert!(text.contains("chosen to fit"), "{text}");
}

#[test]
fn the_first_command_runs_without_a_gpu_and_writes_a_guide() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let text = ok(ortm_no_gpu(
        &["demo", "-o", "out", "--size", "32", "--offsets", "12"],
        dir,
    ));
    assert!(text.contains("CPU mirrors of the passes"), "{text}");
    let guide = std::fs::read_to_string(dir.join("out/guide.md")).unwrap();
    // Every picture the guide shows exists.
    let mut shown = 0;
    for part in guide.split("](").skip(1) {
        let file = &part[..part.find(')').unwrap()];
        assert!(
            dir.join("out").join(file).is_file(),
            "guide shows missing {file}"
        );
        shown += 1;
    }
    assert!(shown >= 8, "{shown} pictures");
    // Progress printed as plain lines (stderr is a pipe here).
    assert!(
        text.contains("writing transfer maps: 12/12 (100 %)"),
        "{text}"
    );
    // The frame's lightmap (multi-resolution maps over the exact transport, applied by the CPU
    // mirror) against the demo's own exact solve: 0.36 % total and 1.89 % indirect with one
    // value per receiver (the bake's default), 0.54 % and 2.88 % with `--receiver-blocks on`;
    // with the bake's default 8×8 clusters instead it was 4.3 % and 22.5 %.
    let cmp = ok(ortm(
        &[
            "compare",
            "out/exact/final.exr",
            "out/final.exr",
            "--first",
            "out/exact/first_order.exr",
            "out/first_order.exr",
            "--scene",
            "cornell",
            "--size",
            "32",
        ],
        dir,
    ));
    let rmse = |label: &str| -> f64 {
        let line = cmp.lines().find(|l| l.starts_with(label)).expect(label);
        let at = line.find("relative RMSE").expect("RMSE") + "relative RMSE".len();
        line[at..]
            .split_whitespace()
            .next()
            .unwrap()
            .parse()
            .unwrap()
    };
    let (total, indirect) = (rmse("total"), rmse("indirect"));
    println!("demo frame vs exact solve: total {total:.4}, indirect {indirect:.4}");
    assert!(total < 0.01 && indirect < 0.03, "{cmp}");
}

#[test]
fn help_texts_use_one_shadow_default_and_user_words() {
    let tmp = tempfile::tempdir().unwrap();
    let render = ok(ortm(&["render", "--help"], tmp.path()));
    let view = ok(ortm(&["view", "--help"], tmp.path()));
    let default = |help: &str| {
        let at = help.find("--shadow-size").unwrap();
        let rest = &help[at..];
        let d = rest.find("[default: ").unwrap() + "[default: ".len();
        rest[d..d + rest[d..].find(']').unwrap()].to_owned()
    };
    assert_eq!(default(&render), default(&view));
    let bench = ok(ortm(&["bench", "render", "--help"], tmp.path()));
    for help in [&render, &view, &bench] {
        for internal in [
            "best_for",
            "TransferOptions",
            "MapContribution",
            "DebugView",
            "::",
        ] {
            assert!(!help.contains(internal), "{internal} in\n{help}");
        }
    }
}

/// A closed unit cube as a bare OBJ (no UVs, no normals, no lights), faces counter-clockwise
/// seen from outside.
const CUBE_OBJ: &str = "v -0.5 -0.5 -0.5\nv 0.5 -0.5 -0.5\nv 0.5 0.5 -0.5\nv -0.5 0.5 -0.5\n\
v -0.5 -0.5 0.5\nv 0.5 -0.5 0.5\nv 0.5 0.5 0.5\nv -0.5 0.5 0.5\n\
f 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n";

/// A convex object has no light transport between its texels (radiosity only: no surface sees
/// another). The bake says so, picks its offsets on a jittered grid and writes a valid bake
/// whose maps add nothing (it used to stop: "transference is 0 at all 101 seed offsets"); the
/// default light sits outside the object (it used to sit inside it, so the render was black).
#[test]
fn a_convex_object_bakes_without_transport_and_its_default_light_is_outside() {
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("cube.obj"), CUBE_OBJ).unwrap();
    let text = ok(ortm(
        &[
            "bake",
            "cube.obj",
            "--size",
            "32",
            "--offsets",
            "4",
            "-o",
            "b",
        ],
        dir.path(),
    ));
    assert!(
        text.contains("no light transport") && text.contains("jittered grid"),
        "{text}"
    );
    assert!(!text.contains("transference is 0"), "{text}");
    let index = BakeIndex::read(&dir.path().join("b")).unwrap();
    assert_eq!(index.maps.len(), 4);
    let text = ok(ortm(
        &["render", "b", "--scene", "cube.obj", "-o", "f.png"],
        dir.path(),
    ));
    let first = rgb_after(&text, "first-order power");
    let fin = rgb_after(&text, "final");
    assert!(
        first.iter().all(|&p| p > 0.0),
        "lit by the default light: {text}"
    );
    for c in 0..3 {
        assert!(
            (fin[c] - first[c]).abs() <= 1e-4 * first[c],
            "nothing transferred: {text}"
        );
    }
}
