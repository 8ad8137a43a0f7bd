//! Lightmap UVs for meshes that have none, or whose UVs overlap (a texture layout that reuses
//! UV space): chart segmentation, planar parameterisation, packing with gutters.
//!
//! # Why our own code
//! The crates that unwrap (`xatlas` bindings) build xatlas' C++ with a C++ toolchain and bring
//! `unsafe` FFI; no pure-Rust unwrapper on crates.io is maintained. Planar charts packed by the
//! skyline packer that already lays out the built-in scenes ([`super::charts`]) are enough for
//! lightmaps: they give one texel density and gutters by construction, and every result is
//! checked for overlaps before it is used.
//!
//! # Algorithm
//! 1. **Charts**: triangles are grown into charts over shared edges (welded positions) from
//!    a seed (the first unassigned triangle, in mesh order): a neighbour joins when its face
//!    normal is within [`CHART_ANGLE_DEG`] of the seed's.
//! 2. **Parameterisation**: each chart is projected orthogonally onto the plane normal to its
//!    seed's normal, in a frame `(e_u, e_v)` with `e_u × e_v` along that normal (never
//!    mirrored). Every triangle is within 40° of the plane, so its area shrinks by at most
//!    cos 40° = 0.77: texel density varies by at most 1.31× inside a chart.
//! 3. **Packing**: the charts' bounding rectangles at one texel density (metres → texels,
//!    each side rounded up) are packed by the skyline packer with
//!    [`super::charts::GUTTER_TEXELS`] (2) empty texels between charts and to the border,
//!    at the largest density that fits (bisection), in the square of the lightmap's
//!    shorter side.
//! 4. **Check**: the layout is rasterized at texel centres; a chart in which two triangles
//!    cover the same centre (a projection that folds over itself) is split into one chart per
//!    triangle and the packing is redone.
//!
//! UVs follow the mesh convention (`v` up, row 0 is `v = 1`). Every corner of a chart that
//! shares a position shares its UV.

use std::collections::HashMap;
use std::path::Path;

use glam::{DVec3, Vec2, Vec3};

use super::charts::{ChartRect, GUTTER_TEXELS, chart_sizes, skyline_pack};
use super::{Mesh, Scene, SceneError};

/// Largest angle between a triangle's normal and its chart seed's normal, degrees.
pub const CHART_ANGLE_DEG: f32 = 40.0;
/// Passes of pack-and-check before every remaining folded chart is split to triangles.
const SPLIT_PASSES: usize = 3;

/// What [`unwrap`] produced.
#[derive(Clone, Debug, PartialEq)]
pub struct UnwrapReport {
    /// Number of charts.
    pub charts: usize,
    /// Texel density, texels per metre.
    pub texels_per_m: f64,
    /// Chart of every triangle.
    pub triangle_chart: Vec<u32>,
}

/// Unit face normals (zero for degenerate triangles) and edge neighbours of every triangle.
fn adjacency(mesh: &Mesh) -> (Vec<Vec3>, Vec<Vec<u32>>) {
    let normals: Vec<Vec3> = mesh
        .triangles
        .iter()
        .map(|t| {
            let [a, b, c] = t.position.map(|i| mesh.positions_m[i as usize].as_dvec3());
            (b - a).cross(c - a).normalize_or_zero().as_vec3()
        })
        .collect();
    let mut edges: HashMap<(u32, u32), Vec<u32>> = HashMap::new();
    for (t, tri) in mesh.triangles.iter().enumerate() {
        for k in 0..3 {
            let (a, b) = (tri.position[k], tri.position[(k + 1) % 3]);
            edges
                .entry((a.min(b), a.max(b)))
                .or_default()
                .push(t as u32);
        }
    }
    let mut neighbours = vec![Vec::new(); mesh.triangles.len()];
    for list in edges.values() {
        for &s in list {
            for &t in list {
                if s != t {
                    neighbours[s as usize].push(t);
                }
            }
        }
    }
    (normals, neighbours)
}

/// Region growing (step 1); triangles in `single` get a chart of their own. Returns the
/// chart of every triangle and each chart's seed normal.
fn segment(normals: &[Vec3], neighbours: &[Vec<u32>], single: &[bool]) -> (Vec<u32>, Vec<Vec3>) {
    let cos_limit = CHART_ANGLE_DEG.to_radians().cos();
    let mut chart = vec![u32::MAX; normals.len()];
    let mut seeds = Vec::new();
    for seed in 0..normals.len() {
        if chart[seed] != u32::MAX {
            continue;
        }
        let id = seeds.len() as u32;
        let n = normals[seed];
        seeds.push(if n == Vec3::ZERO { Vec3::Z } else { n });
        chart[seed] = id;
        if single[seed] || n == Vec3::ZERO {
            continue;
        }
        let mut stack = vec![seed as u32];
        while let Some(t) = stack.pop() {
            for &s in &neighbours[t as usize] {
                let s = s as usize;
                if chart[s] == u32::MAX && !single[s] && normals[s].dot(n) >= cos_limit {
                    chart[s] = id;
                    stack.push(s as u32);
                }
            }
        }
    }
    (chart, seeds)
}

