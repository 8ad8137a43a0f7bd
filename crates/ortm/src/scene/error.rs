//! [`SceneError`]: everything that can go wrong while reading a scene file, an OBJ mesh or an
//! albedo texture.
//!
//! Every message names the file (and the line or field where known), says what is wrong and
//! how to fix it. Line numbers are 1-based, as in text editors. OBJ face numbers are 1-based
//! counts of `f` statements in file order (the n-th `f` line is face n).

use std::fmt;
use std::path::PathBuf;

/// Formats an optional line number as `:LINE` (or nothing) after a file name.
#[derive(Clone, Copy, Debug)]
pub struct AtLine(pub Option<usize>);

impl fmt::Display for AtLine {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self.0 {
            Some(line) => write!(f, ":{line}"),
            None => Ok(()),
        }
    }
}

/// An error while loading a scene (scene file, OBJ mesh, textures).
#[derive(Debug, thiserror::Error)]
pub enum SceneError {
    /// A file named by the caller or by the scene file does not exist.
    #[error(
        "{what} not found: {path}. Fix: check the path (paths inside a scene file are relative \
         to the scene file's folder)"
    )]
    NotFound {
        /// What the file is for (`scene file`, `OBJ mesh`, `albedo texture`).
        what: &'static str,
        /// The path that was tried.
        path: PathBuf,
    },

    /// A file exists but could not be read.
    #[error("cannot read {what} {path}: {source}. Fix: check that it is a readable regular file")]
    Io {
        /// What the file is for.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// The operating system's error.
        #[source]
        source: std::io::Error,
    },

    /// A file is larger than this loader accepts (checked before reading it).
    #[error(
        "{what} {path} is {size} bytes, more than the limit of {limit} bytes. Fix: use a smaller \
         file (decimate the mesh) or check that the path names the right file"
    )]
    TooLarge {
        /// What the file is for.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// Its size in bytes.
        size: u64,
        /// The limit in bytes.
        limit: u64,
    },

    /// A text file is not valid UTF-8.
    #[error(
        "{path}:{line}: {what} is not valid UTF-8 text. Fix: save it as UTF-8 (or plain ASCII)"
    )]
    NotUtf8 {
        /// What the file is for.
        what: &'static str,
        /// The file.
        path: PathBuf,
        /// Line of the first invalid byte.
        line: usize,
    },

    /// The scene file is not valid TOML or does not match the scene format (unknown key,
    /// missing key, wrong type).
    #[error(
        "{path}{}: {message}. Fix: correct the scene file (format: docs/scene-format.md)",
        AtLine(*.line)
    )]
    SceneSyntax {
        /// The scene file.
        path: PathBuf,
        /// Line of the problem, when the TOML parser reports a position.
        line: Option<usize>,
        /// The parser's message (names the key).
        message: String,
    },

    /// A scene-file value is out of range or inconsistent.
    #[error("{path}{}: `{field}` {problem}. Fix: {fix}", AtLine(*.line))]
    InvalidField {
        /// The scene file (or, for [`crate::scene::obj::load_obj`] arguments, the OBJ file).
        path: PathBuf,
        /// Line of the enclosing table or value, when known.
        line: Option<usize>,
        /// Dotted field path, e.g. `material[1].albedo` (indices are 0-based).
        field: String,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },

    /// The OBJ parser rejected the file.
    #[error(
        "{path}{}: OBJ syntax error: {problem}. Fix: correct that statement (Wavefront OBJ: \
         `v x y z`, `vt u v`, `vn x y z`, `f v/vt[/vn] ...` with 1-based indices) or re-export \
         the mesh",
        AtLine(*.line)
    )]
    ObjSyntax {
        /// The OBJ file.
        path: PathBuf,
        /// Line of the bad statement, when known.
        line: Option<usize>,
        /// What the parser found wrong.
        problem: String,
    },

    /// A `v`, `vt` or `vn` statement holds NaN or an infinity.
    #[error(
        "{path}:{line}: non-finite number (NaN or infinity) in a `{statement}` statement: \
         `{text}`. Fix: re-export the mesh, or repair or remove that vertex"
    )]
    ObjNonFinite {
        /// The OBJ file.
        path: PathBuf,
        /// Line of the statement.
        line: usize,
        /// `v`, `vt` or `vn`.
        statement: &'static str,
        /// The line's text (truncated).
        text: String,
    },

    /// The OBJ has no texture coordinates at all.
    #[error(
        "{path}: the mesh has no texture coordinates (no `vt` statements); ORTM needs a \
         lightmap UV layout. Fix: unwrap the mesh in a modelling tool (non-overlapping charts \
         inside [0,1]²) and export it with UVs"
    )]
    ObjNoUvs {
        /// The OBJ file.
        path: PathBuf,
    },

    /// Some face corner has no texture coordinate index.
    #[error(
        "{path}:{line}: face {face} has a corner without a texture coordinate (`f v` or \
         `f v//vn`). Fix: give every face corner a UV (`f v/vt` or `f v/vt/vn`), e.g. by \
         unwrapping the whole mesh"
    )]
    ObjMissingUvs {
        /// The OBJ file.
        path: PathBuf,
        /// Line of the face.
        line: usize,
        /// 1-based face number.
        face: usize,
    },

    /// A face refers to a vertex, UV or normal that does not exist.
    #[error(
        "{path}:{line}: face {face} refers to {kind} {index}, but only {count} exist at that \
         point of the file. Fix: correct the index (OBJ indices start at 1; negative ones count \
         back from the last element defined)"
    )]
    ObjIndexOutOfRange {
        /// The OBJ file.
        path: PathBuf,
        /// Line of the face.
        line: usize,
        /// 1-based face number.
        face: usize,
        /// `position`, `texture coordinate` or `normal`.
        kind: &'static str,
        /// The index as written.
        index: i64,
        /// How many of that kind were defined before the face.
        count: usize,
    },

    /// A texture coordinate used by a face lies outside the unit square.
    #[error(
        "{path}:{line}: face {face} has UV ({u}, {v}) outside [0, 1] ({count} face corners in \
         all). Fix: pack the lightmap UVs into the unit square (tiled or UDIM layouts are not \
         supported)"
    )]
    ObjUvOutOfRange {
        /// The OBJ file.
        path: PathBuf,
        /// Line of the first offending face.
        line: usize,
        /// 1-based number of the first offending face.
        face: usize,
        /// Its u.
        u: f32,
        /// Its v.
        v: f32,
        /// How many face corners are out of range.
        count: usize,
    },

    /// Triangles with zero area in the world.
    #[error(
        "{path}: {count} triangles have zero world area ({first}). Fix: remove or merge those \
         faces in a modelling tool, or set `skip_degenerate_faces = true` in the scene file to \
         drop them with a warning"
    )]
    ObjDegenerate {
        /// The OBJ file.
        path: PathBuf,
        /// How many triangles.
        count: usize,
        /// The first few, as `face N (line L)`.
        first: String,
    },

    /// The OBJ has no faces (after dropping points, lines and skipped faces).
    #[error(
        "{path}: the mesh has no triangles. Fix: check that the file has `f` statements with \
         3 or more corners"
    )]
    ObjNoTriangles {
        /// The OBJ file.
        path: PathBuf,
    },

    /// A glTF file is not valid or cannot be used.
    #[error("{path}: the glTF file {problem}. Fix: {fix}")]
    Gltf {
        /// The glTF file.
        path: PathBuf,
        /// What is wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },

    /// Lightmap UVs could not be generated.
    #[error("{path}: cannot generate lightmap UVs: {problem}. Fix: {fix}")]
    Unwrap {
        /// The mesh file.
        path: PathBuf,
        /// What went wrong.
        problem: String,
        /// How to fix it.
        fix: String,
    },

    /// An albedo texture could not be decoded.
    #[error(
        "{path}: cannot decode the albedo texture: {source}. Fix: use an 8- or 16-bit sRGB PNG"
    )]
    Texture {
        /// The image file.
        path: PathBuf,
        /// The decoder's error.
        #[source]
        source: image::ImageError,
    },
}
