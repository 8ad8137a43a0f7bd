//! `ortm compare` and the library's accuracy figures (`ortm::accuracy::compare`) on known
//! images with known figures: a 10 % scale on interior texels is a relative RMSE of exactly
//! 0.1, errors on border texels only count for nothing, the indirect figure with both first
//! orders, per-channel energy ratios, the interior mask of the Cornell charts, the worst texels
//! and the false-colour picture, the first-order edge mask against a brute-force search; then the tool end to end on OpenEXRs written here (its printed
//! figures are the library's), `ortm solve`'s OpenEXRs, and bad inputs (sizes, missing files,
//! non-EXR files, non-finite values) refused with the file named; the reference's noise from its
//! standard error and the share of texels within 3 standard errors.

mod common;

use std::collections::HashMap;
use std::path::Path;

use common::{fails, ok, ortm};
use glam::{DVec3, Vec3};
use ortm::Lightmap;
use ortm::accuracy::compare::{
    UNCOVERED_GREY, compare, error_image, interior_mask, near_first_order_edges, noise_corrected,
    power_w, reference_noise, reference_rms, viridis,
};
use ortm::bake::lighting::{from_lightmap, to_lightmap};
use ortm::bake::texels::TexelGrid;
use ortm::render::lightmap_exr::{read_lightmap_exr, write_lightmap_exr};
use ortm::scene::cornell_box;

/// The Cornell box's texels at `size`².
fn cornell_grid(size: u32) -> TexelGrid {
    TexelGrid::build(&cornell_box(size)).unwrap()
}

/// A smooth, positive, colourful reference value per texel (W/m²).
fn reference_values(grid: &TexelGrid) -> Vec<Vec3> {
    grid.texels
        .iter()
        .map(|t| {
            let p = t.position_m;
            Vec3::new(1.0 + 3.0 * p.x, 2.0 + p.y * p.y, 0.5 + 2.0 * p.z)
        })
        .collect()
}

/// Relative closeness.
fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1e-12)
}

#[test]
fn interior_mask_of_each_cornell_chart_is_its_rectangle_less_one_texel_all_round() {
    for size in [32u32, 64] {
        let grid = cornell_grid(size);
        let mask = interior_mask(&grid);
        // Per chart: bounding box, covered and interior counts.
        let mut charts: HashMap<u32, (u32, u32, u32, u32, usize, usize)> = HashMap::new();
        for (t, m) in grid.texels.iter().zip(&mask) {
            let e = charts
                .entry(t.chart)
                .or_insert((u32::MAX, u32::MAX, 0, 0, 0, 0));
            e.0 = e.0.min(t.x);
            e.1 = e.1.min(t.y);
            e.2 = e.2.max(t.x);
            e.3 = e.3.max(t.y);
            e.4 += 1;
            e.5 += *m as usize;
        }
        assert_eq!(charts.len(), 15);
        for (chart, (x0, y0, x1, y1, covered, interior)) in charts {
            let (w, h) = ((x1 - x0 + 1) as usize, (y1 - y0 + 1) as usize);
            assert_eq!(
                covered,
                w * h,
                "size {size} chart {chart}: a full rectangle"
            );
            assert_eq!(
                interior,
                (w - 2) * (h - 2),
                "size {size} chart {chart}: {w}x{h}"
            );
        }
    }
}

