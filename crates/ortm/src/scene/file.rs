//! The TOML scene file: scene file → [`Scene`] (mesh in metres, materials, lights).
//!
//! The format is specified, with annotated examples, in `docs/scene-format.md`. In short:
//!
//! ```toml
//! mesh = "head.obj"            # OBJ, relative to this file's folder
//! metres_per_unit = 0.34       # required, > 0
//! [lightmap]
//! width = 512                  # default 256, 1..=8192 (powers of two not required)
//! height = 512
//! [[material]]
//! name = "skin"                # matched to the OBJ's `usemtl` names
//! albedo = [0.8, 0.6, 0.5]     # or albedo_texture = "albedo.png" (sRGB PNG)
//! subsurface = { preset = "skin1" }
//! [[light]]
//! type = "point"               # point | spot | directional
//! position = [0.0, 0.3, 0.6]   # METRES, world space (after metres_per_unit scaling)
//! intensity = 0.5              # W/sr
//! ```
//!
//! # Data flow
//! TOML text → `Raw*` structs (serde, `deny_unknown_fields`: a misspelt key is an error
//! naming the key and the line) → validation (every error names the scene file, the line of
//! the enclosing table where known, and the dotted field, e.g. `material[1].albedo`) →
//! [`load_obj_with`] for the mesh → `usemtl` names mapped to materials → [`Scene`].
//!
//! # Material assignment
//! A face's `usemtl NAME` is matched to the `[[material]]` with that exact `name`. Faces whose
//! name has no match (and faces before any `usemtl`) use the material named `default` when
//! there is one, else the first `[[material]]`. Unmatched non-empty names produce a warning.
//!
//! # Units and conventions
//! `metres_per_unit` scales OBJ coordinates to metres. Light positions are in **metres in
//! world space** (the scaled mesh's frame), not in model units. Intensities are W/sr,
//! directional irradiance W/m² on a surface facing the light; `direction` of a directional
//! light is the direction the light *travels*, of a spot light the direction it *points*.
//! Subsurface coefficients are in mm⁻¹. Albedo textures are sRGB PNGs, converted to linear.
//!
//! # Warnings
//! Non-fatal findings (missing MTL file, unmatched `usemtl`, skipped degenerate faces) are
//! returned by [`load_scene_with_warnings`]; [`load_scene`] prints them to stderr.

use std::ops::Range;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::Vec3;
use serde::Deserialize;
use toml::Spanned;

use super::gltf::load_gltf;
use super::normals::{DEFAULT_CREASE_DEG, NormalRule};
use super::obj::{MeshOptions, ObjOptions, load_obj_mesh};
use super::presets::{PRESET_NAMES, subsurface_preset};
use super::{
    Albedo, AlbedoTexture, Light, Material, Mesh, Scene, SceneError, Subsurface, SubsurfaceModel,
    read_text_bounded,
};

/// Largest scene file accepted, in bytes ([`crate::io::limits::MAX_SCENE_BYTES`]).
pub const MAX_SCENE_BYTES: u64 = crate::io::limits::MAX_SCENE_BYTES;
/// Default lightmap width and height, in texels.
pub const DEFAULT_LIGHTMAP_SIZE: u32 = 256;
/// Largest lightmap width or height, in texels ([`crate::io::limits::MAX_LIGHTMAP_SIDE`]).
pub const MAX_LIGHTMAP_SIZE: u32 = crate::io::limits::MAX_LIGHTMAP_SIDE;
/// Accepted range of the relative index of refraction η.
pub const ETA_RANGE: (f32, f32) = (1.0, 3.0);

/// Top level of the scene file.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawScene {
    name: Option<String>,
    mesh: Spanned<String>,
    metres_per_unit: Option<Spanned<f64>>,
    crease_angle_deg: Option<Spanned<f32>>,
    #[serde(default)]
    allow_uv_overlap: bool,
    #[serde(default)]
    skip_degenerate_faces: bool,
    lightmap: Option<Spanned<RawLightmap>>,
    #[serde(default)]
    material: Vec<Spanned<RawMaterial>>,
    #[serde(default)]
    light: Vec<Spanned<RawLight>>,
}

/// `[lightmap]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLightmap {
    width: Option<u32>,
    height: Option<u32>,
}

/// `[[material]]`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawMaterial {
    name: String,
    albedo: Option<[f32; 3]>,
    albedo_texture: Option<String>,
    subsurface: Option<RawSubsurface>,
}

/// `subsurface = { ... }`.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawSubsurface {
    preset: Option<String>,
    sigma_a: Option<[f32; 3]>,
    sigma_s_prime: Option<[f32; 3]>,
    eta: Option<f32>,
    model: Option<RawModel>,
}

/// `model = "dipole" | "exponential"`.
#[derive(Deserialize, Clone, Copy)]
#[serde(rename_all = "lowercase")]
enum RawModel {
    Dipole,
    Exponential,
}

/// `type = "point" | "spot" | "directional"`.
#[derive(Deserialize, Clone, Copy, PartialEq, Eq)]
#[serde(rename_all = "lowercase")]
enum RawLightKind {
    Point,
    Spot,
    Directional,
}

/// `[[light]]` (one flat table; which keys are allowed depends on `type`).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLight {
    #[serde(rename = "type")]
    kind: RawLightKind,
    position: Option<[f32; 3]>,
    direction: Option<[f32; 3]>,
    color: Option<[f32; 3]>,
    intensity: Option<f32>,
    irradiance: Option<f32>,
    inner_deg: Option<f32>,
    outer_deg: Option<f32>,
}

/// A light set-up alone: a scene-file fragment holding only `[[light]]` tables (what
/// `ortm view` saves and loads).
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawLightsFragment {
    #[serde(default)]
    light: Vec<Spanned<RawLight>>,
}

/// Reads a scene-file fragment that holds only `[[light]]` tables (same keys, units and
/// validation as in a scene file; errors name the file, the line and the field).
pub fn load_lights_fragment(path: &Path) -> Result<Vec<Light>, SceneError> {
    let text = read_text_bounded(path, "light set-up file", MAX_SCENE_BYTES)?;
    parse_lights_fragment(&text, path)
}

