//! Bad input: one file per case. Each error must name the file and the problem (and, where
//! the format allows, the line), and nothing may panic.

mod common;

use std::path::Path;

use common::data;

use ortm::scene::{SceneError, load_obj, load_scene};

/// Loads an OBJ that must fail; returns the error and its message.
fn obj_error(rel: &str) -> (SceneError, String) {
    let e = load_obj(&data(rel), 1.0).expect_err("must fail");
    let msg = e.to_string();
    let file = Path::new(rel).file_name().unwrap().to_str().unwrap();
    assert!(msg.contains(file), "message does not name {file}: {msg}");
    assert!(msg.contains("Fix:"), "message has no fix: {msg}");
    (e, msg)
}

/// Loads a scene that must fail; returns the error and its message.
fn scene_error(rel: &str) -> (SceneError, String) {
    let e = load_scene(&data(rel)).expect_err("must fail");
    let msg = e.to_string();
    assert!(msg.contains("Fix:"), "message has no fix: {msg}");
    (e, msg)
}

#[test]
fn missing_scene_file() {
    let (e, msg) = scene_error("bad/there_is_no_such_scene.toml");
    assert!(matches!(e, SceneError::NotFound { .. }), "{e:?}");
    assert!(
        msg.contains("there_is_no_such_scene.toml") && msg.contains("not found"),
        "{msg}"
    );
}

#[test]
fn missing_obj_file() {
    let e = load_obj(&data("bad/there_is_no_such_mesh.obj"), 1.0).unwrap_err();
    assert!(matches!(e, SceneError::NotFound { .. }), "{e:?}");
    assert!(e.to_string().contains("there_is_no_such_mesh.obj"));
}

#[test]
fn missing_mesh_named_by_scene() {
    let (_, msg) = scene_error("bad/missing_mesh.toml");
    assert!(msg.contains("missing_mesh.toml"), "{msg}");
    assert!(
        msg.contains("`mesh`") && msg.contains("no_such_mesh.obj"),
        "{msg}"
    );
    assert!(msg.contains("does not exist"), "{msg}");
    assert!(msg.contains(":2:"), "line of the `mesh` key: {msg}");
}

#[test]
fn obj_syntax_error_names_the_line() {
    let (e, msg) = obj_error("bad/syntax_error.obj");
    assert!(
        matches!(e, SceneError::ObjSyntax { line: Some(4), .. }),
        "{e:?}"
    );
    assert!(
        msg.contains("syntax_error.obj:4") && msg.contains("`v`"),
        "{msg}"
    );
}

#[test]
fn obj_without_uvs() {
    let (e, msg) = obj_error("bad/no_uvs.obj");
    assert!(matches!(e, SceneError::ObjNoUvs { .. }), "{e:?}");
    assert!(msg.contains("no texture coordinates"), "{msg}");
}