#[test]
fn ten_percent_more_on_interior_texels_is_a_relative_rmse_of_one_tenth() {
    let grid = cornell_grid(64);
    let mask = interior_mask(&grid);
    let reference = reference_values(&grid);
    // Interior texels 1.1 × the reference; border texels wildly off (they must not count).
    let test: Vec<Vec3> = reference
        .iter()
        .zip(&mask)
        .map(|(b, m)| if *m { *b * 1.1 } else { *b * 7.0 + 3.0 })
        .collect();
    let c = compare(&grid, &reference, &test, None, 5);
    assert!(close(c.total, 0.1, 1e-5), "total {}", c.total);
    assert_eq!(c.indirect, None);
    assert_eq!(c.covered, grid.texels.len());
    assert_eq!(c.interior, mask.iter().filter(|&&m| m).count());
    // The worst texels are interior ones, their error |0.1 b| / RMS(b) (largest |b| first).
    let rms = reference_rms(&reference, &mask);
    let largest = reference
        .iter()
        .zip(&mask)
        .filter(|(_, m)| **m)
        .map(|(b, _)| b.length() as f64)
        .fold(0.0, f64::max);
    assert!(close(c.worst[0].relative_error, 0.1 * largest / rms, 1e-4));
    for w in &c.worst {
        let i = grid.at(w.x as i32, w.y as i32).unwrap() as usize;
        assert!(mask[i], "worst texel ({}, {}) is on a border", w.x, w.y);
    }
}

#[test]
fn errors_on_border_texels_only_give_zero_but_change_the_energy() {
    let grid = cornell_grid(64);
    let mask = interior_mask(&grid);
    let reference = reference_values(&grid);
    let offset = Vec3::new(0.5, 1.0, 2.0);
    let test: Vec<Vec3> = reference
        .iter()
        .zip(&mask)
        .map(|(b, m)| if *m { *b } else { *b + offset })
        .collect();
    let c = compare(&grid, &reference, &test, None, 3);
    assert_eq!(c.total, 0.0);
    assert!(c.worst.iter().all(|w| w.relative_error == 0.0));
    // Energy counts every covered texel: ratio = 1 + offset · A_border / P_ref.
    let border_area: f64 = grid
        .texels
        .iter()
        .zip(&mask)
        .filter(|(_, m)| !**m)
        .map(|(t, _)| t.area_m2 as f64)
        .sum();
    let p_ref = power_w(&grid, &reference);
    for ch in 0..3 {
        let want = 1.0 + offset[ch] as f64 * border_area / p_ref[ch];
        assert!(
            close(c.energy_ratio[ch], want, 1e-6),
            "channel {ch}: {} vs {want}",
            c.energy_ratio[ch]
        );
        assert!(want > 1.01, "the offset changes the energy noticeably");
    }
}

#[test]
fn indirect_figure_and_per_channel_energy_ratio() {
    let grid = cornell_grid(64);
    let reference = reference_values(&grid);
    // Same first order (half the reference) for both; the test's indirect is 1.2 × the
    // reference's: indirect error 0.2 exactly, total error 0.2 × 0.5 = 0.1.
    let first: Vec<Vec3> = reference.iter().map(|b| *b * 0.5).collect();
    let test: Vec<Vec3> = reference
        .iter()
        .zip(&first)
        .map(|(b, f)| *f + (*b - *f) * 1.2)
        .collect();
    let c = compare(&grid, &reference, &test, Some((&first, &first)), 0);
    assert!(close(c.indirect.unwrap(), 0.2, 1e-5), "{:?}", c.indirect);
    assert!(close(c.total, 0.1, 1e-5), "{}", c.total);
    assert!(c.worst.is_empty());
    // Channels scaled by (1, 2, 0.5): energy ratio exactly that.
    let scaled: Vec<Vec3> = reference
        .iter()
        .map(|b| *b * Vec3::new(1.0, 2.0, 0.5))
        .collect();
    let c = compare(&grid, &reference, &scaled, None, 0);
    assert!(
        (c.energy_ratio - DVec3::new(1.0, 2.0, 0.5))
            .abs()
            .max_element()
            < 1e-6
    );
    // A perfect test: zeros and ones.
    let c = compare(&grid, &reference, &reference, Some((&first, &first)), 1);
    assert_eq!((c.total, c.indirect), (0.0, Some(0.0)));
    assert_eq!(c.energy_ratio, DVec3::ONE);
}

