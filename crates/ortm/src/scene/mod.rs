//! The scene: a triangle mesh with a lightmap UV layout, its materials and its lights.
//!
//! Everything here is in SI units: positions in metres (a scene file's `metres_per_unit`
//! has already been applied), radiant intensity in W/sr, irradiance in W/m².
//!
//! Scenes come from a TOML scene file ([`file`](mod@file), format in `docs/scene-format.md`) or are
//! built in code ([`cornell`], [`maze`]; their charts by [`charts`]). Meshes are read from OBJ by [`obj`], which validates them.
//! Lights and their one text form (`--light`) live in [`light`].
//! Named subsurface coefficient sets live in [`presets`], the profile they define in
//! [`subsurface`]; all loading errors are
//! [`SceneError`]s (file, problem, fix).

pub mod charts;
pub mod cornell;
mod error;
pub mod file;
pub mod head;
pub mod light;
pub mod maze;
pub mod obj;
pub mod presets;
pub mod subsurface;

use std::io::Read;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use glam::{Vec2, Vec3};
use sha2::{Digest, Sha256};

pub use cornell::cornell_box;
pub use error::{AtLine, SceneError};
pub use file::{load_scene, load_scene_with_warnings};
pub use light::Light;
pub use maze::maze;
pub use obj::load_obj;
pub use presets::subsurface_preset;

/// A triangle mesh in metres with per-corner lightmap UVs and smooth normals.
#[derive(Clone, Debug, Default)]
pub struct Mesh {
    /// Vertex positions in metres.
    pub positions_m: Vec<Vec3>,
    /// Lightmap UVs in `[0, 1]²` (v up: v = 1 is image row 0).
    pub uvs: Vec<Vec2>,
    /// Unit shading normals (smooth; computed from the faces when the file has none).
    pub normals: Vec<Vec3>,
    /// Triangles (quads and polygons are fan-triangulated on load).
    pub triangles: Vec<MeshTriangle>,
}

impl Mesh {
    /// Axis-aligned bounding box `(lo, hi)` of the positions, metres (`(+∞, −∞)` when there are
    /// none).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        aabb(&self.positions_m)
    }

    /// The sphere around [`Mesh::bounds`]: the box's centre and half its diagonal, metres;
    /// `None` when the box is not finite (no positions).
    pub fn bounding_sphere(&self) -> Option<(Vec3, f32)> {
        let (lo, hi) = self.bounds();
        (lo.is_finite() && hi.is_finite()).then(|| ((lo + hi) * 0.5, (hi - lo).length() * 0.5))
    }
}

/// Axis-aligned bounding box `(lo, hi)` of `points` (`(+∞, −∞)` when empty).
pub(crate) fn aabb(points: &[Vec3]) -> (Vec3, Vec3) {
    points.iter().fold(
        (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY)),
        |(lo, hi), p| (lo.min(*p), hi.max(*p)),
    )
}

/// One triangle: indices into the mesh's position, UV and normal arrays, and its material.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct MeshTriangle {
    /// Indices into [`Mesh::positions_m`], counter-clockwise seen from the front.
    pub position: [u32; 3],
    /// Indices into [`Mesh::uvs`].
    pub uv: [u32; 3],
    /// Indices into [`Mesh::normals`].
    pub normal: [u32; 3],
    /// Index into [`Scene::materials`].
    pub material: u32,
}

/// Diffuse albedo ρ (linear RGB, each channel in `[0, 1]`).
#[derive(Clone, Debug)]
pub enum Albedo {
    /// One colour for the whole material.
    Constant(Vec3),
    /// An image texture sampled (bilinearly) at the lightmap UV.
    Texture(Arc<AlbedoTexture>),
}

/// A linear-RGB albedo image; row 0 is v = 1.
#[derive(Clone, Debug)]
pub struct AlbedoTexture {
    /// Where it was read from (for messages).
    pub path: PathBuf,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// Linear RGB, row-major.
    pub data: Vec<Vec3>,
}

