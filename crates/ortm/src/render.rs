//! Glue between the bake and the real-time renderer (`passes` crate): converts ortm's scene,
//! texel grid, lights and transfer atlases into `passes::types`, parses the `ortm render`
//! light and camera specifications, frames a default camera, and reads/writes lightmaps as
//! linear OpenEXR files.
//!
//! # Data flow
//! ```text
//! Scene.mesh ──mesh_data──▶ MeshData        (one GPU vertex per distinct position/UV/normal corner)
//! TexelGrid ──albedo_map──▶ AlbedoMap       (ρ per texel; subsurface: effective albedo)
//! Scene.lights / --light ──light_desc──▶ LightDesc
//! AtlasSet ──transfer_inputs──▶ (Vec<AtlasData>, Vec<TransferPiece>)
//!                     passes::Renderer ──▶ TexelImage ──to_lightmap──▶ Lightmap ──write_lightmap_exr──▶ .exr
//! ```
//!
//! # Units and conventions
//! Everything is SI, as in the rest of ortm: positions in metres, point/spot intensity in
//! W/sr, directional irradiance in W/m², lightmaps in radiosity `B = π·L_out` (W/m², linear
//! RGB). Lightmap texel `(x, y)` has its centre at `u = (x+0.5)/W`, `v = 1 − (y+0.5)/H`
//! (row 0 is `v = 1`), identical in `ortm` and `passes`, so no flips happen here. Transfer
//! pieces keep the bake's offset convention (`Δt = (dx, dy)` in texels, `+dy` down).
//!
//! # Lightmap files
//! [`write_lightmap_exr`] writes a single-part scan-line OpenEXR file, channels `R`, `G`, `B`
//! as 32-bit floats (lossless; values are W/m²), data window = display window = the whole
//! `W×H` lightmap, row 0 first. It writes a temporary file in the same directory and renames
//! it, so a crash never leaves a half-written file under the final name.
//! [`read_lightmap_exr`] reads such a file back (any RGB(A) OpenEXR image, first layer).
//!
//! # Limits
//! - The first-order pass uses shadow maps; [`shadow_layers_for`] sizes the layer array
//!   (6 per point light, 1 per spot or directional light).
//! - [`default_camera`] looks along −z at the mesh's bounding sphere (the Cornell box's open
//!   side and the head's face are towards +z); use `--camera` for anything else.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use glam::Vec3;
use passes::display::Camera;
use passes::{AlbedoMap, AtlasData, LightDesc, MeshData, PassError, TexelImage, TransferPiece};

use crate::Lightmap;
use crate::atlas::{ATLAS_INDEX_FILE_NAME, AtlasError, AtlasSet};
use crate::bake::texels::TexelGrid;
use crate::bake_dir::{BakeIndex, INDEX_FILE_NAME};
use crate::maps::{MapsError, TransferMap};
use crate::scene::{Light, Mesh, Scene};

/// Everything that can go wrong in the render glue.
#[derive(Debug, thiserror::Error)]
pub enum RenderError {
    /// A GPU pass failed (no adapter, device lost, invalid input, …); the message says why.
    #[error(transparent)]
    Pass(#[from] PassError),
    /// A `--light`, `--camera` or `--size` value could not be parsed.
    #[error("{what} {spec:?} is invalid: {problem}; expected {syntax}")]
    BadSpec {
        /// Which option (`--light`, `--camera`, `--size`).
        what: &'static str,
        /// The text given.
        spec: String,
        /// What is wrong.
        problem: String,
        /// The accepted syntax.
        syntax: &'static str,
    },
    /// The atlas set is inconsistent (atlas data length, piece outside its atlas or the
    /// lightmap, lightmap size differing from the scene's).
    #[error("atlas set: {problem}; rebuild the atlases with `ortm bin` from this bake")]
    BadAtlas {
        /// What is wrong (names the atlas or piece).
        problem: String,
    },
    /// A lightmap handed to the EXR writer holds the wrong number of texels.
    #[error(
        "lightmap for {}: {width}×{height} but holds {len} texels; build it with Lightmap::new",
        path.display()
    )]
    LightmapLength {
        /// Destination file.
        path: PathBuf,
        /// Width.
        width: u32,
        /// Height.
        height: u32,
        /// Actual data length.
        len: usize,
    },
    /// Writing or reading an OpenEXR lightmap failed.
    #[error(
        "cannot {op} OpenEXR lightmap {}: {source}; check the path (folder exists, writable, \
         enough space) or that the file is a complete RGB OpenEXR image",
        path.display()
    )]
    Exr {
        /// `write` or `read`.
        op: &'static str,
        /// The file.
        path: PathBuf,
        /// The codec's error.
        #[source]
        source: exr::error::Error,
    },
    /// The bake's maps or index could not be read.
    #[error(transparent)]
    Maps(#[from] MapsError),
    /// The atlases could not be built or read.
    #[error(transparent)]
    Atlas(#[from] AtlasError),
    /// The folder is not a bake directory.
    #[error(
        "{} is not a bake directory: it has neither {INDEX_FILE_NAME} nor {ATLAS_INDEX_FILE_NAME}; \
         pass the folder written by `ortm bake` (and optionally `ortm bin`)",
        dir.display()
    )]
    NotABake {
        /// The folder given.
        dir: PathBuf,
    },
    /// The scene given is not the one the bake was made from.
    #[error(
        "the bake in {} was made from a different scene (scene hash {expected}, but `{scene}` \
         at {width}×{height} hashes to {found}); pass the scene file (or `cornell`) used for \
         the bake with --scene",
        dir.display()
    )]
    SceneMismatch {
        /// The bake folder.
        dir: PathBuf,
        /// The scene argument.
        scene: String,
        /// Lightmap width of the bake.
        width: u32,
        /// Lightmap height of the bake.
        height: u32,
        /// Hash stored in the bake index.
        expected: String,
        /// Hash of the scene given.
        found: String,
    },
    /// A file-system operation failed.
    #[error("cannot {op} {}: {source}; check that the folder exists and is writable", path.display())]
    Io {
        /// What was being done.
        op: &'static str,
        /// The path.
        path: PathBuf,
        /// Cause.
        #[source]
        source: std::io::Error,
    },
}