#[test]
fn error_image_colours_by_error_over_the_scale_and_greys_uncovered_texels() {
    let grid = cornell_grid(32);
    let reference = reference_values(&grid);
    let mut test = reference.clone();
    // Texel 0 off by exactly the scale (2 W/m²), texel 1 by half of it, the rest exact.
    test[0] += Vec3::new(2.0, 0.0, 0.0);
    test[1] += Vec3::new(0.0, 0.0, 1.0);
    let img = error_image(&grid, &reference, &test, 2.0);
    let k = 512 / 32; // pixels per texel
    assert_eq!(img.width(), 32 * k);
    assert!(img.height() > 32 * k, "colour bar under the map");
    let at = |x: u32, y: u32| *img.get_pixel(x * k + k / 2, y * k + k / 2);
    let (t0, t1, t2) = (&grid.texels[0], &grid.texels[1], &grid.texels[2]);
    assert_eq!(at(t0.x, t0.y), viridis(1.0));
    assert_eq!(at(t1.x, t1.y), viridis(0.5));
    assert_eq!(at(t2.x, t2.y), viridis(0.0));
    assert_eq!(
        at(0, 0),
        UNCOVERED_GREY,
        "texel (0, 0) is in the border gutter"
    );
    // The ramp's ends are viridis': dark purple to yellow, and its middle is teal.
    assert_eq!(viridis(0.0).0, [68, 1, 84]);
    assert_eq!(viridis(1.0).0, [253, 231, 37]);
    assert_eq!(viridis(0.5).0, [33, 145, 140]);
    assert_eq!(viridis(7.0), viridis(1.0), "clamped above the scale");
    // The bar: left end 0, right end the scale.
    let last = img.height() - 1;
    assert_eq!(*img.get_pixel(0, last), viridis(0.0));
    assert_eq!(*img.get_pixel(img.width() - 1, last), viridis(1.0));
}

/// Writes per-texel values as a lightmap OpenEXR.
fn write_exr(dir: &Path, name: &str, grid: &TexelGrid, values: &[Vec3]) {
    write_lightmap_exr(&dir.join(name), &to_lightmap(grid, values)).unwrap();
}

/// Writes each `(name, values)` as a lightmap OpenEXR in `dir`.
fn write_exrs(dir: &Path, grid: &TexelGrid, files: &[(&str, &[Vec3])]) {
    for (name, values) in files {
        write_exr(dir, name, grid, values);
    }
}

/// The number after `key` on the line starting with `label` of `text`.
fn figure(text: &str, label: &str, key: &str) -> f64 {
    let line = text
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no '{label}' line in:\n{text}"));
    let rest = &line[line.find(key).unwrap() + key.len()..];
    rest.split_whitespace().next().unwrap().parse().unwrap()
}

#[test]
fn cli_prints_the_library_figures_and_writes_the_error_picture() {
    let dir = tempfile::tempdir().unwrap();
    let grid = cornell_grid(32);
    let reference = reference_values(&grid);
    let first: Vec<Vec3> = reference.iter().map(|b| *b * 0.4).collect();
    let test: Vec<Vec3> = reference
        .iter()
        .enumerate()
        .map(|(i, b)| *b * (1.0 + 0.05 * ((i % 7) as f32 - 3.0)))
        .collect();
    let test_first: Vec<Vec3> = first.iter().map(|b| *b * 1.02).collect();
    write_exrs(
        dir.path(),
        &grid,
        &[
            ("ref.exr", &reference),
            ("test.exr", &test),
            ("ref_first.exr", &first),
            ("test_first.exr", &test_first),
        ],
    );
    let text = ok(ortm(
        &[
            "compare",
            "ref.exr",
            "test.exr",
            "--first",
            "ref_first.exr",
            "test_first.exr",
            "--scene",
            "cornell",
            "--size",
            "32",
            "-o",
            "err.png",
            "--worst",
            "3",
        ],
        dir.path(),
    ));
    let c = compare(&grid, &reference, &test, Some((&first, &test_first)), 3);
    assert!(c.total > 0.05 && c.indirect.unwrap() > 0.05);
    assert!(
        close(figure(&text, "total", "RMSE"), c.total, 1e-5),
        "{text}"
    );
    assert!(close(
        figure(&text, "indirect", "RMSE"),
        c.indirect.unwrap(),
        1e-5
    ));
    assert!(close(
        figure(&text, "energy ratio", "R G B:"),
        c.energy_ratio.x,
        1e-5
    ));
    assert!(text.contains(&format!("{} covered, {} interior", c.covered, c.interior)));
    // The worst texel is listed first with its coordinates.
    let w = &c.worst[0];
    assert!(
        text.lines().any(|l| l
            .split_whitespace()
            .take(2)
            .eq([w.x.to_string(), w.y.to_string()])),
        "{text}"
    );
    let png = image::open(dir.path().join("err.png")).unwrap();
    assert_eq!(png.width(), 512);
}