impl AlbedoTexture {
    /// Bilinear sample at lightmap UV `uv` (texel centres at `((x+0.5)/W, 1−(y+0.5)/H)`,
    /// clamped at the borders). Returns black for an empty or inconsistent image.
    pub fn sample(&self, uv: Vec2) -> Vec3 {
        let (w, h) = (self.width as usize, self.height as usize);
        if w == 0 || h == 0 || self.data.len() != w * h {
            return Vec3::ZERO;
        }
        let x = (uv.x * self.width as f32 - 0.5).clamp(0.0, (w - 1) as f32);
        let y = ((1.0 - uv.y) * self.height as f32 - 0.5).clamp(0.0, (h - 1) as f32);
        let (x0, y0) = (x.floor() as usize, y.floor() as usize);
        let (x1, y1) = ((x0 + 1).min(w - 1), (y0 + 1).min(h - 1));
        let (fx, fy) = (x - x0 as f32, y - y0 as f32);
        let at = |xx: usize, yy: usize| self.data[yy * w + xx];
        let top = at(x0, y0).lerp(at(x1, y0), fx);
        let bottom = at(x0, y1).lerp(at(x1, y1), fx);
        top.lerp(bottom, fy)
    }
}

impl Albedo {
    /// The albedo at lightmap UV `uv` (constant, or a bilinear texture sample).
    pub fn at(&self, uv: Vec2) -> Vec3 {
        match self {
            Albedo::Constant(c) => *c,
            Albedo::Texture(t) => t.sample(uv),
        }
    }
}

/// Which subsurface profile a translucent material uses.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum SubsurfaceModel {
    /// Jensen et al. 2001 dipole diffusion profile R_d(r).
    Dipole,
    /// A normalised exponential falloff `R_d(r) = ρ·e^{−r/ℓ}/(2πℓ²)` with mean free path
    /// ℓ = 1/σ_tr (from the same coefficients), matched to the dipole's total reflectance.
    Exponential,
}

/// Subsurface scattering coefficients (Jensen et al. 2001 notation), per RGB channel.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Subsurface {
    /// Absorption coefficient σ_a in mm⁻¹.
    pub sigma_a_per_mm: Vec3,
    /// Reduced scattering coefficient σ_s' in mm⁻¹.
    pub sigma_s_prime_per_mm: Vec3,
    /// Relative index of refraction η.
    pub eta: f32,
    /// Profile.
    pub model: SubsurfaceModel,
}

/// A surface material.
#[derive(Clone, Debug)]
pub struct Material {
    /// Name (from the scene file or the OBJ's `usemtl`).
    pub name: String,
    /// Diffuse albedo ρ for opaque surfaces. For subsurface materials the effective albedo is
    /// the profile's total diffuse reflectance and this field is ignored by the transport.
    pub albedo: Albedo,
    /// `Some` for translucent (subsurface-scattering) materials.
    pub subsurface: Option<Subsurface>,
}

/// A complete scene ready for baking.
#[derive(Clone, Debug)]
pub struct Scene {
    /// Display name (`cornell`, or the scene file's stem).
    pub name: String,
    /// The mesh, in metres.
    pub mesh: Mesh,
    /// Materials referenced by [`MeshTriangle::material`].
    pub materials: Vec<Material>,
    /// Lights used by default (bakes do not depend on them; previews and renders do).
    pub lights: Vec<Light>,
    /// Lightmap size (width, height) in texels.
    pub lightmap_size: (u32, u32),
    /// Allow overlapping lightmap UVs (overlaps are otherwise an error).
    pub allow_uv_overlap: bool,
}

/// A stable hash (SHA-256, 64 lower-case hex digits) of everything in the scene that a bake
/// depends on: geometry, UVs, normals, triangles, materials, `allow_uv_overlap`; not the lights
/// nor the lightmap size (the bake key adds its settings). A bake stores it and rendering
/// checks a scene against it.
pub fn scene_hash(scene: &Scene) -> String {
    let mut h = Sha256::new();
    let m = &scene.mesh;
    for p in &m.positions_m {
        for c in p.to_array() {
            h.update(c.to_le_bytes());
        }
    }
    for uv in &m.uvs {
        h.update(uv.x.to_le_bytes());
        h.update(uv.y.to_le_bytes());
    }
    for n in &m.normals {
        for c in n.to_array() {
            h.update(c.to_le_bytes());
        }
    }
    for t in &m.triangles {
        for k in 0..3 {
            h.update(t.position[k].to_le_bytes());
            h.update(t.uv[k].to_le_bytes());
            h.update(t.normal[k].to_le_bytes());
        }
        h.update(t.material.to_le_bytes());
    }
    h.update(format!("{:?}", scene.materials).as_bytes());
    h.update(format!("{}", scene.allow_uv_overlap).as_bytes());
    crate::io::hex(&h.finalize())
}

