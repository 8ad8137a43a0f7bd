//! glTF 2.0 loading (`.gltf` with external or embedded buffers, `.glb`): file → one world-space
//! [`Mesh`] in metres, its materials and its `KHR_lights_punctual` lights. Parsing, buffer
//! and image decoding are the `gltf` crate's; this module flattens the node tree.
//!
//! # Data flow
//! 1. The file is read whole (refused when larger than [`MAX_GLTF_BYTES`]); `gltf` parses
//!    and validates it and resolves its buffers (GLB chunk, `data:` URIs, files beside it).
//! 2. The default scene (else the first) is walked from its roots; every node's world matrix
//!    is the product of its ancestors' (`matrix` or TRS). Every triangle primitive of every
//!    mesh is appended in that order (points, lines, strips and fans are skipped with a
//!    warning). Positions go to world space
//!    (× `metres_per_unit`, 1 for glTF, whose unit is the metre), normals by the inverse
//!    transpose; a mirroring matrix (negative determinant) reverses the winding so faces stay
//!    counter-clockwise from the front. Positions are welded by bit-identical world
//!    coordinates (so crease normals and unwrap charts see shared edges).
//! 3. Lightmap UVs: `TEXCOORD_1` when every primitive has it; else `TEXCOORD_0` when every
//!    primitive has it, no primitive has a second set, and it lies in `[0, 1]`; else none
//!    ([`GltfScene::uvs_missing`]: the scene loader generates them). glTF's `v` runs down the
//!    image, ours up: `v_ours = 1 − v_gltf`. Overlaps are judged by the scene loader.
//! 4. Normals: the file's `NORMAL` when every primitive has it; else the crease rule of
//!    [`super::normals`] on the welded positions.
//! 5. Materials: one per glTF material used (name from the file, else `material<i>`), plus
//!    `default` (white, the glTF default) for primitives without one. Albedo is
//!    `baseColorFactor.rgb` (already linear), times `baseColorTexture` decoded from sRGB when
//!    present. The texture is sampled through its own UV set; [`GltfScene::textures`] keeps
//!    what is needed to resample it into lightmap space once the lightmap UVs are final
//!    ([`resample_textures`]).
//! 6. Lights (`KHR_lights_punctual`), converted with the luminous efficacy
//!    [`LUMENS_PER_WATT`] = 683 lm/W (the definition of the candela at 540 THz): point and
//!    spot intensity cd → W/sr = cd / 683; directional illuminance lux → W/m² = lux / 683;
//!    `color` is the tint. A light sits at its node's world origin and shines along its
//!    node's world −Z; spot cone angles (radians, half-angles) become degrees. `range` is
//!    ignored (with a warning): our lights follow the inverse-square law without cut-off.

use std::collections::HashMap;
use std::path::Path;
use std::sync::Arc;

use glam::{Mat3, Mat4, Vec2, Vec3};

use super::normals::{NormalRule, crease_normals};
use super::{Albedo, AlbedoTexture, Light, Material, Mesh, MeshTriangle, SceneError};

/// Largest glTF/GLB file accepted, bytes (the OBJ limit, [`crate::io::limits::MAX_OBJ_BYTES`]).
pub const MAX_GLTF_BYTES: u64 = crate::io::limits::MAX_OBJ_BYTES;
/// Luminous efficacy used to turn photometric glTF light units into radiometric ones, lm/W.
pub const LUMENS_PER_WATT: f32 = 683.0;

/// A point or spot light's intensity in W/sr from glTF's candela.
pub fn candela_to_w_per_sr(cd: f32) -> f32 {
    cd / LUMENS_PER_WATT
}

/// A directional light's irradiance in W/m² from glTF's lux.
pub fn lux_to_w_per_m2(lux: f32) -> f32 {
    lux / LUMENS_PER_WATT
}

/// A base-colour texture waiting to be resampled into lightmap space.
#[derive(Clone, Debug)]
pub struct PendingTexture {
    /// Index into [`GltfScene::materials`].
    pub material: u32,
    /// The image (linear RGB × baseColorFactor), in its own UV set (row 0 is v = 1).
    pub image: Arc<AlbedoTexture>,
    /// Per triangle of the mesh, the texture UVs of its corners (ours: v up).
    pub corner_uvs: Vec<[Vec2; 3]>,
}