/// Parses the text of a `[[light]]`-only fragment; `path` is only used in error messages.
pub fn parse_lights_fragment(text: &str, path: &Path) -> Result<Vec<Light>, SceneError> {
    let raw: RawLightsFragment = toml::from_str(text).map_err(|e| SceneError::SceneSyntax {
        path: path.to_path_buf(),
        line: e.span().map(|s| line_of(text, s.start)),
        message: e.message().trim_end_matches('\n').to_string(),
    })?;
    let ctx = Ctx { path, text };
    raw.light
        .iter()
        .enumerate()
        .map(|(i, l)| ctx.light(i, l))
        .collect()
}

/// Writes lights as `[[light]]` tables of a scene file (metres, W/sr, W/m²), readable by
/// [`parse_lights_fragment`] and pasteable into a scene file.
pub fn lights_to_toml(lights: &[Light]) -> String {
    let v = |a: Vec3| format!("[{}, {}, {}]", a.x, a.y, a.z);
    let mut out = String::new();
    for l in lights {
        out.push_str("[[light]]\n");
        match *l {
            Light::Point {
                position_m,
                color,
                intensity_w_sr,
            } => {
                out.push_str("type = \"point\"\n");
                out.push_str(&format!("position = {}   # metres\n", v(position_m)));
                out.push_str(&format!("color = {}\n", v(color)));
                out.push_str(&format!("intensity = {intensity_w_sr}   # W/sr\n"));
            }
            Light::Spot {
                position_m,
                direction,
                color,
                intensity_w_sr,
                inner_deg,
                outer_deg,
            } => {
                out.push_str("type = \"spot\"\n");
                out.push_str(&format!("position = {}   # metres\n", v(position_m)));
                out.push_str(&format!("direction = {}\n", v(direction)));
                out.push_str(&format!("color = {}\n", v(color)));
                out.push_str(&format!("intensity = {intensity_w_sr}   # W/sr\n"));
                out.push_str(&format!("inner_deg = {inner_deg}\n"));
                out.push_str(&format!("outer_deg = {outer_deg}\n"));
            }
            Light::Directional {
                direction,
                color,
                irradiance_w_m2,
            } => {
                out.push_str("type = \"directional\"\n");
                out.push_str(&format!("direction = {}\n", v(direction)));
                out.push_str(&format!("color = {}\n", v(color)));
                out.push_str(&format!("irradiance = {irradiance_w_m2}   # W/m²\n"));
            }
        }
        out.push('\n');
    }
    out
}

/// Reads, validates and loads a scene file; warnings are printed to stderr.
///
/// See [`load_scene_with_warnings`] and `docs/scene-format.md`.
pub fn load_scene(path: &Path) -> Result<Scene, SceneError> {
    let (scene, warnings) = load_scene_with_warnings(path)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// Reads, validates and loads a scene and its mesh and textures, returning the scene and the
/// non-fatal warnings. `path` is a TOML scene file, or a mesh that is a scene by itself:
/// a glTF (`.gltf`, `.glb`: its materials and lights) or an OBJ (`.obj`: metres, one grey
/// material, a default light), see [`mesh_scene`].
pub fn load_scene_with_warnings(path: &Path) -> Result<(Scene, Vec<String>), SceneError> {
    load_scene_sized_with_warnings(path, None)
}

/// [`load_scene`] with the lightmap made `size × size` (as `--size` does) before lightmap UVs
/// are generated and glTF textures resampled, so generated UVs have their 2-texel gutters at
/// that size. A size outside `1..=MAX_LIGHTMAP_SIZE` is ignored (the caller refuses it).
pub fn load_scene_sized(path: &Path, size: Option<u32>) -> Result<Scene, SceneError> {
    let (scene, warnings) = load_scene_sized_with_warnings(path, size)?;
    for w in warnings {
        eprintln!("warning: {w}");
    }
    Ok(scene)
}

/// [`load_scene_sized`] returning the warnings.
pub fn load_scene_sized_with_warnings(
    path: &Path,
    size: Option<u32>,
) -> Result<(Scene, Vec<String>), SceneError> {
    let size = size
        .filter(|s| (1..=MAX_LIGHTMAP_SIZE).contains(s))
        .map(|s| (s, s));
    if let Some(kind) = MeshKind::of(path) {
        return mesh_scene(path, kind, size);
    }
    let text = read_text_bounded(path, "scene file", MAX_SCENE_BYTES)?;
    let raw: RawScene = toml::from_str(&text).map_err(|e| SceneError::SceneSyntax {
        path: path.to_path_buf(),
        line: e.span().map(|s| line_of(&text, s.start)),
        message: e.message().trim_end_matches('\n').to_string(),
    })?;
    let ctx = Ctx { path, text: &text };
    let dir = path.parent().unwrap_or(Path::new(""));
    let mesh_path = ctx.mesh_path(&raw.mesh, dir)?;
    let kind = MeshKind::of(&mesh_path).unwrap_or(MeshKind::Obj);
    let mpu = ctx.metres_per_unit(raw.metres_per_unit.as_ref(), kind)?;
    let rule = ctx.crease_rule(raw.crease_angle_deg.as_ref())?;
    let lightmap_size = ctx.lightmap_size(raw.lightmap.as_ref())?;
    let lightmap_size = size.unwrap_or(lightmap_size);
    let materials = if raw.material.is_empty() && kind == MeshKind::Gltf {
        Vec::new()
    } else {
        ctx.materials(&raw.material, dir)?
    };
    let lights = raw
        .light
        .iter()
        .enumerate()
        .map(|(i, l)| ctx.light(i, l))
        .collect::<Result<Vec<_>, _>>()?;
    let name = raw.name.unwrap_or_else(|| stem(path));
    let mut scene = Scene {
        name,
        mesh: Mesh::default(),
        materials,
        lights,
        lightmap_size,
        allow_uv_overlap: raw.allow_uv_overlap,
    };
    let loaded = LoadedMesh::read(&mesh_path, kind, mpu, rule, raw.skip_degenerate_faces)?;
    let mut warnings = loaded.warnings.clone();
    loaded.into_scene(path, &mesh_path, &mut scene, true, &mut warnings)?;
    Ok((scene, warnings))
}

/// The kinds of mesh file, by extension.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum MeshKind {
    /// Wavefront OBJ (`.obj`).
    Obj,
    /// glTF 2.0 (`.gltf`, `.glb`).
    Gltf,
}