/// Chart-plane coordinates (metres) of every triangle corner, shifted so each chart's
/// bounding box starts at the origin, and each chart's extent.
fn project(mesh: &Mesh, chart: &[u32], seeds: &[Vec3]) -> (Vec<[Vec2; 3]>, Vec<(f32, f32)>) {
    let frames: Vec<(DVec3, DVec3)> = seeds
        .iter()
        .map(|n| {
            let n = n.as_dvec3();
            let u = n.any_orthonormal_vector();
            (u, n.cross(u))
        })
        .collect();
    let mut lo = vec![Vec2::splat(f32::INFINITY); seeds.len()];
    let mut hi = vec![Vec2::splat(f32::NEG_INFINITY); seeds.len()];
    let mut corners: Vec<[Vec2; 3]> = mesh
        .triangles
        .iter()
        .zip(chart)
        .map(|(t, &c)| {
            let (u, v) = frames[c as usize];
            t.position.map(|i| {
                let p = mesh.positions_m[i as usize].as_dvec3();
                let q = Vec2::new(p.dot(u) as f32, p.dot(v) as f32);
                lo[c as usize] = lo[c as usize].min(q);
                hi[c as usize] = hi[c as usize].max(q);
                q
            })
        })
        .collect();
    for (q, &c) in corners.iter_mut().zip(chart) {
        for p in q.iter_mut() {
            *p -= lo[c as usize];
        }
    }
    let sides = lo
        .iter()
        .zip(&hi)
        .map(|(l, h)| (h.x - l.x, h.y - l.y))
        .collect();
    (corners, sides)
}

/// Packs charts of `sides` metres into `size × size` at the largest texel density that fits
/// (step 3); `None` when even minimum-size charts do not fit.
fn pack(sides: &[(f32, f32)], size: u32) -> Option<(f64, Vec<(ChartRect, bool)>)> {
    let longest = sides
        .iter()
        .fold(0.0f32, |m, &(a, b)| m.max(a).max(b))
        .max(f32::MIN_POSITIVE);
    let fits = |s: f64| skyline_pack(&chart_sizes(sides, s), size);
    fits(0.0)?;
    let (mut lo, mut hi) = (0.0f64, 2.0 * size as f64 / longest as f64);
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if fits(mid).is_some() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    Some((lo, fits(lo)?))
}

/// Texel-space corners (x right, y down, in texels of the `size` square) of every triangle.
fn place(
    corners: &[[Vec2; 3]],
    chart: &[u32],
    sides: &[(f32, f32)],
    density: f64,
    rects: &[(ChartRect, bool)],
) -> Vec<[Vec2; 3]> {
    corners
        .iter()
        .zip(chart)
        .map(|(q, &c)| {
            let (r, turned) = rects[c as usize];
            let (w, h) = sides[c as usize];
            q.map(|p| {
                // Turning by 90° counter-clockwise keeps the frame unmirrored.
                let (a, b, hh) = if turned {
                    (h - p.y, p.x, w)
                } else {
                    (p.x, p.y, h)
                };
                let d = density as f32;
                Vec2::new(r.x as f32 + a * d, r.y as f32 + (hh - b) * d)
            })
        })
        .collect()
}

/// Charts in which two triangles cover one texel centre of the `size` square.
fn folded_charts(texel: &[[Vec2; 3]], chart: &[u32], size: u32) -> Vec<u32> {
    let mut owner: HashMap<(u32, u32), u32> = HashMap::new();
    let mut folded = Vec::new();
    for (t, p) in texel.iter().enumerate() {
        let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
        if area.abs() < 1e-12 {
            continue;
        }
        let lo = p[0].min(p[1]).min(p[2]).floor().max(Vec2::ZERO);
        let hi = p[0]
            .max(p[1])
            .max(p[2])
            .ceil()
            .min(Vec2::splat(size as f32));
        for y in lo.y as u32..hi.y as u32 {
            for x in lo.x as u32..hi.x as u32 {
                let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let b1 = (c - p[0]).perp_dot(p[2] - p[0]) / area;
                let b2 = (p[1] - p[0]).perp_dot(c - p[0]) / area;
                if b1 <= 0.0 || b2 <= 0.0 || b1 + b2 >= 1.0 {
                    continue;
                }
                if let Some(prev) = owner.insert((x, y), t as u32) {
                    folded.push(chart[prev as usize]);
                    folded.push(chart[t]);
                }
            }
        }
    }
    folded.sort_unstable();
    folded.dedup();
    folded
}