/// What a glTF file holds, in ortm's types.
#[derive(Clone, Debug)]
pub struct GltfScene {
    /// The flattened world-space mesh, metres.
    pub mesh: Mesh,
    /// Materials referenced by the mesh's triangles.
    pub materials: Vec<Material>,
    /// The `KHR_lights_punctual` lights, in W/sr and W/m².
    pub lights: Vec<Light>,
    /// Base-colour textures to resample once the lightmap UVs are final.
    pub textures: Vec<PendingTexture>,
    /// No usable lightmap UV set (see the module docs); the mesh's UVs are placeholders.
    pub uvs_missing: bool,
    /// Non-fatal findings.
    pub warnings: Vec<String>,
}

/// An error about the glTF file `path`.
fn gltf_err(path: &Path, problem: impl Into<String>, fix: &str) -> SceneError {
    SceneError::Gltf {
        path: path.to_path_buf(),
        problem: problem.into(),
        fix: fix.to_string(),
    }
}

/// Per-vertex data of the primitives, before welding.
#[derive(Default)]
struct Soup {
    positions: Vec<Vec3>,
    normals: Vec<Vec3>,
    lightmap_uvs: Vec<Vec2>,
    /// Per vertex, the UVs of sets 0 and 1 (ours: v up), where present.
    sets: Vec<[Option<Vec2>; 2]>,
    /// Per triangle: vertex indices and glTF material (`None` = default).
    triangles: Vec<([u32; 3], Option<usize>)>,
    all_normals: bool,
    /// Primitives with (set 0, set 1), and primitives in all.
    with_set: [usize; 2],
    primitives: usize,
}

/// Loads a glTF 2.0 file (see the module docs); `metres_per_unit` scales it (1 for plain
/// glTF), `rule` gives normals to meshes without `NORMAL`.
pub fn load_gltf(
    path: &Path,
    metres_per_unit: f64,
    rule: NormalRule,
) -> Result<GltfScene, SceneError> {
    let bytes = super::read_bytes_bounded(path, "glTF file", MAX_GLTF_BYTES)?;
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice(&bytes).map_err(|e| {
        gltf_err(
            path,
            format!("is not a valid glTF 2.0 file: {e}"),
            "export it again as glTF 2.0 (.gltf or .glb)",
        )
    })?;
    let dir = path.parent().unwrap_or(Path::new(""));
    let buffers = gltf::import_buffers(&document, Some(dir), blob).map_err(|e| {
        gltf_err(
            path,
            format!("a buffer cannot be read: {e}"),
            "keep the .bin files named by the .gltf beside it, or export a .glb",
        )
    })?;
    let Some(scene) = document
        .default_scene()
        .or_else(|| document.scenes().next())
    else {
        return Err(gltf_err(path, "has no scene", "export a scene with meshes"));
    };
    let (mut soup, lights, mut warnings) =
        walk(path, &document, &scene, metres_per_unit, &buffers)?;
    if soup.triangles.is_empty() {
        return Err(gltf_err(
            path,
            "has no triangles in its scene",
            "export the meshes as triangles (mode 4) in the default scene",
        ));
    }
    if !soup.positions.iter().all(|p| p.is_finite()) {
        return Err(gltf_err(
            path,
            "has a position that is not a finite number (after the node transforms)",
            "check the model's coordinates and node scales",
        ));
    }
    let uvs_missing = choose_lightmap_uvs(&mut soup);
    let (mesh, kept) = build_mesh(path, &soup, rule, &mut warnings);
    let (materials, tri_material) = materials(&document, &soup, &kept);
    let mut mesh = mesh;
    for (t, m) in mesh.triangles.iter_mut().zip(&tri_material) {
        t.material = *m;
    }
    let textures = textures(
        path,
        &document,
        &buffers,
        &soup,
        &kept,
        &materials,
        &mut warnings,
    )?;
    Ok(GltfScene {
        mesh,
        materials,
        lights,
        textures,
        uvs_missing,
        warnings,
    })
}

