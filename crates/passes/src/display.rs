//! Display pass: the mesh seen through a perspective camera, lit per pixel by the lights
//! (with the first-order pass's shadow maps) plus the transferred light from the lightmap,
//! or textured with a lightmap as the paper displays it; tonemapped into an offscreen RGBA8
//! image, optionally side by side (first order | final, Sec. 5.3).
//! `shaders/display.wgsl` (+ `shaders/lights.wgsl`, `shaders/shadow.wgsl`), mirror
//! [`crate::cpu::display`].
//!
//! # Data flow
//! [`DisplayPass::prepare_mesh`] takes the uploaded mesh ([`GpuMesh`], shared with the
//! first-order pass) and allocates the colour (`Rgba8Unorm`, linear storage of sRGB-encoded
//! values) and depth targets. [`DisplayPass::encode`] writes the [`DisplayView`] uniform and
//! draws the mesh once (or twice, into the left and right halves, for side-by-side).
//! [`crate::gpu::Gpu::read_rgba8`] reads the image back. The frame script
//! ([`crate::frame::Renderer`]) feeds it: per-pixel direct light ([`DirectInputs`]) binds the
//! first-order scene's lights, layer matrices and shadow maps of this frame, the
//! [`surface_map`] (albedo ρ and diffusion length ℓ per texel, dilated once per scene), the
//! dilated first-order map, and as the lightmap the dilated *transferred* light
//! `T = final − first order` ([`crate::indirect`]).
//!
//! # Shading and units
//! - Lightmap display ([`DirectLight::Lightmap`], `--direct lightmap`): `B` (W/m², radiosity)
//!   is looked up between texel centres and turned into radiance `L = B/π` (W/(m²·sr)); the
//!   optional specular adds normalised Blinn-Phong `k_s·(s+8)/(8π)·(n·h)^s·E` per light,
//!   unshadowed.
//! - Per-pixel direct light ([`DirectLight::PerPixel`], the default):
//!   `L = w·ρ·E/π + (1 − w)·B_o/π + T/π`, `E` the irradiance of every point, spot and
//!   directional light at the pixel's interpolated surface point and normal, shadowed by the
//!   same lookup as the first-order texels (`shadow.wgsl`: 2×2 hardware PCF; normal offset
//!   of `FirstOrderOptions::normal_offset_texels` shadow texels, 1.5 by default, plus the
//!   shadow pass's slope-scaled depth bias 2.0 — see `docs/render.md`, *Shadows*); ρ bilinear
//!   from the surface map. `w = clamp(1 − ℓ/f, 0, 1)` with `f` the larger side of the
//!   pixel's footprint on the surface (screen derivatives of the world position): 1 on
//!   diffuse surfaces (ℓ = 0); on subsurface ones the lightmap's diffused first order `B_o`
//!   (which the subsurface transfer redistributes) takes over where the diffusion length
//!   exceeds the footprint, so scattering keeps its soft shadow edges and the total stays
//!   the lightmap solution's. The specular term is shadowed here. The first-order view and
//!   the left half of side-by-side show the direct light alone (`T` left out), per pixel on
//!   every surface (`w = 1`: the first order is unscattered light). The lightmap bound is
//!   `T` on scenes without subsurface texels (`w = 1`: `L = ρ·E/π + T/π`), else the final
//!   light `B = B_o + T`, as `L = w·ρ·E/π + (B − w·B_o)/π`: where a triangle's every pixel
//!   takes `w = 0` in this view it is drawn with the lightmap display's shader (`B/π`,
//!   without the light loop), and where no light reaches a triangle without the light loop
//!   ([`crate::display_split`], [`DisplayOptions::split`]; the same image).
//! - Then `L·exposure`, Reinhard `x/(1+x)` per channel, sRGB encoding.
//!
//! # Lightmap filter
//! [`LightmapSampling::Bilinear`] (default) or [`LightmapSampling::Bicubic`] (uniform cubic
//! B-spline over 4×4 texels, non-negative weights summing to 1: smoother magnification
//! without ringing), a pipeline-overridable constant of the shader. Chart borders: every
//! lookup reads dilated maps (the dilation fills 4 gutter texels, the B-spline needs 2), so
//! neither filter pulls black or another chart's values into a chart (tested with a
//! constant lightmap, `apps/ortm/tests/display_direct.rs`). ρ is always bilinear.
//!
//! # Cost (see `docs/render.md`, display section, for the measurements)
//! - The bilinear lookup is the sampler's ([`LightmapFilter::Hardware`]) when the device
//!   has `FLOAT32_FILTERABLE` (RGBA32F lightmaps), else four `textureLoad`s
//!   ([`LightmapFilter::Manual`]); both give the texel-centre convention's bilinear value.
//!   The B-spline takes four bilinear samples, or sixteen loads.
//! - Specular on and off are separate pipelines (entry points for the lightmap display, the
//!   override `SPECULAR` for the per-pixel one): on SIMD software rasterisers such as
//!   lavapipe a uniform branch around a loop still costs its masked body. Without specular
//!   the lightmap display's vertex shader (`vs_uv`) passes on only the lightmap UV.
//! - The per-pixel light loop reads the lights and matrices from uniform arrays (as the
//!   first-order pass), one shadow-map comparison sample per lit light.
//! - The shader encodes sRGB itself with a fit of three square roots instead of `pow`
//!   (within 0.012/255 of IEC 61966-2-1, [`crate::cpu::display::srgb_encode`]); an
//!   `Rgba8UnormSrgb` target view measured no faster on lavapipe than `pow`.
//!
//! # Conventions
//! Right-handed world, camera from [`Camera`] (look-at, vertical field of view, depth
//! `[0, 1]`); image row 0 is the top. Both sides of every triangle are drawn (back faces
//! culled for a closed outward mesh seen from outside). Use dilated lightmaps
//! ([`crate::dilate`]) so chart borders do not bleed black.
//!
//! # Limits
//! One `encode` per submit (the view uniform is written with `Queue::write_buffer`). The
//! per-pixel pipelines are built for one `max_shadow_layers`
//! ([`DisplayPass::with_shadow_layers`]; the frame script passes the first-order pass's).