/// Converts the scene mesh (per-corner position, UV and normal indices) into the passes'
/// indexed vertex layout: one vertex per distinct `(position, uv, normal)` index triple, in
/// order of first use, so shared corners stay shared and seams are split.
pub fn mesh_data(mesh: &Mesh) -> MeshData {
    let mut map: HashMap<[u32; 3], u32> = HashMap::new();
    let mut out = MeshData::default();
    out.indices.reserve(mesh.triangles.len() * 3);
    for t in &mesh.triangles {
        for k in 0..3 {
            let key = [t.position[k], t.uv[k], t.normal[k]];
            let next = out.positions_m.len() as u32;
            let ix = *map.entry(key).or_insert_with(|| {
                let get3 = |v: Option<&Vec3>| v.copied().unwrap_or(Vec3::ZERO).to_array();
                out.positions_m
                    .push(get3(mesh.positions_m.get(key[0] as usize)));
                out.lightmap_uvs.push(
                    mesh.uvs
                        .get(key[1] as usize)
                        .copied()
                        .unwrap_or_default()
                        .to_array(),
                );
                out.normals.push(get3(mesh.normals.get(key[2] as usize)));
                next
            });
            out.indices.push(ix);
        }
    }
    out
}

/// The per-texel reflectance ρ of the grid (`TexelGrid::albedo_map`: effective albedo for
/// subsurface materials, 0 on uncovered texels) as the first-order pass's albedo map.
pub fn albedo_map(grid: &TexelGrid) -> AlbedoMap {
    let m = grid.albedo_map();
    AlbedoMap {
        width: m.width,
        height: m.height,
        rgb: m.data,
    }
}

/// One ortm light as a passes light (same units and models; see `ortm::bake::lighting`).
pub fn light_desc(light: &Light) -> LightDesc {
    match *light {
        Light::Point {
            position_m,
            color,
            intensity_w_sr,
        } => LightDesc::Point {
            position_m: position_m.to_array(),
            color: color.to_array(),
            intensity_w_sr,
        },
        Light::Spot {
            position_m,
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
        } => LightDesc::Spot {
            position_m: position_m.to_array(),
            direction: direction.to_array(),
            color: color.to_array(),
            intensity_w_sr,
            inner_deg,
            outer_deg,
        },
        Light::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => LightDesc::Directional {
            direction: direction.to_array(),
            color: color.to_array(),
            irradiance_w_m2,
        },
    }
}

/// Shadow-map layers the first-order pass needs for `lights` (6 per point light, 1 per spot
/// or directional light), at least 1.
pub fn shadow_layers_for(lights: &[Light]) -> u32 {
    lights
        .iter()
        .map(|l| match l {
            Light::Point { .. } => 6,
            Light::Spot { .. } | Light::Directional { .. } => 1,
        })
        .sum::<u32>()
        .max(1)
}

