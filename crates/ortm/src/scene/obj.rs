//! Wavefront OBJ loading and validation: OBJ file → [`Mesh`] in metres.
//!
//! # Data flow
//! 1. The file is read whole (refused up front when larger than [`MAX_OBJ_BYTES`]) and must
//!    be UTF-8.
//! 2. `tobj` parses it (`triangulate: false`, `single_index: false` so positions and UVs keep
//!    separate indices: per-corner UVs such as the head scan's survive; points and lines are
//!    ignored). A syntax error is reported with the line the parser stopped on.
//! 3. A light line scan of the same text finds what `tobj` does not report: NaN/infinite
//!    numbers in `v`/`vt`/`vn` (with the line), face corners without a UV, indices out of
//!    range (with the line), `usemtl` names, smoothing groups (`s`) and `mtllib` files. Every
//!    face of n corners becomes n − 2 triangles in file order, so the scan also knows each
//!    triangle's OBJ face, line, `usemtl` name and smoothing group.
//! 4. The `tobj` models (one per `o`/`g`/`usemtl` run) are merged into one [`Mesh`]:
//!    positions are welded by bit-identical coordinates (this undoes `tobj`'s per-group
//!    duplication, so the head's 8,844 positions stay 8,844 and smooth normals do not break
//!    at group borders), UVs and normals are concatenated. A quad `a b c d` is split into
//!    `a b c` + `a c d`, as written. Polygons of 5 or more corners are ear-clipped in their
//!    best-fit plane (`triangulate_polygon`): concave polygons come out right, and a convex
//!    one becomes the fan from its first corner. A polygon that cannot be ear-clipped
//!    (self-intersecting) becomes that fan, with a warning naming its line.
//! 5. Validation: every UV must lie in `[0, 1]` (within 1e-6, then clamped). Triangles whose
//!    world area is at most 1e-10 × (bounding-box diagonal)² are *degenerate*. A degenerate
//!    triangle of a polygon whose own total area is not degenerate is a *sliver* of its
//!    triangulation (every triangulation of a finely sampled circle has some): it is dropped,
//!    with one warning per polygon naming its line, the count and the share of the polygon's
//!    area lost (at most count × 1e-10 × diagonal²); it would hold no lightmap texel. Any
//!    other degenerate triangle (a face given with 3 corners, or every triangle of a polygon
//!    that is degenerate as a whole) is an error listing the count and the first faces, or,
//!    with [`ObjOptions::skip_degenerate_faces`], dropped with a warning. Triangles with
//!    (near-)zero UV area (≤ 1e-12; the head scan has 16, collapsed by its 5-decimal UVs) are
//!    kept with a warning: they still occlude light, but cover no texel centre, so the
//!    lightmap holds nothing for them.
//! 6. Normals: the file's `vn` normals (normalised) when every face corner has one; otherwise
//!    computed by [`MeshOptions::normals`]: [`load_obj`] smooths every (welded) position
//!    (area-weighted), the scene loader keeps hard edges ([`super::normals`]: smoothing groups
//!    `s` when the file has them, else the crease angle).
//!
//! A file without any `vt` is refused, unless [`MeshOptions::allow_missing_uvs`] (the scene
//! loader, which then generates lightmap UVs): every corner gets UV (0, 0).
//!
//! # Conventions and units
//! Positions are multiplied by `metres_per_unit` (→ metres). Faces are counter-clockwise
//! seen from the front (the OBJ convention). UVs are used as written (`v = 1` is the top row
//! of the lightmap image). Material indices in [`MeshTriangle::material`] index the returned
//! list of `usemtl` names (order of first use); faces before any `usemtl` get the name `""`.
//! The scene loader maps these names to scene-file materials. MTL files are not read (their
//! contents are not used); a `mtllib` file that does not exist is only a warning.
//!
//! # Limits
//! Free-form geometry (curves, surfaces) is ignored. Polylines (`l`) with more than two
//! vertices are rejected. Face numbers in messages are 1-based counts of `f` statements.

use std::collections::HashMap;
use std::io::{BufRead, Read};
use std::path::Path;

use glam::{DVec2, DVec3, Vec2, Vec3};

use super::normals::NormalRule;
use super::{Mesh, MeshTriangle, SceneError, read_text_bounded};

/// Largest OBJ file accepted, in bytes, checked before reading ([`crate::io::limits::MAX_OBJ_BYTES`]).
pub const MAX_OBJ_BYTES: u64 = crate::io::limits::MAX_OBJ_BYTES;
/// How far outside `[0, 1]` a UV may lie and still be accepted (it is then clamped).
pub const UV_TOLERANCE: f32 = 1e-6;
/// A triangle whose world area is at most this × (bounding-box diagonal)² is degenerate.
pub const DEGENERATE_RELATIVE_AREA: f64 = 1e-10;
/// A triangle whose UV area (unit square = 1) is at most this gets a warning (no texels).
pub const DEGENERATE_UV_AREA: f64 = 1e-12;
/// Most corner-in-ear tests spent on one polygon (about a second) before it is fanned instead.
const EAR_TEST_BUDGET: u64 = 1_000_000_000;
/// How many faces a degenerate-face message or warning lists.
const LIST_FIRST: usize = 5;

/// Options for [`load_obj_with`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ObjOptions {
    /// Drop triangles with zero world area with a warning instead of failing.
    pub skip_degenerate_faces: bool,
}

/// What the scene loader asks of an OBJ beyond [`ObjOptions`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct MeshOptions {
    /// How normals are computed when the file has none ([`load_obj`] smooths every shared
    /// position; scene files use the crease rule of [`super::normals`]).
    pub normals: NormalRule,
    /// Accept a file without any `vt` (every corner gets UV (0, 0) and
    /// [`ObjMesh::uvs_missing`] is set: the caller generates lightmap UVs).
    pub allow_missing_uvs: bool,
}