use std::sync::Mutex;

use bytemuck::{Pod, Zeroable};
use glam::camera::rh::proj::directx as proj_dx;
use glam::camera::rh::view::look_at_mat4;
use glam::{Mat4, Vec3};

use crate::dilate::DilatePlan;
use crate::error::PassError;
use crate::first_order::{Bounds, FirstOrderScene, GpuLight, pack_lights, vertex_layout};
use crate::gpu::Gpu;
use crate::mesh::GpuMesh;
use crate::types::{AlbedoMap, LightDesc, MeshData};
use crate::util;

/// Background colour of the image (sRGB-encoded RGBA8).
pub const BACKGROUND: [u8; 4] = [16, 16, 20, 255];

/// How the fragment shader looks up the lightmap bilinearly between texel centres.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum LightmapFilter {
    /// The sampler's linear filter (`textureSampleLevel`, clamp to edge); needs
    /// `FLOAT32_FILTERABLE` for RGBA32F lightmaps ([`Gpu::supports_float32_filter`]).
    Hardware,
    /// Four `textureLoad`s and two lerps in the shader; works on every device.
    Manual,
}

impl LightmapFilter {
    /// The cheaper filter this device supports: [`LightmapFilter::Hardware`] with
    /// `FLOAT32_FILTERABLE`, else [`LightmapFilter::Manual`].
    pub fn best_for(gpu: &Gpu) -> Self {
        if gpu.supports_float32_filter() {
            LightmapFilter::Hardware
        } else {
            LightmapFilter::Manual
        }
    }
}

/// Where the displayed direct light comes from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DirectLight {
    /// Evaluated per pixel with the first-order pass's shadow maps; the lightmaps give the
    /// transferred light (final − first order) and, on subsurface surfaces, the diffused
    /// light (see the module docs). Needs [`DisplayInputs::direct`].
    #[default]
    PerPixel,
    /// From the lightmaps, as the paper displays them: the shown map's `B/π` (first order |
    /// final side by side).
    Lightmap,
}

/// How lightmaps are filtered between texel centres.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum LightmapSampling {
    /// Bilinear (2×2 texels).
    #[default]
    Bilinear,
    /// Uniform cubic B-spline (4×4 texels, non-negative weights: smooth, no ringing; needs a
    /// gutter of 2 dilated texels, the default dilation fills 4).
    Bicubic,
}

/// When the per-pixel display splits the mesh by [`crate::display_split::Class`].
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum SplitMode {
    /// On CPU adapters (lavapipe), where a masked-off branch costs what running it does and
    /// the split cuts the display's cost (`docs/render.md`); off on hardware GPUs, which
    /// skip a branch no lane of a warp takes (the split would only add CPU work per frame).
    #[default]
    Auto,
    /// Always.
    On,
    /// Never: one draw with the full shader.
    Off,
}

/// Settings fixed at creation.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct DisplayOptions {
    /// Image width in pixels (each half is `width/2` in side-by-side mode).
    pub width: u32,
    /// Image height in pixels.
    pub height: u32,
    /// Draw first-order (left) and final (right) side by side.
    pub side_by_side: bool,
    /// Direct light per pixel (default) or from the lightmaps. [`DirectLight::PerPixel`]
    /// builds the per-pixel pipelines too; a frame without [`DisplayInputs::direct`] is
    /// still drawn from the lightmaps.
    pub direct: DirectLight,
    /// Lightmap filter.
    pub sampling: LightmapSampling,
    /// Per-pixel direct light: whether to draw the triangles whose every pixel takes
    /// `w = 0` (subsurface surfaces) or that no light reaches with pipelines without the
    /// light loop ([`crate::display_split`]; the same image).
    pub split: SplitMode,
}

impl Default for DisplayOptions {
    fn default() -> Self {
        Self {
            width: 1280,
            height: 720,
            side_by_side: false,
            direct: DirectLight::default(),
            sampling: LightmapSampling::default(),
            split: SplitMode::Auto,
        }
    }
}

/// A perspective camera (metres, degrees).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Camera {
    /// Eye position.
    pub eye: [f32; 3],
    /// Point looked at.
    pub target: [f32; 3],
    /// Up direction (not parallel to `target − eye`).
    pub up: [f32; 3],
    /// Vertical field of view in degrees (0 < fov < 180).
    pub fov_y_deg: f32,
    /// Near clipping distance.
    pub near: f32,
    /// Far clipping distance.
    pub far: f32,
}

impl Default for Camera {
    /// At `(0, 0, 1)` looking at the origin, `+y` up, 45°, depth range `[0.1, 10]` m.
    fn default() -> Self {
        Self {
            eye: [0.0, 0.0, 1.0],
            target: [0.0; 3],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 45.0,
            near: 0.1,
            far: 10.0,
        }
    }
}

impl Camera {
    /// View-projection matrix for an `aspect` = width/height viewport (wgpu clip space).
    pub fn view_proj(&self, aspect: f32) -> Mat4 {
        proj_dx::perspective(self.fov_y_deg.to_radians(), aspect, self.near, self.far)
            * look_at_mat4(self.eye.into(), self.target.into(), self.up.into())
    }

    fn validate(&self) -> Result<(), PassError> {
        let dir = Vec3::from(self.target) - Vec3::from(self.eye);
        let ok = dir.length() > 0.0
            && dir.cross(Vec3::from(self.up)).length() > 1e-6 * dir.length()
            && self.fov_y_deg > 0.0
            && self.fov_y_deg < 180.0
            && self.near > 0.0
            && self.far > self.near;
        if ok {
            Ok(())
        } else {
            Err(PassError::InvalidInput {
                what: "Camera".into(),
                problem: "needs eye ≠ target, up not parallel to the view direction, \
                          0 < fov_y_deg < 180 and 0 < near < far"
                    .into(),
            })
        }
    }
}

/// Optional Blinn-Phong highlight.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Specular {
    /// Specular reflectance `k_s` (0–1).
    pub strength: f32,
    /// Blinn-Phong exponent `s`.
    pub shininess: f32,
}

