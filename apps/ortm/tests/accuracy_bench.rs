//! `ortm bench accuracy` measures what a user's own commands make (offsets and
//! multi-resolution maps), and its Cornell 64² rows guard the bake's accuracy: a change that makes them worse than their bound fails here.
//!
//! The check of the table's numbers goes through other code than the bench's: `ortm bake`
//! (its defaults must be the bench's bake), the bake directory read back and applied on the CPU
//! (Eq. 9), `ortm solve`'s OpenEXRs and `ortm compare` (its parsing of OpenEXRs and coverage).

mod common;

use common::{ok, ortm};
use ortm::bake::lighting::{from_lightmap, to_lightmap};
use ortm::bake::texels::TexelGrid;
use ortm::bake_dir::BakeIndex;
use ortm::render::lightmap_exr::{read_lightmap_exr, write_lightmap_exr};
use ortm::scene::cornell_box;

/// One row of the table: method, offsets column, total and indirect RMSE (fractions), energy.
#[derive(Debug)]
struct Row {
    method: String,
    offsets: String,
    total: f64,
    indirect: f64,
    energy: f64,
}

fn percent(s: &str) -> f64 {
    s.trim()
        .trim_end_matches('%')
        .parse::<f64>()
        .unwrap_or_else(|_| panic!("not a percentage: '{s}'"))
        / 100.0
}

/// The measured rows of the table printed by `ortm bench accuracy` (not the reference line).
fn table_rows(text: &str) -> Vec<Row> {
    text.lines()
        .filter(|l| l.starts_with("| cornell"))
        .map(|l| l.split('|').map(str::trim).collect::<Vec<_>>())
        .filter(|c| !c[3].starts_with("reference"))
        .map(|c| Row {
            method: c[3].to_string(),
            offsets: c[4].to_string(),
            total: percent(c[5]),
            indirect: percent(c[6]),
            energy: c[7].parse().unwrap(),
        })
        .collect()
}

/// The figure after `label` in `ortm compare`'s output (`total  relative RMSE 0.043852 (…)`).
fn compare_figure(text: &str, label: &str) -> f64 {
    let line = text
        .lines()
        .find(|l| l.starts_with(label))
        .unwrap_or_else(|| panic!("no '{label}' line in:\n{text}"));
    line.split_whitespace()
        .nth(3)
        .and_then(|v| v.parse().ok())
        .unwrap_or_else(|| panic!("no figure in '{line}'"))
}

/// `ortm compare` of a bake's final lightmap `applied` (kept over covered texels only, gutters
/// 0 as the solve writes them; saved as `name`) against `exact/` (same first order).
fn compare_with_exact(
    dir: &std::path::Path,
    grid: &TexelGrid,
    applied: &ortm::Lightmap,
    name: &str,
) -> String {
    let applied = to_lightmap(grid, &from_lightmap(grid, applied));
    write_lightmap_exr(&dir.join(name), &applied).unwrap();
    ok(ortm(
        &[
            "compare",
            "exact/final.exr",
            name,
            "--first",
            "exact/first_order.exr",
            "exact/first_order.exr",
            "--scene",
            "cornell",
            "--size",
            "64",
        ],
        dir,
    ))
}

/// `ortm bench accuracy --cases cornell-64 --levels 3e-3` with `extra` arguments, run in `dir`.
fn cornell_64_table(dir: &std::path::Path, extra: &[&str]) -> String {
    let mut args = vec![
        "bench",
        "accuracy",
        "--cases",
        "cornell-64",
        "--levels",
        "3e-3",
    ];
    args.extend_from_slice(extra);
    ok(ortm(&args, dir))
}

/// Asserts that `row`'s total and indirect figures are those `ortm compare` printed (`cmp`) to
/// the table's 0.1 % rounding; `how` names the commands that made the compared lightmap.
fn assert_row_matches(row: &Row, cmp: &str, how: &str) {
    for (label, table_value) in [("total", row.total), ("indirect", row.indirect)] {
        let by_hand = compare_figure(cmp, label);
        assert!(
            (by_hand - table_value).abs() <= 0.00051,
            "{label}: table {table_value}, {how} {by_hand}"
        );
    }
}