impl MeshKind {
    /// The kind of `path` by its extension (case-insensitive); `None` for anything else.
    fn of(path: &Path) -> Option<Self> {
        let ext = path.extension()?.to_str()?.to_ascii_lowercase();
        match ext.as_str() {
            "obj" => Some(MeshKind::Obj),
            "gltf" | "glb" => Some(MeshKind::Gltf),
            _ => None,
        }
    }
}

/// Default albedo of a mesh given without a scene file (and of OBJ faces without material).
pub const DEFAULT_ALBEDO: f32 = 0.8;

/// A mesh read from OBJ or glTF, with what the file brought beside it.
struct LoadedMesh {
    mesh: Mesh,
    /// Material names (OBJ `usemtl`) or materials (glTF), indexed by the triangles.
    materials: Vec<Material>,
    lights: Vec<Light>,
    textures: Vec<super::gltf::PendingTexture>,
    uvs_missing: bool,
    is_gltf: bool,
    warnings: Vec<String>,
}

impl LoadedMesh {
    /// Reads `path` as `kind` (OBJ files may lack UVs: they are generated later).
    fn read(
        path: &Path,
        kind: MeshKind,
        mpu: f64,
        normals: NormalRule,
        skip_degenerate_faces: bool,
    ) -> Result<Self, SceneError> {
        Ok(match kind {
            MeshKind::Obj => {
                let options = ObjOptions {
                    skip_degenerate_faces,
                };
                let mesh_options = MeshOptions {
                    normals,
                    allow_missing_uvs: true,
                };
                let m = load_obj_mesh(path, mpu, &options, &mesh_options)?;
                LoadedMesh {
                    mesh: m.mesh,
                    materials: m
                        .material_names
                        .into_iter()
                        .map(|name| Material {
                            name,
                            albedo: Albedo::Constant(Vec3::splat(DEFAULT_ALBEDO)),
                            subsurface: None,
                        })
                        .collect(),
                    lights: Vec::new(),
                    textures: Vec::new(),
                    uvs_missing: m.uvs_missing,
                    is_gltf: false,
                    warnings: m.warnings,
                }
            }
            MeshKind::Gltf => {
                let g = load_gltf(path, mpu, normals)?;
                LoadedMesh {
                    mesh: g.mesh,
                    materials: g.materials,
                    lights: g.lights,
                    textures: g.textures,
                    uvs_missing: g.uvs_missing,
                    is_gltf: true,
                    warnings: g.warnings,
                }
            }
        })
    }

    /// Completes `scene` (whose materials and lights come from the scene file, if any) with
    /// this mesh: materials matched by name (the scene file's win; with none, the file's own
    /// are used), lights (the file's when the scene file has none), lightmap UVs generated
    /// when unusable, glTF textures resampled into lightmap space.
    fn into_scene(
        self,
        scene_path: &Path,
        mesh_path: &Path,
        scene: &mut Scene,
        warn_unmatched: bool,
        warnings: &mut Vec<String>,
    ) -> Result<(), SceneError> {
        let LoadedMesh {
            mut mesh,
            materials: file_materials,
            lights,
            textures,
            uvs_missing,
            is_gltf,
            ..
        } = self;
        let names: Vec<String> = file_materials.iter().map(|m| m.name.clone()).collect();
        let mut textures = textures;
        if scene.materials.is_empty() {
            scene.materials = file_materials;
        } else {
            if is_gltf {
                // glTF materials the scene file does not name keep their own albedo.
                let mut new_index = vec![u32::MAX; file_materials.len()];
                for (i, m) in file_materials.into_iter().enumerate() {
                    if !scene.materials.iter().any(|s| s.name == m.name) {
                        new_index[i] = scene.materials.len() as u32;
                        scene.materials.push(m);
                    }
                }
                // A texture of a material the scene file overrides is not used.
                textures.retain_mut(|t| {
                    t.material = new_index[t.material as usize];
                    t.material != u32::MAX
                });
            }
            let mut unmatched = Vec::new();
            let out = if warn_unmatched {
                &mut *warnings
            } else {
                &mut unmatched
            };
            assign_materials(
                scene_path,
                mesh_path,
                &mut mesh,
                &names,
                &scene.materials,
                out,
            );
        }
        if scene.lights.is_empty() {
            scene.lights = if lights.is_empty() {
                default_lights(&mesh)
            } else {
                lights
            };
        }
        scene.mesh = mesh;
        super::unwrap::ensure_lightmap_uvs(scene, mesh_path, uvs_missing, warnings)?;
        super::gltf::resample_textures(
            &scene.mesh,
            &mut scene.materials,
            &textures,
            scene.lightmap_size,
        );
        Ok(())
    }
}

/// The default light of a scene without lights: a point light a quarter of the bounding
/// box's height above its centre when that point lies in an open space the surfaces face (a
/// room), bright enough for 1 W/m² at the bounding sphere's radius (`I = r²` W/sr); when it
/// lies inside a closed object (most of the surfaces its rays reach face away from it:
/// [`inside_solid`]), a point light outside, 2.5 radii from the centre, above, to the right and
/// in front (+x, +y, +z), with 1 W/m² at that distance (`I = (2.5 r)²`). Lights do not change a
/// bake; they light previews and renders.
pub fn default_lights(mesh: &Mesh) -> Vec<Light> {
    let (lo, hi) = mesh.bounds();
    let Some((centre, r)) = mesh.bounding_sphere() else {
        return Vec::new();
    };
    let inside = centre + Vec3::new(0.0, 0.25 * (hi.y - lo.y), 0.0);
    let (position_m, d) = if inside_solid(mesh, inside) {
        (
            centre + Vec3::new(1.0, 2.0, 1.5).normalize() * 2.5 * r,
            2.5 * r,
        )
    } else {
        (inside, r)
    };
    vec![Light::Point {
        position_m,
        color: Vec3::ONE,
        intensity_w_sr: (d * d).max(f32::MIN_POSITIVE),
    }]
}