/// Walks `scene`'s node trees (each node's world matrix = its parent's × its own, after the
/// `metres_per_unit` scale), collecting every triangle primitive and light. A node hierarchy
/// that visits more nodes than the document has (a cycle, which glTF forbids) is an error.
fn walk(
    path: &Path,
    document: &gltf::Document,
    scene: &gltf::Scene,
    metres_per_unit: f64,
    buffers: &[gltf::buffer::Data],
) -> Result<(Soup, Vec<Light>, Vec<String>), SceneError> {
    let mut warnings = Vec::new();
    let mut soup = Soup {
        all_normals: true,
        ..Soup::default()
    };
    let mut lights = Vec::new();
    let scale = Mat4::from_scale(Vec3::splat(metres_per_unit as f32));
    let mut stack: Vec<(gltf::Node, Mat4)> = scene.nodes().map(|n| (n, scale)).collect();
    stack.reverse();
    let mut visits = 0usize;
    while let Some((node, parent)) = stack.pop() {
        visits += 1;
        if visits > document.nodes().len() {
            return Err(gltf_err(
                path,
                "has a node hierarchy with a cycle or a node with two parents",
                "export the scene again (glTF nodes form trees)",
            ));
        }
        let world = parent * Mat4::from_cols_array_2d(&node.transform().matrix());
        if let Some(mesh) = node.mesh() {
            add_mesh(path, &mesh, world, buffers, &mut soup, &mut warnings)?;
        }
        if let Some(light) = node.light() {
            lights.push(convert_light(path, &light, world, &mut warnings));
        }
        let children: Vec<_> = node.children().map(|c| (c, world)).collect();
        stack.extend(children.into_iter().rev());
    }
    Ok((soup, lights, warnings))
}

/// Appends every triangle primitive of `mesh` under the world matrix `world` to `soup`.
fn add_mesh(
    path: &Path,
    mesh: &gltf::Mesh,
    world: Mat4,
    buffers: &[gltf::buffer::Data],
    soup: &mut Soup,
    warnings: &mut Vec<String>,
) -> Result<(), SceneError> {
    let normal_m = Mat3::from_mat4(world).inverse().transpose();
    let mirrored = Mat3::from_mat4(world).determinant() < 0.0;
    let mesh_name = mesh.name().unwrap_or("(unnamed)");
    for prim in mesh.primitives() {
        if prim.mode() != gltf::mesh::Mode::Triangles {
            warnings.push(format!(
                "{}: mesh `{mesh_name}` has a {:?} primitive; only triangle lists are read, it \
                 is skipped",
                path.display(),
                prim.mode()
            ));
            continue;
        }
        let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d.0[..]));
        let Some(pos) = reader.read_positions() else {
            warnings.push(format!(
                "{}: a primitive of mesh `{mesh_name}` has no POSITION; skipped",
                path.display()
            ));
            continue;
        };
        let base = soup.positions.len() as u32;
        let count = pos.len();
        soup.positions
            .extend(pos.map(|p| world.transform_point3(Vec3::from_array(p))));
        match reader.read_normals() {
            Some(n) if n.len() == count => soup.normals.extend(n.map(|n| {
                (normal_m * Vec3::from_array(n))
                    .try_normalize()
                    .unwrap_or(Vec3::Z)
            })),
            _ => {
                soup.all_normals = false;
                soup.normals.extend(std::iter::repeat_n(Vec3::Z, count));
            }
        }
        let mut sets = vec![[None, None]; count];
        for set in 0..2 {
            if let Some(tc) = reader.read_tex_coords(set) {
                let tc: Vec<[f32; 2]> = tc.into_f32().collect();
                if tc.len() == count {
                    soup.with_set[set as usize] += 1;
                    for (s, t) in sets.iter_mut().zip(tc) {
                        s[set as usize] = Some(Vec2::new(t[0], 1.0 - t[1]));
                    }
                }
            }
        }
        soup.sets.extend(sets);
        soup.primitives += 1;
        let indices: Vec<u32> = match reader.read_indices() {
            Some(i) => i.into_u32().collect(),
            None => (0..count as u32).collect(),
        };
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= count) {
            return Err(gltf_err(
                path,
                format!("mesh `{mesh_name}` has index {bad} but only {count} vertices"),
                "export the mesh again",
            ));
        }
        let material = prim.material().index();
        for t in indices.chunks_exact(3) {
            let tri = if mirrored {
                [t[0], t[2], t[1]]
            } else {
                [t[0], t[1], t[2]]
            };
            soup.triangles.push((tri.map(|i| base + i), material));
        }
    }
    Ok(())
}

