//! First-order pass: the mesh rasterised by its lightmap UVs into a `W×H` RGBA32F target,
//! `B_o = ρ·E` per covered texel with shadow maps; `shaders/first_order.wgsl` (+
//! `shaders/lights.wgsl`), mirror [`crate::cpu::first_order`].
//!
//! # Data flow
//! Once: [`FirstOrderPass::new`] builds the pipelines; [`FirstOrderPass::prepare_mesh`]
//! takes the uploaded mesh ([`GpuMesh`]: interleaved [`Vertex`], plus positions alone for
//! the shadow pass), uploads the albedo map, allocates the shadow-map array and the output,
//! and rasterises the mesh once by its UVs into a texel G-buffer (interpolated world position
//! and coverage, interpolated normal and the texel's world area; two RGBA32F maps, `N×` the
//! lightmap's size with an averaged input, below). Per frame: [`FirstOrderPass::encode`] writes the lights
//! ([`GpuLight`]) and one view-projection matrix per shadow layer ([`shadow_layers`]),
//! renders every shadow layer (depth only), then the lightmap as one full-screen triangle:
//! per texel the G-buffer's position and normal, `E = Σ_lights E_light·visibility`, output
//! `(ρ·E, 1)` (`0` where the G-buffer says uncovered). Deferring to a G-buffer gives the
//! same values as shading while rasterising the mesh (same interpolants, stored in f32)
//! but shades each texel once: rasterising 17k small triangles into 256² shades partial
//! 4×4 blocks many times over on a software rasteriser.
//!
//! # Averaged input ([`FirstOrderOptions::samples`] `N > 1`, odd)
//! The transfer multiplies each sender's first order, and a sender stands for its whole
//! square: where the light changes within a texel (a shadow's edge, a lamp beside a wall) the
//! centre's value is the wrong sample. With `N > 1` the G-buffer is rasterised at `N×` the
//! lightmap's size (odd `N`: a texel's centre is its middle sub-texel's, so coverage is
//! unchanged) with each sub-texel's world area in `normal.w` (`|∂P/∂x × ∂P/∂y|` from the
//! position's derivatives, constant per triangle), and `fs_lightmap_averaged` writes two
//! targets per texel: the **transfer's input** ([`FirstOrderScene::transfer_input`]) `ρ · Σ
//! a_s E_s / Σ a_s` over the covered sub-texels, and the **first order**
//! ([`FirstOrderScene::output`]) — the centre's `ρ·E` on opaque texels (what a texel's own
//! light is, as the path-traced reference defines it), the average on translucent ones
//! ([`FirstOrderPass::set_translucent`], the albedo texture's alpha: their transfer holds
//! `−B_in` at the texel itself, so their final is the scattered average). The transfer's
//! pieces and the pyramid read the input and its final starts from the first order
//! ([`crate::transfer::TransferInputs::base`]): `final = first order + T(input) − input`.
//! Cost: `N² + 1` shadowed irradiance evaluations per texel instead of one.
//!
//! # Lights (SI units)
//! Point/spot `E = I·cosθ/d²` (spot × `smoothstep(cos outer, cos inner, cos α)`),
//! directional `E = E⊥·cosθ`; `θ` against the interpolated, renormalised vertex normal.
//! Irradiance in W/m², `B_o` in W/m² (radiosity).
//!
//! # Shadow maps
//! One `Depth32Float` 2D array of `shadow_map_size²` layers shared by all lights:
//! - point light outside the mesh's bounding sphere (×1.05; [`point_cone`]): 1 perspective
//!   layer whose cone just contains the sphere, `near`/`far` at the sphere's extent — the
//!   mesh fills the map instead of a corner of one cube face, and one depth pass replaces six;
//! - point light inside it: 6 layers, 90° perspective faces in the order +X, −X, +Y, −Y, +Z,
//!   −Z; the lookup picks the face by the major axis (a cube map without cube-map
//!   conventions);
//! - spot light: 1 perspective layer, half-angle = outer angle + 1° (≤ 89°);
//! - directional light: 1 orthographic layer fitted to the mesh's bounding sphere.
//!
//! Cube faces and spot maps use `far` = 1.01 × the distance to the farthest corner of the mesh's
//! bounding box and `near = far/1000`; geometry nearer than `near` to a light casts no
//! shadow. Biases: lookups are offset along the normal by
//! [`FirstOrderOptions::normal_offset_texels`] shadow texels (world size of a texel at that
//! distance), and the depth pass adds a slope-scaled bias
//! ([`FirstOrderOptions::slope_bias`]); comparisons use 2×2 hardware PCF (linear comparison
//! sampler). Defaults (2048², 1.5 texels, slope 2.0) remove acne on surfaces lit at up to
//! ~80° from the normal and keep peter-panning under ~2 shadow texels.
//!
//! Shadow maps are re-rendered only when a light's layer matrices change (the mesh is
//! static); [`FirstOrderScene::invalidate_shadow_maps`] forces a re-render.
//!
//! # Conventions
//! Clip position of a vertex is `(2u − 1, 2v − 1)`: `v = 1` is row 0, so framebuffer pixel
//! `(x, y)` is lightmap texel `(x, y)` and the rasteriser's pixel-centre rule covers a texel
//! exactly when its centre `((x+0.5)/W, 1 − (y+0.5)/H)` lies in a UV triangle (ties on
//! shared edges go to one triangle by the top-left rule). Alpha: 1 covered, 0 not.
//!
//! # Limits
//! Overlapping UV triangles: the last drawn wins. One `encode` per submit (light data is
//! written with `Queue::write_buffer`). At most [`FirstOrderOptions::max_shadow_layers`]
//! layers (a point light takes 6); lights and layer matrices are uniform arrays of that many
//! entries, so it is also bounded by the device's uniform-binding size (80 bytes per entry:
//! 819 layers at the 64 KiB minimum).

use bytemuck::{Pod, Zeroable};
use glam::camera::rh::proj::directx as proj_dx;
use glam::camera::rh::view::look_to_mat4;
use glam::{Mat4, Vec3};

use crate::error::PassError;
use crate::gpu::Gpu;
use crate::mesh::GpuMesh;
use crate::types::{AlbedoMap, LightDesc, MeshData};
use crate::util;

/// Light kind codes; must match `LIGHT_*` in `shaders/lights.wgsl`.
pub const LIGHT_POINT: u32 = 0;
/// Spot light code.
pub const LIGHT_SPOT: u32 = 1;
/// Directional light code.
pub const LIGHT_DIRECTIONAL: u32 = 2;