/// `ortm bake cornell --size 64 ARGS -o bake`, `ortm solve cornell --size 64
/// --first-order-samples 1 -o exact` (once per
/// `dir`), the maps applied on the CPU to the solve's first order and `ortm compare`d with the
/// exact solve: the bake's index and the comparison's output.
fn bake_and_compare(dir: &std::path::Path, args: &[&str]) -> (BakeIndex, String) {
    let mut bake = vec!["bake", "cornell", "--size", "64"];
    bake.extend_from_slice(args);
    bake.extend_from_slice(&["-o", "bake"]);
    ok(ortm(&bake, dir));
    if !dir.join("exact/final.exr").exists() {
        ok(ortm(
            // The bench's default input: the centres' first order.
            &[
                "solve",
                "cornell",
                "--size",
                "64",
                "--first-order-samples",
                "1",
                "-o",
                "exact",
            ],
            dir,
        ));
    }
    let grid = TexelGrid::build(&cornell_box(64)).unwrap();
    let first = read_lightmap_exr(&dir.join("exact/first_order.exr")).unwrap();
    let index = BakeIndex::read(&dir.join("bake")).unwrap();
    let maps = index.load_maps(&dir.join("bake")).unwrap();
    let applied = ortm::maps::apply(&maps, &first).unwrap();
    let cmp = compare_with_exact(dir, &grid, &applied, "bake_final.exr");
    (index, cmp)
}

#[test]
fn the_cornell_rows_match_bake_solve_and_compare_and_stay_within_their_bounds() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let table = cornell_64_table(dir, &["--offsets", "50"]);
    let rows = table_rows(&table);
    assert_eq!(
        rows.len(),
        5,
        "evaluator + multi-resolution maps (per receiver, receiver blocks) + two cell rules:\n{table}"
    );
    assert!(table.contains("reference: exact dense solve"), "{table}");

    // The integrated row, rebuilt from the user's commands.
    let (_, cmp) = bake_and_compare(dir, &["--offsets", "50"]);
    let grid = TexelGrid::build(&cornell_box(64)).unwrap();
    let first = read_lightmap_exr(&dir.join("exact/first_order.exr")).unwrap();
    let integrated = rows
        .iter()
        .find(|r| r.method.contains("integrated"))
        .unwrap();
    assert_eq!(integrated.offsets, "50");
    assert_row_matches(integrated, &cmp, "bake + solve + compare");

    // The multi-resolution row, rebuilt from `ortm bake --levels` (the bench's default clusters)
    // and the CPU reference of the level maps.
    ok(ortm(
        &[
            "bake",
            "cornell",
            "--size",
            "64",
            "--levels",
            "3e-3",
            "--coarse-block",
            "8",
            "--receiver-blocks",
            "off",
            "-o",
            "lbake",
        ],
        dir,
    ));
    let lmaps = BakeIndex::read(&dir.join("lbake"))
        .unwrap()
        .load_maps(&dir.join("lbake"))
        .unwrap();
    let applied = ortm::maps::levels::apply_levels(&lmaps, &first, &grid.area_map()).unwrap();
    let cmp = compare_with_exact(dir, &grid, &applied, "lbake_final.exr");
    let levels = rows
        .iter()
        .find(|r| r.method.contains("multi-resolution") && !r.method.contains("receiver blocks"))
        .unwrap();
    // Receiver blocks keep the transferred power (the energy column agrees to its rounding) and
    // add little error: measured 1.9 % / 15.6 % against 1.8 % / 14.9 % per receiver (bound:
    // the per-receiver row's + 25 %).
    let blocks = rows
        .iter()
        .find(|r| r.method.contains("receiver blocks"))
        .unwrap();
    assert!(
        (blocks.energy - levels.energy).abs() <= 0.0011,
        "{blocks:?} vs {levels:?}"
    );
    assert!(
        blocks.total <= 1.25 * levels.total && blocks.indirect <= 1.25 * levels.indirect,
        "{blocks:?} vs {levels:?}"
    );
    assert_eq!(levels.offsets, lmaps.len().to_string(), "maps of the bake");
    assert_row_matches(levels, &cmp, "bake --levels + solve + compare");

    // Guards: the values measured when the table was introduced (Cornell 64², scene light,
    // seed 1) — evaluator 1.6 % / 13.4 % (total / indirect), energy 0.963 — and, for the
    // importance offsets, when the texels' form factors were collocated at their centres:
    // integrated cells 44.9 % / 362.9 %, Eq. 10 23.3 % / 187.9 %, energy 0.997 / 0.853 (25.9 % /
    // 210.9 % and 18.2 % / 148.4 % before; 50 offsets are a lottery of where the sites fall: over
    // seeds 1–4 the integrated row reads 44.9 / 31.4 / 22.8 / 32.8 % total, `ortm bench accuracy
    // --cases cornell-64 --offsets 50 --seed S`). Each may grow by 25 % (the errors, and the
    // energy ratios' distance from 1) before this fails; the integrated row's energy keeps its
    // first measurement, 0.932, as the bound (0.997 ± 25 % of its distance from 1 is rounding).
    let bound = |method: &str, total: f64, indirect: f64, energy: f64| {
        let r = rows.iter().find(|r| r.method.contains(method)).unwrap();
        assert!(
            r.total <= 1.25 * total && r.indirect <= 1.25 * indirect,
            "{method}: {r:?} exceeds the bounds {total} / {indirect} (+25 %)"
        );
        assert!(
            (r.energy - 1.0).abs() <= 1.25 * (energy - 1.0f64).abs(),
            "{method}: energy {} is further from 1 than {energy} (+25 %)",
            r.energy
        );
    };
    bound("evaluator", 0.016, 0.134, 0.963);
    // Multi-resolution maps at ε = 3e-3, measured when they were added: 1.8 % / 14.9 %, 0.957
    // (they converge to the evaluator above, whose 8×8 clusters set the floor).
    bound("multi-resolution", 0.018, 0.149, 0.957);
    bound("integrated", 0.449, 3.629, 0.932);
    bound("Eq. 10", 0.233, 1.879, 0.853);
}