/// Whether `p` lies inside a closed object rather than in a space its surfaces face: of the
/// rays from `p` along the 26 directions of a 3×3×3 stencil, more of those that hit the mesh
/// hit a triangle's back (its counter-clockwise normal points away from `p`) than its front.
/// Brute force over the triangles (26 rays).
pub fn inside_solid(mesh: &Mesh, p: Vec3) -> bool {
    let (mut front, mut back) = (0u32, 0u32);
    for dz in -1i32..=1 {
        for dy in -1i32..=1 {
            for dx in -1i32..=1 {
                if (dx, dy, dz) == (0, 0, 0) {
                    continue;
                }
                let dir = Vec3::new(dx as f32, dy as f32, dz as f32).normalize();
                let mut best: Option<(f32, Vec3)> = None;
                for t in &mesh.triangles {
                    let [a, b, c] = t.position.map(|i| mesh.positions_m[i as usize]);
                    if let Some(s) = ray_triangle(p, dir, a, b, c)
                        && best.is_none_or(|(bs, _)| s < bs)
                    {
                        best = Some((s, (b - a).cross(c - a)));
                    }
                }
                match best {
                    Some((_, n)) if n.dot(dir) > 0.0 => back += 1,
                    Some(_) => front += 1,
                    None => {}
                }
            }
        }
    }
    back > front
}

/// Distance along the unit `dir` from `o` to triangle `abc` (Möller–Trumbore, both sides), or
/// `None`.
fn ray_triangle(o: Vec3, dir: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let (e1, e2) = (b - a, c - a);
    let pv = dir.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let tv = o - a;
    let u = tv.dot(pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = tv.cross(e1);
    let v = dir.dot(qv) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let s = e2.dot(qv) * inv;
    (s > 0.0).then_some(s)
}

/// The file stem of `path` (or `scene`).
fn stem(path: &Path) -> String {
    path.file_stem()
        .map(|s| s.to_string_lossy().into_owned())
        .unwrap_or_else(|| "scene".into())
}

/// A mesh given as the scene: a glTF with its own materials and lights (a default light when
/// it has none), or an OBJ in metres with one grey material ([`DEFAULT_ALBEDO`]) and the
/// default light, a 256² lightmap, normals by the crease rule, lightmap UVs generated when
/// missing or overlapping. Warnings say what was assumed and how to write a scene file.
fn mesh_scene(
    path: &Path,
    kind: MeshKind,
    size: Option<(u32, u32)>,
) -> Result<(Scene, Vec<String>), SceneError> {
    let loaded = LoadedMesh::read(path, kind, 1.0, NormalRule::default(), false)?;
    let mut warnings = loaded.warnings.clone();
    let mut scene = Scene {
        name: stem(path),
        mesh: Mesh::default(),
        materials: Vec::new(),
        lights: Vec::new(),
        lightmap_size: size.unwrap_or((DEFAULT_LIGHTMAP_SIZE, DEFAULT_LIGHTMAP_SIZE)),
        allow_uv_overlap: false,
    };
    if kind == MeshKind::Obj {
        scene.materials = vec![Material {
            name: "default".into(),
            albedo: Albedo::Constant(Vec3::splat(DEFAULT_ALBEDO)),
            subsurface: None,
        }];
        warnings.push(format!(
            "{}: an OBJ given as the scene: 1 unit = 1 metre, every face grey (albedo \
             {DEFAULT_ALBEDO}), a {side}² lightmap and a default light. For \
             other units, materials or lights write a scene file (docs/scene-format.md), e.g.\n  \
             mesh = \"{}\"\n  metres_per_unit = 0.01\n  [[material]]\n  name = \"default\"\n  \
             albedo = [0.8, 0.8, 0.8]",
            path.display(),
            path.file_name()
                .map_or_else(String::new, |f| f.to_string_lossy().into_owned()),
            side = scene.lightmap_size.0,
        ));
    }
    let had_lights = !loaded.lights.is_empty();
    loaded.into_scene(path, path, &mut scene, false, &mut warnings)?;
    if kind == MeshKind::Gltf && !had_lights {
        warnings.push(format!(
            "{}: the glTF has no KHR_lights_punctual light; a default point light is used \
             (lights do not change a bake)",
            path.display()
        ));
    }
    Ok((scene, warnings))
}

/// Maps the OBJ's `usemtl` names (`obj_names`, indexed by the triangles' material) to scene
/// `materials` by name; a name without a material uses the material `default` (or the first)
/// with a warning (faces before any `usemtl`, name `""`, use it silently).
fn assign_materials(
    path: &Path,
    mesh_path: &Path,
    mesh: &mut Mesh,
    obj_names: &[String],
    materials: &[Material],
    warnings: &mut Vec<String>,
) {
    let fallback = materials
        .iter()
        .position(|m| m.name == "default")
        .unwrap_or(0);
    let map: Vec<u32> = obj_names
        .iter()
        .map(
            |name| match materials.iter().position(|m| m.name == *name) {
                Some(i) => i as u32,
                None => {
                    if !name.is_empty() {
                        warnings.push(format!(
                            "{}: `usemtl {name}` in {} has no [[material]] of that name; those \
                         faces use material `{}`",
                            path.display(),
                            mesh_path.display(),
                            materials[fallback].name
                        ));
                    }
                    fallback as u32
                }
            },
        )
        .collect();
    for t in &mut mesh.triangles {
        t.material = map
            .get(t.material as usize)
            .copied()
            .unwrap_or(fallback as u32);
    }
}

/// Upper bound of the bytes decoding an albedo texture takes per pixel: the decoded image (at
/// most 8, RGBA 16-bit), its RGB f32 copy (12) and the linear RGB texture (12).
const TEXTURE_BYTES_PER_PIXEL: u64 = 32;

/// Why a path that must name a regular file does not: it is missing, or it is something else
/// (a directory, a device such as `/dev/zero`, a pipe), which is refused before reading.
fn not_a_file(path: &Path) -> String {
    let what =
        crate::io::not_a_regular_file(path).unwrap_or_else(|| "is not a regular file".into());
    format!("names {}, which {what}", path.display())
}

/// 1-based line of byte offset `offset` in `text`.
fn line_of(text: &str, offset: usize) -> usize {
    let end = offset.min(text.len());
    1 + text.as_bytes()[..end]
        .iter()
        .filter(|&&b| b == b'\n')
        .count()
}

/// Validation context: the scene file and its text (for line numbers).
struct Ctx<'a> {
    path: &'a Path,
    text: &'a str,
}