/// Settings fixed at creation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FirstOrderOptions {
    /// Side of every shadow-map layer in texels.
    pub shadow_map_size: u32,
    /// Layers in the shadow-map array (6 per point light, 1 per spot/directional light).
    pub max_shadow_layers: u32,
    /// Normal offset of shadow lookups, in shadow texels.
    pub normal_offset_texels: f32,
    /// Slope-scaled depth bias of the shadow pass.
    pub slope_bias: f32,
    /// How the lighting pass reads the albedo and G-buffer textures; `None` =
    /// [`Gpu::best_texel_reads`] (same values either way, see [`util::TexelReads`]).
    pub texel_reads: Option<util::TexelReads>,
    /// Sub-texels per texel side (odd, 1–[`MAX_SAMPLES`]): with `N > 1` the transfer's input
    /// is the first order averaged over each texel's square ("Averaged input" in the module
    /// docs); 1 takes it at the centres.
    pub samples: u32,
}

/// The largest [`FirstOrderOptions::samples`].
pub const MAX_SAMPLES: u32 = 7;

impl Default for FirstOrderOptions {
    fn default() -> Self {
        Self {
            shadow_map_size: 2048,
            max_shadow_layers: 16,
            normal_offset_texels: 1.5,
            slope_bias: 2.0,
            texel_reads: None,
            samples: 1,
        }
    }
}

/// Interleaved mesh vertex. 32 bytes.
/// Must match `VertexIn` in `shaders/first_order.wgsl` (and `display.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct Vertex {
    /// Position in metres.
    pub position: [f32; 3],
    /// Unit normal.
    pub normal: [f32; 3],
    /// Lightmap UV.
    pub uv: [f32; 2],
}

/// The vertex buffer layout of [`Vertex`] (locations 0, 1, 2).
pub fn vertex_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRS: [wgpu::VertexAttribute; 3] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x2];
    wgpu::VertexBufferLayout {
        array_stride: std::mem::size_of::<Vertex>() as u64,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRS,
    }
}

/// The shadow pass's vertex buffer layout: positions only (`[f32; 3]`, metres, location 0).
pub fn position_layout() -> wgpu::VertexBufferLayout<'static> {
    const ATTRS: [wgpu::VertexAttribute; 1] = wgpu::vertex_attr_array![0 => Float32x3];
    wgpu::VertexBufferLayout {
        array_stride: 12,
        step_mode: wgpu::VertexStepMode::Vertex,
        attributes: &ATTRS,
    }
}

/// A light as the shaders see it. 80 bytes.
/// Must match `GpuLight` in `shaders/lights.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    /// xyz position (m).
    pub position: [f32; 4],
    /// xyz unit spot axis or travel direction.
    pub direction: [f32; 4],
    /// rgb color·strength.
    pub radiance: [f32; 4],
    /// cos outer, cos inner, shadow texel per metre (perspective), shadow texel (m, ortho).
    pub cone: [f32; 4],
    /// `LIGHT_*` code.
    pub kind: u32,
    /// First shadow layer.
    pub first_layer: u32,
    /// Number of shadow layers.
    pub layer_count: u32,
    /// Padding.
    pub _pad: u32,
}

/// Uniform of `first_order.wgsl`. 32 bytes. Must match `Params` there.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct FirstOrderParams {
    /// Lightmap `[W, H]`.
    pub lightmap_size: [u32; 2],
    /// Number of valid entries in the light buffer.
    pub light_count: u32,
    /// Shadow-map side in texels.
    pub shadow_size: u32,
    /// Normal offset in shadow texels.
    pub normal_offset_texels: f32,
    /// Padding.
    pub _pad: [f32; 3],
}

/// Axis-aligned bounds of the mesh (m).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds {
    /// Minimum corner.
    pub min: Vec3,
    /// Maximum corner.
    pub max: Vec3,
}

impl Bounds {
    /// Bounds of a point set (`[0, 0]` box if empty).
    pub fn of(points: &[[f32; 3]]) -> Self {
        let mut min = Vec3::splat(f32::INFINITY);
        let mut max = Vec3::splat(f32::NEG_INFINITY);
        for p in points {
            min = min.min(Vec3::from(*p));
            max = max.max(Vec3::from(*p));
        }
        if points.is_empty() {
            min = Vec3::ZERO;
            max = Vec3::ZERO;
        }
        Self { min, max }
    }

    /// Centre and radius of the bounding sphere through the corners (radius ≥ 1 mm).
    pub fn sphere(&self) -> (Vec3, f32) {
        let c = 0.5 * (self.min + self.max);
        (c, (0.5 * (self.max - self.min).length()).max(1e-3))
    }

    /// Whether `p` lies in the box (boundary included).
    pub fn contains(&self, p: Vec3) -> bool {
        p.cmpge(self.min).all() && p.cmple(self.max).all()
    }

    /// Largest distance from `p` to a corner.
    pub fn farthest_corner(&self, p: Vec3) -> f32 {
        let mut d: f32 = 0.0;
        for i in 0..8 {
            let c = Vec3::new(
                if i & 1 == 0 { self.min.x } else { self.max.x },
                if i & 2 == 0 { self.min.y } else { self.max.y },
                if i & 4 == 0 { self.min.z } else { self.max.z },
            );
            d = d.max(c.distance(p));
        }
        d
    }
}

/// Forward directions of the point-light faces, +X, −X, +Y, −Y, +Z, −Z (must match
/// `cube_face` in `shaders/first_order.wgsl`).
pub fn point_face_dirs() -> [Vec3; 6] {
    [
        Vec3::X,
        Vec3::NEG_X,
        Vec3::Y,
        Vec3::NEG_Y,
        Vec3::Z,
        Vec3::NEG_Z,
    ]
}

/// An up vector not parallel to `dir`.
fn up_for(dir: Vec3) -> Vec3 {
    if dir.y.abs() > 0.9 { Vec3::Z } else { Vec3::Y }
}

/// Margin on the bounding-sphere radius of a point light's single shadow cone (covers the
/// normal offset of lookups near the silhouette).
const POINT_CONE_MARGIN: f32 = 1.05;