/// Uniform of `display.wgsl`. 112 bytes. Must match `View` there.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct DisplayView {
    /// Column-major view-projection matrix.
    pub view_proj: [f32; 16],
    /// Eye xyz (m), exposure.
    pub eye_exposure: [f32; 4],
    /// Lightmap `[W, H]`.
    pub lightmap_size: [u32; 2],
    /// Lights in the buffer.
    pub light_count: u32,
    /// 1 = specular on.
    pub specular_on: u32,
    /// `k_s`, exponent, unused, unused.
    pub specular: [f32; 4],
}

/// Maximum number of lights the specular term uses.
pub const MAX_SPECULAR_LIGHTS: usize = 16;

/// The display pass.
#[derive(Debug)]
pub struct DisplayPass {
    options: DisplayOptions,
    filter: LightmapFilter,
    view_layout: wgpu::BindGroupLayout,
    map_layout: wgpu::BindGroupLayout,
    /// Bilinear, clamp-to-edge sampler ([`LightmapFilter::Hardware`] only).
    sampler: Option<wgpu::Sampler>,
    /// Lightmap display: `[specular off, on][both sides, back faces culled]`.
    pipelines: [[wgpu::RenderPipeline; 2]; 2],
    /// Per-pixel direct light ([`DirectLight::PerPixel`] only).
    direct: Option<DirectPipelines>,
}

/// The per-pixel direct light's group 2 layout, comparison sampler and pipelines.
#[derive(Debug)]
struct DirectPipelines {
    layout: wgpu::BindGroupLayout,
    shadow_sampler: wgpu::Sampler,
    /// Layers of the uniform arrays the shader was built for (must equal the first-order
    /// pass's `max_shadow_layers`).
    shadow_layers: u32,
    /// `[subsurface split off, on][specular off, on][both sides, back faces culled]`.
    pipelines: [[[wgpu::RenderPipeline; 2]; 2]; 2],
    /// The triangles whose pixels all take `w = 0`, and on scenes without subsurface
    /// texels those no light reaches (no specular): `vs_uv` + the lightmap display's
    /// `fs_filtered` / `fs_manual` (`B/π`, resp. `T/π`), `[both sides, back faces culled]`.
    diffused: [wgpu::RenderPipeline; 2],
    /// The triangles no light reaches on scenes with subsurface texels: the per-pixel
    /// shader with `SUBSURFACE` and without the light loop (`LIGHTS` off), `[both sides,
    /// back faces culled]`.
    unlit: [wgpu::RenderPipeline; 2],
}

/// Per-scene GPU data.
#[derive(Debug)]
pub struct DisplayScene {
    /// The mesh's buffers (shared with the first-order pass).
    mesh: GpuMesh,
    view: wgpu::Buffer,
    lights: wgpu::Buffer,
    view_group: wgpu::BindGroup,
    color: wgpu::Texture,
    color_view: wgpu::TextureView,
    depth_view: wgpu::TextureView,
    /// The per-pixel display's split of the last frame that had one.
    split: Mutex<Split>,
}

/// The index buffer of a split ([`DisplayPass::split_triangles`]), kept between frames.
#[derive(Debug, Default)]
struct Split {
    /// Allocated by the first frame whose split has triangles without the light loop (the
    /// mesh's index count).
    buffer: Option<wgpu::Buffer>,
    /// What the buffer was split for (`None` before the first split).
    key: Option<SplitKey>,
    /// Indices of the first two classes, at the start of the buffer in that order.
    counts: [u32; 2],
}

/// The inputs of a split: the same ones give the same classes.
#[derive(Debug)]
struct SplitKey {
    camera: Camera,
    height_px: u32,
    lights: Vec<LightDesc>,
    lengths: Option<Vec<f32>>,
}

impl DisplayScene {
    /// The image the last `encode` drew (`Rgba8Unorm`, sRGB-encoded values).
    pub fn color(&self) -> &wgpu::Texture {
        &self.color
    }
}

/// Per-frame inputs.
#[derive(Clone, Copy, Debug)]
pub struct DisplayInputs<'a> {
    /// The prepared scene.
    pub scene: &'a DisplayScene,
    /// Final lightmap (dilated), any float RGBA format.
    pub final_lightmap: &'a wgpu::TextureView,
    /// Its `[W, H]`.
    pub lightmap_size: [u32; 2],
    /// First-order lightmap (dilated), required in side-by-side mode, same size.
    pub first_order: Option<&'a wgpu::TextureView>,
    /// The camera.
    pub camera: Camera,
    /// Multiplies radiance before tonemapping.
    pub exposure: f32,
    /// Lights for the specular term of the lightmap display (ignored without `specular`;
    /// the per-pixel direct light uses the first-order pass's lights).
    pub lights: &'a [LightDesc],
    /// Optional specular highlight.
    pub specular: Option<Specular>,
    /// Per-pixel direct light: `Some` draws with it (the pass must have been created with
    /// [`DirectLight::PerPixel`]), and `final_lightmap` is then the *transferred* light
    /// (final − first order) added on top, or with [`DirectInputs::subsurface`] the final
    /// light itself (see the module docs); `None` draws from the lightmaps.
    pub direct: Option<DirectInputs<'a>>,
}

/// What the per-pixel direct light reads besides the lightmap.
#[derive(Clone, Copy, Debug)]
pub struct DirectInputs<'a> {
    /// The first-order scene whose last `encode` wrote this frame's lights, layer matrices
    /// and shadow maps.
    pub first_order: &'a FirstOrderScene,
    /// RGBA32F map of the lightmap's size: RGB albedo ρ, alpha the diffusion length ℓ in
    /// metres (0 = diffuse), dilated like the lightmaps ([`surface_map`]).
    pub surface: &'a wgpu::TextureView,
    /// The first-order lightmap (dilated): the lightmap's share `1 − w` on subsurface
    /// surfaces. Not read where ℓ = 0.
    pub first_order_map: &'a wgpu::TextureView,
    /// Direct light only (no transferred light) in a single view — the first-order view;
    /// side by side the left half always is, the right half unless this is set.
    pub direct_only: bool,
    /// Some texel of the surface map has a diffusion length > 0: draw with the
    /// diffusion-length split (otherwise `w = 1` everywhere, without its cost).
    pub subsurface: bool,
    /// Per triangle of the mesh the smallest diffusion length its pixels can look up
    /// ([`crate::display_split::DisplaySplit::min_lengths`] of the surface map's texels,
    /// [`GpuMesh::split`]). With `subsurface` and [`DisplayOptions::split`] the triangles
    /// whose every pixel takes `w = 0` in this view are drawn without the light loop.
    /// `None`: every triangle with the full shader.
    pub triangle_lengths: Option<&'a [f32]>,
}