/// A `KHR_lights_punctual` light at the node with world matrix `world`, in our units (see
/// the module docs).
fn convert_light(
    path: &Path,
    light: &gltf::khr_lights_punctual::Light,
    world: Mat4,
    warnings: &mut Vec<String>,
) -> Light {
    use gltf::khr_lights_punctual::Kind;
    let position_m = world.transform_point3(Vec3::ZERO);
    let direction = world
        .transform_vector3(Vec3::NEG_Z)
        .try_normalize()
        .unwrap_or(Vec3::NEG_Z);
    let color = Vec3::from_array(light.color()).max(Vec3::ZERO);
    let intensity = light.intensity().max(0.0);
    if light.range().is_some() {
        warnings.push(format!(
            "{}: light `{}` has a range; ignored (ortm's lights fall off as 1/d² without cut-off)",
            path.display(),
            light.name().unwrap_or("(unnamed)")
        ));
    }
    match light.kind() {
        Kind::Point => Light::Point {
            position_m,
            color,
            intensity_w_sr: candela_to_w_per_sr(intensity),
        },
        Kind::Spot {
            inner_cone_angle,
            outer_cone_angle,
        } => {
            let outer = outer_cone_angle.to_degrees().clamp(1e-3, 90.0);
            Light::Spot {
                position_m,
                direction,
                color,
                intensity_w_sr: candela_to_w_per_sr(intensity),
                inner_deg: inner_cone_angle.to_degrees().clamp(0.0, outer),
                outer_deg: outer,
            }
        }
        Kind::Directional => Light::Directional {
            direction,
            color,
            irradiance_w_m2: lux_to_w_per_m2(intensity),
        },
    }
}

/// Fills `soup.lightmap_uvs` by the rule of the module docs; returns whether none is usable
/// (then every UV is (0, 0)).
fn choose_lightmap_uvs(soup: &mut Soup) -> bool {
    let n = soup.primitives;
    let set = if soup.with_set[1] == n {
        Some(1)
    } else if soup.with_set[0] == n && soup.with_set[1] == 0 {
        let inside = soup.sets.iter().all(|s| {
            s[0].is_some_and(|uv| uv.min_element() >= -1e-6 && uv.max_element() <= 1.0 + 1e-6)
        });
        inside.then_some(0)
    } else {
        None
    };
    soup.lightmap_uvs = soup
        .sets
        .iter()
        .map(|s| {
            set.and_then(|k| s[k])
                .unwrap_or(Vec2::ZERO)
                .clamp(Vec2::ZERO, Vec2::ONE)
        })
        .collect();
    set.is_none()
}

/// Welds positions, drops zero-area triangles (with a warning) and computes normals. Returns
/// the mesh (materials unset) and, per mesh triangle, its index in `soup.triangles`.
fn build_mesh(
    path: &Path,
    soup: &Soup,
    rule: NormalRule,
    warnings: &mut Vec<String>,
) -> (Mesh, Vec<usize>) {
    let mut weld: HashMap<[u32; 3], u32> = HashMap::new();
    let mut positions_m = Vec::new();
    let welded: Vec<u32> = soup
        .positions
        .iter()
        .map(|p| {
            *weld
                .entry(p.to_array().map(f32::to_bits))
                .or_insert_with(|| {
                    positions_m.push(*p);
                    (positions_m.len() - 1) as u32
                })
        })
        .collect();
    let (lo, hi) = super::aabb(&positions_m);
    let limit = 2.0 * super::obj::DEGENERATE_RELATIVE_AREA * (hi - lo).as_dvec3().length_squared();
    let mut triangles = Vec::with_capacity(soup.triangles.len());
    let mut kept = Vec::with_capacity(soup.triangles.len());
    for (t, (v, _)) in soup.triangles.iter().enumerate() {
        let [a, b, c] = v.map(|i| soup.positions[i as usize].as_dvec3());
        if (b - a).cross(c - a).length() <= limit {
            continue;
        }
        triangles.push(MeshTriangle {
            position: v.map(|i| welded[i as usize]),
            uv: *v,
            normal: *v,
            material: 0,
        });
        kept.push(t);
    }
    if kept.len() < soup.triangles.len() {
        warnings.push(format!(
            "{}: skipped {} triangle(s) with zero area",
            path.display(),
            soup.triangles.len() - kept.len()
        ));
    }
    let normals = if soup.all_normals {
        soup.normals.clone()
    } else {
        let (normals, index) = crease_normals(&positions_m, &triangles, None, rule);
        for (t, i) in triangles.iter_mut().zip(index) {
            t.normal = i;
        }
        normals
    };
    let mesh = Mesh {
        positions_m,
        uvs: soup.lightmap_uvs.clone(),
        normals,
        triangles,
    };
    (mesh, kept)
}