/// For a point light at `p` outside the mesh's (margined) bounding sphere: the axis, the
/// half-angle (radians) of the cone that just contains the sphere, and `near`, `far` (m) of
/// the perspective map along that cone. `None` when the light is inside or too close (the
/// cone would be wider than 2·75°): then it takes six 90° faces.
pub fn point_cone(p: Vec3, bounds: &Bounds) -> Option<(Vec3, f32, f32, f32)> {
    let (c, r) = bounds.sphere();
    let r = r * POINT_CONE_MARGIN;
    let to_c = c - p;
    let d = to_c.length();
    if d <= r {
        return None;
    }
    let half = (r / d).asin();
    if half > 75f32.to_radians() {
        return None;
    }
    let far = d + r;
    let near = (d - r).max(far * 1e-3);
    Some((to_c / d, half, near, far))
}

/// The shader record of a light and its shadow layers' view-projection matrices
/// (`first_layer` filled in by the caller).
pub fn shadow_layers(
    light: &LightDesc,
    bounds: &Bounds,
    shadow_size: u32,
) -> (GpuLight, Vec<Mat4>) {
    let size = shadow_size.max(1) as f32;
    match *light {
        LightDesc::Point {
            position_m,
            color,
            intensity_w_sr,
        } => point_layers(
            Vec3::from(position_m),
            (Vec3::from(color) * intensity_w_sr).extend(0.0).into(),
            bounds,
            size,
        ),
        LightDesc::Spot {
            position_m,
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
        } => spot_layers(
            Vec3::from(position_m),
            Vec3::from(direction).normalize(),
            (Vec3::from(color) * intensity_w_sr).extend(0.0).into(),
            [inner_deg, outer_deg],
            bounds,
            size,
        ),
        LightDesc::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => directional_layers(
            Vec3::from(direction).normalize(),
            (Vec3::from(color) * irradiance_w_m2).extend(0.0).into(),
            bounds,
            size,
        ),
    }
}

/// A point light at `p` of `radiance` (`I·colour`, W/sr): one cone layer from outside the
/// bounding sphere, else six 90° cube faces.
fn point_layers(p: Vec3, radiance: [f32; 4], bounds: &Bounds, size: f32) -> (GpuLight, Vec<Mat4>) {
    if let Some((dir, half, near, far)) = point_cone(p, bounds) {
        // Outside the bounding sphere: one perspective layer whose cone just
        // contains the sphere sees every surface the light can reach.
        let proj = proj_dx::perspective(2.0 * half, 1.0, near, far);
        let g = GpuLight {
            position: [p.x, p.y, p.z, 0.0],
            radiance,
            cone: [-2.0, -1.0, 2.0 * half.tan() / size, 0.0],
            kind: LIGHT_POINT,
            layer_count: 1,
            ..Default::default()
        };
        return (g, vec![proj * look_to_mat4(p, dir, up_for(dir))]);
    }
    let far = bounds.farthest_corner(p) * 1.01 + 1e-3;
    let near = (far * 1e-3).max(1e-5);
    let proj = proj_dx::perspective(std::f32::consts::FRAC_PI_2, 1.0, near, far);
    let mats = point_face_dirs()
        .iter()
        .map(|&d| proj * look_to_mat4(p, d, up_for(d)))
        .collect();
    let g = GpuLight {
        position: [p.x, p.y, p.z, 0.0],
        radiance,
        cone: [-2.0, -1.0, 2.0 / size, 0.0],
        kind: LIGHT_POINT,
        layer_count: 6,
        ..Default::default()
    };
    (g, mats)
}

/// A spot light at `p` aiming along unit `d`, `[inner, outer]` cone angles in degrees: one
/// perspective layer of half-angle `outer + 1°` (≤ 89°).
fn spot_layers(
    p: Vec3,
    d: Vec3,
    radiance: [f32; 4],
    [inner_deg, outer_deg]: [f32; 2],
    bounds: &Bounds,
    size: f32,
) -> (GpuLight, Vec<Mat4>) {
    let far = bounds.farthest_corner(p) * 1.01 + 1e-3;
    let near = (far * 1e-3).max(1e-5);
    let half = (outer_deg + 1.0).min(89.0).to_radians();
    let proj = proj_dx::perspective(2.0 * half, 1.0, near, far);
    let g = GpuLight {
        position: [p.x, p.y, p.z, 0.0],
        direction: d.extend(0.0).into(),
        radiance,
        // cos inner is kept above cos outer so smoothstep is defined.
        cone: [
            outer_deg.to_radians().cos(),
            inner_deg
                .to_radians()
                .cos()
                .max(outer_deg.to_radians().cos() + 1e-6),
            2.0 * half.tan() / size,
            0.0,
        ],
        kind: LIGHT_SPOT,
        layer_count: 1,
        ..Default::default()
    };
    (g, vec![proj * look_to_mat4(p, d, up_for(d))])
}

/// A directional light along unit `d` of `radiance` (`E⊥·colour`, W/m²): one orthographic
/// layer fitted to the bounding sphere.
fn directional_layers(
    d: Vec3,
    radiance: [f32; 4],
    bounds: &Bounds,
    size: f32,
) -> (GpuLight, Vec<Mat4>) {
    let (c, r) = bounds.sphere();
    let eye = c - d * (2.0 * r);
    let proj = proj_dx::orthographic(-r, r, -r, r, 0.5 * r, 3.5 * r);
    let g = GpuLight {
        direction: d.extend(0.0).into(),
        radiance,
        cone: [-2.0, -1.0, 0.0, 2.0 * r / size],
        kind: LIGHT_DIRECTIONAL,
        layer_count: 1,
        ..Default::default()
    };
    (g, vec![proj * look_to_mat4(eye, d, up_for(d))])
}

/// Validates `lights` and packs them with their shadow layers.
pub fn pack_lights(
    lights: &[LightDesc],
    bounds: &Bounds,
    shadow_size: u32,
    max_layers: u32,
) -> Result<(Vec<GpuLight>, Vec<Mat4>), PassError> {
    let mut gl = Vec::with_capacity(lights.len());
    let mut mats = Vec::new();
    for (i, l) in lights.iter().enumerate() {
        l.validate(i)?;
        let (mut g, m) = shadow_layers(l, bounds, shadow_size);
        g.first_layer = mats.len() as u32;
        mats.extend(m);
        gl.push(g);
    }
    if mats.len() as u32 > max_layers {
        return Err(PassError::InvalidInput {
            what: "lights".into(),
            problem: format!(
                "need {} shadow layers (6 per point light, 1 per spot/directional) but the \
                 pass was created with max_shadow_layers = {max_layers}; raise it or use \
                 fewer lights",
                mats.len()
            ),
        });
    }
    Ok((gl, mats))
}