impl Default for MeshOptions {
    fn default() -> Self {
        Self {
            normals: NormalRule::SmoothAll,
            allow_missing_uvs: false,
        }
    }
}

/// A loaded OBJ: the mesh and what the loader learnt.
#[derive(Clone, Debug)]
pub struct ObjMesh {
    /// The mesh, metres.
    pub mesh: Mesh,
    /// `usemtl` names, indexed by [`MeshTriangle::material`].
    pub material_names: Vec<String>,
    /// Non-fatal findings.
    pub warnings: Vec<String>,
    /// The file has no `vt` (only with [`MeshOptions::allow_missing_uvs`]).
    pub uvs_missing: bool,
}

/// Loads and validates an OBJ mesh with default [`ObjOptions`] (degenerate faces are errors).
///
/// Returns the mesh in metres, the `usemtl` names indexed by [`MeshTriangle::material`], and
/// warnings (missing MTL file, ignored normals, ...). See the module docs for the checks.
pub fn load_obj(
    path: &Path,
    metres_per_unit: f64,
) -> Result<(Mesh, Vec<String>, Vec<String>), SceneError> {
    load_obj_with(path, metres_per_unit, &ObjOptions::default())
}

/// Loads and validates an OBJ mesh; like [`load_obj`] with explicit options.
pub fn load_obj_with(
    path: &Path,
    metres_per_unit: f64,
    options: &ObjOptions,
) -> Result<(Mesh, Vec<String>, Vec<String>), SceneError> {
    let m = load_obj_mesh(path, metres_per_unit, options, &MeshOptions::default())?;
    Ok((m.mesh, m.material_names, m.warnings))
}

/// Loads and validates an OBJ mesh with explicit normal and UV options (the scene loader's
/// entry point).
pub fn load_obj_mesh(
    path: &Path,
    metres_per_unit: f64,
    options: &ObjOptions,
    mesh_options: &MeshOptions,
) -> Result<ObjMesh, SceneError> {
    if !(metres_per_unit.is_finite() && metres_per_unit > 0.0) {
        return Err(SceneError::InvalidField {
            path: path.to_path_buf(),
            line: None,
            field: "metres_per_unit".into(),
            problem: format!("is {metres_per_unit}, but must be a finite number > 0"),
            fix: "give the size of one model unit in metres, e.g. 0.01 for centimetres".into(),
        });
    }
    let text = read_text_bounded(path, "OBJ mesh", MAX_OBJ_BYTES)?;
    let models = parse_with_tobj(path, &text)?;
    let scan = scan(path, &text, mesh_options.allow_missing_uvs)?;
    let mut warnings = Vec::new();
    for lib in &scan.mtllibs {
        let mtl = path.parent().unwrap_or(Path::new("")).join(lib);
        if !mtl.is_file() {
            warnings.push(format!(
                "{}: material library `{lib}` ({}) not found; ignored (materials come from the \
                 scene file, matched by `usemtl` name)",
                path.display(),
                mtl.display()
            ));
        }
    }
    if let Some(&(line, corners)) = scan.short_faces.first() {
        warnings.push(format!(
            "{}:{line}: a face (`f`) with {corners} corner{} makes no triangle; ignored{}",
            path.display(),
            if corners == 1 { "" } else { "s" },
            match scan.short_faces.len() - 1 {
                0 => String::new(),
                n => format!(" (and {n} more such faces)"),
            }
        ));
    }
    build_mesh(
        path,
        metres_per_unit,
        (options, mesh_options),
        &models,
        &scan,
        warnings,
    )
}

/// A `BufRead` over a byte slice that knows how far the consumer has read, so a parser
/// error can be attributed to a line.
struct CountingReader<'a> {
    data: &'a [u8],
    pos: usize,
}

impl CountingReader<'_> {
    /// The 1-based line of the last byte consumed (the line being parsed).
    fn current_line(&self) -> usize {
        let consumed = &self.data[..self.pos.min(self.data.len())];
        let newlines = consumed.iter().filter(|&&b| b == b'\n').count();
        if consumed.last() == Some(&b'\n') {
            newlines.max(1)
        } else {
            newlines + 1
        }
    }
}

impl Read for CountingReader<'_> {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let rest = &self.data[self.pos.min(self.data.len())..];
        let n = rest.len().min(buf.len());
        buf[..n].copy_from_slice(&rest[..n]);
        self.pos += n;
        Ok(n)
    }
}

impl BufRead for CountingReader<'_> {
    fn fill_buf(&mut self) -> std::io::Result<&[u8]> {
        Ok(&self.data[self.pos.min(self.data.len())..])
    }

    fn consume(&mut self, amt: usize) {
        self.pos = (self.pos + amt).min(self.data.len());
    }
}