impl Ctx<'_> {
    /// An [`SceneError::InvalidField`] at the start of `span`.
    fn err(
        &self,
        span: Option<Range<usize>>,
        field: &str,
        problem: String,
        fix: &str,
    ) -> SceneError {
        SceneError::InvalidField {
            path: self.path.to_path_buf(),
            line: span.map(|s| line_of(self.text, s.start)),
            field: field.to_string(),
            problem,
            fix: fix.to_string(),
        }
    }

    /// `metres_per_unit`: required for an OBJ mesh, 1 (glTF's metre) by default for glTF;
    /// a finite number > 0.
    fn metres_per_unit(
        &self,
        raw: Option<&Spanned<f64>>,
        kind: MeshKind,
    ) -> Result<f64, SceneError> {
        let Some(raw) = raw else {
            if kind == MeshKind::Gltf {
                return Ok(1.0);
            }
            return Err(SceneError::SceneSyntax {
                path: self.path.to_path_buf(),
                line: None,
                message: "missing field `metres_per_unit` (required with an OBJ mesh: the size \
                          of one model unit in metres, e.g. 0.01 for centimetres)"
                    .into(),
            });
        };
        let mpu = *raw.get_ref();
        if !(mpu.is_finite() && mpu > 0.0) {
            return Err(self.err(
                Some(raw.span()),
                "metres_per_unit",
                format!("is {mpu}, but must be a finite number > 0"),
                "give the size of one model unit in metres, e.g. 0.01 for centimetres",
            ));
        }
        Ok(mpu)
    }

    /// `crease_angle_deg` (default [`DEFAULT_CREASE_DEG`]): a number in `[0, 180]`.
    fn crease_rule(&self, raw: Option<&Spanned<f32>>) -> Result<NormalRule, SceneError> {
        let Some(raw) = raw else {
            return Ok(NormalRule::Crease(DEFAULT_CREASE_DEG));
        };
        let deg = *raw.get_ref();
        if !(deg.is_finite() && (0.0..=180.0).contains(&deg)) {
            return Err(self.err(
                Some(raw.span()),
                "crease_angle_deg",
                format!("is {deg}, outside [0, 180]"),
                "give the largest angle between faces that is still shaded smooth, in degrees \
                 (60 by default; 180 smooths every shared position)",
            ));
        }
        Ok(NormalRule::Crease(deg))
    }

    /// `[lightmap]`: each side defaults to [`DEFAULT_LIGHTMAP_SIZE`] and must lie in
    /// `1..=MAX_LIGHTMAP_SIZE`.
    fn lightmap_size(&self, lm: Option<&Spanned<RawLightmap>>) -> Result<(u32, u32), SceneError> {
        let Some(lm) = lm else {
            return Ok((DEFAULT_LIGHTMAP_SIZE, DEFAULT_LIGHTMAP_SIZE));
        };
        let mut size = [0u32; 2];
        for (k, (key, value)) in [
            ("width", lm.get_ref().width),
            ("height", lm.get_ref().height),
        ]
        .into_iter()
        .enumerate()
        {
            let v = value.unwrap_or(DEFAULT_LIGHTMAP_SIZE);
            if !(1..=MAX_LIGHTMAP_SIZE).contains(&v) {
                return Err(self.err(
                    Some(lm.span()),
                    &format!("lightmap.{key}"),
                    format!("is {v}, outside 1..={MAX_LIGHTMAP_SIZE}"),
                    "choose a lightmap size between 1 and 8192 texels (e.g. 256 or 512)",
                ));
            }
            size[k] = v;
        }
        Ok((size[0], size[1]))
    }

    /// Every `[[material]]` (at least one, names distinct); textures are read from `dir`.
    fn materials(
        &self,
        raw: &[Spanned<RawMaterial>],
        dir: &Path,
    ) -> Result<Vec<Material>, SceneError> {
        if raw.is_empty() {
            return Err(self.err(
                None,
                "material",
                "is missing: the scene has no [[material]]".into(),
                "add at least one [[material]] table with a `name` and an `albedo`",
            ));
        }
        let mut materials: Vec<Material> = Vec::with_capacity(raw.len());
        for (i, m) in raw.iter().enumerate() {
            let material = self.material(i, m, dir)?;
            if materials.iter().any(|x| x.name == material.name) {
                return Err(self.err(
                    Some(m.span()),
                    &format!("material[{i}].name"),
                    format!("`{}` is used by two materials", material.name),
                    "give every [[material]] a different name",
                ));
            }
            materials.push(material);
        }
        Ok(materials)
    }

    /// The `mesh` path, relative to the scene file's folder `dir`; it must name a file.
    fn mesh_path(&self, mesh: &Spanned<String>, dir: &Path) -> Result<PathBuf, SceneError> {
        let mesh_rel = mesh.get_ref();
        if mesh_rel.trim().is_empty() {
            return Err(self.err(
                Some(mesh.span()),
                "mesh",
                "is empty".into(),
                "give the OBJ file's path, relative to the scene file's folder",
            ));
        }
        let mesh_path = dir.join(mesh_rel);
        if crate::io::not_a_regular_file(&mesh_path).is_some() {
            return Err(self.err(
                Some(mesh.span()),
                "mesh",
                not_a_file(&mesh_path),
                "correct the path (it is relative to the scene file's folder)",
            ));
        }
        Ok(mesh_path)
    }

    /// Checks an RGB triple: finite, within `[lo, hi]`.
    fn rgb(
        &self,
        span: &Range<usize>,
        field: &str,
        v: [f32; 3],
        (lo, hi): (f32, f32),
        fix: &str,
    ) -> Result<Vec3, SceneError> {
        if v.iter().all(|x| x.is_finite() && (lo..=hi).contains(x)) {
            Ok(Vec3::from_array(v))
        } else {
            Err(self.err(
                Some(span.clone()),
                field,
                format!("is {v:?}, but every component must be a finite number in [{lo}, {hi}]"),
                fix,
            ))
        }
    }

    /// Validates one `[[material]]`.
    fn material(
        &self,
        i: usize,
        m: &Spanned<RawMaterial>,
        dir: &Path,
    ) -> Result<Material, SceneError> {
        let span = m.span();
        let raw = m.get_ref();
        let f = |key: &str| format!("material[{i}].{key}");
        if raw.name.trim().is_empty() {
            return Err(self.err(
                Some(span),
                &f("name"),
                "is empty".into(),
                "name the material as in the OBJ's `usemtl` (or `default`)",
            ));
        }
        let subsurface = match &raw.subsurface {
            None => None,
            Some(s) => Some(self.subsurface(i, &span, s)?),
        };
        let albedo = match (&raw.albedo, &raw.albedo_texture) {
            (Some(_), Some(_)) => {
                return Err(self.err(
                    Some(span),
                    &f("albedo_texture"),
                    "is given together with `albedo`".into(),
                    "keep only one of `albedo = [r, g, b]` and `albedo_texture = \"file.png\"`",
                ));
            }
            (Some(rgb), None) => Albedo::Constant(self.rgb(
                &span,
                &f("albedo"),
                *rgb,
                (0.0, 1.0),
                "give linear-RGB reflectances between 0 and 1, e.g. [0.73, 0.73, 0.73]",
            )?),
            (None, Some(file)) => Albedo::Texture(Arc::new(self.texture(
                &span,
                &f("albedo_texture"),
                &dir.join(file),
            )?)),
            (None, None) if subsurface.is_some() => Albedo::Constant(Vec3::ONE),
            (None, None) => {
                return Err(self.err(
                    Some(span),
                    &f("albedo"),
                    "is missing".into(),
                    "add `albedo = [r, g, b]` (linear, 0..1) or `albedo_texture = \"file.png\"`",
                ));
            }
        };
        Ok(Material {
            name: raw.name.clone(),
            albedo,
            subsurface,
        })
    }

    /// Validates a `subsurface = { ... }` table.
    fn subsurface(
        &self,
        i: usize,
        span: &Range<usize>,
        s: &RawSubsurface,
    ) -> Result<Subsurface, SceneError> {
        let f = |key: &str| format!("material[{i}].subsurface.{key}");
        let mut out = match (&s.preset, s.sigma_a, s.sigma_s_prime) {
            (Some(name), None, None) => subsurface_preset(name).ok_or_else(|| {
                self.err(
                    Some(span.clone()),
                    &f("preset"),
                    format!("`{name}` is not a known preset"),
                    &format!("use one of: {}", PRESET_NAMES.join(", ")),
                )
            })?,
            (Some(_), _, _) => {
                return Err(self.err(
                    Some(span.clone()),
                    &f("preset"),
                    "is given together with sigma_a/sigma_s_prime".into(),
                    "give either `preset` or both `sigma_a` and `sigma_s_prime`",
                ));
            }
            (None, Some(a), Some(s_prime)) => {
                let fix = "give three finite coefficients > 0 in mm⁻¹ (R, G, B)";
                let a = self.rgb(span, &f("sigma_a"), a, (0.0, f32::MAX), fix)?;
                let sp = self.rgb(span, &f("sigma_s_prime"), s_prime, (0.0, f32::MAX), fix)?;
                for (key, v) in [("sigma_a", a), ("sigma_s_prime", sp)] {
                    if v.min_element() <= 0.0 {
                        return Err(self.err(
                            Some(span.clone()),
                            &f(key),
                            format!("is {:?}, but every component must be > 0", v.to_array()),
                            fix,
                        ));
                    }
                }
                Subsurface {
                    sigma_a_per_mm: a,
                    sigma_s_prime_per_mm: sp,
                    eta: super::presets::PRESET_ETA,
                    model: SubsurfaceModel::Dipole,
                }
            }
            (None, _, _) => {
                return Err(self.err(
                    Some(span.clone()),
                    &f(if s.sigma_a.is_none() {
                        "sigma_a"
                    } else {
                        "sigma_s_prime"
                    }),
                    "is missing".into(),
                    &format!(
                        "give `preset` (one of: {}) or both `sigma_a` and `sigma_s_prime` in mm⁻¹",
                        PRESET_NAMES.join(", ")
                    ),
                ));
            }
        };
        if let Some(eta) = s.eta {
            if !(eta.is_finite() && (ETA_RANGE.0..=ETA_RANGE.1).contains(&eta)) {
                return Err(self.err(
                    Some(span.clone()),
                    &f("eta"),
                    format!("is {eta}, outside [{}, {}]", ETA_RANGE.0, ETA_RANGE.1),
                    "give the relative index of refraction, e.g. 1.3 for skin",
                ));
            }
            out.eta = eta;
        }
        if let Some(model) = s.model {
            out.model = match model {
                RawModel::Dipole => SubsurfaceModel::Dipole,
                RawModel::Exponential => SubsurfaceModel::Exponential,
            };
        }
        Ok(out)
    }

    /// Loads an sRGB PNG as linear RGB.
    fn texture(
        &self,
        span: &Range<usize>,
        field: &str,
        file: &Path,
    ) -> Result<AlbedoTexture, SceneError> {
        if crate::io::not_a_regular_file(file).is_some() {
            return Err(self.err(
                Some(span.clone()),
                field,
                not_a_file(file),
                "correct the path (it is relative to the scene file's folder)",
            ));
        }
        let (opened, _) = crate::io::open_regular(file).map_err(|source| SceneError::Io {
            what: "albedo texture",
            path: file.to_path_buf(),
            source,
        })?;
        let mut reader = image::ImageReader::new(std::io::BufReader::new(opened))
            .with_guessed_format()
            .map_err(|source| SceneError::Io {
                what: "albedo texture",
                path: file.to_path_buf(),
                source,
            })?;
        // The declared image size is checked against the limits before pixels are allocated.
        let mut limits = image::Limits::default();
        limits.max_image_width = Some(crate::io::limits::MAX_TEXTURE_SIDE);
        limits.max_image_height = Some(crate::io::limits::MAX_TEXTURE_SIDE);
        limits.max_alloc = Some(crate::io::limits::MAX_TEXTURE_DECODE_BYTES);
        reader.limits(limits);
        let tex_err = |source| SceneError::Texture {
            path: file.to_path_buf(),
            source,
        };
        let decoder = reader.into_decoder().map_err(tex_err)?;
        // The decode's memory, from the declared size, against the memory limit before any
        // pixel is allocated.
        let (w, h) = image::ImageDecoder::dimensions(&decoder);
        let need = u64::from(w) * u64::from(h) * TEXTURE_BYTES_PER_PIXEL;
        let limit = crate::io::limits::memory_limit_bytes()
            .map_err(|e| self.err(Some(span.clone()), field, e.to_string(), "fix the variable"))?;
        if let Some(limit) = limit.filter(|&l| need > l) {
            return Err(self.err(
                Some(span.clone()),
                field,
                format!(
                    "names {}, a {w}×{h} image whose decoding needs {need} bytes, more than the \
                     memory limit of {limit} bytes (physical memory or ORTM_MEMORY_LIMIT_BYTES)",
                    file.display()
                ),
                "use a smaller texture",
            ));
        }
        let decoded = image::DynamicImage::from_decoder(decoder).map_err(tex_err)?;
        let rgb = decoded.to_rgb32f();
        drop(decoded);
        let data = rgb
            .pixels()
            .map(|p| {
                Vec3::new(
                    srgb_to_linear(p[0]),
                    srgb_to_linear(p[1]),
                    srgb_to_linear(p[2]),
                )
            })
            .collect();
        Ok(AlbedoTexture {
            path: file.to_path_buf(),
            width: rgb.width(),
            height: rgb.height(),
            data,
        })
    }

    /// The keys of a `type_name` light: one that this type does not take is an error first (a
    /// misplaced key explains a missing one), then a missing one. `f` names a key in messages.
    fn check_light_keys(
        &self,
        span: &Range<usize>,
        f: &dyn Fn(&str) -> String,
        raw: &RawLight,
        type_name: &str,
    ) -> Result<(), SceneError> {
        let allowed: &[&str] = match raw.kind {
            RawLightKind::Point => &["position", "intensity"],
            RawLightKind::Spot => &[
                "position",
                "direction",
                "intensity",
                "inner_deg",
                "outer_deg",
            ],
            RawLightKind::Directional => &["direction", "irradiance"],
        };
        let present = [
            ("position", raw.position.is_some()),
            ("direction", raw.direction.is_some()),
            ("intensity", raw.intensity.is_some()),
            ("irradiance", raw.irradiance.is_some()),
            ("inner_deg", raw.inner_deg.is_some()),
            ("outer_deg", raw.outer_deg.is_some()),
        ];
        for (key, is_present) in present {
            if is_present && !allowed.contains(&key) {
                return Err(self.err(
                    Some(span.clone()),
                    &f(key),
                    format!("is not used by a {type_name} light"),
                    &format!(
                        "remove it; a {type_name} light takes {}",
                        allowed.join(", ")
                    ),
                ));
            }
        }
        for (key, is_present) in present {
            if !is_present && allowed.contains(&key) {
                return Err(self.err(
                    Some(span.clone()),
                    &f(key),
                    format!("is missing (required for a {type_name} light)"),
                    &format!("a {type_name} light takes {}", allowed.join(", ")),
                ));
            }
        }
        Ok(())
    }

    /// A spot light's `(inner_deg, outer_deg)`: `0 ≤ inner ≤ outer ≤ 90`, `outer > 0`.
    fn spot_cone(
        &self,
        span: &Range<usize>,
        f: &dyn Fn(&str) -> String,
        raw: &RawLight,
    ) -> Result<(f32, f32), SceneError> {
        let inner = raw.inner_deg.unwrap_or(0.0);
        let outer = raw.outer_deg.unwrap_or(0.0);
        let ok = inner.is_finite()
            && outer.is_finite()
            && 0.0 <= inner
            && inner <= outer
            && 0.0 < outer
            && outer <= 90.0;
        if !ok {
            return Err(self.err(
                Some(span.clone()),
                &f("outer_deg"),
                format!("inner_deg = {inner}, outer_deg = {outer} are not a valid cone"),
                "give half-angles in degrees with 0 ≤ inner_deg ≤ outer_deg ≤ 90 and \
                 outer_deg > 0",
            ));
        }
        Ok((inner, outer))
    }

    /// Validates one `[[light]]`.
    fn light(&self, i: usize, l: &Spanned<RawLight>) -> Result<Light, SceneError> {
        let span = l.span();
        let raw = l.get_ref();
        let f = |key: &str| format!("light[{i}].{key}");
        let type_name = match raw.kind {
            RawLightKind::Point => "point",
            RawLightKind::Spot => "spot",
            RawLightKind::Directional => "directional",
        };
        let color = match raw.color {
            None => Vec3::ONE,
            Some(c) => self.rgb(
                &span,
                &f("color"),
                c,
                (0.0, f32::MAX),
                "give a linear-RGB tint with components ≥ 0, e.g. [1, 1, 1]",
            )?,
        };
        self.check_light_keys(&span, &f, raw, type_name)?;
        let position = |p: [f32; 3]| {
            self.rgb(
                &span,
                &f("position"),
                p,
                (f32::MIN, f32::MAX),
                "give a finite position in metres (world space, after metres_per_unit)",
            )
        };
        let direction = |d: [f32; 3]| {
            let v = Vec3::from_array(d);
            v.try_normalize().filter(|_| v.is_finite()).ok_or_else(|| {
                self.err(
                    Some(span.clone()),
                    &f("direction"),
                    format!("is {d:?}, which has no direction"),
                    "give a finite non-zero vector (it is normalised)",
                )
            })
        };
        let non_negative = |key: &str, v: f32, unit: &str| {
            if v.is_finite() && v >= 0.0 {
                Ok(v)
            } else {
                Err(self.err(
                    Some(span.clone()),
                    &f(key),
                    format!("is {v}, but must be a finite number ≥ 0 ({unit})"),
                    &format!("give the {key} in {unit}"),
                ))
            }
        };
        Ok(match raw.kind {
            RawLightKind::Point => Light::Point {
                position_m: position(raw.position.unwrap_or_default())?,
                color,
                intensity_w_sr: non_negative("intensity", raw.intensity.unwrap_or(0.0), "W/sr")?,
            },
            RawLightKind::Spot => {
                let (inner, outer) = self.spot_cone(&span, &f, raw)?;
                Light::Spot {
                    position_m: position(raw.position.unwrap_or_default())?,
                    direction: direction(raw.direction.unwrap_or_default())?,
                    color,
                    intensity_w_sr: non_negative(
                        "intensity",
                        raw.intensity.unwrap_or(0.0),
                        "W/sr",
                    )?,
                    inner_deg: inner,
                    outer_deg: outer,
                }
            }
            RawLightKind::Directional => Light::Directional {
                direction: direction(raw.direction.unwrap_or_default())?,
                color,
                irradiance_w_m2: non_negative("irradiance", raw.irradiance.unwrap_or(0.0), "W/m²")?,
            },
        })
    }
}