/// The first-order pass.
#[derive(Debug)]
pub struct FirstOrderPass {
    options: FirstOrderOptions,
    /// `options.texel_reads` resolved for the device.
    reads: util::TexelReads,
    layout: wgpu::BindGroupLayout,
    shadow_layout: wgpu::BindGroupLayout,
    /// Shadow pipelines: `[both sides, back faces culled]`.
    shadow_pipelines: [wgpu::RenderPipeline; 2],
    /// `fs_lightmap` (one target), or with `samples > 1` `fs_lightmap_averaged` (two: the
    /// first order and the transfer's input).
    lightmap_pipeline: wgpu::RenderPipeline,
    gbuffer_pipeline: wgpu::RenderPipeline,
    sampler: wgpu::Sampler,
}

/// Per-scene GPU data.
#[derive(Debug)]
pub struct FirstOrderScene {
    /// Lightmap `[W, H]`.
    pub lightmap_size: [u32; 2],
    /// The mesh's buffers (shared with the display pass).
    mesh: GpuMesh,
    /// Per-frame uniforms: [`FirstOrderParams`], lights, layer matrices.
    uniforms: FrameUniforms,
    shadow_layer_views: Vec<wgpu::TextureView>,
    /// All shadow layers as one 2D-array view (the lighting pass and the display read it).
    shadow_array_view: wgpu::TextureView,
    /// Layer matrices the shadow maps were last rendered with (`None`: not valid).
    shadow_cache: std::sync::Mutex<Option<Vec<[f32; 16]>>>,
    bind_group: wgpu::BindGroup,
    shadow_bind_group: wgpu::BindGroup,
    /// The albedo texture (RGB ρ; alpha 1 on opaque texels, 0 on translucent ones) and the
    /// values it holds.
    albedo: (wgpu::Texture, Vec<[f32; 4]>),
    output: wgpu::Texture,
    /// The transfer's input when it is averaged (`samples > 1`).
    transfer_input: Option<wgpu::Texture>,
}

impl FirstOrderScene {
    /// Mesh bounds (for shadow frusta).
    pub fn bounds(&self) -> &Bounds {
        self.mesh.bounds()
    }
}

/// The uniform buffers written every frame (bindings 0, 1, 2 of `first_order.wgsl`).
#[derive(Debug)]
struct FrameUniforms {
    params: wgpu::Buffer,
    lights: wgpu::Buffer,
    matrices: wgpu::Buffer,
}

impl FrameUniforms {
    /// Buffers for `layers` shadow layers (and as many lights at most).
    fn new(device: &wgpu::Device, layers: u32) -> Self {
        let uniform = |label: &str, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        Self {
            params: uniform(
                "ortm.first_order.params",
                std::mem::size_of::<FirstOrderParams>() as u64,
            ),
            lights: uniform(
                "ortm.first_order.lights",
                (std::mem::size_of::<GpuLight>() as u32 * layers) as u64,
            ),
            matrices: uniform("ortm.first_order.layer_matrices", 64 * layers as u64),
        }
    }
}

impl FirstOrderScene {
    /// Forgets which lights the shadow maps hold, so the next `encode` re-renders them even
    /// if the lights did not move (benchmarks of the moving-light case use this).
    pub fn invalidate_shadow_maps(&self) {
        if let Ok(mut c) = self.shadow_cache.lock() {
            *c = None;
        }
    }

    /// The first-order lightmap the last `encode` wrote (RGBA32F, alpha = coverage).
    pub fn output(&self) -> &wgpu::Texture {
        &self.output
    }

    /// The first order the transfer multiplies (its shifted reads and the pyramid): with
    /// [`FirstOrderOptions::samples`] `> 1` the light averaged over each texel's square, else
    /// [`FirstOrderScene::output`] itself.
    pub fn transfer_input(&self) -> &wgpu::Texture {
        self.transfer_input.as_ref().unwrap_or(&self.output)
    }

    /// What the display's per-pixel direct light binds (`shaders/shadow.wgsl`, bindings 0,
    /// 1, 2 and 4): this frame's params, lights and layer matrices (written by the last
    /// `encode`) and the shadow-map array. Their uniform arrays hold the pass's
    /// [`FirstOrderOptions::max_shadow_layers`] entries.
    pub(crate) fn shadow_bindings(&self) -> [wgpu::BindingResource<'_>; 4] {
        let u = &self.uniforms;
        [
            u.params.as_entire_binding(),
            u.lights.as_entire_binding(),
            u.matrices.as_entire_binding(),
            wgpu::BindingResource::TextureView(&self.shadow_array_view),
        ]
    }
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct FirstOrderInputs<'a> {
    /// The prepared scene.
    pub scene: &'a FirstOrderScene,
    /// This frame's lights.
    pub lights: &'a [LightDesc],
}

/// Output of the pass.
#[derive(Clone, Debug)]
pub struct FirstOrderOutput {
    /// RGBA32F `W×H`: RGB `B_o` in W/m², alpha = coverage. Owned by the scene.
    pub first_order_tex: wgpu::Texture,
}

/// Checks `options` against the device; returns the resolved texel reads.
fn check_options(gpu: &Gpu, options: &FirstOrderOptions) -> Result<util::TexelReads, PassError> {
    if options.samples.is_multiple_of(2) || options.samples > MAX_SAMPLES {
        return Err(PassError::InvalidInput {
            what: "FirstOrderOptions.samples".into(),
            problem: format!(
                "is {}; give an odd number of sub-texels per side from 1 to {MAX_SAMPLES} (odd, \
                 so that a texel's centre is a sub-texel's)",
                options.samples
            ),
        });
    }
    if options.shadow_map_size == 0 || options.max_shadow_layers == 0 {
        return Err(PassError::InvalidInput {
            what: "FirstOrderOptions".into(),
            problem: "shadow_map_size and max_shadow_layers must be ≥ 1".into(),
        });
    }
    gpu.check_texture_size(
        "shadow map",
        options.shadow_map_size,
        options.shadow_map_size,
    )?;
    // Lights and layer matrices live in uniform arrays of `max_shadow_layers` entries
    // (a light takes ≥ 1 layer, so there are never more lights than layers): both must
    // fit one uniform binding, as well as the shadow-map array its layer count.
    let limits = gpu.device.limits();
    let ubo_entries =
        limits.max_uniform_buffer_binding_size / std::mem::size_of::<GpuLight>() as u64;
    let layer_limit = (limits.max_texture_array_layers as u64).min(ubo_entries) as u32;
    if options.max_shadow_layers > layer_limit {
        return Err(PassError::TooLarge {
            what: "FirstOrderOptions.max_shadow_layers".into(),
            size: options.max_shadow_layers as u64,
            limit: layer_limit as u64,
        });
    }
    let reads = options.texel_reads.unwrap_or(gpu.best_texel_reads());
    if reads == util::TexelReads::Storage && !gpu.supports_storage_reads() {
        return Err(PassError::MissingFeature {
            option: "FirstOrderOptions.texel_reads = Some(Storage)".into(),
            feature: "read-only storage textures in fragment shaders".into(),
            adapter: gpu.adapter_info.name.clone(),
            fallback: "None (the device's best) or Some(TexelReads::Sampled)".into(),
        });
    }
    Ok(reads)
}