/// Parses with `tobj`; on error, names the line (for errors `tobj` only detects at the end
/// of a group, the line scan finds the exact statement).
fn parse_with_tobj(path: &Path, text: &str) -> Result<Vec<tobj::Model>, SceneError> {
    let options = tobj::LoadOptions {
        single_index: false,
        // Polygons are triangulated here ([`triangulate_polygon`]), not by tobj's fan.
        triangulate: false,
        ignore_points: true,
        ignore_lines: true,
    };
    let mut reader = CountingReader {
        data: text.as_bytes(),
        pos: 0,
    };
    // MTL contents are not used: materials come from the scene file.
    match tobj::load_obj_buf(&mut reader, &options, |_| {
        Ok((Vec::new(), Default::default()))
    }) {
        Ok((models, _)) => Ok(models),
        Err(e) => {
            use tobj::LoadError as E;
            let deferred = matches!(
                e,
                E::FaceVertexOutOfBounds
                    | E::FaceTexCoordOutOfBounds
                    | E::FaceNormalOutOfBounds
                    | E::FaceColorOutOfBounds
                    | E::InvalidPolygon
            );
            if deferred {
                // Reported when a group ends, not at the face: find the face.
                scan(path, text, true)?;
            }
            let problem = match e {
                E::PositionParseError => "a `v` statement needs three numbers `v x y z`".into(),
                E::TexcoordParseError => "a `vt` statement needs two numbers `vt u v`".into(),
                E::NormalParseError => "a `vn` statement needs three numbers `vn x y z`".into(),
                E::FaceParseError => "a face corner must be `v`, `v/vt`, `v//vn` or `v/vt/vn` \
                                      with non-zero integer indices"
                    .into(),
                E::ScalingByZeroError => "a `v` statement has the weight w = 0".into(),
                E::ColorParseError => {
                    "a `v` statement has the wrong number of values (3, 4 or 6 expected)".into()
                }
                E::MaterialParseError => "`usemtl` needs a material name".into(),
                other => other.to_string(),
            };
            Err(SceneError::ObjSyntax {
                path: path.to_path_buf(),
                line: (!deferred).then(|| reader.current_line()),
                problem,
            })
        }
    }
}

/// One `f` statement with three or more corners.
#[derive(Clone, Copy, Debug)]
struct FaceRecord {
    /// 1-based line.
    line: usize,
    /// 1-based face number (counting every `f` statement).
    face: usize,
    /// Triangles it becomes (corners − 2).
    triangles: usize,
    /// Index into [`Scan::material_names`].
    material: u32,
    /// Smoothing group (`s N`; 0 = `s off` or before any `s`).
    group: u32,
}

/// What the line scan learns about the file.
#[derive(Debug, Default)]
struct Scan {
    /// Faces with ≥ 3 corners, in file order.
    faces: Vec<FaceRecord>,
    /// `usemtl` names in order of first use by a face (`""` = before any `usemtl`).
    material_names: Vec<String>,
    /// Number of `vt` statements.
    vt_count: usize,
    /// Whether every corner of every face has a normal index.
    all_corners_have_normals: bool,
    /// `mtllib` file names.
    mtllibs: Vec<String>,
    /// `(line, corners)` of the faces with one or two corners, which make no triangle.
    short_faces: Vec<(usize, usize)>,
    /// Whether the file has any `s` statement.
    has_groups: bool,
    /// The smoothing group of the faces being read.
    group: u32,
}

/// Shortens a line for a message.
fn excerpt(line: &str) -> String {
    let t = line.trim();
    match t.char_indices().nth(80) {
        Some((i, _)) => format!("{}…", &t[..i]),
        None => t.to_string(),
    }
}

/// Resolves an OBJ index (1-based, or negative = relative to `count`) to 0-based.
fn resolve_index(index: i64, count: usize) -> Option<usize> {
    let count = i64::try_from(count).ok()?;
    let zero_based = if index > 0 { index - 1 } else { count + index };
    (index != 0 && (0..count).contains(&zero_based)).then_some(zero_based as usize)
}

/// Scans the text for non-finite numbers, bad indices, missing UVs (a file without any `vt`
/// is accepted when `uvs_optional`), materials, smoothing groups and faces.
fn scan(path: &Path, text: &str, uvs_optional: bool) -> Result<Scan, SceneError> {
    let mut s = Scan {
        all_corners_have_normals: true,
        ..Scan::default()
    };
    let (mut v_count, mut vn_count, mut face_no) = (0usize, 0usize, 0usize);
    let mut current_material: Option<String> = None;
    let mut first_missing_uv: Option<(usize, usize)> = None;
    for (i, line) in text.lines().enumerate() {
        let line_no = i + 1;
        let mut words = line.split_whitespace();
        let Some(keyword) = words.next() else {
            continue;
        };
        match keyword {
            "v" | "vt" | "vn" => {
                let (statement, count) = match keyword {
                    "v" => ("v", &mut v_count),
                    "vt" => ("vt", &mut s.vt_count),
                    _ => ("vn", &mut vn_count),
                };
                *count += 1;
                check_finite(path, line_no, line, statement, words)?;
            }
            "l" if words.clone().count() > 2 => {
                return Err(SceneError::ObjSyntax {
                    path: path.to_path_buf(),
                    line: Some(line_no),
                    problem: "polylines (`l`) with more than two vertices are not supported; \
                              remove the statement"
                        .into(),
                });
            }
            "f" => {
                face_no += 1;
                let at = FaceAt {
                    path,
                    line: line_no,
                    face: face_no,
                };
                let counts = [v_count, s.vt_count, vn_count];
                s.face(&at, words, counts, &mut first_missing_uv, &current_material)?;
            }
            "usemtl" => {
                let name = line
                    .trim()
                    .split_once(char::is_whitespace)
                    .map(|x| x.1.trim());
                current_material = name.map(str::to_string);
            }
            "s" => {
                s.has_groups = true;
                // `s off`, `s 0` and anything unreadable are "no group" (flat).
                s.group = words.next().and_then(|w| w.parse().ok()).unwrap_or(0);
            }
            "mtllib" => {
                if let Some((_, lib)) = line.trim().split_once(char::is_whitespace) {
                    s.mtllibs.push(lib.trim().to_string());
                }
            }
            _ => {}
        }
    }
    if s.vt_count == 0 && uvs_optional {
        return Ok(s);
    }
    if s.vt_count == 0 && !s.faces.is_empty() {
        return Err(SceneError::ObjNoUvs {
            path: path.to_path_buf(),
        });
    }
    if let Some((line, face)) = first_missing_uv {
        return Err(SceneError::ObjMissingUvs {
            path: path.to_path_buf(),
            line,
            face,
        });
    }
    Ok(s)
}