/// A reference whose standard error is 10 % of its value everywhere is 10 % noisy (total)
/// and 10 % / 0.6 of its indirect term when its first order is 40 % of it; a test 2σ off on
/// every texel of one kind and 4σ on the rest is within 3σ on exactly the first kind; noise
/// comes off an error in quadrature. Then the tool prints the same, finding `std_error.exr`
/// beside the reference by itself.
#[test]
fn reference_noise_and_the_three_sigma_share() {
    let grid = cornell_grid(32);
    let reference = reference_values(&grid);
    let first: Vec<Vec3> = reference.iter().map(|b| *b * 0.4).collect();
    let se: Vec<Vec3> = reference.iter().map(|b| *b * 0.1).collect();
    let near = |i: usize| !i.is_multiple_of(3);
    let test: Vec<Vec3> = (reference.iter().zip(&se).enumerate())
        .map(|(i, (b, s))| *b + *s * if near(i) { 2.0 } else { 4.0 })
        .collect();
    let n = reference_noise(&grid, &reference, &se, &test, Some(&first));
    let expected_within =
        (0..grid.texels.len()).filter(|&i| near(i)).count() as f64 / grid.texels.len() as f64;
    assert!(close(n.total, 0.1, 1e-5), "{n:?}");
    assert!(close(n.indirect.unwrap(), 0.1 / 0.6, 1e-5), "{n:?}");
    assert!(close(n.within_three_sigma, expected_within, 1e-12), "{n:?}");
    assert!(close(noise_corrected(0.5, 0.3), 0.4, 1e-12));
    assert_eq!(noise_corrected(0.2, 0.3), 0.0);
    assert_eq!((n.unlit_misses, n.unlit_largest), (0, 0.0), "{n:?}");
    let lit = first.iter().filter(|f| f.max_element() > 0.0).count();
    let lit_within = (0..grid.texels.len())
        .filter(|&i| near(i) && first[i].max_element() > 0.0)
        .count();
    let (n_lit, share) = n.within_lit.unwrap();
    assert_eq!(n_lit, lit, "{n:?}");
    assert!(
        lit > 0 && close(share, lit_within as f64 / lit as f64, 1e-12),
        "{n:?}"
    );
    // Texels the reference found unlit (0 ± 0): an exact 0 is within 3σ, anything else a
    // miss counted apart with its largest value.
    let (mut r0, mut se0, mut t0) = (reference.clone(), se.clone(), reference.clone());
    for i in 0..3 {
        r0[i] = Vec3::ZERO;
        se0[i] = Vec3::ZERO;
        t0[i] = Vec3::new(0.0, [0.0, 2e-6, 5e-6][i], 0.0);
    }
    let n0 = reference_noise(&grid, &r0, &se0, &t0, None);
    assert_eq!(n0.within_lit, None, "{n0:?}");
    assert_eq!(n0.unlit_misses, 2, "{n0:?}");
    assert!(close(n0.unlit_largest, 5e-6, 1e-6), "{n0:?}");
    assert!(
        close(
            n0.within_three_sigma,
            1.0 - 2.0 / grid.texels.len() as f64,
            1e-12
        ),
        "{n0:?}"
    );

    let dir = tempfile::tempdir().unwrap();
    std::fs::create_dir(dir.path().join("r")).unwrap();
    write_exrs(
        dir.path(),
        &grid,
        &[
            ("r/final.exr", &reference),
            ("r/first_order.exr", &first),
            ("r/std_error.exr", &se),
            ("test.exr", &test),
        ],
    );
    let args: Vec<&str> = "compare r/final.exr test.exr --first r/first_order.exr \
                           r/first_order.exr --scene cornell --size 32 -o err.png"
        .split_whitespace()
        .collect();
    let text = ok(ortm(&args, dir.path()));
    assert!(
        close(figure(&text, "reference noise", "total"), 10.0, 1e-3),
        "{text}"
    );
    assert!(
        close(
            figure(&text, "within 3σ", "3σ"),
            100.0 * expected_within,
            1e-3
        ),
        "{text}"
    );
    let c = compare(&grid, &reference, &test, Some((&first, &first)), 1);
    let corrected = figure(&text, "reference noise", "quadrature: total");
    assert!(
        close(corrected, 100.0 * noise_corrected(c.total, 0.1), 1e-3),
        "{text}"
    );
    // `std_error.exr` beside the reference is found whatever the reference's name; without it,
    // no noise line; `--std-error` names another file.
    std::fs::rename(dir.path().join("r/final.exr"), dir.path().join("r/b.exr")).unwrap();
    let text = ok(ortm(
        &[&["compare", "r/b.exr"][..], &args[2..]].concat(),
        dir.path(),
    ));
    assert!(text.contains("reference noise"), "{text}");
    std::fs::rename(
        dir.path().join("r/std_error.exr"),
        dir.path().join("r/se.exr"),
    )
    .unwrap();
    let text = ok(ortm(
        &[&["compare", "r/b.exr"][..], &args[2..]].concat(),
        dir.path(),
    ));
    assert!(!text.contains("reference noise"), "{text}");
    let with = [
        &["compare", "r/b.exr"][..],
        &args[2..],
        &["--std-error", "r/se.exr"],
    ]
    .concat();
    assert!(ok(ortm(&with, dir.path())).contains("reference noise r/se.exr"));
}

