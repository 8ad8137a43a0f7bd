//! Messages and bounds of issue 19, item 6: a face with fewer than three corners beside valid
//! faces is named in a warning (file and line) instead of vanishing; `--coarse-block 0` and an
//! `--iterations` beyond its bound are refused with the bound, which the help text states.

mod common;

use std::fs;

use common::{fails, ok, ortm};

#[test]
fn two_corner_face_is_a_warning_naming_its_line() {
    let dir = tempfile::tempdir().unwrap();
    let obj = dir.path().join("m.obj");
    fs::write(
        &obj,
        "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n\
         f 1/1 2/2 3/3 4/4\nf 1/1 3/3\n",
    )
    .unwrap();
    let (mesh, _, warnings) = ortm::scene::load_obj(&obj, 1.0).unwrap();
    // The quad still gives its two triangles; the 2-corner face on line 10 gives none.
    assert_eq!(mesh.triangles.len(), 2);
    let expected = format!("{}:10: a face (`f`) with 2 corners", obj.display());
    assert!(
        warnings.iter().any(|w| w.contains(&expected)),
        "{warnings:?}"
    );
}

#[test]
fn coarse_block_and_iterations_are_bounded_with_the_bound_in_the_help() {
    let dir = tempfile::tempdir().unwrap();
    let help = ok(ortm(&["bake", "--help"], dir.path()));
    let max_it = ortm::io::limits::MAX_REFINEMENT_ITERATIONS;
    let max_block = ortm::io::limits::MAX_COARSE_BLOCK;
    assert!(help.contains(&format!("0..={max_it}")), "{help}");
    assert!(help.contains(&format!("1..={max_block}")), "{help}");
    // The default block is the library's.
    let default = ortm::bake::BakeSettings::default().coarse_block;
    assert!(help.contains(&format!("[default: {default}]")), "{help}");
    let bake = |extra: &[&str]| {
        let mut args = vec![
            "bake",
            "cornell",
            "--size",
            "32",
            "--offsets",
            "2",
            "-o",
            "b",
        ];
        args.extend(extra);
        fails(ortm(&args, dir.path()))
    };
    let too_large = (max_block + 1).to_string();
    let err = bake(&["--coarse-block", &too_large]);
    assert!(
        err.contains("--coarse-block") && err.contains(&format!("0..={max_block}")),
        "{err}"
    );
    let err = bake(&["--iterations", "4294967295"]);
    assert!(
        err.contains("--iterations") && err.contains(&format!("0..={max_it}")),
        "{err}"
    );
    // Refused before anything was written.
    assert!(!dir.path().join("b").exists());
}