/// Refuses a `v`/`vt`/`vn` statement (`statement`, on line `line_no`) with a NaN or infinite
/// number among `words`.
fn check_finite<'a>(
    path: &Path,
    line_no: usize,
    line: &str,
    statement: &'static str,
    words: impl Iterator<Item = &'a str>,
) -> Result<(), SceneError> {
    let non_finite = words
        .filter_map(|w| w.parse::<f32>().ok())
        .any(|x| !x.is_finite());
    if non_finite {
        return Err(SceneError::ObjNonFinite {
            path: path.to_path_buf(),
            line: line_no,
            statement,
            text: excerpt(line),
        });
    }
    Ok(())
}

/// Where a face statement is, for its messages.
struct FaceAt<'a> {
    path: &'a Path,
    /// 1-based line.
    line: usize,
    /// 1-based face number.
    face: usize,
}

impl FaceAt<'_> {
    /// Checks one face corner `v[/vt[/vn]]` against the `counts` of `v`, `vt` and `vn`
    /// statements so far: an index out of range is an error; a missing UV is remembered in
    /// `first_missing_uv` (line, face), a missing normal clears `all_normals`.
    fn check_corner(
        &self,
        corner: &str,
        counts: [usize; 3],
        first_missing_uv: &mut Option<(usize, usize)>,
        all_normals: &mut bool,
    ) -> Result<(), SceneError> {
        let mut parts = corner.split('/');
        let slots = [
            ("position", counts[0], parts.next()),
            ("texture coordinate", counts[1], parts.next()),
            ("normal", counts[2], parts.next()),
        ];
        for (slot, (kind, count, part)) in slots.into_iter().enumerate() {
            let part = part.filter(|p| !p.is_empty());
            match (slot, part) {
                (1, None) => {
                    first_missing_uv.get_or_insert((self.line, self.face));
                }
                (2, None) => *all_normals = false,
                _ => {}
            }
            let Some(part) = part else { continue };
            // Unparseable indices were already rejected by tobj.
            let Ok(index) = part.parse::<i64>() else {
                continue;
            };
            if resolve_index(index, count).is_none() {
                return Err(SceneError::ObjIndexOutOfRange {
                    path: self.path.to_path_buf(),
                    line: self.line,
                    face: self.face,
                    kind,
                    index,
                    count,
                });
            }
        }
        Ok(())
    }
}

impl Scan {
    /// One `f` statement at `at` with the corners `words`, after `counts` `v`, `vt` and `vn`
    /// statements: every corner is checked ([`FaceAt::check_corner`]) and a face of three or
    /// more corners is recorded under the current `usemtl` name `material`.
    fn face<'a>(
        &mut self,
        at: &FaceAt,
        words: impl Iterator<Item = &'a str>,
        counts: [usize; 3],
        first_missing_uv: &mut Option<(usize, usize)>,
        material: &Option<String>,
    ) -> Result<(), SceneError> {
        let corners: Vec<&str> = words.collect();
        if corners.is_empty() {
            return Err(SceneError::ObjSyntax {
                path: at.path.to_path_buf(),
                line: Some(at.line),
                problem: "a face (`f`) without corners".into(),
            });
        }
        for corner in &corners {
            at.check_corner(
                corner,
                counts,
                first_missing_uv,
                &mut self.all_corners_have_normals,
            )?;
        }
        if corners.len() < 3 {
            self.short_faces.push((at.line, corners.len()));
            return Ok(());
        }
        let name = material.clone().unwrap_or_default();
        let material = match self.material_names.iter().position(|n| *n == name) {
            Some(m) => m,
            None => {
                self.material_names.push(name);
                self.material_names.len() - 1
            }
        };
        self.faces.push(FaceRecord {
            line: at.line,
            face: at.face,
            triangles: corners.len() - 2,
            material: material as u32,
            group: self.group,
        });
        Ok(())
    }
}

/// An error for data `tobj` returned inconsistently (should not happen).
fn internal(path: &Path, what: &str) -> SceneError {
    SceneError::ObjSyntax {
        path: path.to_path_buf(),
        line: None,
        problem: format!("the OBJ parser returned inconsistent data ({what})"),
    }
}

/// Formats up to [`LIST_FIRST`] faces as `face N (line L), ...`.
fn list_faces(faces: &[FaceRecord]) -> String {
    let mut out: Vec<String> = faces
        .iter()
        .take(LIST_FIRST)
        .map(|f| format!("face {} (line {})", f.face, f.line))
        .collect();
    if faces.len() > LIST_FIRST {
        out.push("...".into());
    }
    out.join(", ")
}

/// Twice the area of a triangle (f64).
fn double_area(a: DVec3, b: DVec3, c: DVec3) -> f64 {
    (b - a).cross(c - a).length()
}

/// The `tobj` models merged into one list of triangles (before scaling and validation).
struct Merged {
    /// Welded positions, in file units.
    positions: Vec<Vec3>,
    uvs: Vec<Vec2>,
    file_normals: Vec<Vec3>,
    /// Per triangle: position, UV and file-normal indices.
    tris: Vec<[[u32; 3]; 3]>,
    /// Whether every corner has a file normal.
    use_file_normals: bool,
}