#[test]
fn solve_writes_exrs_that_compare_and_add_up() {
    // `ortm solve maze`: final = first order + indirect in its OpenEXRs, and comparing the first
    // order against the final gives the energy ratio of their powers (< 1: light is added).
    let dir = tempfile::tempdir().unwrap();
    let text = ok(ortm(
        &["solve", "maze", "--size", "32", "-o", "s"],
        dir.path(),
    ));
    assert!(text.contains("final.exr"), "{text}");
    let read = |n: &str| read_lightmap_exr(&dir.path().join("s").join(n)).unwrap();
    let (fo, fin, ind) = (
        read("first_order.exr"),
        read("final.exr"),
        read("indirect.exr"),
    );
    assert_eq!((fin.width, fin.height), (32, 32));
    for ((a, b), c) in fo.data.iter().zip(&fin.data).zip(&ind.data) {
        for ch in 0..3 {
            assert!((a[ch] + c[ch] - b[ch]).abs() <= 1e-5 * b[ch].abs().max(1.0));
        }
    }
    let text = ok(ortm(
        &[
            "compare",
            "s/final.exr",
            "s/first_order.exr",
            "--scene",
            "maze",
            "--size",
            "32",
        ],
        dir.path(),
    ));
    let grid = TexelGrid::build(&ortm::scene::maze(32)).unwrap();
    let ratio = power_w(&grid, &from_lightmap(&grid, &fo)).x
        / power_w(&grid, &from_lightmap(&grid, &fin)).x;
    assert!(ratio < 0.9, "{ratio}");
    assert!(
        close(figure(&text, "energy ratio", "R G B:"), ratio, 1e-5),
        "{text}"
    );
    assert!(dir.path().join("error.png").is_file());

    // `--light` replaces the scene's lamp: one in the far bay lights the right wall (x = 2)
    // directly, which the default lamp never does.
    let right_wall_first = |out: &str| {
        let fo = read_lightmap_exr(&dir.path().join(out).join("first_order.exr")).unwrap();
        let values = from_lightmap(&grid, &fo);
        grid.texels
            .iter()
            .zip(values)
            .filter(|(t, _)| t.normal.x < -0.5 && t.position_m.x > 1.99)
            .map(|(_, v)| v.element_sum())
            .fold(0.0f32, f32::max)
    };
    assert_eq!(right_wall_first("s"), 0.0);
    let light = "point:1.75,0.5,1.0:10";
    ok(ortm(
        &[
            "solve", "maze", "--size", "32", "-o", "far", "--light", light,
        ],
        dir.path(),
    ));
    // Unshadowed at the wall point nearest the lamp: 0.7 · 10 W/sr / (0.25 m)² = 112 W/m² per
    // channel; texel centres are a little farther.
    let lit = right_wall_first("far");
    assert!(
        lit > 0.5 * 3.0 * 112.0 && lit <= 3.0 * 112.0 * 1.001,
        "{lit}"
    );
    let e = fails(ortm(
        &[
            "solve",
            "maze",
            "--size",
            "32",
            "-o",
            "bad",
            "--light",
            "point:1,2",
        ],
        dir.path(),
    ));
    assert!(e.contains("--light") && e.contains("point:1,2"), "{e}");
}