/// `--tolerances`: the rows on the hierarchical transport. Its evaluator's error falls with the
/// tolerance and is within issue 16's 2 % (indirect) at the default tolerance, and its bake row
/// is what `ortm bake --tolerance` (alone: the default tolerance) makes.
#[test]
fn the_hierarchical_rows_fall_with_the_tolerance_and_match_bake_tolerance() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path();
    let table = cornell_64_table(dir, &["--offsets", "20", "--tolerances", "1e-3,1e-4"]);
    let rows = table_rows(&table);
    assert_eq!(
        rows.len(),
        15,
        "(evaluator + two multi-resolution rows + two cell rules) on the clusters and at each \
         tolerance:\n{table}"
    );
    let row = |method: &str| {
        rows.iter()
            .find(|r| r.method == method)
            .unwrap_or_else(|| panic!("no row '{method}' in:\n{table}"))
    };
    // Measured: 4.4 % at 1e-3, 0.9 % at 1e-4 (indirect), energy 1.000; bound: measured + 25 %.
    let coarse = row("evaluator, every pair, hierarchical ε = 1e-3");
    let fine = row("evaluator, every pair, hierarchical ε = 1e-4");
    assert!(fine.indirect < coarse.indirect, "{fine:?} vs {coarse:?}");
    assert!(
        fine.indirect <= 0.0113 && coarse.indirect <= 0.055,
        "{fine:?}, {coarse:?}"
    );
    assert!((fine.energy - 1.0).abs() <= 0.002, "{fine:?}");

    let (index, cmp) = bake_and_compare(dir, &["--offsets", "20", "--tolerance"]);
    assert_eq!(
        index.settings["tolerance"].as_f64().map(|t| t as f32),
        Some(ortm::bake::transport::hier::DEFAULT_TOLERANCE),
        "--tolerance alone bakes at the default tolerance: {}",
        index.settings
    );
    let baked = row("importance offsets, integrated cells, hierarchical ε = 1e-4");
    assert_row_matches(baked, &cmp, "bake --tolerance + solve + compare");
}