/// Merges the `tobj` models into one validated [`Mesh`].
fn build_mesh(
    path: &Path,
    metres_per_unit: f64,
    (options, mesh_options): (&ObjOptions, &MeshOptions),
    models: &[tobj::Model],
    scan: &Scan,
    mut warnings: Vec<String>,
) -> Result<ObjMesh, SceneError> {
    let uvs_missing = scan.vt_count == 0;
    let Merged {
        positions,
        mut uvs,
        file_normals,
        tris,
        use_file_normals,
    } = merge_models(path, models, scan, &mut warnings)?;
    let faces = triangle_faces(path, scan, tris.len())?;
    let positions_m = to_metres(path, &positions, metres_per_unit)?;
    check_uvs(path, &faces, &tris, &mut uvs)?;
    let keep = degenerate_triangles(
        path,
        options,
        &faces,
        &tris,
        &positions_m,
        (&uvs, uvs_missing),
        &mut warnings,
    )?;
    let use_file_normals =
        file_normals_usable(path, use_file_normals, &tris, &file_normals, &mut warnings)?;

    let mut triangles: Vec<MeshTriangle> = Vec::with_capacity(tris.len());
    let mut groups: Vec<u32> = Vec::with_capacity(tris.len());
    for (t, tri) in tris.iter().enumerate() {
        if !keep[t] {
            continue;
        }
        triangles.push(MeshTriangle {
            position: tri[0],
            uv: tri[1],
            normal: if use_file_normals { tri[2] } else { tri[0] },
            material: faces.of(t).material,
        });
        groups.push(faces.of(t).group);
    }
    if triangles.is_empty() {
        return Err(SceneError::ObjNoTriangles {
            path: path.to_path_buf(),
        });
    }
    let normals = if use_file_normals {
        file_normals.iter().map(|n| n.normalize()).collect()
    } else {
        let groups = scan.has_groups.then_some(groups.as_slice());
        let (normals, index) =
            super::normals::crease_normals(&positions_m, &triangles, groups, mesh_options.normals);
        for (t, idx) in triangles.iter_mut().zip(index) {
            t.normal = idx;
        }
        normals
    };
    let mesh = Mesh {
        positions_m,
        uvs,
        normals,
        triangles,
    };
    Ok(ObjMesh {
        mesh,
        material_names: scan.material_names.clone(),
        warnings,
        uvs_missing,
    })
}

/// Merges the `tobj` models: positions welded by bit-identical coordinates, UVs and normals
/// concatenated, polygons triangulated ([`triangulate_polygon`]; a polygon that cannot be
/// ear-clipped becomes a fan with a warning naming its line, from the `scan`).
fn merge_models(
    path: &Path,
    models: &[tobj::Model],
    scan: &Scan,
    warnings: &mut Vec<String>,
) -> Result<Merged, SceneError> {
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let mut out = Merged {
        positions: Vec::new(),
        uvs: Vec::new(),
        file_normals: Vec::new(),
        tris: Vec::new(),
        use_file_normals: scan.all_corners_have_normals,
    };
    let mut face_no = 0usize;
    for model in models {
        let m = &model.mesh;
        let positions = &mut out.positions;
        let pos_map: Vec<u32> = m
            .positions
            .chunks_exact(3)
            .map(|p| {
                let key = [p[0].to_bits(), p[1].to_bits(), p[2].to_bits()];
                *weld.entry(key).or_insert_with(|| {
                    positions.push(Vec3::new(p[0], p[1], p[2]));
                    (positions.len() - 1) as u32
                })
            })
            .collect();
        let uv_offset = out.uvs.len() as u32;
        out.uvs
            .extend(m.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], t[1])));
        let n_offset = out.file_normals.len() as u32;
        out.file_normals.extend(
            m.normals
                .chunks_exact(3)
                .map(|n| Vec3::new(n[0], n[1], n[2])),
        );
        if m.texcoord_indices.is_empty() && scan.vt_count == 0 {
            // No UVs in the file (accepted by the scan only when asked): one placeholder UV.
            if out.uvs.is_empty() {
                out.uvs.push(Vec2::ZERO);
            }
        } else if m.texcoord_indices.len() != m.indices.len() {
            return Err(internal(path, "face corners without UV indices"));
        }
        if m.normal_indices.len() != m.indices.len() {
            out.use_file_normals = false;
        }
        let arities: Vec<usize> = if m.face_arities.is_empty() {
            if m.indices.len() % 3 != 0 {
                return Err(internal(path, "triangle corners"));
            }
            vec![3; m.indices.len() / 3]
        } else {
            m.face_arities.iter().map(|&a| a as usize).collect()
        };
        let mut first = 0usize;
        for arity in arities {
            let corners = first..first + arity;
            first += arity;
            if arity < 3 {
                continue; // points and lines make no triangle
            }
            let mut position = Vec::with_capacity(arity);
            for c in corners.clone() {
                let p = m
                    .indices
                    .get(c)
                    .and_then(|&i| pos_map.get(i as usize))
                    .ok_or_else(|| internal(path, "position index"))?;
                position.push(*p);
            }
            let uv: Vec<u32> = corners
                .clone()
                .map(|c| m.texcoord_indices.get(c).map_or(0, |&i| uv_offset + i))
                .collect();
            if uv.iter().any(|&i| i as usize >= out.uvs.len()) {
                return Err(internal(path, "UV index"));
            }
            let normal: Vec<u32> = corners
                .map(|c| n_offset + m.normal_indices.get(c).copied().unwrap_or(0))
                .collect();
            let line = scan.faces.get(face_no).map_or(0, |f| f.line);
            face_no += 1;
            let points: Vec<DVec3> = position
                .iter()
                .map(|&i| out.positions[i as usize].as_dvec3())
                .collect();
            let local = triangulate_polygon(&points).unwrap_or_else(|| {
                warnings.push(format!(
                    "{}:{line}: the {arity}-corner polygon could not be ear-clipped (it is \
                     self-intersecting, or has too many concave corners to clip in \
                     {EAR_TEST_BUDGET} tests); triangulated as a fan from its first corner, \
                     which may overlap itself: split it into simple polygons",
                    path.display()
                ));
                fan(arity)
            });
            for t in local {
                out.tris.push([
                    t.map(|k| position[k]),
                    t.map(|k| uv[k]),
                    t.map(|k| normal[k]),
                ]);
            }
        }
    }
    Ok(out)
}