#[test]
fn solve_effects_select_the_transport_terms() {
    // `ortm solve --effects`: the maze has no translucent material, so subsurface scattering
    // alone adds nothing to its first order, and radiosity alone is its whole solve; an unknown
    // effect is refused by name.
    let dir = tempfile::tempdir().unwrap();
    for (out, effects) in [
        ("all", "radiosity,sss"),
        ("rad", "radiosity"),
        ("sss", "sss"),
    ] {
        ok(ortm(
            &[
                "solve",
                "maze",
                "--size",
                "32",
                "-o",
                out,
                "--effects",
                effects,
            ],
            dir.path(),
        ));
    }
    let read = |out: &str, n: &str| read_lightmap_exr(&dir.path().join(out).join(n)).unwrap();
    assert_eq!(read("all", "final.exr").data, read("rad", "final.exr").data);
    let indirect = read("sss", "indirect.exr");
    assert!(indirect.data.iter().all(|v| *v == [0.0; 3]));
    assert!(
        read("all", "indirect.exr").data.iter().any(|v| v[0] > 0.0),
        "radiosity adds light in the maze"
    );
    let text = fails(ortm(
        &[
            "solve",
            "maze",
            "--size",
            "32",
            "-o",
            "x",
            "--effects",
            "glow",
        ],
        dir.path(),
    ));
    assert!(text.contains("--effects: unknown effect 'glow'"), "{text}");
}