/// The sRGB transfer function inverse (electro-optical): encoded `c` in [0, 1] → linear.
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 {
        c / 12.92
    } else {
        ((c + 0.055) / 1.055).powf(2.4)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn srgb_decode_matches_definition_at_known_points() {
        assert_eq!(srgb_to_linear(0.0), 0.0);
        assert!((srgb_to_linear(1.0) - 1.0).abs() < 1e-6);
        // Continuity at the breakpoint of the piecewise definition.
        let lo = 0.04045 / 12.92;
        let hi = ((0.04045f32 + 0.055) / 1.055).powf(2.4);
        assert!((lo - hi).abs() < 1e-6);
        // Monotone.
        let mut prev = -1.0;
        for i in 0..=255 {
            let v = srgb_to_linear(i as f32 / 255.0);
            assert!(v > prev);
            prev = v;
        }
    }

    #[test]
    fn line_of_counts_newlines() {
        let t = "a\nbb\n\nc";
        assert_eq!(line_of(t, 0), 1);
        assert_eq!(line_of(t, 2), 2);
        assert_eq!(line_of(t, 5), 3);
        assert_eq!(line_of(t, 6), 4);
        assert_eq!(line_of(t, 100), 4);
    }

    #[test]
    fn light_fragments_round_trip_and_report_bad_fields() {
        let lights = vec![
            Light::Point {
                position_m: Vec3::new(0.1, -0.25, 3.5),
                color: Vec3::new(1.0, 0.5, 0.25),
                intensity_w_sr: 0.125,
            },
            Light::Spot {
                position_m: Vec3::new(0.0, 1.0, 0.0),
                direction: Vec3::new(0.0, -1.0, 0.0),
                color: Vec3::ONE,
                intensity_w_sr: 2.0,
                inner_deg: 10.0,
                outer_deg: 25.5,
            },
            Light::Directional {
                direction: Vec3::new(0.6, -0.8, 0.0),
                color: Vec3::new(0.9, 0.9, 1.0),
                irradiance_w_m2: 7.0,
            },
        ];
        let text = lights_to_toml(&lights);
        let back = parse_lights_fragment(&text, Path::new("lights.toml")).unwrap();
        assert_eq!(back, lights);
        assert!(
            parse_lights_fragment("", Path::new("x.toml"))
                .unwrap()
                .is_empty()
        );
        // A spot field on a point light: error names the file, line and field.
        let bad = "[[light]]\ntype = \"point\"\nposition = [0, 0, 0]\nintensity = 1.0\n\n\
                   [[light]]\ntype = \"point\"\nposition = [0, 0, 0]\nintensity = 1.0\n\
                   outer_deg = 3.0\n";
        let e = parse_lights_fragment(bad, Path::new("lights.toml"))
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("lights.toml:6") && e.contains("light[1].outer_deg"),
            "{e}"
        );
        // Scene keys are not allowed in a light set-up.
        let e = parse_lights_fragment("mesh = \"a.obj\"\n", Path::new("l.toml"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("mesh"), "{e}");
    }
}