/// The fan from corner 0 of an `n`-corner polygon: `[0, k, k + 1]` for `k` in `1..n − 1`.
fn fan(n: usize) -> Vec<[usize; 3]> {
    (1..n - 1).map(|k| [0, k, k + 1]).collect()
}

/// Triangulates a polygon (corners in order, counter-clockwise seen from the front) by ear
/// clipping in its best-fit plane; returns `corners − 2` triangles of corner indices, each
/// counter-clockwise, or `None` when no ear can be found (self-intersecting polygon) or
/// [`EAR_TEST_BUDGET`] is spent.
///
/// Triangles and quads are not clipped: a quad `a b c d` is split along its first diagonal,
/// `a b c` + `a c d`, as written (scanned quads are often non-planar, and the diagonal is
/// then the modeller's choice: the head scan has 16 quads that are concave seen along their
/// Newell normal; a planar quad concave at `b` or `d` must be written as two triangles).
/// The plane is the one normal to the Newell normal. The walk
/// starts at corner 1 and moves forward, so a convex polygon becomes exactly the fan from
/// corner 0 (`0 1 2`, `0 2 3`, ...) in O(n). A corner
/// is an ear when it is convex and no reflex corner lies in its triangle (only reflex corners
/// are tested: O(n × reflex corners), O(n²) in the worst case). *Flat* corners, whose triangle
/// with their neighbours has at most [`DEGENERATE_RELATIVE_AREA`] × (polygon bounding-box
/// diagonal)² area (collinear corners, the corners of a finely sampled circle), are neither:
/// they are clipped only after a full turn of the ring found no convex ear, and never block
/// an ear. Polygons of zero area become the fan.
fn triangulate_polygon(points: &[DVec3]) -> Option<Vec<[usize; 3]>> {
    let n = points.len();
    if n <= 4 {
        return Some(fan(n.max(2)));
    }
    let o = points[0];
    let normal: DVec3 = (0..n)
        .map(|i| (points[i] - o).cross(points[(i + 1) % n] - o))
        .sum();
    let Some(normal) = normal.try_normalize() else {
        return Some(fan(n));
    };
    let u = normal.any_orthonormal_vector();
    let v = normal.cross(u);
    let p: Vec<DVec2> = points
        .iter()
        .map(|&q| DVec2::new((q - o).dot(u), (q - o).dot(v)))
        .collect();
    let (lo, hi) = p
        .iter()
        .fold((p[0], p[0]), |(lo, hi), &q| (lo.min(q), hi.max(q)));
    let flat = 2.0 * DEGENERATE_RELATIVE_AREA * (hi - lo).length_squared();
    if flat == 0.0 {
        return Some(fan(n));
    }
    ear_clip(&p, flat)
}

/// Twice the signed area of the 2D triangle `a b c` (> 0: counter-clockwise).
fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// Ear clipping of the counter-clockwise 2D polygon `p` (see [`triangulate_polygon`]); a
/// corner whose doubled triangle area is within ±`flat` is flat.
fn ear_clip(p: &[DVec2], flat: f64) -> Option<Vec<[usize; 3]>> {
    let n = p.len();
    let mut prev: Vec<usize> = (0..n).map(|i| (i + n - 1) % n).collect();
    let mut next: Vec<usize> = (0..n).map(|i| (i + 1) % n).collect();
    let turn = |prev: &[usize], next: &[usize], i: usize| orient(p[prev[i]], p[i], p[next[i]]);
    let mut reflex: Vec<bool> = (0..n).map(|i| turn(&prev, &next, i) < -flat).collect();
    let mut reflex_list: Vec<usize> = (0..n).filter(|&i| reflex[i]).collect();
    let mut out = Vec::with_capacity(n - 2);
    let (mut alive, mut i, mut since_ear, mut allow_flat) = (n, 1usize, 0usize, false);
    let mut tests = 0u64;
    while alive > 3 {
        if since_ear > alive {
            if allow_flat {
                return None;
            }
            allow_flat = true;
            since_ear = 0;
        }
        let (a, c) = (prev[i], next[i]);
        let t = turn(&prev, &next, i);
        let tip = t > flat || (allow_flat && t >= -flat);
        let blocked = tip && {
            reflex_list.retain(|&r| reflex[r]);
            tests += reflex_list.len() as u64;
            if tests > EAR_TEST_BUDGET {
                return None;
            }
            reflex_list.iter().any(|&r| {
                r != a
                    && r != c
                    && orient(p[a], p[i], p[r]) >= 0.0
                    && orient(p[i], p[c], p[r]) >= 0.0
                    && orient(p[c], p[a], p[r]) >= 0.0
            })
        };
        if tip && !blocked {
            out.push([a, i, c]);
            next[a] = c;
            prev[c] = a;
            reflex[i] = false;
            for k in [a, c] {
                reflex[k] = reflex[k] && turn(&prev, &next, k) < -flat;
            }
            alive -= 1;
            since_ear = 0;
            i = c;
        } else {
            i = next[i];
            since_ear += 1;
        }
    }
    out.push([prev[i], i, next[i]]);
    Some(out)
}

/// The OBJ face of every triangle.
struct TriangleFaces<'a> {
    scan: &'a Scan,
    /// Per triangle, the index into the scan's faces.
    tri_face: Vec<usize>,
}

impl TriangleFaces<'_> {
    /// The face triangle `t` comes from.
    fn of(&self, t: usize) -> FaceRecord {
        self.scan.faces[self.tri_face[t]]
    }
}