/// Output of the pass.
#[derive(Clone, Debug)]
pub struct DisplayOutput {
    /// `Rgba8Unorm` image holding sRGB-encoded values; owned by the scene.
    pub color_tex: wgpu::Texture,
}

/// Texels of the per-pixel direct light's surface map ([`DirectInputs::surface`]): RGB the
/// albedo, alpha the diffusion length ℓ (metres, `diffusion_m`, 0 = diffuse; `None`: all
/// diffuse), each texel taken from its dilation source in `plan` (covered texels keep
/// their own values, gutter texels copy their nearest covered texel, others are 0), so a
/// lookup at a chart border sees only the chart's own albedo.
///
/// # Errors
/// [`PassError::InvalidInput`] when the sizes of `albedo`, `diffusion_m` and `plan` differ,
/// or a length is negative or not finite.
pub fn surface_texels(
    albedo: &AlbedoMap,
    diffusion_m: Option<&[f32]>,
    plan: &DilatePlan,
) -> Result<Vec<[f32; 4]>, PassError> {
    let n = albedo.width as usize * albedo.height as usize;
    let bad = |what: &str, problem: String| PassError::InvalidInput {
        what: what.into(),
        problem,
    };
    if (plan.width, plan.height) != (albedo.width, albedo.height) || albedo.rgb.len() != n {
        return Err(bad(
            "AlbedoMap",
            format!(
                "{}×{} with {} texels, the dilation plan is {}×{}; build both for the \
                 lightmap's size",
                albedo.width,
                albedo.height,
                albedo.rgb.len(),
                plan.width,
                plan.height
            ),
        ));
    }
    plan.check_sources()?;
    if let Some(d) = diffusion_m {
        if d.len() != n {
            return Err(bad(
                "diffusion lengths",
                format!("{} values for {n} texels; give one per texel", d.len()),
            ));
        }
        if let Some(i) = d.iter().position(|l| !(l.is_finite() && *l >= 0.0)) {
            return Err(bad(
                "diffusion lengths",
                format!("texel {i}: {} m; lengths must be finite and ≥ 0", d[i]),
            ));
        }
    }
    Ok(plan
        .sources
        .iter()
        .map(|&src| {
            if src == crate::dilate::NO_SOURCE {
                return [0.0; 4];
            }
            let i = src as usize;
            let [r, g, b] = albedo.rgb[i];
            [r, g, b, diffusion_m.map_or(0.0, |d| d[i])]
        })
        .collect())
}

/// Uploads [`surface_texels`] as the RGBA32F surface map.
pub fn surface_map(
    gpu: &Gpu,
    albedo: &AlbedoMap,
    diffusion_m: Option<&[f32]>,
    plan: &DilatePlan,
) -> Result<wgpu::Texture, PassError> {
    let texels = surface_texels(albedo, diffusion_m, plan)?;
    upload_surface(gpu, [albedo.width, albedo.height], &texels)
}

/// Uploads surface texels ([`surface_texels`]) of a `size[0] × size[1]` lightmap as the
/// RGBA32F surface map.
pub fn upload_surface(
    gpu: &Gpu,
    size: [u32; 2],
    texels: &[[f32; 4]],
) -> Result<wgpu::Texture, PassError> {
    gpu.create_rgba32f_texture(
        "ortm.display.surface",
        size[0],
        size[1],
        texels,
        wgpu::TextureUsages::TEXTURE_BINDING,
    )
}

/// Checks `filter` and the image size against the device.
fn check_options(
    gpu: &Gpu,
    options: &DisplayOptions,
    filter: LightmapFilter,
) -> Result<(), PassError> {
    if filter == LightmapFilter::Hardware && !gpu.supports_float32_filter() {
        return Err(PassError::InvalidInput {
            what: "LightmapFilter::Hardware".into(),
            problem: format!(
                "adapter '{}' lacks FLOAT32_FILTERABLE (RGBA32F lightmaps cannot be \
                 filtered); use LightmapFilter::Manual or LightmapFilter::best_for",
                gpu.adapter_info.name
            ),
        });
    }
    gpu.check_texture_size("display image", options.width, options.height)?;
    if options.side_by_side && options.width < 2 {
        return Err(PassError::InvalidInput {
            what: "DisplayOptions.width".into(),
            problem: "side-by-side needs a width of at least 2 pixels".into(),
        });
    }
    Ok(())
}

/// The lightmap bind group (group 1) of `filter`: its layout entries, the fragment entry
/// point (without `_specular`) and the sampler ([`LightmapFilter::Hardware`] only).
fn lightmap_binding(
    device: &wgpu::Device,
    filter: LightmapFilter,
) -> (
    Vec<wgpu::BindGroupLayoutEntry>,
    &'static str,
    Option<wgpu::Sampler>,
) {
    let fs = wgpu::ShaderStages::FRAGMENT;
    match filter {
        LightmapFilter::Manual => (vec![util::texture_entry(0, fs)], "fs_manual", None),
        LightmapFilter::Hardware => {
            let mut texture = util::texture_entry(0, fs);
            texture.ty = wgpu::BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D2,
                multisampled: false,
            };
            let sampler_entry = wgpu::BindGroupLayoutEntry {
                binding: 1,
                visibility: fs,
                ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                count: None,
            };
            let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
                label: Some("ortm.display.lightmap_sampler"),
                address_mode_u: wgpu::AddressMode::ClampToEdge,
                address_mode_v: wgpu::AddressMode::ClampToEdge,
                mag_filter: wgpu::FilterMode::Linear,
                min_filter: wgpu::FilterMode::Linear,
                ..Default::default()
            });
            (vec![texture, sampler_entry], "fs_filtered", Some(sampler))
        }
    }
}