/// The materials used by the kept triangles (glTF order, then `default`), and each kept
/// triangle's index into them. Albedo textures are attached later ([`resample_textures`]).
fn materials(document: &gltf::Document, soup: &Soup, kept: &[usize]) -> (Vec<Material>, Vec<u32>) {
    let mut index_of: HashMap<Option<usize>, u32> = HashMap::new();
    let mut used: Vec<Option<usize>> = kept.iter().map(|&t| soup.triangles[t].1).collect();
    used.sort_unstable();
    used.dedup();
    let mut out = Vec::new();
    for m in used.iter().flatten() {
        let mat = document.materials().nth(*m);
        let factor = mat
            .as_ref()
            .map_or([1.0; 4], |m| m.pbr_metallic_roughness().base_color_factor());
        let name = mat
            .and_then(|m| m.name().map(str::to_string))
            .unwrap_or_else(|| format!("material{m}"));
        index_of.insert(Some(*m), out.len() as u32);
        out.push(Material {
            name,
            albedo: Albedo::Constant(
                Vec3::new(factor[0], factor[1], factor[2]).clamp(Vec3::ZERO, Vec3::ONE),
            ),
            subsurface: None,
        });
    }
    if used.contains(&None) {
        index_of.insert(None, out.len() as u32);
        out.push(Material {
            name: "default".into(),
            albedo: Albedo::Constant(Vec3::ONE),
            subsurface: None,
        });
    }
    let per_tri = kept
        .iter()
        .map(|&t| index_of[&soup.triangles[t].1])
        .collect();
    (out, per_tri)
}

/// The base-colour textures of the used materials, decoded (sRGB → linear, × factor), with
/// the corner UVs of their set for every kept triangle.
fn textures(
    path: &Path,
    document: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    soup: &Soup,
    kept: &[usize],
    materials: &[Material],
    warnings: &mut Vec<String>,
) -> Result<Vec<PendingTexture>, SceneError> {
    let mut out = Vec::new();
    let dir = path.parent().unwrap_or(Path::new(""));
    for (mi, gm) in document.materials().enumerate() {
        let Some(ours) = materials.iter().position(|m| {
            m.name
                == gm
                    .name()
                    .map_or_else(|| format!("material{mi}"), str::to_string)
        }) else {
            continue;
        };
        let pbr = gm.pbr_metallic_roughness();
        let Some(info) = pbr.base_color_texture() else {
            continue;
        };
        let set = info.tex_coord() as usize;
        let data = decode_image(&info.texture().source(), dir, buffers);
        let img = match data {
            Ok(i) => i.to_rgb32f(),
            Err(e) => {
                warnings.push(format!(
                    "{}: the base colour texture of material `{}` cannot be read ({e}); its \
                     baseColorFactor is used alone",
                    path.display(),
                    materials[ours].name
                ));
                continue;
            }
        };
        if set > 1 || soup.with_set[set] != soup.primitives {
            warnings.push(format!(
                "{}: the base colour texture of material `{}` uses TEXCOORD_{set}, which not every \
                 primitive has; its baseColorFactor is used alone",
                path.display(),
                materials[ours].name
            ));
            continue;
        }
        let factor = Vec3::from_slice(&pbr.base_color_factor()[..3]);
        let texture = AlbedoTexture {
            path: path.to_path_buf(),
            width: img.width(),
            height: img.height(),
            data: img
                .pixels()
                .map(|p| {
                    let s = super::file::srgb_to_linear;
                    Vec3::new(s(p[0]), s(p[1]), s(p[2])) * factor
                })
                .collect(),
        };
        let corner_uvs = kept
            .iter()
            .map(|&t| {
                soup.triangles[t]
                    .0
                    .map(|v| soup.sets[v as usize][set].unwrap_or(Vec2::ZERO))
            })
            .collect();
        out.push(PendingTexture {
            material: ours as u32,
            image: Arc::new(texture),
            corner_uvs,
        });
    }
    Ok(out)
}