/// Replaces `mesh`'s UVs with generated lightmap UVs for a `width × height` lightmap (see the
/// module docs). `path` names the mesh in errors.
pub fn unwrap(
    mesh: &mut Mesh,
    (width, height): (u32, u32),
    path: &Path,
) -> Result<UnwrapReport, SceneError> {
    let size = width.min(height);
    let (normals, neighbours) = adjacency(mesh);
    let mut single = vec![false; mesh.triangles.len()];
    for pass in 0..=SPLIT_PASSES {
        let (chart, seeds) = segment(&normals, &neighbours, &single);
        let (corners, sides) = project(mesh, &chart, &seeds);
        let Some((density, rects)) = pack(&sides, size) else {
            return Err(SceneError::Unwrap {
                path: path.to_path_buf(),
                problem: format!(
                    "its {} charts do not fit in a {width}×{height} lightmap even at the \
                     smallest chart size ({} texels with {GUTTER_TEXELS}-texel gutters)",
                    seeds.len(),
                    super::charts::MIN_CHART_TEXELS
                ),
                fix: "choose a larger lightmap (`[lightmap]` in the scene file or --size)".into(),
            });
        };
        let texel = place(&corners, &chart, &sides, density, &rects);
        let folded = folded_charts(&texel, &chart, size);
        if !folded.is_empty() && pass < SPLIT_PASSES {
            for (t, c) in chart.iter().enumerate() {
                single[t] |= folded.binary_search(c).is_ok();
            }
            continue;
        }
        write_uvs(mesh, &texel, &chart, (width, height));
        return Ok(UnwrapReport {
            charts: seeds.len(),
            texels_per_m: density,
            triangle_chart: chart,
        });
    }
    unreachable!("the last pass always returns")
}

/// Stores the texel-space corners as UVs, one per (chart, position).
fn write_uvs(mesh: &mut Mesh, texel: &[[Vec2; 3]], chart: &[u32], (width, height): (u32, u32)) {
    let mut index: HashMap<(u32, u32), u32> = HashMap::new();
    let mut uvs = Vec::new();
    for (t, tri) in mesh.triangles.iter_mut().enumerate() {
        for (k, &p) in texel[t].iter().enumerate() {
            let key = (chart[t], tri.position[k]);
            tri.uv[k] = *index.entry(key).or_insert_with(|| {
                uvs.push(Vec2::new(p.x / width as f32, 1.0 - p.y / height as f32));
                (uvs.len() - 1) as u32
            });
        }
    }
    mesh.uvs = uvs;
}

/// Why `scene`'s lightmap UVs cannot be used as they are: `uvs_missing` (the file has none),
/// or more than [`crate::bake::texels::OVERLAP_TOLERANCE`] of the covered texels overlap
/// (unless the scene allows overlaps), or they cover no texel. `None` when they can be used.
pub fn unusable_uvs(scene: &mut Scene, uvs_missing: bool) -> Option<String> {
    if uvs_missing {
        return Some("it has no lightmap UVs".into());
    }
    let (w, h) = scene.lightmap_size;
    if scene.allow_uv_overlap || crate::io::limits::check_lightmap_memory(w, h).is_err() {
        // Too large to rasterize here: the caller refuses the size with its own message.
        return None;
    }
    scene.allow_uv_overlap = true;
    let grid = crate::bake::texels::TexelGrid::build(scene);
    scene.allow_uv_overlap = false;
    match grid {
        Err(_) => Some("its UVs cover no lightmap texel".into()),
        Ok(g) => {
            let fraction = g.stats.overlapping as f64 / g.stats.covered.max(1) as f64;
            (fraction > crate::bake::texels::OVERLAP_TOLERANCE).then(|| {
                format!(
                    "its UVs overlap ({} of {} covered texels at {}×{})",
                    g.stats.overlapping, g.stats.covered, g.width, g.height
                )
            })
        }
    }
}

/// Generates lightmap UVs for `scene` when [`unusable_uvs`] says so, with a warning naming
/// the mesh file `path`, the reason and what was generated.
pub fn ensure_lightmap_uvs(
    scene: &mut Scene,
    path: &Path,
    uvs_missing: bool,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    let Some(reason) = unusable_uvs(scene, uvs_missing) else {
        return Ok(());
    };
    let report = unwrap(&mut scene.mesh, scene.lightmap_size, path)?;
    warnings.push(format!(
        "{}: {reason}; generated lightmap UVs: {} charts at {:.1} texels/m in {}×{} with \
         {GUTTER_TEXELS}-texel gutters (`ortm unwrap` writes them to a file)",
        path.display(),
        report.charts,
        report.texels_per_m,
        scene.lightmap_size.0,
        scene.lightmap_size.1
    ));
    Ok(())
}