/// The atlases and pieces of `set` as passes inputs, after checking that every atlas holds
/// `atlas_size` texels, every piece lies inside its atlas and the lightmap, and the lightmap
/// size is `lightmap_size`.
pub fn transfer_inputs(
    set: &AtlasSet,
    lightmap_size: (u32, u32),
) -> Result<(Vec<AtlasData>, Vec<TransferPiece>), RenderError> {
    let bad = |problem: String| RenderError::BadAtlas { problem };
    if set.lightmap_size != lightmap_size {
        return Err(bad(format!(
            "made for a {}×{} lightmap but the scene's lightmap is {}×{}",
            set.lightmap_size.0, set.lightmap_size.1, lightmap_size.0, lightmap_size.1
        )));
    }
    let (aw, ah) = set.atlas_size;
    let texels = aw as usize * ah as usize;
    let mut atlases = Vec::with_capacity(set.atlases.len());
    for (i, a) in set.atlases.iter().enumerate() {
        if a.len() != texels {
            return Err(bad(format!(
                "atlas {i} holds {} texels, expected {aw}×{ah} = {texels}",
                a.len()
            )));
        }
        atlases.push(AtlasData {
            width: aw,
            height: ah,
            rgb: a.clone(),
        });
    }
    let (lw, lh) = lightmap_size;
    let inside = |o: u32, len: u32, size: u32| o as u64 + len as u64 <= size as u64;
    let pieces = set
        .pieces
        .iter()
        .enumerate()
        .map(|(i, p)| {
            if p.atlas as usize >= atlases.len()
                || !inside(p.src_x, p.w, aw)
                || !inside(p.src_y, p.h, ah)
                || !inside(p.dst_x, p.w, lw)
                || !inside(p.dst_y, p.h, lh)
            {
                return Err(bad(format!(
                    "piece {i} (map {}, atlas {}, {}×{} from ({}, {}) to ({}, {})) lies outside \
                     its atlas or the lightmap",
                    p.map_index, p.atlas, p.w, p.h, p.src_x, p.src_y, p.dst_x, p.dst_y
                )));
            }
            Ok(TransferPiece {
                atlas: p.atlas,
                src_x: p.src_x,
                src_y: p.src_y,
                w: p.w,
                h: p.h,
                dst_x: p.dst_x,
                dst_y: p.dst_y,
                offset: p.offset,
            })
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((atlases, pieces))
}

/// Where [`load_bake_atlases`] got the atlases from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum AtlasSource {
    /// `atlases.json` and its atlas files (written by `ortm bin`).
    Files,
    /// Packed in memory from the bake's transfer maps.
    PackedFromMaps,
}

/// Atlas side used when a bake has no `atlases.json` (the paper's 1024²).
pub const DEFAULT_ATLAS_SIDE: u32 = 1024;

/// Reads a bake directory for rendering: its `index.json` (if present) and its atlases —
/// from `atlases.json` when `ortm bin` wrote one (checked against the bake key), otherwise
/// packed in memory from the transfer maps at `atlas_side`² (the maps' sizes and checksums
/// are verified on load).
pub fn load_bake_atlases(
    dir: &Path,
    atlas_side: u32,
) -> Result<(Option<BakeIndex>, AtlasSet, AtlasSource), RenderError> {
    let has_index = dir.join(INDEX_FILE_NAME).is_file();
    let has_atlases = dir.join(ATLAS_INDEX_FILE_NAME).is_file();
    if !has_index && !has_atlases {
        return Err(RenderError::NotABake {
            dir: dir.to_owned(),
        });
    }
    let index = if has_index {
        Some(BakeIndex::read(dir)?)
    } else {
        None
    };
    if has_atlases {
        return Ok((
            index,
            crate::atlas::read_atlas_set(dir)?,
            AtlasSource::Files,
        ));
    }
    let index = index.ok_or_else(|| RenderError::NotABake {
        dir: dir.to_owned(),
    })?;
    let maps = index.load_maps(dir)?;
    let set = crate::atlas::build_atlas_set(&maps, atlas_side, atlas_side)?;
    Ok((Some(index), set, AtlasSource::PackedFromMaps))
}

/// The scene argument stored in a bake's settings (`settings.scene`, a string), if the bake
/// recorded one.
pub fn scene_arg_from_settings(index: &BakeIndex) -> Option<String> {
    index
        .settings
        .get("scene")
        .and_then(|v| v.as_str())
        .map(str::to_owned)
}

/// Checks that `scene` (named `scene_arg` in messages) hashes to the bake's `scene_hash`
/// ([`crate::scene::scene_hash`]: geometry, UVs, normals, materials; not the lights).
pub fn check_scene(
    dir: &Path,
    index: &BakeIndex,
    scene: &Scene,
    scene_arg: &str,
) -> Result<(), RenderError> {
    let found = crate::scene::scene_hash(scene);
    if found != index.scene_hash {
        return Err(RenderError::SceneMismatch {
            dir: dir.to_owned(),
            scene: scene_arg.to_owned(),
            width: index.lightmap.width,
            height: index.lightmap.height,
            expected: index.scene_hash.clone(),
            found,
        });
    }
    Ok(())
}

/// Synthetic transfer maps for benchmarks, with the crops a real bake of the same scene
/// would get when every pair of covered texels exchanges light: the map of offset `Δt` is
/// non-zero at receiver `t` exactly when both `t` and `t + Δt` are covered texels of `grid`
/// (value `0.01·ρ(t)/(1 + |Δt|²)`, dimensionless), then cropped by
/// [`TransferMap::from_full`] like a baked map. A real bake's maps are zero where
/// visibility or the kernels vanish, so these are an upper bound on its stored texels (with
/// multiple bounces, nearly tight: the paper's 3 atlases for 50 maps of 256² imply maps
/// filled to ≈ 85 %).
pub fn synthetic_transfer_maps(
    grid: &TexelGrid,
    offsets: &[glam::IVec2],
) -> Result<Vec<TransferMap>, MapsError> {
    let (w, h) = (grid.width, grid.height);
    let albedo = grid.albedo_map();
    let n = offsets.len().max(1) as f64;
    offsets
        .iter()
        .map(|&o| {
            let mut full = Lightmap::new(w, h);
            let k = 0.01 / (1.0 + o.length_squared() as f32);
            for t in &grid.texels {
                if grid.at(t.x as i32 + o.x, t.y as i32 + o.y).is_some() {
                    let rho = albedo.get(t.x, t.y);
                    full.set(t.x, t.y, rho.map(|c| (c * k).max(1e-6)));
                }
            }
            TransferMap::from_full(o, 1.0 / n, k as f64, &full)
        })
        .collect()
}

/// The RGB part of a read-back texel image as a [`Lightmap`] (alpha, the coverage, dropped).
pub fn to_lightmap(img: &TexelImage) -> Lightmap {
    Lightmap {
        width: img.width,
        height: img.height,
        data: img.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    }
}

/// An exposure that maps the 95th percentile of the radiance `L = B/π` over covered texels
/// (alpha > 0) of `lightmap` to 1 (Reinhard 0.5), or 1 when nothing is lit.
///
/// Every covered texel counts, unlit ones (`L ≤ 0`, e.g. a shadowed texel whose subsurface
/// terms cancel to ±1e-9 W/m²) as 0: counting only `L > 0` let rounding noise in the dark
/// texels move the percentile (the blend and compute paths differed by 4 % on the head).
pub fn auto_exposure(lightmap: &TexelImage) -> f32 {
    let mut l: Vec<f32> = lightmap
        .rgba
        .iter()
        .filter(|p| p[3] > 0.0)
        .map(|p| p[0].max(p[1]).max(p[2]) / std::f32::consts::PI)
        .filter(|v| v.is_finite())
        .map(|v| v.max(0.0))
        .collect();
    if l.is_empty() {
        return 1.0;
    }
    let k = ((l.len() - 1) as f64 * 0.95).round() as usize;
    let (_, p95, _) = l.select_nth_unstable_by(k, f32::total_cmp);
    if *p95 > 0.0 { 1.0 / *p95 } else { 1.0 }
}

/// A camera looking along −z at the bounding sphere of `mesh`, from far enough that the
/// sphere fits both the vertical field of view (`fov_y_deg`) and the horizontal one at
/// `aspect` = width/height. Up is +y.
pub fn default_camera(mesh: &Mesh, aspect: f32, fov_y_deg: f32) -> Camera {
    let (centre, radius) = match mesh.bounding_sphere() {
        Some((c, r)) => (c, r.max(1e-3)),
        None => (Vec3::ZERO, 1.0),
    };
    let half_y = (fov_y_deg.to_radians() * 0.5).clamp(1e-3, 1.5);
    let half_x = (half_y.tan() * aspect.max(1e-3)).atan();
    let dist = radius / half_y.min(half_x).sin();
    let eye = centre + Vec3::Z * dist;
    Camera {
        eye: eye.to_array(),
        target: centre.to_array(),
        up: [0.0, 1.0, 0.0],
        fov_y_deg,
        near: (dist - radius).max(dist * 1e-3) * 0.5,
        far: (dist + radius) * 2.0,
    }
}

/// Syntax of `--light` (also the `ortm render --help` text).
pub const LIGHT_SYNTAX: &str = "point:X,Y,Z:INTENSITY_W_SR[:R,G,B] | \
     spot:X,Y,Z:DX,DY,DZ:INTENSITY_W_SR:INNER_DEG,OUTER_DEG[:R,G,B] | \
     dir:DX,DY,DZ:IRRADIANCE_W_M2[:R,G,B] (metres; direction = where the light travels/points)";

/// Syntax of `--camera`.
pub const CAMERA_SYNTAX: &str = "EX,EY,EZ:TX,TY,TZ[:FOV_Y_DEG] (eye and target in metres, up = +y)";

fn floats<const N: usize>(
    part: &str,
    what: &'static str,
    spec: &str,
    syntax: &'static str,
) -> Result<[f32; N], RenderError> {
    let vals: Vec<&str> = part.split(',').collect();
    let err = |problem: String| RenderError::BadSpec {
        what,
        spec: spec.to_owned(),
        problem,
        syntax,
    };
    if vals.len() != N {
        return Err(err(format!(
            "`{part}` has {} comma-separated numbers, expected {N}",
            vals.len()
        )));
    }
    let mut out = [0.0; N];
    for (o, v) in out.iter_mut().zip(vals) {
        *o = v
            .trim()
            .parse::<f32>()
            .ok()
            .filter(|x| x.is_finite())
            .ok_or_else(|| err(format!("`{v}` is not a finite number")))?;
    }
    Ok(out)
}

/// Parses a `--light` specification ([`LIGHT_SYNTAX`]). Directions are normalised; the
/// colour defaults to white. Strengths must be ≥ 0, spot angles `0 ≤ inner ≤ outer < 90`.
pub fn parse_light(spec: &str) -> Result<Light, RenderError> {
    const WHAT: &str = "--light";
    let err = |problem: String| RenderError::BadSpec {
        what: WHAT,
        spec: spec.to_owned(),
        problem,
        syntax: LIGHT_SYNTAX,
    };
    let parts: Vec<&str> = spec.split(':').collect();
    let f1 = |p: &str| floats::<1>(p, WHAT, spec, LIGHT_SYNTAX).map(|v| v[0]);
    let f3 = |p: &str| floats::<3>(p, WHAT, spec, LIGHT_SYNTAX).map(Vec3::from_array);
    let color = |opt: Option<&&str>| -> Result<Vec3, RenderError> {
        match opt {
            None => Ok(Vec3::ONE),
            Some(p) => {
                let c = f3(p)?;
                if c.min_element() < 0.0 {
                    return Err(err(format!("colour `{p}` has a negative channel")));
                }
                Ok(c)
            }
        }
    };
    let strength = |p: &str| -> Result<f32, RenderError> {
        let s = f1(p)?;
        if s < 0.0 {
            return Err(err(format!("strength `{p}` is negative")));
        }
        Ok(s)
    };
    let direction = |p: &str| -> Result<Vec3, RenderError> {
        f3(p)?
            .try_normalize()
            .ok_or_else(|| err(format!("direction `{p}` is the zero vector")))
    };
    let count_ok = |lo: usize, hi: usize| -> Result<(), RenderError> {
        if parts.len() < lo || parts.len() > hi {
            return Err(err(format!(
                "has {} ':'-separated fields, a {} light takes {}..={}",
                parts.len(),
                parts[0],
                lo,
                hi
            )));
        }
        Ok(())
    };
    match parts[0].trim() {
        "point" => {
            count_ok(3, 4)?;
            Ok(Light::Point {
                position_m: f3(parts[1])?,
                intensity_w_sr: strength(parts[2])?,
                color: color(parts.get(3))?,
            })
        }
        "spot" => {
            count_ok(5, 6)?;
            let [inner_deg, outer_deg] = floats::<2>(parts[4], WHAT, spec, LIGHT_SYNTAX)?;
            if !(0.0..90.0).contains(&outer_deg) || !(0.0..=outer_deg).contains(&inner_deg) {
                return Err(err(format!(
                    "cone angles {inner_deg}, {outer_deg} must satisfy 0 ≤ inner ≤ outer < 90"
                )));
            }
            Ok(Light::Spot {
                position_m: f3(parts[1])?,
                direction: direction(parts[2])?,
                intensity_w_sr: strength(parts[3])?,
                inner_deg,
                outer_deg,
                color: color(parts.get(5))?,
            })
        }
        "dir" | "directional" => {
            count_ok(3, 4)?;
            Ok(Light::Directional {
                direction: direction(parts[1])?,
                irradiance_w_m2: strength(parts[2])?,
                color: color(parts.get(3))?,
            })
        }
        other => Err(err(format!(
            "unknown light type `{other}` (use point, spot or dir)"
        ))),
    }
}

/// Parses a `--camera` specification ([`CAMERA_SYNTAX`]); the field of view defaults to
/// `default_fov_deg`. Near and far planes come from the eye–target distance and
/// `scene_radius_m` (the mesh's bounding-sphere radius): `far = dist + 2·radius`,
/// `near = far / 2000`.
pub fn parse_camera(
    spec: &str,
    default_fov_deg: f32,
    scene_radius_m: f32,
) -> Result<Camera, RenderError> {
    const WHAT: &str = "--camera";
    let err = |problem: String| RenderError::BadSpec {
        what: WHAT,
        spec: spec.to_owned(),
        problem,
        syntax: CAMERA_SYNTAX,
    };
    let parts: Vec<&str> = spec.split(':').collect();
    if !(2..=3).contains(&parts.len()) {
        return Err(err(format!(
            "has {} ':'-separated fields, expected 2 or 3",
            parts.len()
        )));
    }
    let eye = Vec3::from_array(floats::<3>(parts[0], WHAT, spec, CAMERA_SYNTAX)?);
    let target = Vec3::from_array(floats::<3>(parts[1], WHAT, spec, CAMERA_SYNTAX)?);
    let fov = match parts.get(2) {
        Some(p) => floats::<1>(p, WHAT, spec, CAMERA_SYNTAX)?[0],
        None => default_fov_deg,
    };
    if !(fov > 0.0 && fov < 180.0) {
        return Err(err(format!("field of view {fov}° must be in (0, 180)")));
    }
    let dir = target - eye;
    if dir.length() <= 0.0 {
        return Err(err("eye and target are the same point".into()));
    }
    if dir.normalize().cross(Vec3::Y).length() < 1e-4 {
        return Err(err(
            "the view direction is vertical (parallel to up = +y); tilt it slightly".into(),
        ));
    }
    let far = dir.length() + 2.0 * scene_radius_m.max(1e-3);
    Ok(Camera {
        eye: eye.to_array(),
        target: target.to_array(),
        up: [0.0, 1.0, 0.0],
        fov_y_deg: fov,
        near: far / 2000.0,
        far,
    })
}

/// Parses `WxH` (e.g. `1280x720`), each side in `1..=16384`.
pub fn parse_size(spec: &str) -> Result<(u32, u32), RenderError> {
    let err = |problem: &str| RenderError::BadSpec {
        what: "--size",
        spec: spec.to_owned(),
        problem: problem.to_owned(),
        syntax: "WIDTHxHEIGHT in pixels, e.g. 1280x720",
    };
    let (w, h) = spec
        .split_once(['x', 'X'])
        .ok_or_else(|| err("no `x` between width and height"))?;
    let p = |s: &str| {
        s.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=16384).contains(v))
            .ok_or_else(|| err("each side must be a whole number in 1..=16384"))
    };
    Ok((p(w)?, p(h)?))
}