/// Decodes a glTF image: from a buffer view, a `data:` URI, or a file beside the glTF.
fn decode_image(
    source: &gltf::Image,
    dir: &Path,
    buffers: &[gltf::buffer::Data],
) -> image::ImageResult<image::DynamicImage> {
    let other = |e: String| image::ImageError::IoError(std::io::Error::other(e));
    match source.source() {
        gltf::image::Source::View { view, .. } => {
            let bytes = buffers
                .get(view.buffer().index())
                .and_then(|b| b.0.get(view.offset()..view.offset() + view.length()))
                .ok_or_else(|| other("the image's buffer view lies outside its buffer".into()))?;
            image::load_from_memory(bytes)
        }
        gltf::image::Source::Uri { uri, .. } if uri.starts_with("data:") => {
            gltf::image::Data::from_source(source.source(), Some(dir), buffers)
                .map_err(|e| other(e.to_string()))
                .and_then(decoded_to_image)
        }
        gltf::image::Source::Uri { uri, .. } => image::open(dir.join(uri)),
    }
}

/// A `gltf` decoded image as an `image` image (8-bit grey, grey-alpha, RGB or RGBA).
fn decoded_to_image(d: gltf::image::Data) -> image::ImageResult<image::DynamicImage> {
    use gltf::image::Format as F;
    let bad = || image::ImageError::IoError(std::io::Error::other("unsupported pixel format"));
    let (w, h, px) = (d.width, d.height, d.pixels);
    Ok(match d.format {
        F::R8 => {
            image::DynamicImage::ImageLuma8(image::GrayImage::from_raw(w, h, px).ok_or_else(bad)?)
        }
        F::R8G8B8 => {
            image::DynamicImage::ImageRgb8(image::RgbImage::from_raw(w, h, px).ok_or_else(bad)?)
        }
        F::R8G8B8A8 => {
            image::DynamicImage::ImageRgba8(image::RgbaImage::from_raw(w, h, px).ok_or_else(bad)?)
        }
        _ => return Err(bad()),
    })
}

/// Bakes each pending texture into a `width × height` image in lightmap space: every texel
/// centre inside a triangle of the texture's material takes the texture's bilinear sample at
/// the barycentrically interpolated texture UV; the material's albedo becomes that image.
pub fn resample_textures(
    mesh: &Mesh,
    materials: &mut [Material],
    textures: &[PendingTexture],
    (width, height): (u32, u32),
) {
    for pending in textures {
        let mut data = vec![Vec3::ZERO; width as usize * height as usize];
        for (t, tri) in mesh.triangles.iter().enumerate() {
            if tri.material != pending.material {
                continue;
            }
            // Texel space: (u·W, (1 − v)·H).
            let p = tri
                .uv
                .map(|i| mesh.uvs[i as usize] * Vec2::new(width as f32, height as f32))
                .map(|q| Vec2::new(q.x, height as f32 - q.y));
            let area = (p[1] - p[0]).perp_dot(p[2] - p[0]);
            if area.abs() < 1e-12 {
                continue;
            }
            let lo = p[0].min(p[1]).min(p[2]).floor().max(Vec2::ZERO);
            let hi = p[0].max(p[1]).max(p[2]).ceil();
            for y in lo.y as u32..(hi.y as u32).min(height) {
                for x in lo.x as u32..(hi.x as u32).min(width) {
                    let c = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                    let b1 = (c - p[0]).perp_dot(p[2] - p[0]) / area;
                    let b2 = (p[1] - p[0]).perp_dot(c - p[0]) / area;
                    let b0 = 1.0 - b1 - b2;
                    if b0.min(b1).min(b2) < -1e-4 {
                        continue;
                    }
                    let [a, b, cc] = pending.corner_uvs[t];
                    let uv = a * b0 + b * b1 + cc * b2;
                    // glTF's default wrap mode repeats the texture.
                    let inside = uv.min_element() >= 0.0 && uv.max_element() <= 1.0;
                    let uv = if inside { uv } else { uv - uv.floor() };
                    data[(y * width + x) as usize] = pending.image.sample(uv);
                }
            }
        }
        let m = &mut materials[pending.material as usize];
        m.albedo = Albedo::Texture(Arc::new(AlbedoTexture {
            path: pending.image.path.clone(),
            width,
            height,
            data,
        }));
    }
}