#[test]
fn obj_face_corner_without_uv() {
    let (e, msg) = obj_error("bad/missing_uv_corner.obj");
    assert!(
        matches!(
            e,
            SceneError::ObjMissingUvs {
                line: 10,
                face: 2,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg.contains("missing_uv_corner.obj:10") && msg.contains("face 2"),
        "{msg}"
    );
}

#[test]
fn obj_uv_outside_unit_square() {
    let (e, msg) = obj_error("bad/uv_outside.obj");
    assert!(
        matches!(
            e,
            SceneError::ObjUvOutOfRange {
                line: 11,
                face: 2,
                count: 1,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg.contains("(1.5, 0.25)") && msg.contains("outside [0, 1]"),
        "{msg}"
    );
}

#[test]
fn obj_degenerate_faces() {
    let (e, msg) = obj_error("bad/degenerate.obj");
    assert!(
        matches!(e, SceneError::ObjDegenerate { count: 2, .. }),
        "{e:?}"
    );
    assert!(
        msg.contains("face 2 (line 11)") && msg.contains("face 3 (line 12)"),
        "{msg}"
    );
    assert!(msg.contains("skip_degenerate_faces"), "{msg}");
}

#[test]
fn obj_nan_names_the_line() {
    let (e, msg) = obj_error("bad/nan.obj");
    assert!(
        matches!(e, SceneError::ObjNonFinite { line: 4, .. }),
        "{e:?}"
    );
    assert!(msg.contains("nan.obj:4") && msg.contains("NaN"), "{msg}");
}

#[test]
fn obj_nan_through_a_scene() {
    let (e, msg) = scene_error("bad/nan_scene.toml");
    assert!(
        matches!(e, SceneError::ObjNonFinite { line: 4, .. }),
        "{e:?}"
    );
    assert!(msg.contains("nan.obj:4"), "{msg}");
}

#[test]
fn obj_index_out_of_range() {
    let (e, msg) = obj_error("bad/index_out_of_range.obj");
    assert!(
        matches!(
            e,
            SceneError::ObjIndexOutOfRange {
                line: 8,
                face: 1,
                index: 7,
                count: 3,
                ..
            }
        ),
        "{e:?}"
    );
    assert!(
        msg.contains("index_out_of_range.obj:8") && msg.contains("position 7"),
        "{msg}"
    );
}

#[test]
fn unknown_scene_key_names_key_and_line() {
    let (e, msg) = scene_error("bad/unknown_key.toml");
    assert!(
        matches!(e, SceneError::SceneSyntax { line: Some(4), .. }),
        "{e:?}"
    );
    assert!(
        msg.contains("unknown_key.toml:4") && msg.contains("metres_per_unti"),
        "{msg}"
    );
}

#[test]
fn missing_required_scene_field() {
    let (e, msg) = scene_error("bad/missing_field.toml");
    assert!(matches!(e, SceneError::SceneSyntax { .. }), "{e:?}");
    assert!(
        msg.contains("missing_field.toml") && msg.contains("metres_per_unit"),
        "{msg}"
    );
}

#[test]
fn unknown_subsurface_preset_lists_the_presets() {
    let (e, msg) = scene_error("bad/bad_preset.toml");
    assert!(matches!(e, SceneError::InvalidField { .. }), "{e:?}");
    assert!(
        msg.contains("bad_preset.toml") && msg.contains("skin3"),
        "{msg}"
    );
    assert!(msg.contains("material[0].subsurface.preset"), "{msg}");
    for name in ortm::scene::presets::PRESET_NAMES {
        assert!(msg.contains(name), "{msg}");
    }
}

#[test]
fn oversized_files_are_refused_before_reading() {
    // A sparse file just over the limit: the size check must refuse it without reading.
    let dir = tempfile::tempdir().unwrap();
    let p = dir.path().join("huge.obj");
    let f = std::fs::File::create(&p).unwrap();
    f.set_len(ortm::scene::obj::MAX_OBJ_BYTES + 1).unwrap();
    let e = load_obj(&p, 1.0).unwrap_err();
    assert!(matches!(e, SceneError::TooLarge { .. }), "{e:?}");
    assert!(e.to_string().contains("huge.obj"));
}

#[test]
fn invalid_scene_values_name_the_field() {
    let dir = tempfile::tempdir().unwrap();
    let obj = data("scene/two_quads.obj");
    let cases: [(&str, &str); 8] = [
        ("metres_per_unit = -1.0", "`metres_per_unit`"),
        (
            "metres_per_unit = 1.0\n[lightmap]\nwidth = 0",
            "`lightmap.width`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"\nalbedo = [1.5, 0, 0]",
            "`material[0].albedo`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"",
            "`material[0].albedo`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"\nalbedo = [1, 1, 1]\n\
             [[light]]\ntype = \"point\"\nposition = [0, 0, 0]\nirradiance = 3",
            "`light[0].irradiance`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"\nalbedo = [1, 1, 1]\n\
             [[light]]\ntype = \"spot\"\nposition = [0, 0, 0]\ndirection = [0, 0, 0]\n\
             intensity = 1\ninner_deg = 10\nouter_deg = 20",
            "`light[0].direction`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"\nalbedo = [1, 1, 1]\n\
             [[light]]\ntype = \"spot\"\nposition = [0, 0, 0]\ndirection = [0, 0, 1]\n\
             intensity = 1\ninner_deg = 30\nouter_deg = 20",
            "`light[0].outer_deg`",
        ),
        (
            "metres_per_unit = 1.0\n[[material]]\nname = \"a\"\n\
             subsurface = { sigma_a = [0.1, 0.1, 0.1], sigma_s_prime = [1, 1, 1], eta = 0.2 }",
            "`material[0].subsurface.eta`",
        ),
    ];
    for (i, (body, field)) in cases.iter().enumerate() {
        let p = dir.path().join(format!("case{i}.toml"));
        let mut text = format!("mesh = {:?}\n{body}\n", obj.to_str().unwrap());
        if !body.contains("[[material]]") {
            text += "[[material]]\nname = \"a\"\nalbedo = [1, 1, 1]\n";
        }
        std::fs::write(&p, text).unwrap();
        let e = load_scene(&p).expect_err(body);
        let msg = e.to_string();
        assert!(
            matches!(e, SceneError::InvalidField { .. }),
            "{body}: {e:?}"
        );
        assert!(msg.contains(&format!("case{i}.toml")), "{msg}");
        assert!(msg.contains(field), "{field} not in: {msg}");
    }
}