#[test]
fn solve_first_order_samples_average_the_transfer_input() {
    // `ortm solve --first-order-samples 3`: the written first order stays the centres' values,
    // the final changes (the Cornell box's lamp sits 2 cm under the ceiling, so the ceiling's
    // texels beside it send far more light averaged over their squares than at their centres),
    // and an even or too large N is refused with the rule.
    let dir = tempfile::tempdir().unwrap();
    for (out, n) in [("one", "1"), ("three", "3")] {
        ok(ortm(
            &[
                "solve",
                "cornell",
                "--size",
                "32",
                "-o",
                out,
                "--first-order-samples",
                n,
            ],
            dir.path(),
        ));
    }
    let read = |out: &str, n: &str| read_lightmap_exr(&dir.path().join(out).join(n)).unwrap();
    assert_eq!(
        read("one", "first_order.exr").data,
        read("three", "first_order.exr").data
    );
    let sum = |out: &str| -> f64 {
        (read(out, "indirect.exr").data.iter())
            .map(|v| v[0] as f64)
            .sum()
    };
    let (one, three) = (sum("one"), sum("three"));
    assert!(
        three > 1.05 * one,
        "indirect light, centres {one:.1} vs averaged {three:.1}"
    );
    for bad in ["2", "9"] {
        let text = fails(ortm(
            &[
                "solve",
                "cornell",
                "--size",
                "32",
                "-o",
                "x",
                "--first-order-samples",
                bad,
            ],
            dir.path(),
        ));
        assert!(
            text.contains(&format!("--first-order-samples {bad}: must be odd, 1 to 7")),
            "{text}"
        );
    }
}

#[test]
fn bad_inputs_are_refused_naming_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let grid = cornell_grid(32);
    let reference = reference_values(&grid);
    write_exr(dir.path(), "ref.exr", &grid, &reference);
    std::fs::write(dir.path().join("text.exr"), "not an image").unwrap();
    let mut nan = to_lightmap(&grid, &reference);
    let t = &grid.texels[5];
    nan.set(t.x, t.y, [f32::NAN, 0.0, 0.0]);
    write_lightmap_exr(&dir.path().join("nan.exr"), &nan).unwrap();
    write_lightmap_exr(&dir.path().join("small.exr"), &Lightmap::new(16, 16)).unwrap();
    let run = |args: &[&str]| fails(ortm(args, dir.path()));
    let base = |test: &'static str| {
        [
            "compare", "ref.exr", test, "--scene", "cornell", "--size", "32",
        ]
    };

    let e = run(&base("small.exr"));
    assert!(
        e.contains("small.exr") && e.contains("16x16") && e.contains("32x32"),
        "{e}"
    );
    // Without --size the scene's own size (64²) is the one the EXRs must have.
    let e = run(&["compare", "ref.exr", "ref.exr", "--scene", "cornell"]);
    assert!(
        e.contains("ref.exr") && e.contains("32x32") && e.contains("64x64"),
        "{e}"
    );
    assert!(e.contains("--size 32"), "the fix: {e}");
    let e = run(&base("missing.exr"));
    assert!(e.contains("missing.exr"), "{e}");
    let e = run(&base("text.exr"));
    assert!(e.contains("text.exr"), "{e}");
    let e = run(&base("nan.exr"));
    assert!(
        e.contains("nan.exr") && e.contains(&format!("({}, {})", t.x, t.y)),
        "{e}"
    );
    let e = run(&[
        "compare",
        "ref.exr",
        "ref.exr",
        "--first",
        "ref.exr",
        "small.exr",
        "--scene",
        "cornell",
        "--size",
        "32",
    ]);
    assert!(e.contains("small.exr"), "{e}");
    let e = run(&[
        "compare",
        "ref.exr",
        "ref.exr",
        "--scene",
        "no-such-scene.toml",
    ]);
    assert!(e.contains("no-such-scene.toml"), "{e}");
}