/// Reads a whole text file, refusing files larger than `limit` bytes before reading and
/// reporting invalid UTF-8 with its line. `what` names the file's role in messages.
pub(crate) fn read_text_bounded(
    path: &Path,
    what: &'static str,
    limit: u64,
) -> Result<String, SceneError> {
    let io_err = |source: std::io::Error| {
        if source.kind() == std::io::ErrorKind::NotFound {
            SceneError::NotFound {
                what,
                path: path.to_path_buf(),
            }
        } else {
            SceneError::Io {
                what,
                path: path.to_path_buf(),
                source,
            }
        }
    };
    // Never blocks: a FIFO, device or directory is refused from its metadata, with its kind.
    let (file, meta) = crate::io::open_regular(path).map_err(io_err)?;
    let size = meta.len();
    if size > limit {
        return Err(SceneError::TooLarge {
            what,
            path: path.to_path_buf(),
            size,
            limit,
        });
    }
    let mut bytes = Vec::with_capacity(size as usize);
    file.take(limit + 1)
        .read_to_end(&mut bytes)
        .map_err(io_err)?;
    if bytes.len() as u64 > limit {
        return Err(SceneError::TooLarge {
            what,
            path: path.to_path_buf(),
            size: bytes.len() as u64,
            limit,
        });
    }
    String::from_utf8(bytes).map_err(|e| {
        let valid = &e.as_bytes()[..e.utf8_error().valid_up_to()];
        SceneError::NotUtf8 {
            what,
            path: path.to_path_buf(),
            line: 1 + valid.iter().filter(|&&b| b == b'\n').count(),
        }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn texture_sample_hits_texel_centres_and_interpolates() {
        // 2×2 image: row 0 (v = 1) red, green; row 1 (v = 0) blue, white.
        let t = AlbedoTexture {
            path: PathBuf::from("t.png"),
            width: 2,
            height: 2,
            data: vec![Vec3::X, Vec3::Y, Vec3::Z, Vec3::ONE],
        };
        // Texel centres reproduce the texel values exactly.
        assert_eq!(t.sample(Vec2::new(0.25, 0.75)), Vec3::X);
        assert_eq!(t.sample(Vec2::new(0.75, 0.75)), Vec3::Y);
        assert_eq!(t.sample(Vec2::new(0.25, 0.25)), Vec3::Z);
        assert_eq!(t.sample(Vec2::new(0.75, 0.25)), Vec3::ONE);
        // The centre of the image is the mean of the four texels.
        let mean = (Vec3::X + Vec3::Y + Vec3::Z + Vec3::ONE) / 4.0;
        assert!((t.sample(Vec2::splat(0.5)) - mean).length() < 1e-6);
        // Outside the centres the border value is held.
        assert_eq!(t.sample(Vec2::new(0.0, 1.0)), Vec3::X);
        assert_eq!(
            Albedo::Texture(Arc::new(t)).at(Vec2::new(1.0, 0.0)),
            Vec3::ONE
        );
    }

    #[test]
    fn read_text_bounded_reports_size_and_utf8_line() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("x.txt");
        std::fs::write(&p, b"ok\nok\nbad \xff here\n").unwrap();
        match read_text_bounded(&p, "test file", 1 << 20) {
            Err(SceneError::NotUtf8 { line, .. }) => assert_eq!(line, 3),
            other => panic!("expected NotUtf8, got {other:?}"),
        }
        match read_text_bounded(&p, "test file", 4) {
            Err(SceneError::TooLarge { size, limit, .. }) => {
                assert_eq!((size, limit), (17, 4));
            }
            other => panic!("expected TooLarge, got {other:?}"),
        }
        let missing = dir.path().join("nope.txt");
        let err = read_text_bounded(&missing, "test file", 10).unwrap_err();
        assert!(matches!(err, SceneError::NotFound { .. }));
        assert!(err.to_string().contains("nope.txt"));
    }
}