#[cfg(test)]
mod default_light_tests {
    use super::*;
    use crate::scene::MeshTriangle;

    /// A unit cube at `(0, 0.5, 0)` (so the default light's candidate, above the centre, is
    /// inside it), its faces counter-clockwise seen from outside, or from inside when
    /// `inward`.
    fn cube(inward: bool) -> Mesh {
        let p = |x: f32, y: f32, z: f32| Vec3::new(x - 0.5, y, z - 0.5);
        let positions_m = vec![
            p(0.0, 0.0, 0.0),
            p(1.0, 0.0, 0.0),
            p(1.0, 1.0, 0.0),
            p(0.0, 1.0, 0.0),
            p(0.0, 0.0, 1.0),
            p(1.0, 0.0, 1.0),
            p(1.0, 1.0, 1.0),
            p(0.0, 1.0, 1.0),
        ];
        // Outward counter-clockwise quads.
        let quads = [
            [0, 3, 2, 1],
            [4, 5, 6, 7],
            [0, 1, 5, 4],
            [1, 2, 6, 5],
            [2, 3, 7, 6],
            [3, 0, 4, 7],
        ];
        let mut triangles = Vec::new();
        for q in quads {
            for mut t in [[q[0], q[1], q[2]], [q[0], q[2], q[3]]] {
                if inward {
                    t.swap(1, 2);
                }
                triangles.push(MeshTriangle {
                    position: t,
                    uv: [0; 3],
                    normal: [0; 3],
                    material: 0,
                });
            }
        }
        Mesh {
            positions_m,
            uvs: vec![glam::Vec2::ZERO],
            normals: vec![Vec3::Y],
            triangles,
        }
    }

    fn light_position(mesh: &Mesh) -> Vec3 {
        match default_lights(mesh).as_slice() {
            [Light::Point { position_m, .. }] => *position_m,
            other => panic!("one point light expected, got {other:?}"),
        }
    }

    #[test]
    fn a_room_keeps_its_light_inside_and_an_object_gets_one_outside() {
        // Seen from inside (a room): the light stays a quarter of the height above the centre.
        let room = cube(true);
        assert!(!inside_solid(&room, Vec3::new(0.0, 0.75, 0.0)));
        let p = light_position(&room);
        assert!((p - Vec3::new(0.0, 0.75, 0.0)).length() < 1e-5, "{p}");
        // A closed object: the candidate is inside the solid, the light moves out, above it.
        let object = cube(false);
        assert!(inside_solid(&object, Vec3::new(0.0, 0.75, 0.0)));
        let p = light_position(&object);
        assert!(
            p.x > 0.5 && p.y > 1.0 && p.z > 0.5,
            "outside, above, in front: {p}"
        );
        // Outside the object, the object's faces face the point.
        assert!(!inside_solid(&object, p));
    }
}