/// The face of each of the `triangles` triangles, from the scan (same order as tobj's output);
/// an error when there are none.
fn triangle_faces<'a>(
    path: &Path,
    scan: &'a Scan,
    triangles: usize,
) -> Result<TriangleFaces<'a>, SceneError> {
    let mut tri_face: Vec<usize> = Vec::with_capacity(triangles);
    for (f, rec) in scan.faces.iter().enumerate() {
        tri_face.extend(std::iter::repeat_n(f, rec.triangles));
    }
    if tri_face.len() != triangles {
        return Err(internal(
            path,
            &format!(
                "{} triangles parsed, {} expected from the face statements",
                triangles,
                tri_face.len()
            ),
        ));
    }
    if triangles == 0 {
        return Err(SceneError::ObjNoTriangles {
            path: path.to_path_buf(),
        });
    }
    Ok(TriangleFaces { scan, tri_face })
}

/// `positions` scaled to metres; an error when one overflows.
fn to_metres(
    path: &Path,
    positions: &[Vec3],
    metres_per_unit: f64,
) -> Result<Vec<Vec3>, SceneError> {
    let positions_m: Vec<Vec3> = positions
        .iter()
        .map(|p| (p.as_dvec3() * metres_per_unit).as_vec3())
        .collect();
    if positions_m.iter().any(|p| !p.is_finite()) {
        return Err(SceneError::InvalidField {
            path: path.to_path_buf(),
            line: None,
            field: "metres_per_unit".into(),
            problem: format!("({metres_per_unit}) makes some positions overflow to infinity"),
            fix: "check metres_per_unit and the model's coordinates".into(),
        });
    }
    Ok(positions_m)
}

/// Every UV used by a triangle must lie in `[0, 1]` within [`UV_TOLERANCE`] (an error naming
/// the first face); then all UVs are clamped to `[0, 1]`.
fn check_uvs(
    path: &Path,
    faces: &TriangleFaces,
    tris: &[[[u32; 3]; 3]],
    uvs: &mut [Vec2],
) -> Result<(), SceneError> {
    let mut bad_uv: Option<(usize, Vec2)> = None;
    let mut bad_uv_count = 0usize;
    for (t, tri) in tris.iter().enumerate() {
        for &i in &tri[1] {
            let uv = uvs[i as usize];
            let outside = uv.min_element() < -UV_TOLERANCE || uv.max_element() > 1.0 + UV_TOLERANCE;
            if outside {
                bad_uv_count += 1;
                bad_uv.get_or_insert((t, uv));
            }
        }
    }
    if let Some((t, uv)) = bad_uv {
        let rec = faces.of(t);
        return Err(SceneError::ObjUvOutOfRange {
            path: path.to_path_buf(),
            line: rec.line,
            face: rec.face,
            u: uv.x,
            v: uv.y,
            count: bad_uv_count,
        });
    }
    for uv in uvs {
        *uv = uv.clamp(Vec2::ZERO, Vec2::ONE);
    }
    Ok(())
}

/// The degenerate-triangle rules of the module docs: which triangles to keep, an error for
/// zero world area unless skipped, and warnings for skipped and zero-UV-area triangles.
/// Slivers of a polygon whose own area is not degenerate are dropped ([`polygon_slivers`]).
fn degenerate_triangles(
    path: &Path,
    options: &ObjOptions,
    faces: &TriangleFaces,
    tris: &[[[u32; 3]; 3]],
    positions_m: &[Vec3],
    (uvs, uvs_missing): (&[Vec2], bool),
    warnings: &mut Vec<String>,
) -> Result<Vec<bool>, SceneError> {
    let (lo, hi) = super::aabb(positions_m);
    let diag2 = (hi.as_dvec3() - lo.as_dvec3()).length_squared();
    let world_limit = 2.0 * DEGENERATE_RELATIVE_AREA * diag2;
    let uv_limit = 2.0 * DEGENERATE_UV_AREA;
    let area2: Vec<f64> = tris
        .iter()
        .map(|tri| {
            let p = tri[0].map(|i| positions_m[i as usize].as_dvec3());
            double_area(p[0], p[1], p[2])
        })
        .collect();
    let mut keep = polygon_slivers(path, faces, &area2, world_limit, warnings);
    let mut zero_world: Vec<FaceRecord> = Vec::new();
    let mut zero_uv: Vec<FaceRecord> = Vec::new();
    for (t, tri) in tris.iter().enumerate() {
        if !keep[t] {
            continue;
        }
        let q = tri[1].map(|i| uvs[i as usize].as_dvec2().extend(0.0));
        let rec = faces.of(t);
        if area2[t] <= world_limit {
            zero_world.push(rec);
            keep[t] = !options.skip_degenerate_faces;
        } else if double_area(q[0], q[1], q[2]) <= uv_limit {
            zero_uv.push(rec);
        }
    }
    if !zero_world.is_empty() {
        if !options.skip_degenerate_faces {
            return Err(SceneError::ObjDegenerate {
                path: path.to_path_buf(),
                count: zero_world.len(),
                first: list_faces(&zero_world),
            });
        }
        warnings.push(format!(
            "{}: skipped {} triangles with zero world area ({})",
            path.display(),
            zero_world.len(),
            list_faces(&zero_world)
        ));
    }
    if !zero_uv.is_empty() && !uvs_missing {
        warnings.push(format!(
            "{}: {} triangles have zero UV area ({}); they are kept (they still cast shadows) \
             but receive no lightmap texels",
            path.display(),
            zero_uv.len(),
            list_faces(&zero_uv)
        ));
    }
    Ok(keep)
}