/// One display pipeline: the mesh ([`vertex_layout`]) with depth test into `Rgba8Unorm`;
/// `(vs, fs)` entry points, `cull_mode` `Some(Back)` for closed outward meshes seen from
/// outside (see [`DisplayPass::encode`]).
fn display_pipeline(
    device: &wgpu::Device,
    layout: &wgpu::PipelineLayout,
    module: &wgpu::ShaderModule,
    (vs, fs): (&str, &str),
    cull_mode: Option<wgpu::Face>,
    constants: &[(&str, f64)],
) -> wgpu::RenderPipeline {
    device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
        label: Some("ortm.display.pipeline"),
        layout: Some(layout),
        vertex: wgpu::VertexState {
            module,
            entry_point: Some(vs),
            compilation_options: Default::default(),
            buffers: &[Some(vertex_layout())],
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
            bias: Default::default(),
        }),
        multisample: Default::default(),
        fragment: Some(wgpu::FragmentState {
            module,
            entry_point: Some(fs),
            compilation_options: wgpu::PipelineCompilationOptions {
                constants,
                ..Default::default()
            },
            targets: &[Some(wgpu::ColorTargetState {
                format: wgpu::TextureFormat::Rgba8Unorm,
                blend: None,
                write_mask: wgpu::ColorWrites::ALL,
            })],
        }),
        multiview_mask: None,
        cache: None,
    })
}

/// `lengths` must hold one value per triangle.
fn check_triangle_lengths(triangles: usize, lengths: &[f32]) -> Result<(), PassError> {
    if lengths.len() == triangles {
        return Ok(());
    }
    Err(PassError::InvalidInput {
        what: "DirectInputs.triangle_lengths".into(),
        problem: format!(
            "{} values for {triangles} triangles; compute them with \
             DisplaySplit::min_lengths for this mesh",
            lengths.len()
        ),
    })
}

/// Whether back faces can be culled: a closed outward mesh hides its back faces behind its
/// front faces for an eye outside it, unless the near plane cuts into the mesh — true when
/// the eye is farther from the bounding box than any point of the near-plane rectangle of a
/// viewport of `aspect` (saves shading back faces drawn before the front face covering
/// them).
fn cull_back_faces(mesh: &GpuMesh, cam: &Camera, aspect: f32) -> bool {
    let t = (0.5 * cam.fov_y_deg.to_radians()).tan();
    let near_reach = cam.near * (1.0 + t * t * (1.0 + aspect * aspect)).sqrt();
    let grown = Bounds {
        min: mesh.bounds.min - Vec3::splat(near_reach),
        max: mesh.bounds.max + Vec3::splat(near_reach),
    };
    mesh.closed_outward && !grown.contains(Vec3::from(cam.eye))
}

/// The per-pixel direct light's group 2 layout (`display.wgsl`: shadow.wgsl's bindings 0,
/// 1, 2, 4, 5, then the surface map 6 and the first-order map 7) and its pipelines
/// (`vs_direct` + `fs_direct_filtered` / `fs_direct_manual`, the overrides `SUBSURFACE` and
/// `SPECULAR` per row). `(filter, bicubic)`: the lookup and the `BICUBIC` override value.
fn direct_pipelines(
    device: &wgpu::Device,
    module: &wgpu::ShaderModule,
    [view_layout, map_layout]: [&wgpu::BindGroupLayout; 2],
    (filter, bicubic): (LightmapFilter, f64),
    shadow_layers: u32,
) -> DirectPipelines {
    let fs = wgpu::ShaderStages::FRAGMENT;
    let map = |binding| {
        let mut e = util::texture_entry(binding, fs);
        e.ty = wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float {
                filterable: filter == LightmapFilter::Hardware,
            },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        };
        e
    };
    let layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("ortm.display.direct_layout"),
        entries: &[
            util::uniform_entry(0, fs),
            util::uniform_entry(1, fs),
            util::uniform_entry(2, fs),
            util::shadow_maps_entry(4, fs),
            util::shadow_sampler_entry(5, fs),
            map(6),
            map(7),
        ],
    });
    let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some("ortm.display.direct_pipeline_layout"),
        bind_group_layouts: &[Some(view_layout), Some(map_layout), Some(&layout)],
        immediate_size: 0,
    });
    // The triangles whose pixels all take w = 0 show B/π: the lightmap display's shader.
    let (fs_name, fs_diffused) = match filter {
        LightmapFilter::Hardware => ("fs_direct_filtered", "fs_filtered"),
        LightmapFilter::Manual => ("fs_direct_manual", "fs_manual"),
    };
    // `[both sides, back faces culled]` of one entry-point pair and constants.
    let culls = |entry: (&str, &str), constants: &[(&str, f64)]| {
        [None, Some(wgpu::Face::Back)]
            .map(|cull| display_pipeline(device, &pl, module, entry, cull, constants))
    };
    let pipelines = [0.0, 1.0].map(|subsurface| {
        [0.0, 1.0].map(|specular| {
            let constants = [
                ("BICUBIC", bicubic),
                ("SPECULAR", specular),
                ("SUBSURFACE", subsurface),
            ];
            culls(("vs_direct", fs_name), &constants)
        })
    });
    let diffused = culls(("vs_uv", fs_diffused), &[("BICUBIC", bicubic)]);
    let unlit = culls(
        ("vs_direct", fs_name),
        &[("BICUBIC", bicubic), ("SUBSURFACE", 1.0), ("LIGHTS", 0.0)],
    );
    DirectPipelines {
        layout,
        shadow_sampler: crate::first_order::shadow_sampler(device),
        shadow_layers,
        pipelines,
        diffused,
        unlit,
    }
}