/// What [`unwrap_file`] did.
#[derive(Clone, Debug)]
pub struct UnwrapSummary {
    /// The unwrap.
    pub report: UnwrapReport,
    /// Triangles written.
    pub triangles: usize,
    /// Non-fatal findings (from reading, and what the output leaves out).
    pub warnings: Vec<String>,
}

/// A mesh file read for [`unwrap_file`]: the mesh (in its file's units), its materials, lights
/// and warnings.
type ReadMesh = (Mesh, Vec<super::Material>, Vec<super::Light>, Vec<String>);

/// Reads `input` (`.obj`, `.gltf` or `.glb`) for [`unwrap_file`] (`output` is named in the
/// warning about textures a glTF loses).
fn read_mesh_file(input: &Path, output: &Path) -> Result<ReadMesh, SceneError> {
    use super::normals::NormalRule;
    use super::obj::{MeshOptions, ObjOptions, load_obj_mesh};
    Ok(match extension(input).as_str() {
        "obj" => {
            let options = MeshOptions {
                normals: NormalRule::default(),
                allow_missing_uvs: true,
            };
            let m = load_obj_mesh(input, 1.0, &ObjOptions::default(), &options)?;
            let materials = m
                .material_names
                .iter()
                .map(|name| super::Material {
                    name: name.clone(),
                    albedo: super::Albedo::Constant(Vec3::splat(super::file::DEFAULT_ALBEDO)),
                    subsurface: None,
                })
                .collect::<Vec<_>>();
            (m.mesh, materials, Vec::new(), m.warnings)
        }
        "gltf" | "glb" => {
            let g = super::gltf::load_gltf(input, 1.0, NormalRule::default())?;
            let mut w = g.warnings;
            if !g.textures.is_empty() {
                w.push(format!(
                    "{}: base colour textures are not written to {} (their UV set is replaced); \
                     keep the original file for them, or name it in a scene file",
                    input.display(),
                    output.display()
                ));
            }
            (g.mesh, g.materials, g.lights, w)
        }
        _ => return Err(bad_extension(input, "input")),
    })
}

/// The lower-case extension of `p` (empty when none).
fn extension(p: &Path) -> String {
    p.extension()
        .and_then(|e| e.to_str())
        .map(str::to_ascii_lowercase)
        .unwrap_or_default()
}

/// The error for an `ortm unwrap` file (`role`: input or output) of another kind.
fn bad_extension(p: &Path, role: &str) -> SceneError {
    SceneError::Unwrap {
        path: p.to_path_buf(),
        problem: format!("the {role} must end in .obj, .gltf or .glb"),
        fix: "name an OBJ or glTF file".into(),
    }
}

/// Reads a mesh (`.obj`, `.gltf`, `.glb`), generates lightmap UVs for a `size × size`
/// lightmap and writes the mesh with them to `output` (`.obj`: positions in the input's
/// units, `vt` = the lightmap UVs, `vn` = the normals used; `.gltf`/`.glb`: see
/// [`super::gltf_write`], the lightmap UVs as `TEXCOORD_1`). A glTF is written flattened to
/// world space with its materials' base colour factors and its lights; its textures are not
/// carried over (a warning says so).
pub fn unwrap_file(input: &Path, output: &Path, size: u32) -> Result<UnwrapSummary, SceneError> {
    use super::gltf_write::{BufferMode, GltfWrite, write_gltf};
    use super::obj::write_obj;
    let out_ext = extension(output);
    if !matches!(out_ext.as_str(), "obj" | "gltf" | "glb") {
        return Err(bad_extension(output, "output"));
    }
    let (mut mesh, materials, lights, mut warnings) = read_mesh_file(input, output)?;
    let report = unwrap(&mut mesh, (size, size), input)?;
    let io = |source| SceneError::Io {
        what: "unwrapped mesh",
        path: output.to_path_buf(),
        source,
    };
    if out_ext == "obj" {
        let names: Vec<String> = materials.iter().map(|m| m.name.clone()).collect();
        write_obj(output, &mesh, &names).map_err(io)?;
    } else {
        let w = GltfWrite {
            mesh: &mesh,
            materials: &materials,
            lights: &lights,
            node_chain: Vec::new(),
            buffer: BufferMode::External,
        };
        write_gltf(output, &w).map_err(io)?;
    }
    if extension(input) == "obj" && out_ext != "obj" {
        warnings.push(format!(
            "{}: OBJ coordinates are written as metres to {} (glTF's unit)",
            input.display(),
            output.display()
        ));
    }
    Ok(UnwrapSummary {
        triangles: mesh.triangles.len(),
        report,
        warnings,
    })
}