/// The shader module: `lights.wgsl` + `first_order.wgsl` with `MAX_LAYERS` substituted
/// and the texel-read declarations of bindings 3, 6, 7 prepended.
/// The shadow maps' comparison sampler: linear (2×2 hardware PCF), clamp to edge,
/// `LessEqual` (shared by the first-order pass and the display's per-pixel direct light).
pub(crate) fn shadow_sampler(device: &wgpu::Device) -> wgpu::Sampler {
    device.create_sampler(&wgpu::SamplerDescriptor {
        label: Some("ortm.first_order.shadow_sampler"),
        address_mode_u: wgpu::AddressMode::ClampToEdge,
        address_mode_v: wgpu::AddressMode::ClampToEdge,
        mag_filter: wgpu::FilterMode::Linear,
        min_filter: wgpu::FilterMode::Linear,
        compare: Some(wgpu::CompareFunction::LessEqual),
        ..Default::default()
    })
}

/// `shaders/shadow.wgsl` (the per-frame uniforms, shadow maps and `shadow_visibility`) for
/// bind group `group`, with uniform arrays of `max_layers` entries. Fixed-size uniform
/// arrays: llvmpipe loads uniforms with plain vector loads but storage buffers lane by lane,
/// which made the lighting pass ~2.5× slower (docs/render.md). Shared by the first-order
/// pass (group 0) and the display's per-pixel direct light (group 2).
pub(crate) fn shadow_wgsl(group: u32, max_layers: u32) -> String {
    include_str!("../shaders/shadow.wgsl")
        .replace("SHADOW_GROUP", &group.to_string())
        .replace("MAX_LAYERS", &max_layers.to_string())
}

fn shader_module(
    device: &wgpu::Device,
    max_layers: u32,
    reads: util::TexelReads,
    samples: u32,
) -> wgpu::ShaderModule {
    let source = format!(
        "{}{}{}",
        include_str!("../shaders/lights.wgsl"),
        shadow_wgsl(0, max_layers),
        include_str!("../shaders/first_order.wgsl")
            .replace("SAMPLES_PER_SIDE", &samples.to_string())
    );
    let f32x4 = wgpu::TextureFormat::Rgba32Float;
    let source = format!(
        "{}{}{}{}{source}",
        util::FULLSCREEN_WGSL,
        reads.wgsl(0, 3, "albedo", f32x4),
        reads.wgsl(0, 6, "gbuffer_position", f32x4),
        reads.wgsl(0, 7, "gbuffer_normal", f32x4),
    );
    util::shader(device, "ortm.first_order.shader", &source)
}

/// The lighting pass's group 0; order = @binding order in first_order.wgsl.
fn lighting_layout(device: &wgpu::Device, reads: util::TexelReads) -> wgpu::BindGroupLayout {
    let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
    let fs = wgpu::ShaderStages::FRAGMENT;
    let f32x4 = wgpu::TextureFormat::Rgba32Float;
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("ortm.first_order.layout"),
        entries: &[
            util::uniform_entry(0, vf),
            util::uniform_entry(1, fs),
            util::uniform_entry(2, vf),
            reads.entry(3, fs, f32x4),
            util::shadow_maps_entry(4, fs),
            util::shadow_sampler_entry(5, fs),
            reads.entry(6, fs, f32x4),
            reads.entry(7, fs, f32x4),
        ],
    })
}

/// A depth-only shadow pipeline (`vs_shadow`, positions only) with the slope-scaled bias;
/// `cull_mode` `Some(Back)` for a closed outward mesh lit from outside its bounds (the
/// nearest surface seen from the light is then always a front face, so the depths are the
/// same and about half the triangles are never rasterised).
fn shadow_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    slope_bias: f32,
    cull_mode: Option<wgpu::Face>,
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("ortm.first_order.shadow_pipeline"),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_shadow"),
            compilation_options: Default::default(),
            buffers: &[Some(position_layout())],
        },
        primitive: wgpu::PrimitiveState {
            cull_mode,
            ..Default::default()
        },
        depth_stencil: Some(wgpu::DepthStencilState {
            format: wgpu::TextureFormat::Depth32Float,
            depth_write_enabled: Some(true),
            depth_compare: Some(wgpu::CompareFunction::Less),
            stencil: Default::default(),
            bias: wgpu::DepthBiasState {
                constant: 0,
                slope_scale: slope_bias,
                clamp: 0.0,
            },
        }),
        multisample: Default::default(),
        fragment: None,
        multiview_mask: None,
        cache: None,
    })
}