impl DisplayPass {
    /// Builds the pipelines with the device's cheaper lightmap filter
    /// ([`LightmapFilter::best_for`]).
    pub fn new(gpu: &Gpu, options: &DisplayOptions) -> Result<Self, PassError> {
        Self::with_filter(gpu, options, LightmapFilter::best_for(gpu))
    }

    /// Builds the pipelines with the given lightmap filter (per-pixel direct light for a
    /// first-order pass with the default `max_shadow_layers`).
    ///
    /// Errors: [`PassError::InvalidInput`] for [`LightmapFilter::Hardware`] on a device
    /// without `FLOAT32_FILTERABLE`, or a bad size.
    pub fn with_filter(
        gpu: &Gpu,
        options: &DisplayOptions,
        filter: LightmapFilter,
    ) -> Result<Self, PassError> {
        let layers = crate::first_order::FirstOrderOptions::default().max_shadow_layers;
        Self::with_shadow_layers(gpu, options, filter, layers)
    }

    /// Builds the pipelines; the per-pixel direct light reads a first-order pass created
    /// with `max_shadow_layers = shadow_layers` (its uniform arrays have that length).
    pub fn with_shadow_layers(
        gpu: &Gpu,
        options: &DisplayOptions,
        filter: LightmapFilter,
        shadow_layers: u32,
    ) -> Result<Self, PassError> {
        check_options(gpu, options, filter)?;
        gpu.scoped("ortm.display.new", || {
            let device = &gpu.device;
            let source = format!(
                "{}{}{}",
                include_str!("../shaders/lights.wgsl"),
                crate::first_order::shadow_wgsl(2, shadow_layers.max(1)),
                include_str!("../shaders/display.wgsl")
            );
            let module = util::shader(device, "ortm.display.shader", &source);
            let vf = wgpu::ShaderStages::VERTEX_FRAGMENT;
            // Order = @binding order in display.wgsl.
            let view_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.display.view_layout"),
                entries: &[
                    util::uniform_entry(0, vf),
                    util::storage_entry(1, wgpu::ShaderStages::FRAGMENT, true),
                ],
            });
            let (map_entries, entry_point, sampler) = lightmap_binding(device, filter);
            let map_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
                label: Some("ortm.display.lightmap_layout"),
                entries: &map_entries,
            });
            let pl = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
                label: Some("ortm.display.pipeline_layout"),
                bind_group_layouts: &[Some(&view_layout), Some(&map_layout)],
                immediate_size: 0,
            });
            let bicubic = f64::from(u8::from(options.sampling == LightmapSampling::Bicubic));
            let constants = [("BICUBIC", bicubic)];
            // `[specular off, on][both sides, back faces culled]`. Without specular the
            // shaders interpolate only the UV and have no light loop.
            let pipelines = [false, true].map(|specular| {
                let fs = if specular {
                    format!("{entry_point}_specular")
                } else {
                    entry_point.to_string()
                };
                let vs = if specular { "vs_main" } else { "vs_uv" };
                [None, Some(wgpu::Face::Back)]
                    .map(|cull| display_pipeline(device, &pl, &module, (vs, &fs), cull, &constants))
            });
            let direct = (options.direct == DirectLight::PerPixel).then(|| {
                direct_pipelines(
                    device,
                    &module,
                    [&view_layout, &map_layout],
                    (filter, bicubic),
                    shadow_layers,
                )
            });
            Self {
                options: *options,
                filter,
                view_layout,
                map_layout,
                sampler,
                pipelines,
                direct,
            }
        })
    }

    /// The lightmap filter the pipelines use.
    pub fn filter(&self) -> LightmapFilter {
        self.filter
    }

    /// The options the pass was created with.
    pub fn options(&self) -> &DisplayOptions {
        &self.options
    }

    /// Uploads the mesh ([`GpuMesh::upload`]) and calls [`DisplayPass::prepare_mesh`].
    pub fn prepare(&self, gpu: &Gpu, mesh: &MeshData) -> Result<DisplayScene, PassError> {
        self.prepare_mesh(gpu, &GpuMesh::upload(gpu, mesh)?)
    }

    /// Allocates the uniforms and the colour and depth targets for the uploaded `mesh`.
    pub fn prepare_mesh(&self, gpu: &Gpu, mesh: &GpuMesh) -> Result<DisplayScene, PassError> {
        let device = &gpu.device;
        let view = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.display.view"),
            size: std::mem::size_of::<DisplayView>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let lights = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("ortm.display.lights"),
            size: (std::mem::size_of::<GpuLight>() * MAX_SPECULAR_LIGHTS) as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        // Order = @binding order in display.wgsl.
        let view_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.display.view_bind_group"),
            layout: &self.view_layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: view.as_entire_binding(),
                },
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: lights.as_entire_binding(),
                },
            ],
        });
        let size = [self.options.width, self.options.height];
        let color = util::texture_2d(
            device,
            "ortm.display.color",
            size,
            wgpu::TextureFormat::Rgba8Unorm,
            wgpu::TextureUsages::RENDER_ATTACHMENT
                | wgpu::TextureUsages::COPY_SRC
                | wgpu::TextureUsages::TEXTURE_BINDING,
        );
        let depth = util::texture_2d(
            device,
            "ortm.display.depth",
            size,
            wgpu::TextureFormat::Depth32Float,
            wgpu::TextureUsages::RENDER_ATTACHMENT,
        );
        gpu.check("ortm.display.prepare")?;
        Ok(DisplayScene {
            mesh: mesh.clone(),
            view,
            lights,
            view_group,
            color_view: util::view(&color),
            color,
            depth_view: util::view(&depth),
            split: Mutex::default(),
        })
    }

    /// Writes the view uniform (and the specular lights) and records the draw(s).
    pub fn encode(
        &self,
        gpu: &Gpu,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &DisplayInputs<'_>,
    ) -> Result<DisplayOutput, PassError> {
        inputs.camera.validate()?;
        let scene = inputs.scene;
        let (w, h) = (self.options.width, self.options.height);
        let half_w = if self.options.side_by_side { w / 2 } else { w };
        self.write_view(gpu, inputs, half_w as f32 / h as f32)?;
        let draws = self.draws(gpu, inputs, half_w)?;
        let direct_group = inputs
            .direct
            .as_ref()
            .map(|d| self.direct_group(gpu, d))
            .transpose()?;
        let mut pass = self.begin_pass(encoder, scene);
        let cull = usize::from(cull_back_faces(
            &scene.mesh,
            &inputs.camera,
            half_w as f32 / h as f32,
        ));
        let specular_on = usize::from(inputs.specular.is_some());
        let split = self.split_triangles(gpu, inputs, h)?;
        match (&direct_group, &self.direct, &inputs.direct) {
            (Some(group), Some(d), Some(di)) => {
                let full = &d.pipelines[usize::from(di.subsurface)][specular_on][cull];
                pass.set_bind_group(2, group, &[]);
                pass.set_bind_group(0, &scene.view_group, &[]);
                pass.set_vertex_buffer(0, scene.mesh.vertices.slice(..));
                match &split {
                    Some((buffer, _)) => {
                        pass.set_index_buffer(buffer.slice(..), wgpu::IndexFormat::Uint32)
                    }
                    None => pass
                        .set_index_buffer(scene.mesh.indices.slice(..), wgpu::IndexFormat::Uint32),
                }
                for (x, group, direct_only) in &draws {
                    pass.set_viewport(*x as f32, 0.0, half_w as f32, h as f32, 0.0, 1.0);
                    pass.set_bind_group(1, group, &[]);
                    // The instance index tells `vs_direct` whether to add the lightmap.
                    let i = u32::from(*direct_only);
                    let mut start = 0;
                    if let Some((_, counts)) = split.as_ref().filter(|_| !*direct_only) {
                        // Triangles without the light loop first: those whose pixels all
                        // take w = 0, then those no light reaches (module docs).
                        let unlit = if di.subsurface {
                            &d.unlit[cull]
                        } else {
                            &d.diffused[cull]
                        };
                        for (pipeline, n) in [(&d.diffused[cull], counts[0]), (unlit, counts[1])] {
                            if n > 0 {
                                pass.set_pipeline(pipeline);
                                pass.draw_indexed(start..start + n, 0, i..i + 1);
                                start += n;
                            }
                        }
                    }
                    pass.set_pipeline(full);
                    pass.draw_indexed(start..scene.mesh.index_count, 0, i..i + 1);
                }
            }
            _ => {
                pass.set_pipeline(&self.pipelines[specular_on][cull]);
                pass.set_bind_group(0, &scene.view_group, &[]);
                pass.set_vertex_buffer(0, scene.mesh.vertices.slice(..));
                pass.set_index_buffer(scene.mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                for (x, group, _) in &draws {
                    pass.set_viewport(*x as f32, 0.0, half_w as f32, h as f32, 0.0, 1.0);
                    pass.set_bind_group(1, group, &[]);
                    pass.draw_indexed(0..scene.mesh.index_count, 0, 0..1);
                }
            }
        }
        drop(pass);
        Ok(DisplayOutput {
            color_tex: scene.color.clone(),
        })
    }

    /// With per-pixel direct light (no specular, [`DisplayOptions::split`]): the scene's
    /// split index buffer — the triangles by [`crate::display_split::Class`] in this view:
    /// those whose every pixel takes `w = 0` (with [`DirectInputs::triangle_lengths`]), those
    /// no light reaches, the rest; each class in the mesh's order, rewritten only when the
    /// classes change — and the index counts of the first two classes. `None` when neither
    /// class has a triangle, or without the split (the mesh's own index buffer, one
    /// pipeline).
    fn split_triangles(
        &self,
        gpu: &Gpu,
        inputs: &DisplayInputs<'_>,
        height_px: u32,
    ) -> Result<Option<(wgpu::Buffer, [u32; 2])>, PassError> {
        let Some(di) = inputs.direct.as_ref() else {
            return Ok(None);
        };
        let on = match self.options.split {
            SplitMode::Auto => gpu.adapter_info.device_type == wgpu::DeviceType::Cpu,
            SplitMode::On => true,
            SplitMode::Off => false,
        };
        if !(inputs.specular.is_none() && on) {
            return Ok(None);
        }
        let scene = inputs.scene;
        let triangles = scene.mesh.split();
        let lengths = di.triangle_lengths.filter(|_| di.subsurface);
        if let Some(lengths) = lengths {
            check_triangle_lengths(triangles.triangles(), lengths)?;
        }
        let mut split = scene.split.lock().unwrap_or_else(|e| e.into_inner());
        // The classes depend on the view, the lights and the lengths only: compared in
        // place each frame, copied only when they change.
        let same = split.key.as_ref().is_some_and(|k| {
            k.camera == inputs.camera
                && k.height_px == height_px
                && k.lights == inputs.lights
                && k.lengths.as_deref() == lengths
        });
        if !same {
            let key = SplitKey {
                camera: inputs.camera,
                height_px,
                lights: inputs.lights.to_vec(),
                lengths: lengths.map(<[f32]>::to_vec),
            };
            let diffused = lengths.map(|l| triangles.diffused_only(&inputs.camera, height_px, l));
            let classes = triangles.classes(diffused.as_deref(), &triangles.unlit(inputs.lights));
            let (indices, counts) = triangles.indices(&classes);
            split.counts = [counts[0], counts[1]];
            if counts[0] + counts[1] > 0 {
                let buffer = split.buffer.get_or_insert_with(|| {
                    gpu.device.create_buffer(&wgpu::BufferDescriptor {
                        label: Some("ortm.display.split_indices"),
                        size: u64::from(scene.mesh.index_count.max(1)) * 4,
                        usage: wgpu::BufferUsages::INDEX | wgpu::BufferUsages::COPY_DST,
                        mapped_at_creation: false,
                    })
                });
                gpu.queue
                    .write_buffer(buffer, 0, bytemuck::cast_slice(&indices));
            }
            split.key = Some(key);
        }
        if split.counts == [0, 0] {
            return Ok(None);
        }
        let buffer = split.buffer.clone().expect("written with the classes");
        Ok(Some((buffer, split.counts)))
    }

    /// Writes the [`DisplayView`] uniform for a viewport of `aspect`, and the lights when
    /// the specular term is on.
    fn write_view(
        &self,
        gpu: &Gpu,
        inputs: &DisplayInputs<'_>,
        aspect: f32,
    ) -> Result<(), PassError> {
        let scene = inputs.scene;
        let (light_count, specular) = match inputs.specular {
            Some(s) => {
                if inputs.lights.len() > MAX_SPECULAR_LIGHTS {
                    return Err(PassError::InvalidInput {
                        what: "DisplayInputs.lights".into(),
                        problem: format!(
                            "{} lights; the specular term supports at most {MAX_SPECULAR_LIGHTS}",
                            inputs.lights.len()
                        ),
                    });
                }
                let (gl, _) = pack_lights(inputs.lights, &scene.mesh.bounds, 1, u32::MAX)?;
                if !gl.is_empty() {
                    gpu.queue
                        .write_buffer(&scene.lights, 0, bytemuck::cast_slice(&gl));
                }
                (gl.len() as u32, [s.strength, s.shininess, 0.0, 0.0])
            }
            None => (0, [0.0; 4]),
        };
        let e = inputs.camera.eye;
        let view = DisplayView {
            view_proj: inputs.camera.view_proj(aspect).to_cols_array(),
            eye_exposure: [e[0], e[1], e[2], inputs.exposure],
            lightmap_size: inputs.lightmap_size,
            light_count,
            specular_on: inputs.specular.is_some() as u32,
            specular,
        };
        gpu.queue
            .write_buffer(&scene.view, 0, bytemuck::bytes_of(&view));
        Ok(())
    }

    /// The per-pixel direct light's group 2 for `d`.
    fn direct_group(&self, gpu: &Gpu, d: &DirectInputs<'_>) -> Result<wgpu::BindGroup, PassError> {
        let pipelines = self
            .direct
            .as_ref()
            .ok_or_else(|| PassError::InvalidInput {
                what: "DisplayInputs.direct".into(),
                problem: "the display pass was created with DirectLight::Lightmap; create it \
                      with DirectLight::PerPixel for per-pixel direct light"
                    .into(),
            })?;
        let [params, lights, matrices, shadow] = d.first_order.shadow_bindings();
        let entry = |binding, resource| wgpu::BindGroupEntry { binding, resource };
        Ok(gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("ortm.display.direct_bind_group"),
            layout: &pipelines.layout,
            entries: &[
                entry(0, params),
                entry(1, lights),
                entry(2, matrices),
                entry(4, shadow),
                entry(5, wgpu::BindingResource::Sampler(&pipelines.shadow_sampler)),
                entry(6, wgpu::BindingResource::TextureView(d.surface)),
                entry(7, wgpu::BindingResource::TextureView(d.first_order_map)),
            ],
        }))
    }

    /// The first-order pass's `max_shadow_layers` the per-pixel pipelines were built for
    /// (`None` without them).
    pub fn shadow_layers(&self) -> Option<u32> {
        self.direct.as_ref().map(|d| d.shadow_layers)
    }

    /// `(viewport x, lightmap bind group, direct light only)` per draw: the final map, or
    /// the first-order map left of it in side-by-side mode. With per-pixel direct light the
    /// bound map is the transferred light and the left half shows the direct light only.
    fn draws(
        &self,
        gpu: &Gpu,
        inputs: &DisplayInputs<'_>,
        half_w: u32,
    ) -> Result<Vec<(u32, wgpu::BindGroup, bool)>, PassError> {
        let map_group = |v: &wgpu::TextureView, label: &str| {
            let mut entries = vec![wgpu::BindGroupEntry {
                binding: 0,
                resource: wgpu::BindingResource::TextureView(v),
            }];
            if let Some(s) = &self.sampler {
                entries.push(wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Sampler(s),
                });
            }
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(label),
                layout: &self.map_layout,
                entries: &entries,
            })
        };
        let mut draws = Vec::new();
        let direct_only = inputs.direct.is_some_and(|d| d.direct_only);
        let shown = || map_group(inputs.final_lightmap, "ortm.display.final_bind_group");
        if self.options.side_by_side {
            if inputs.direct.is_some() {
                // Left: per-pixel direct light only (the bound map is not read).
                draws.push((0, shown(), true));
            } else {
                let fo = inputs.first_order.ok_or_else(|| PassError::InvalidInput {
                    what: "DisplayInputs.first_order".into(),
                    problem: "side-by-side mode needs the first-order lightmap".into(),
                })?;
                draws.push((
                    0,
                    map_group(fo, "ortm.display.first_order_bind_group"),
                    false,
                ));
            }
            draws.push((half_w, shown(), direct_only));
        } else {
            draws.push((0, shown(), direct_only));
        }
        Ok(draws)
    }

    /// The render pass: colour cleared to [`BACKGROUND`], depth cleared to 1 (discarded).
    fn begin_pass<'e>(
        &self,
        encoder: &'e mut wgpu::CommandEncoder,
        scene: &DisplayScene,
    ) -> wgpu::RenderPass<'e> {
        let bg = |i: usize| BACKGROUND[i] as f64 / 255.0;
        encoder.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("ortm.display.pass"),
            color_attachments: &[Some(wgpu::RenderPassColorAttachment {
                view: &scene.color_view,
                depth_slice: None,
                resolve_target: None,
                ops: wgpu::Operations {
                    load: wgpu::LoadOp::Clear(wgpu::Color {
                        r: bg(0),
                        g: bg(1),
                        b: bg(2),
                        a: 1.0,
                    }),
                    store: wgpu::StoreOp::Store,
                },
            })],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &scene.depth_view,
                depth_ops: Some(wgpu::Operations {
                    load: wgpu::LoadOp::Clear(1.0),
                    store: wgpu::StoreOp::Discard,
                }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        })
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn view_size_matches_wgsl() {
        assert_eq!(std::mem::size_of::<super::DisplayView>(), 112);
    }
}