#[test]
fn solve_methods_agree_and_the_dense_limit_names_the_other() {
    // The hierarchical solve against the exact dense one through the CLI (maze 32², ε = 10⁻⁴),
    // and the refusals: the dense solve above its limit names `--method hierarchical`; a
    // tolerance must be positive.
    let dir = tempfile::tempdir().unwrap();
    for (name, method) in [("d", "dense"), ("h", "hierarchical")] {
        let text = ok(ortm(
            &[
                "solve",
                "maze",
                "--size",
                "32",
                "-o",
                name,
                "--method",
                method,
                "--tolerance",
                "1e-4",
            ],
            dir.path(),
        ));
        assert!(text.contains(&format!("{method} solve")), "{text}");
    }
    let read = |d: &str| read_lightmap_exr(&dir.path().join(d).join("indirect.exr")).unwrap();
    let (d, h) = (read("d"), read("h"));
    let (mut num, mut den) = (0.0f64, 0.0f64);
    for (a, b) in d.data.iter().zip(&h.data) {
        for ch in 0..3 {
            num += ((a[ch] - b[ch]) as f64).powi(2);
            den += (a[ch] as f64).powi(2);
        }
    }
    let rel = (num / den).sqrt();
    println!(
        "maze 32², indirect: hierarchical vs dense relative RMSE {rel:.4} (all covered texels)"
    );
    // Measured: 0.0018 (at 32² most pairs are near, so most links are exact texel pairs).
    // Bound: measured + 25 %.
    assert!(rel < 0.0023, "hierarchical vs dense: {rel:.4}");
    let e = fails(ortm(
        &[
            "solve", "maze", "--size", "128", "-o", "big", "--method", "dense",
        ],
        dir.path(),
    ));
    assert!(
        e.contains("--method hierarchical") && e.contains("limited"),
        "{e}"
    );
    let e = fails(ortm(
        &[
            "solve",
            "maze",
            "--size",
            "32",
            "-o",
            "t",
            "--tolerance",
            "0",
        ],
        dir.path(),
    ));
    assert!(e.contains("--tolerance"), "{e}");
    // Links beyond half the memory limit stop the refinement with an error that names the
    // tolerance (maze 64² at 10⁻⁴ holds ~19 MB of links).
    let out = common::ortm_command()
        .args([
            "solve",
            "maze",
            "--size",
            "64",
            "-o",
            "m",
            "--method",
            "hierarchical",
        ])
        .env("ORTM_MEMORY_LIMIT_BYTES", "4000000")
        .current_dir(dir.path())
        .output()
        .unwrap();
    let e = fails(out);
    assert!(
        e.contains("needs more than 2000000 bytes") && e.contains("--tolerance"),
        "{e}"
    );
    assert!(!dir.path().join("m").join("final.exr").exists());
}

/// The first-order edge mask (hashed cubes) against the plain search over every pair, on the
/// Cornell box at 32² with a first order that jumps 4× across a plane through the room and is
/// 0 on one wall: the same texels; a uniform first order has no edges.
#[test]
fn first_order_edges_match_the_plain_search() {
    let grid = cornell_grid(32);
    let t = &grid.texels;
    assert!(
        near_first_order_edges(&grid, &vec![Vec3::ONE; t.len()])
            .iter()
            .all(|e| !e)
    );
    let first: Vec<Vec3> = t
        .iter()
        .map(|x| {
            let p = x.position_m;
            if x.normal.x > 0.9 {
                Vec3::ZERO
            } else if p.y + 0.3 * p.z > 0.35 {
                Vec3::splat(4.0)
            } else {
                Vec3::new(1.0, 0.5, 0.25)
            }
        })
        .collect();
    let fast = near_first_order_edges(&grid, &first);
    let plain: Vec<bool> = (0..t.len())
        .map(|i| {
            let own = first[i].element_sum();
            (0..t.len()).any(|j| {
                let o = first[j].element_sum();
                (o > 2.0 * own || own > 2.0 * o)
                    && (t[i].position_m - t[j].position_m).length()
                        < 2.5 * t[i].area_m2.max(t[j].area_m2).sqrt()
            })
        })
        .collect();
    let flagged = fast.iter().filter(|&&e| e).count();
    assert!(
        flagged > 0 && flagged < t.len(),
        "{flagged} of {} flagged",
        t.len()
    );
    assert_eq!(fast, plain);
}