/// The texel G-buffer pipeline: the mesh by its UVs (`vs_gbuffer`, both sides) into two
/// RGBA32F targets (position + coverage, normal).
fn gbuffer_pipeline(device: &wgpu::Device, module: &wgpu::ShaderModule) -> wgpu::RenderPipeline {
    let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("ortm.first_order.gbuffer_pipeline_layout"),
        bind_group_layouts: &[],
        immediate_size: 0,
    });
    let target = Some(wgpu::ColorTargetState {
        format: wgpu::TextureFormat::Rgba32Float,
        blend: None,
        write_mask: wgpu::ColorWrites::ALL,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("ortm.first_order.gbuffer_pipeline"),
        layout: Some(&layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_gbuffer"),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
        },
        primitive: wgpu::PrimitiveState {
            cull_mode: None,
            ..Default::default()
        },
        depth_stencil: None,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_gbuffer"),
            compilation_options: Default::default(),
            targets: &[target.clone(), target],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// The averaged lighting pipeline (`fs_lightmap_averaged`, full-screen): two RGBA32F
/// targets, the first-order lightmap and the transfer's input.
fn averaged_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
) -> wgpu::RenderPipeline {
    let target = Some(wgpu::ColorTargetState {
        format: wgpu::TextureFormat::Rgba32Float,
        blend: None,
        write_mask: wgpu::ColorWrites::ALL,
    });
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("ortm.first_order.averaged_pipeline"),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some("vs_fullscreen"),
            compilation_options: Default::default(),
            buffers: &[],
        },
        primitive: wgpu::PrimitiveState::default(),
        depth_stencil: None,
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some("fs_lightmap_averaged"),
            compilation_options: Default::default(),
            targets: &[target.clone(), target],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// Checks that `albedo` holds `width·height` values of a lightmap the device can hold;
/// returns `[W, H]`.
fn check_albedo(gpu: &Gpu, albedo: &AlbedoMap) -> Result<[u32; 2], PassError> {
    let size = [albedo.width, albedo.height];
    gpu.check_texture_size("lightmap (AlbedoMap)", size[0], size[1])?;
    let n = size[0] as usize * size[1] as usize;
    if albedo.rgb.len() != n {
        return Err(PassError::BadLength {
            what: "AlbedoMap.rgb".into(),
            expected: n,
            got: albedo.rgb.len(),
            hint: "width·height reflectances".into(),
        });
    }
    Ok(size)
}

/// The shadow-map array of `layers` `size²` depth layers: one 2D view per layer (render
/// targets) and the array view (the lighting pass's binding 4).
fn shadow_maps(
    device: &wgpu::Device,
    size: u32,
    layers: u32,
) -> (Vec<wgpu::TextureView>, wgpu::TextureView) {
    let shadow = device.create_texture(&wgpu::TextureDescriptor {
        label: Some("ortm.first_order.shadow_maps"),
        size: wgpu::Extent3d {
            width: size,
            height: size,
            depth_or_array_layers: layers,
        },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: wgpu::TextureFormat::Depth32Float,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        view_formats: &[],
    });
    let layer_views = (0..layers)
        .map(|l| {
            shadow.create_view(&wgpu::TextureViewDescriptor {
                label: Some(&format!("ortm.first_order.shadow_layer{l}")),
                dimension: Some(wgpu::TextureViewDimension::D2),
                base_array_layer: l,
                array_layer_count: Some(1),
                ..Default::default()
            })
        })
        .collect();
    let array_view = shadow.create_view(&wgpu::TextureViewDescriptor {
        label: Some("ortm.first_order.shadow_array"),
        dimension: Some(wgpu::TextureViewDimension::D2Array),
        ..Default::default()
    });
    (layer_views, array_view)
}

impl FirstOrderPass {
    /// Builds the shadow and lightmap pipelines.
    pub fn new(gpu: &Gpu, options: &FirstOrderOptions) -> Result<Self, PassError> {
        let reads = check_options(gpu, options)?;
        gpu.scoped("ortm.first_order.new", || {
            let device = &gpu.device;
            let module = shader_module(device, options.max_shadow_layers, reads, options.samples);
            let layout = lighting_layout(device, reads);
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.first_order.pipeline_layout"),
                bind_group_layouts: &[Some(&layout)],
                immediate_size: 0,
            });
            // The shadow pass writes the shadow maps, so it cannot bind them: its group 0
            // holds only binding 2 (the layer matrices), same slot as in the main layout.
            let shadow_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.first_order.shadow_layout"),
                entries: &[util::uniform_entry(2, wgpu::ShaderStages::VERTEX)],
            });
            let shadow_pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.first_order.shadow_pipeline_layout"),
                bind_group_layouts: &[Some(&shadow_layout)],
                immediate_size: 0,
            });
            let shadow =
                |cull| shadow_pipeline(device, &shadow_pl, &module, options.slope_bias, cull);
            let shadow_pipelines = [shadow(None), shadow(Some(wgpu::Face::Back))];
            let lightmap_pipeline = if options.samples > 1 {
                averaged_pipeline(device, &pl, &module)
            } else {
                util::fullscreen_pipeline(
                    device,
                    "ortm.first_order.lightmap_pipeline",
                    Some(&pl),
                    &module,
                    "fs_lightmap",
                    wgpu::TextureFormat::Rgba32Float,
                    None,
                )
            };
            let sampler = shadow_sampler(device);
            Self {
                options: *options,
                reads,
                layout,
                shadow_layout,
                shadow_pipelines,
                lightmap_pipeline,
                gbuffer_pipeline: gbuffer_pipeline(device, &module),
                sampler,
            }
        })
    }

    /// The options the pass was created with.
    pub fn options(&self) -> &FirstOrderOptions {
        &self.options
    }

    /// Uploads the mesh ([`GpuMesh::upload`]) and calls [`FirstOrderPass::prepare_mesh`].
    pub fn prepare(
        &self,
        gpu: &Gpu,
        mesh: &MeshData,
        albedo: &AlbedoMap,
    ) -> Result<FirstOrderScene, PassError> {
        self.prepare_mesh(gpu, &GpuMesh::upload(gpu, mesh)?, albedo)
    }

    /// Uploads the albedo, allocates shadow maps and the output, and rasterises the
    /// uploaded `mesh` into the texel G-buffer.
    pub fn prepare_mesh(
        &self,
        gpu: &Gpu,
        mesh: &GpuMesh,
        albedo: &AlbedoMap,
    ) -> Result<FirstOrderScene, PassError> {
        let size = check_albedo(gpu, albedo)?;
        let device = &gpu.device;
        // Alpha 1: opaque (the first-order term is the centre's) until `set_translucent`.
        let rgba: Vec<[f32; 4]> = albedo.rgb.iter().map(|c| [c[0], c[1], c[2], 1.0]).collect();
        let albedo_tex = gpu.create_rgba32f_texture(
            "ortm.first_order.albedo",
            size[0],
            size[1],
            &rgba,
            wgpu::TextureUsages::TEXTURE_BINDING | self.reads.usage(),
        )?;
        let uniforms = FrameUniforms::new(device, self.options.max_shadow_layers);
        let (shadow_layer_views, shadow_array_view) = shadow_maps(
            device,
            self.options.shadow_map_size,
            self.options.max_shadow_layers,
        );
        let n = self.options.samples;
        let gsize = [size[0].saturating_mul(n), size[1].saturating_mul(n)];
        if n > 1 {
            gpu.check_texture_size(
                "first-order G-buffer (FirstOrderOptions.samples × the lightmap's size; fewer \
                 samples or a smaller lightmap)",
                gsize[0],
                gsize[1],
            )?;
        }
        let gbuffer = self.texel_gbuffer(gpu, mesh, gsize);
        let bind_group = self.lighting_bind_group(
            device,
            &uniforms,
            &util::view(&albedo_tex),
            &shadow_array_view,
            &gbuffer,
        );
        let shadow_bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.first_order.shadow_bind_group"),
            layout: &self.shadow_layout,
            entries: &[wgpu::BindGroupEntry {
                binding: 2,
                resource: uniforms.matrices.as_entire_binding(),
            }],
        });
        let lightmap = |label| {
            util::texture_2d(
                device,
                label,
                size,
                wgpu::TextureFormat::Rgba32Float,
                wgpu::TextureUsages::RENDER_ATTACHMENT
                    | wgpu::TextureUsages::TEXTURE_BINDING
                    | wgpu::TextureUsages::COPY_SRC
                    // The transfer pass may read it as a storage texture (`util::TexelReads`).
                    | gpu.best_texel_reads().usage(),
            )
        };
        let output = lightmap("ortm.first_order.first_order_lightmap");
        let transfer_input = (n > 1).then(|| lightmap("ortm.first_order.transfer_input"));
        gpu.check("ortm.first_order.prepare")?;
        Ok(FirstOrderScene {
            lightmap_size: size,
            mesh: mesh.clone(),
            uniforms,
            shadow_layer_views,
            shadow_array_view,
            shadow_cache: std::sync::Mutex::new(None),
            bind_group,
            shadow_bind_group,
            albedo: (albedo_tex, rgba),
            output,
            transfer_input,
        })
    }

    /// Marks the translucent texels (`true`; row-major like the albedo): with
    /// [`FirstOrderOptions::samples`] `> 1` their first-order term is the averaged light,
    /// whose scattering their transfer holds, instead of the centre's. Without averaging it
    /// changes nothing.
    pub fn set_translucent(
        &self,
        gpu: &Gpu,
        scene: &mut FirstOrderScene,
        translucent: &[bool],
    ) -> Result<(), PassError> {
        let (tex, rgba) = &mut scene.albedo;
        if translucent.len() != rgba.len() {
            return Err(PassError::BadLength {
                what: "translucent texels".into(),
                expected: rgba.len(),
                got: translucent.len(),
                hint: "one flag per lightmap texel (width·height)".into(),
            });
        }
        for (v, &t) in rgba.iter_mut().zip(translucent) {
            v[3] = if t { 0.0 } else { 1.0 };
        }
        gpu.queue.write_texture(
            tex.as_image_copy(),
            bytemuck::cast_slice(rgba),
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(16 * scene.lightmap_size[0]),
                rows_per_image: None,
            },
            tex.size(),
        );
        Ok(())
    }

    /// The texel G-buffer: the mesh rasterised once by its UVs into `[position + coverage,
    /// normal]` RGBA32F maps of `size` (the lights change per frame, the surface point of a
    /// texel does not). Submits the draw; returns the two views.
    fn texel_gbuffer(&self, gpu: &Gpu, mesh: &GpuMesh, size: [u32; 2]) -> [wgpu::TextureView; 2] {
        let device = &gpu.device;
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | self.reads.usage();
        let map = |label| {
            let tex =
                util::texture_2d(device, label, size, wgpu::TextureFormat::Rgba32Float, usage);
            util::view(&tex)
        };
        let views = [
            map("ortm.first_order.gbuffer_position"),
            map("ortm.first_order.gbuffer_normal"),
        ];
        let mut enc = device.create_command_encoder(&wgpu::CommandEncoderDescriptor {
            label: Some("ortm.first_order.gbuffer_encoder"),
        });
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("ortm.first_order.gbuffer_pass"),
                color_attachments: &[
                    util::cleared_attachment(&views[0]),
                    util::cleared_attachment(&views[1]),
                ],
                depth_stencil_attachment: None,
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.gbuffer_pipeline);
            pass.set_vertex_buffer(0, mesh.vertices.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            pass.draw_indexed(0..mesh.index_count, 0, 0..1);
        }
        gpu.queue.submit([enc.finish()]);
        views
    }

    /// The lighting pass's bind group; order = @binding order in first_order.wgsl.
    fn lighting_bind_group(
        &self,
        device: &wgpu::Device,
        uniforms: &FrameUniforms,
        albedo: &wgpu::TextureView,
        shadow_array: &wgpu::TextureView,
        gbuffer: &[wgpu::TextureView; 2],
    ) -> wgpu::BindGroup {
        let texture = |binding, view| wgpu::BindGroupEntry {
            binding,
            resource: wgpu::BindingResource::TextureView(view),
        };
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.first_order.bind_group"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: uniforms.params.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: uniforms.lights.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 2,
                    resource: uniforms.matrices.as_entire_binding(),
                },
                texture(3, albedo),
                texture(4, shadow_array),
                wgpu::BindGroupEntry {
                    binding: 5,
                    resource: wgpu::BindingResource::Sampler(&self.sampler),
                },
                texture(6, &gbuffer[0]),
                texture(7, &gbuffer[1]),
            ],
        })
    }

    /// Writes this frame's lights and records the shadow and lightmap passes.
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &FirstOrderInputs<'_>,
    ) -> Result<FirstOrderOutput, PassError> {
        let scene = inputs.scene;
        let (lights, m) = self.write_lights(gpu, scene, inputs.lights)?;
        let layers = m.len();
        // The mesh is static: shadow maps rendered with the same matrices are still valid.
        let reuse = {
            let mut cache = scene
                .shadow_cache
                .lock()
                .map_err(|_| PassError::InvalidInput {
                    what: "FirstOrderScene".into(),
                    problem: "shadow-map cache poisoned by a panic in another thread".into(),
                })?;
            let same = cache.as_ref() == Some(&m);
            *cache = Some(m);
            same
        };
        if !reuse {
            self.encode_shadow_layers(encoder, scene, &lights, inputs.lights, layers);
        }
        let target = util::view(&scene.output);
        let input = scene.transfer_input.as_ref().map(util::view);
        let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ortm.first_order.lightmap_pass"),
            color_attachments: &[
                util::cleared_attachment(&target),
                input.as_ref().and_then(util::cleared_attachment),
            ][..1 + input.is_some() as usize],
            depth_stencil_attachment: None,
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_pipeline(&self.lightmap_pipeline);
        pass.set_bind_group(0, &scene.bind_group, &[]);
        pass.draw(0..3, 0..1);
        drop(pass);
        Ok(FirstOrderOutput {
            first_order_tex: scene.output.clone(),
        })
    }

    /// Packs `lights` and writes the params, lights and layer matrices uniforms; returns
    /// the packed lights and the layer matrices (column-major).
    fn write_lights(
        &self,
        gpu: &Gpu,
        scene: &FirstOrderScene,
        lights: &[LightDesc],
    ) -> Result<(Vec<GpuLight>, Vec<[f32; 16]>), PassError> {
        let (gl, mats) = pack_lights(
            lights,
            scene.mesh.bounds(),
            self.options.shadow_map_size,
            self.options.max_shadow_layers,
        )?;
        let params = FirstOrderParams {
            lightmap_size: scene.lightmap_size,
            light_count: gl.len() as u32,
            shadow_size: self.options.shadow_map_size,
            normal_offset_texels: self.options.normal_offset_texels,
            _pad: [0.0; 3],
        };
        let u = &scene.uniforms;
        gpu.queue
            .write_buffer(&u.params, 0, bytemuck::bytes_of(&params));
        let m: Vec<[f32; 16]> = mats.iter().map(|m| m.to_cols_array()).collect();
        if !gl.is_empty() {
            gpu.queue
                .write_buffer(&u.lights, 0, bytemuck::cast_slice(&gl));
            gpu.queue
                .write_buffer(&u.matrices, 0, bytemuck::cast_slice(&m));
        }
        Ok((gl, m))
    }

    /// Records the depth passes of the first `layers` shadow layers.
    fn encode_shadow_layers(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        scene: &FirstOrderScene,
        packed: &[GpuLight],
        lights: &[LightDesc],
        layers: usize,
    ) {
        let mesh = &scene.mesh;
        for (layer, view) in scene.shadow_layer_views.iter().enumerate().take(layers) {
            let mut pass = encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(&format!("ortm.first_order.shadow_pass{layer}")),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view,
                    depth_ops: Some(wgpu::Operations {
                        load: wgpu::LoadOp::Clear(1.0),
                        store: wgpu::StoreOp::Store,
                    }),
                    stencil_ops: None,
                }),
                timestamp_writes: None,
                occlusion_query_set: None,
                multiview_mask: None,
            });
            // The light owning this layer; cull back faces when it is outside the bounds
            // of a closed outward mesh (a directional light always is).
            let cull = mesh.closed_outward
                && packed
                    .iter()
                    .zip(lights)
                    .find(|(g, _)| {
                        (g.first_layer..g.first_layer + g.layer_count).contains(&(layer as u32))
                    })
                    .is_some_and(|(_, l)| match *l {
                        LightDesc::Directional { .. } => true,
                        LightDesc::Point { position_m, .. }
                        | LightDesc::Spot { position_m, .. } => {
                            !scene.mesh.bounds().contains(Vec3::from(position_m))
                        }
                    });
            pass.set_pipeline(&self.shadow_pipelines[usize::from(cull)]);
            pass.set_bind_group(0, &scene.shadow_bind_group, &[]);
            pass.set_vertex_buffer(0, mesh.positions.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            let l = layer as u32;
            pass.draw_indexed(0..mesh.index_count, 0, l..l + 1);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shared_struct_sizes() {
        assert_eq!(std::mem::size_of::<GpuLight>(), 80);
        assert_eq!(std::mem::size_of::<FirstOrderParams>(), 32);
        assert_eq!(std::mem::size_of::<Vertex>(), 32);
    }

    #[test]
    fn point_faces_see_their_axis_and_bound_the_scene() {
        // The centre of face k's image is its forward axis; every bbox corner projects
        // into [0, 1] depth on the face whose major axis it lies along.
        let b = Bounds {
            min: Vec3::new(-1.0, 0.0, -1.0),
            max: Vec3::new(1.0, 0.5, 1.0),
        };
        let light = LightDesc::Point {
            position_m: [0.2, 1.0, 0.1],
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        let (_, mats) = shadow_layers(&light, &b, 256);
        let p = Vec3::new(0.2, 1.0, 0.1);
        for (k, d) in point_face_dirs().iter().enumerate() {
            let c = mats[k].project_point3(p + *d * 0.5);
            assert!(c.x.abs() < 1e-5 && c.y.abs() < 1e-5, "face {k}: {c}");
            assert!((0.0..=1.0).contains(&c.z));
        }
        let far_corner = Vec3::new(-1.0, 0.0, -1.0);
        let c = mats[1].project_point3(far_corner); // −X major? |dx|=1.2 > |dz|=1.1 > |dy|=1
        assert!(
            c.x.abs() <= 1.0 && c.y.abs() <= 1.0 && (0.0..=1.0).contains(&c.z),
            "{c}"
        );
    }

    #[test]
    fn too_many_layers_is_an_error() {
        let b = Bounds::of(&[[0.0; 3], [1.0; 3]]);
        // Inside the bounding sphere: six cube faces per point light.
        let p = LightDesc::Point {
            position_m: [0.5, 0.6, 0.4],
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        assert!(pack_lights(&[p, p], &b, 64, 12).is_ok());
        assert!(pack_lights(&[p, p, p], &b, 64, 12).is_err());
        // Outside it: one cone each.
        let far = LightDesc::Point {
            position_m: [0.0, 2.0, 0.0],
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        let (_, mats) = pack_lights(&[far, far, far], &b, 64, 3).unwrap();
        assert_eq!(mats.len(), 3);
    }

    #[test]
    fn point_cone_contains_the_bounds() {
        // Every bbox corner projects inside the single cone's map, within [0, 1] depth.
        let b = Bounds {
            min: Vec3::new(-0.1, -0.12, -0.09),
            max: Vec3::new(0.08, 0.13, 0.1),
        };
        let p = Vec3::new(0.1, 0.1, 0.4);
        let light = LightDesc::Point {
            position_m: p.into(),
            color: [1.0; 3],
            intensity_w_sr: 1.0,
        };
        let (g, mats) = shadow_layers(&light, &b, 512);
        assert_eq!((g.layer_count, mats.len()), (1, 1));
        for i in 0..8 {
            let c = Vec3::new(
                if i & 1 == 0 { b.min.x } else { b.max.x },
                if i & 2 == 0 { b.min.y } else { b.max.y },
                if i & 4 == 0 { b.min.z } else { b.max.z },
            );
            let q = mats[0].project_point3(c);
            assert!(
                q.x.abs() < 1.0 && q.y.abs() < 1.0 && q.z > 0.0 && q.z < 1.0,
                "corner {c} → {q}"
            );
        }
    }
}