/// Drops the sliver triangles of polygons: a triangle of a face with more than three corners
/// whose doubled area (`area2`, m²) is at most `world_limit`, when the face's total is above
/// it. One warning per such polygon names its line, the count and the area lost (at most
/// count × `world_limit` / 2). Returns which triangles are kept.
fn polygon_slivers(
    path: &Path,
    faces: &TriangleFaces,
    area2: &[f64],
    world_limit: f64,
    warnings: &mut Vec<String>,
) -> Vec<bool> {
    let mut keep = vec![true; area2.len()];
    let mut face_area2 = vec![0.0f64; faces.scan.faces.len()];
    for (t, &a) in area2.iter().enumerate() {
        face_area2[faces.tri_face[t]] += a;
    }
    // Per face: (sliver count, doubled area lost).
    let mut slivers: HashMap<usize, (usize, f64)> = HashMap::new();
    for (t, &a) in area2.iter().enumerate() {
        let f = faces.tri_face[t];
        if faces.of(t).triangles > 1 && a <= world_limit && face_area2[f] > world_limit {
            keep[t] = false;
            let e = slivers.entry(f).or_default();
            e.0 += 1;
            e.1 += a;
        }
    }
    let mut slivers: Vec<_> = slivers.into_iter().collect();
    slivers.sort_unstable_by_key(|&(f, _)| f);
    for (f, (count, lost2)) in slivers {
        let rec = faces.scan.faces[f];
        warnings.push(format!(
            "{}:{}: polygon (face {}, {} corners) triangulates into {count} sliver triangle{} \
             of zero area (each ≤ {DEGENERATE_RELATIVE_AREA:e} × diagonal²); dropped: they \
             hold no lightmap texels and lose {:.1e} of the polygon's area (at most {:.1e})",
            path.display(),
            rec.line,
            rec.face,
            rec.triangles + 2,
            if count == 1 { "" } else { "s" },
            lost2 / face_area2[f],
            count as f64 * world_limit / face_area2[f],
        ));
    }
    keep
}

/// Whether the file's `vn` normals are used (`usable`: every corner has one): not when one has
/// zero length or is not finite (with a warning); a warning too when some corners lack them.
fn file_normals_usable(
    path: &Path,
    usable: bool,
    tris: &[[[u32; 3]; 3]],
    file_normals: &[Vec3],
    warnings: &mut Vec<String>,
) -> Result<bool, SceneError> {
    if usable
        && tris
            .iter()
            .any(|t| t[2].iter().any(|&i| i as usize >= file_normals.len()))
    {
        return Err(internal(path, "normal index"));
    }
    if usable {
        let bad = file_normals
            .iter()
            .any(|n| !n.is_finite() || n.length_squared() < 1e-20);
        if bad {
            warnings.push(format!(
                "{}: some `vn` normals have zero length; computing smooth normals instead",
                path.display()
            ));
            return Ok(false);
        }
    } else if !file_normals.is_empty() {
        warnings.push(format!(
            "{}: not every face corner has a normal; ignoring the `vn` normals and computing \
             smooth normals",
            path.display()
        ));
    }
    Ok(usable)
}

/// Writes `mesh` as OBJ: `v` (positions as stored), `vt`, `vn`, and `f v/vt/vn` faces under
/// `usemtl` runs named by `material_names` (indexed by the triangles' material; an empty name
/// writes no `usemtl`).
pub fn write_obj(path: &Path, mesh: &Mesh, material_names: &[String]) -> std::io::Result<()> {
    use std::fmt::Write as _;
    let mut out = String::from("# written by ortm\n");
    for p in &mesh.positions_m {
        let _ = writeln!(out, "v {} {} {}", p.x, p.y, p.z);
    }
    for t in &mesh.uvs {
        let _ = writeln!(out, "vt {} {}", t.x, t.y);
    }
    for n in &mesh.normals {
        let _ = writeln!(out, "vn {} {} {}", n.x, n.y, n.z);
    }
    let mut current: Option<u32> = None;
    for t in &mesh.triangles {
        if current != Some(t.material) {
            current = Some(t.material);
            match material_names.get(t.material as usize) {
                Some(name) if !name.is_empty() => {
                    let _ = writeln!(out, "usemtl {name}");
                }
                _ => {}
            }
        }
        out.push('f');
        for k in 0..3 {
            let _ = write!(
                out,
                " {}/{}/{}",
                t.position[k] + 1,
                t.uv[k] + 1,
                t.normal[k] + 1
            );
        }
        out.push('\n');
    }
    std::fs::write(path, out)
}

/// Smooth area-weighted vertex normals, one per position (indexed like positions).
///
/// Each triangle adds its unnormalised face normal `(b−a)×(c−a)` (length = 2·area) to its
/// three corners. A position whose sum cancels to zero gets the normal of the first triangle
/// touching it (or +z if it touches none).
pub fn smooth_normals(positions: &[Vec3], triangles: &[MeshTriangle]) -> Vec<Vec3> {
    let mut sum = vec![DVec3::ZERO; positions.len()];
    let mut first = vec![DVec3::ZERO; positions.len()];
    for tri in triangles {
        if tri.position.iter().any(|&i| i as usize >= positions.len()) {
            continue; // invalid triangle: contributes nothing
        }
        let [a, b, c] = tri.position.map(|i| positions[i as usize].as_dvec3());
        let n = (b - a).cross(c - a);
        for &i in &tri.position {
            sum[i as usize] += n;
            if first[i as usize] == DVec3::ZERO {
                first[i as usize] = n;
            }
        }
    }
    sum.iter()
        .zip(&first)
        .map(|(s, f)| {
            s.try_normalize()
                .or_else(|| f.try_normalize())
                .unwrap_or(DVec3::Z)
                .as_vec3()
        })
        .collect()
}