/// Writes `map` as a linear RGB f32 OpenEXR file (see the module docs), atomically
/// ([`crate::io::write_atomic`]).
pub fn write_lightmap_exr(path: &Path, map: &Lightmap) -> Result<(), RenderError> {
    let (w, h) = (map.width as usize, map.height as usize);
    if map.data.len() != w * h || w == 0 || h == 0 {
        return Err(RenderError::LightmapLength {
            path: path.to_owned(),
            width: map.width,
            height: map.height,
            len: map.data.len(),
        });
    }
    let exr_err = |source| RenderError::Exr {
        op: "write",
        path: path.to_owned(),
        source,
    };
    let channels =
        exr::prelude::SpecificChannels::rgb(|exr::math::Vec2(x, y): exr::math::Vec2<usize>| {
            let v = map.data[y * w + x];
            (v[0], v[1], v[2])
        });
    let mut bytes = std::io::Cursor::new(Vec::new());
    exr::prelude::WritableImage::write(&exr::prelude::Image::from_channels((w, h), channels))
        .to_buffered(&mut bytes)
        .map_err(exr_err)?;
    crate::io::write_atomic(path, bytes.get_ref()).map_err(|e| exr_err(e.into()))
}

/// Reads the first RGB(A) layer of an OpenEXR file as a lightmap (alpha ignored; a missing
/// alpha channel is fine).
pub fn read_lightmap_exr(path: &Path) -> Result<Lightmap, RenderError> {
    let image = exr::prelude::read_first_rgba_layer_from_file(
        path,
        |size, _| Lightmap::new(size.0 as u32, size.1 as u32),
        |map: &mut Lightmap, pos, (r, g, b, _a): (f32, f32, f32, f32)| {
            map.set(pos.0 as u32, pos.1 as u32, [r, g, b]);
        },
    )
    .map_err(|source| RenderError::Exr {
        op: "read",
        path: path.to_owned(),
        source,
    })?;
    Ok(image.layer_data.channel_data.pixels)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::MeshTriangle;
    use glam::Vec2;

    #[test]
    fn auto_exposure_is_the_95th_percentile_over_covered_texels_and_ignores_dark_noise() {
        // 100 covered texels: 50 dark, 50 lit with L = B/π = 1, …, 50 (max over RGB); 20
        // uncovered ones at 1000. Sorted covered values: 50 zeros, then 1…50; the 95th
        // percentile is element round(99·0.95) = 94, i.e. L = 45.
        let mut img = TexelImage::new(12, 10);
        for (i, p) in img.rgba.iter_mut().enumerate() {
            *p = match i {
                0..50 => [0.0, 0.0, 0.0, 1.0],
                50..100 => {
                    let b = (i - 49) as f32 * std::f32::consts::PI;
                    [0.5 * b, b, 0.25 * b, 1.0]
                }
                _ => [1000.0, 1000.0, 1000.0, 0.0],
            };
        }
        let e = auto_exposure(&img);
        assert!((e - 1.0 / 45.0).abs() < 1e-6, "{e}");
        // Rounding noise of either sign in the dark texels changes nothing (counting only
        // L > 0 gave 1/48 without the noise and 1/45 with positive noise).
        for noise in [1e-9f32, -1e-9] {
            for p in &mut img.rgba[..50] {
                *p = [noise, noise, noise, 1.0];
            }
            assert_eq!(auto_exposure(&img), e, "noise {noise}");
        }
        // Nothing lit → 1.
        let dark = TexelImage::new(4, 4);
        assert_eq!(auto_exposure(&dark), 1.0);
    }

    #[test]
    fn mesh_corners_are_shared_only_when_all_three_indices_agree() {
        // Two triangles sharing positions 0 and 2; the shared edge has one UV seam at
        // position 2 (uv 2 vs uv 3), so 0 is shared and 2 is split.
        let mesh = Mesh {
            positions_m: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            uvs: vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE],
            normals: vec![Vec3::Z],
            triangles: vec![
                MeshTriangle {
                    position: [0, 1, 2],
                    uv: [0, 1, 2],
                    normal: [0; 3],
                    material: 0,
                },
                MeshTriangle {
                    position: [0, 2, 3],
                    uv: [0, 3, 3],
                    normal: [0; 3],
                    material: 0,
                },
            ],
        };
        let d = mesh_data(&mesh);
        d.validate().unwrap();
        assert_eq!(d.positions_m.len(), 5);
        assert_eq!(d.indices, vec![0, 1, 2, 0, 3, 4]);
        // Every corner reproduces the mesh's attributes exactly.
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let v = d.indices[3 * t + k] as usize;
                assert_eq!(
                    d.positions_m[v],
                    mesh.positions_m[tri.position[k] as usize].to_array()
                );
                assert_eq!(d.lightmap_uvs[v], mesh.uvs[tri.uv[k] as usize].to_array());
                assert_eq!(
                    d.normals[v],
                    mesh.normals[tri.normal[k] as usize].to_array()
                );
            }
        }
    }

    #[test]
    fn light_specs_parse_and_bad_ones_say_why() {
        let l = parse_light("point:0.1,0.5,-2:8").unwrap();
        assert_eq!(
            l,
            Light::Point {
                position_m: Vec3::new(0.1, 0.5, -2.0),
                color: Vec3::ONE,
                intensity_w_sr: 8.0
            }
        );
        let Light::Spot {
            direction,
            inner_deg,
            outer_deg,
            color,
            ..
        } = parse_light("spot:0,1,0:0,-2,0:40:20,35:1,0.5,0.25").unwrap()
        else {
            panic!("not a spot")
        };
        assert_eq!(direction, Vec3::NEG_Y);
        assert_eq!((inner_deg, outer_deg), (20.0, 35.0));
        assert_eq!(color, Vec3::new(1.0, 0.5, 0.25));
        let Light::Directional {
            direction,
            irradiance_w_m2,
            ..
        } = parse_light("dir:0,0,-3:20").unwrap()
        else {
            panic!("not directional")
        };
        assert_eq!((direction, irradiance_w_m2), (Vec3::NEG_Z, 20.0));
        for (bad, needle) in [
            ("lamp:0,0,0:1", "unknown light type"),
            ("point:0,0:1", "expected 3"),
            ("point:0,0,0:-1", "negative"),
            ("point:0,0,0:x", "not a finite number"),
            ("dir:0,0,0:5", "zero vector"),
            ("spot:0,0,0:0,-1,0:1:40,30", "inner ≤ outer"),
            ("point:0,0,0", "fields"),
        ] {
            let e = parse_light(bad).unwrap_err().to_string();
            assert!(e.contains(needle), "{bad}: {e}");
            assert!(e.contains("point:X,Y,Z"), "syntax missing: {e}");
        }
    }

    #[test]
    fn camera_and_size_specs() {
        let c = parse_camera("0,1,3:0,1,0", 40.0, 0.5).unwrap();
        assert_eq!(
            (c.eye, c.target, c.fov_y_deg),
            ([0.0, 1.0, 3.0], [0.0, 1.0, 0.0], 40.0)
        );
        assert!(c.near > 0.0 && c.far >= 4.0 && c.near < c.far);
        assert_eq!(
            parse_camera("0,1,3:0,1,0:25", 40.0, 0.5).unwrap().fov_y_deg,
            25.0
        );
        assert!(parse_camera("0,1,0:0,0,0", 40.0, 0.5).is_err());
        assert!(parse_camera("0,0,0:0,0,0", 40.0, 0.5).is_err());
        assert!(parse_camera("0,1,3:0,1,0:180", 40.0, 0.5).is_err());
        assert_eq!(parse_size("640x480").unwrap(), (640, 480));
        assert!(parse_size("640*480").is_err());
        assert!(parse_size("0x480").is_err());
    }

    #[test]
    fn default_camera_sees_the_whole_bounding_sphere() {
        let mesh = Mesh {
            positions_m: vec![Vec3::new(-1.0, 0.0, -2.0), Vec3::new(3.0, 2.0, 0.0)],
            ..Default::default()
        };
        for aspect in [0.5, 1.0, 2.0] {
            let c = default_camera(&mesh, aspect, 40.0);
            let centre = Vec3::new(1.0, 1.0, -1.0);
            let r = (Vec3::new(4.0, 2.0, 2.0)).length() * 0.5;
            assert_eq!(c.target, centre.to_array());
            let d = Vec3::from(c.eye) - centre;
            // Looking along −z, and the sphere's angular radius fits both half-angles.
            assert!(d.x.abs() < 1e-6 && d.y.abs() < 1e-6 && d.z > 0.0);
            let ang = (r / d.length()).asin();
            let half_y = 20f32.to_radians();
            let half_x = (half_y.tan() * aspect).atan();
            assert!(ang <= half_y.min(half_x) + 1e-5, "aspect {aspect}");
            assert!(
                ang >= 0.99 * half_y.min(half_x),
                "not tight, aspect {aspect}"
            );
            assert!(c.near < d.length() - r && c.far > d.length() + r);
        }
    }

    #[test]
    fn exr_lightmap_round_trip_is_exact_and_leaves_no_temporary() {
        let dir = tempfile::tempdir().unwrap();
        let mut m = Lightmap::new(7, 5);
        for (i, v) in m.data.iter_mut().enumerate() {
            let f = i as f32;
            *v = [f * 1.25e-3, -f, 1e-7 * f + 3.0];
        }
        let p = dir.path().join("final.exr");
        write_lightmap_exr(&p, &m).unwrap();
        assert_eq!(read_lightmap_exr(&p).unwrap(), m);
        let names: Vec<_> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name())
            .collect();
        assert_eq!(names, vec![std::ffi::OsString::from("final.exr")]);
        // Malformed input and missing folders are errors, not panics.
        let bad = Lightmap {
            width: 3,
            height: 3,
            data: vec![[0.0; 3]; 4],
        };
        assert!(matches!(
            write_lightmap_exr(&p, &bad),
            Err(RenderError::LightmapLength { .. })
        ));
        assert!(write_lightmap_exr(&dir.path().join("no/such/dir/x.exr"), &m).is_err());
        assert!(read_lightmap_exr(&dir.path().join("missing.exr")).is_err());
    }

    #[test]
    fn synthetic_maps_are_non_zero_exactly_where_receiver_and_sender_are_covered() {
        let scene = crate::scene::cornell_box(32);
        let grid = TexelGrid::build(&scene).unwrap();
        let offsets = [
            glam::IVec2::ZERO,
            glam::IVec2::new(5, -3),
            glam::IVec2::new(-31, 31),
        ];
        let maps = synthetic_transfer_maps(&grid, &offsets).unwrap();
        for (m, o) in maps.iter().zip(offsets) {
            assert_eq!(m.offset, o);
            for y in 0..32 {
                for x in 0..32 {
                    let both = grid.at(x, y).is_some() && grid.at(x + o.x, y + o.y).is_some();
                    let v = m.value_at(x as u32, y as u32);
                    assert_eq!(v.iter().all(|c| *c > 0.0), both, "({x}, {y}) offset {o}");
                    assert_eq!(v.iter().any(|c| *c != 0.0), both, "({x}, {y}) offset {o}");
                }
            }
        }
        // The zero offset covers every covered texel; the far corner offset almost nothing.
        assert!(maps[0].stored_texels() as usize >= grid.texels.len());
        assert!(maps[2].stored_texels() < maps[1].stored_texels());
    }

    #[test]
    fn auto_exposure_maps_the_95th_percentile_to_one() {
        let mut img = TexelImage::new(100, 1);
        for (i, p) in img.rgba.iter_mut().enumerate() {
            let b = (i + 1) as f32 * std::f32::consts::PI;
            *p = [b, 0.5 * b, 0.0, 1.0];
        }
        // An uncovered texel, however bright, does not count.
        img.rgba[0] = [1e9, 1e9, 1e9, 0.0];
        // Covered L values are 2..=100; the 95th percentile of those 99 values is index 93 → 95.
        let e = auto_exposure(&img);
        assert!((e - 1.0 / 95.0).abs() < 1e-6, "{e}");
        assert_eq!(auto_exposure(&TexelImage::new(4, 4)), 1.0);
    }
}
