//! `ortm render DIR`: relights a bake on the GPU (wgpu; any Vulkan/Metal/DX12 adapter, or
//! Mesa's lavapipe) and writes the displayed frame as PNG, and optionally the final and
//! first-order lightmaps as linear OpenEXR (W/m²).
//!
//! # Data flow
//! `DIR/atlases.json` (from `ortm bin`; else the maps of `DIR/index.json` are packed into
//! 1024² atlases in memory) + the scene (`--scene`, checked against the bake's scene hash) +
//! lights (`--light`, default the scene's) → `passes::Renderer`: first order with shadow maps
//! → transfer (Eq. 9, blend or compute) → dilation → display → `-o` PNG.
//!
//! # Options worth knowing
//! - `--light` (repeatable) replaces the scene's lights: see [`ortm::scene::light::LIGHT_SYNTAX`].
//! - `--camera EX,EY,EZ:TX,TY,TZ[:FOV]`; default: looking along −z at the whole mesh.
//! - `--exposure auto` (default) maps the 95th percentile of the final radiance to 1 before
//!   Reinhard tonemapping; a number sets it directly (multiplies `L = B/π`).
//! - `--direct pixel` (default) evaluates direct light per pixel with the shadow maps and
//!   takes the transferred light from the lightmap (subsurface materials keep the
//!   lightmap's diffused light where their diffusion length exceeds a pixel's footprint:
//!   [`ortm::render::diffusion_lengths`]); `--direct lightmap` displays the lightmaps as the paper does.
//! - `--filter bilinear|bicubic`: the lightmap filter (bicubic = cubic B-spline).

use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context, Result};
use ortm::bake::texels::TexelGrid;
use ortm::render::{
    self, AtlasSource, BakeAndScene, CAMERA_SYNTAX, DEFAULT_ATLAS_SIDE, to_lightmap,
    write_lightmap_exr,
};
use ortm::scene::light::{LIGHT_SYNTAX, Light, SpecError, parse_light};
use passes::display::{Camera, DirectLight, DisplayOptions, LightmapSampling};
use passes::first_order::FirstOrderOptions;
use passes::frame::{FrameParams, Renderer, RendererOptions};
use passes::transfer::{TransferOptions, TransferPath};
use passes::{Gpu, TexelImage};

/// Transfer implementation.
#[derive(clap::ValueEnum, Clone, Copy, Debug, PartialEq, Eq)]
pub enum PathArg {
    /// The faster for the adapter: rows on a software adapter (lavapipe), compute on a
    /// hardware GPU (both measured by `ortm bench render`); without any adapter, the CPU
    /// mirrors of the passes.
    Auto,
    /// Instanced quads with additive blending (the paper's method; RGBA32F when blendable).
    Blend,
    /// Compute shader gathering per 8×8 tile (reference / fallback).
    Compute,
    /// Compute shader summing each texel's row of map entries (the maps turned around once
    /// per scene; docs/render.md, "Rows path").
    Rows,
}

/// Where the displayed direct light comes from (`--direct`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum DirectArg {
    /// Per pixel, with the first-order pass's shadow maps; the transferred light from the
    /// lightmap.
    #[default]
    Pixel,
    /// From the lightmaps (the paper's display: first order | final side by side).
    Lightmap,
}

impl DirectArg {
    /// The display option.
    pub fn direct(self) -> DirectLight {
        match self {
            DirectArg::Pixel => DirectLight::PerPixel,
            DirectArg::Lightmap => DirectLight::Lightmap,
        }
    }
}

/// Lightmap filter (`--filter`).
#[derive(clap::ValueEnum, Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum FilterArg {
    /// Bilinear between texel centres.
    #[default]
    Bilinear,
    /// Cubic B-spline (4×4 texels, smoother).
    Bicubic,
}

impl FilterArg {
    /// The display option.
    pub fn sampling(self) -> LightmapSampling {
        match self {
            FilterArg::Bilinear => LightmapSampling::Bilinear,
            FilterArg::Bicubic => LightmapSampling::Bicubic,
        }
    }
}

/// `--direct` and `--filter`, shared by `ortm render` and `ortm view`.
#[derive(clap::Args, Clone, Copy, Debug, Default)]
pub struct DisplayArgs {
    /// Direct light per pixel (shadow maps at screen resolution) or from the lightmaps.
    #[arg(long, value_enum, default_value_t = DirectArg::Pixel)]
    pub direct: DirectArg,
    /// Lightmap filter.
    #[arg(long, value_enum, default_value_t = FilterArg::Bilinear)]
    pub filter: FilterArg,
}

/// The bake and the lights, the first arguments of `ortm render` and `ortm view`.
#[derive(clap::Args, Debug)]
pub struct BakeArgs {
    /// Bake directory (with index.json from `ortm bake`, and atlases.json from `ortm bin` if
    /// binned; otherwise the maps are packed in memory).
    pub dir: PathBuf,
    /// Scene the bake was made from ([`super::SCENE_HELP`]). Default: the scene recorded in
    /// the bake's settings, if any.
    #[arg(long, help = format!("The scene the bake was made from. {}. Default: the scene recorded by `ortm bake`", super::SCENE_HELP))]
    pub scene: Option<String>,
    /// A light replacing the scene's lights (repeatable).
    #[arg(long = "light", value_name = "SPEC", allow_hyphen_values = true, help = format!("A light replacing the scene's lights (repeatable): {LIGHT_SYNTAX}"))]
    pub lights: Vec<String>,
}

impl BakeArgs {
    /// Opens the bake directory ([`render::open_bake`], the scene loaded by
    /// [`super::load_scene`]), with atlases of `atlas_size`² when it was not binned.
    /// A folder that does not exist is named as such; a recorded scene that cannot be loaded
    /// is answered with the `--scene` option.
    pub fn open(&self, atlas_size: u32) -> Result<BakeAndScene> {
        if std::fs::symlink_metadata(&self.dir).is_err() {
            anyhow::bail!(
                "the bake folder '{}' does not exist: pass the folder written by `ortm bake -o DIR`",
                self.dir.display()
            );
        }
        let recorded = self.scene.is_none();
        render::open_bake(
            &self.dir,
            self.scene.as_deref(),
            atlas_size,
            |arg: &str, size| {
                super::load_scene(arg, size).with_context(|| {
                    if recorded {
                        format!(
                            "opening the scene '{arg}' recorded by the bake in '{}'; if it moved, \
                             name it with --scene SCENE",
                            self.dir.display()
                        )
                    } else {
                        format!("opening the scene '{arg}' given with --scene")
                    }
                })
            },
        )
    }

    /// The `--light` lights ([`LIGHT_SYNTAX`]), in order.
    pub fn lights(&self) -> Result<Vec<Light>, SpecError> {
        self.lights.iter().map(|s| parse_light(s)).collect()
    }
}

/// Default side of each shadow-map layer, texels (`ortm render`, `ortm view`, `ortm bench
/// render`).
pub const DEFAULT_SHADOW_SIZE: u32 = 2048;

/// Arguments of `ortm render`.
#[derive(clap::Args, Debug)]
pub struct Args {
    #[command(flatten)]
    bake: BakeArgs,
    /// Camera; default: looking along −z at the whole mesh.
    #[arg(long, value_name = "SPEC", allow_hyphen_values = true, help = format!("Camera: {CAMERA_SYNTAX}; default: looking along −z at the whole mesh"))]
    camera: Option<String>,
    /// Vertical field of view in degrees (default camera, or a --camera without FOV).
    #[arg(long, default_value_t = 40.0)]
    fov: f32,
    /// Image size in pixels, WIDTHxHEIGHT.
    #[arg(long, default_value = "1280x720")]
    size: String,
    /// First order (left) and final (right) side by side.
    #[arg(long)]
    side_by_side: bool,
    #[command(flatten)]
    display: DisplayArgs,
    /// Transfer implementation.
    #[arg(long, value_enum, default_value_t = PathArg::Auto)]
    path: PathArg,
    /// Exposure: `auto`, or a number multiplying the radiance B/π before tonemapping.
    #[arg(long, default_value = "auto")]
    exposure: String,
    /// Side of each shadow-map layer, texels.
    #[arg(long, default_value_t = DEFAULT_SHADOW_SIZE)]
    shadow_size: u32,
    /// Sub-texels per texel side (odd, 1–7) over which the transfer's input is averaged: the
    /// maps then multiply each sender's light over its whole square instead of at its centre
    /// (README, "The transfer's input"); 1 takes the centres. Default: 3 where the sub-texels
    /// fit (on a GPU lightmaps up to 1365², on the CPU mirrors up to 682²), else 1.
    #[arg(long, value_name = "N")]
    first_order_samples: Option<u32>,
    #[command(flatten)]
    rows: RowsArgs,
    /// Atlas side when the bake has no atlases.json (power of two).
    #[arg(long, default_value_t = DEFAULT_ATLAS_SIDE)]
    atlas_size: u32,
    /// Output image (PNG).
    #[arg(short, long, default_value = "frame.png")]
    output: PathBuf,
    /// Also write the final lightmap (undilated, W/m², linear) as OpenEXR.
    #[arg(long)]
    lightmap_out: Option<PathBuf>,
    /// Also write the first-order lightmap (W/m², linear) as OpenEXR.
    #[arg(long)]
    first_order_out: Option<PathBuf>,
    /// Also write the transfer's input (W/m², linear; the first order averaged over each
    /// texel's square with --first-order-samples > 1) as OpenEXR: the final is the first
    /// order plus the maps applied to it, less it.
    #[arg(long)]
    transfer_input_out: Option<PathBuf>,
}

/// The rows path's pruning (`ortm render`, `ortm bench render`).
#[derive(clap::Args, Clone, Copy, Debug)]
pub struct RowsArgs {
    /// Rows path (the default on CPU adapters such as lavapipe): drop each texel's smallest
    /// entries while they sum to at most TAU of its row's weight, so its transfer changes by
    /// at most TAU · Σ|w| · the brightest first order read (docs/render.md, "Rows pruning");
    /// 0 keeps every entry.
    #[arg(long, value_name = "TAU", default_value_t = passes::rows::ROWS_PRUNE)]
    pub rows_prune: f32,
}

impl RowsArgs {
    /// `Err` naming the flag and the range when `--rows-prune` is not in `[0, 1)`.
    pub fn check(&self) -> Result<()> {
        let t = self.rows_prune;
        if !(t.is_finite() && (0.0..1.0).contains(&t)) {
            anyhow::bail!(
                "--rows-prune {t}: give a fraction of each row's weight from 0 (keep every \
                 entry) to below 1, e.g. {}",
                passes::rows::ROWS_PRUNE
            );
        }
        Ok(())
    }
}

/// Runs `ortm render`.
pub fn run(a: Args) -> Result<()> {
    let t0 = Instant::now();
    a.rows.check()?;
    // A bad --first-order-samples fails before the bake is opened (the default is chosen once
    // the device's limits are known, below).
    if let Some(n) = a.first_order_samples {
        super::solve::check_first_order_samples(n)?;
    }
    let (img_w, img_h) = render::parse_size(&a.size)?;
    let opened = a.bake.open(a.atlas_size)?;
    let effects = opened.effects();
    let BakeAndScene {
        set, source, scene, ..
    } = opened;
    let (w, h) = set.lightmap_size;
    let grid = TexelGrid::build_with_size(&scene, w, h)?;
    let lights = if a.bake.lights.is_empty() {
        scene.lights.clone()
    } else {
        a.bake.lights()?
    };
    if lights.is_empty() {
        eprintln!(
            "warning: no lights (the scene has none and no --light was given): the image is black"
        );
    }
    let light_descs: Vec<_> = lights.iter().map(render::light_desc).collect();
    let (atlases, pieces) = render::transfer_inputs(&set, (w, h))?;
    let t_load = t0.elapsed().as_secs_f64();

    let gpu = match Gpu::new_headless() {
        Ok(gpu) => gpu,
        // No adapter at all (no Vulkan driver): the CPU mirrors of the passes, unless a GPU
        // transfer path was asked for.
        Err(e @ passes::PassError::NoAdapter { .. }) if a.path == PathArg::Auto => {
            let cpu = super::render_cpu::CpuRender {
                grid: &grid,
                mesh: &scene.mesh,
                scene: &scene,
                effects,
                first_order_samples: super::solve::first_order_samples(
                    a.first_order_samples,
                    (w, h),
                    ortm::bake::lighting::DEFAULT_SAMPLES_CPU_BUDGET,
                    u32::MAX,
                )?,
                set: &set,
                lights: &lights,
                camera: camera(&a, &scene.mesh, (img_w, img_h))?,
                size: (img_w, img_h),
                side_by_side: a.side_by_side,
                exposure: render::parse_exposure(&a.exposure)?,
                output: &a.output,
                lightmap_out: a.lightmap_out.as_deref(),
                first_order_out: a.first_order_out.as_deref(),
                transfer_input_out: a.transfer_input_out.as_deref(),
            };
            return super::render_cpu::run(&cpu, &e);
        }
        Err(e) => return Err(e.into()),
    };
    let samples = super::solve::first_order_samples(
        a.first_order_samples,
        (w, h),
        ortm::bake::lighting::DEFAULT_SAMPLES_GPU_BUDGET,
        gpu.device.limits().max_texture_dimension_2d,
    )?;
    let options = renderer_options(&a, &gpu, &lights, (img_w, img_h), samples);
    let renderer = Renderer::new(&gpu, &options)?;
    let mesh = render::mesh_data(&scene.mesh);
    let mut rscene = renderer.prepare_with_weights(
        &gpu,
        &mesh,
        &render::albedo_map(&grid),
        &atlases,
        &pieces,
        Some(&render::texel_weights(&grid)),
    )?;
    if let Some(lengths) = render::diffusion_lengths(&scene, &grid, effects) {
        renderer.set_diffusion_lengths(&gpu, &mut rscene, &lengths)?;
    }
    let t1 = Instant::now();
    let (fo, fin) = renderer.render_lightmaps(&gpu, &rscene, &light_descs)?;
    let exposure =
        render::parse_exposure(&a.exposure)?.unwrap_or_else(|| render::auto_exposure(&fin));
    let params = FrameParams {
        lights: &light_descs,
        camera: camera(&a, &scene.mesh, (img_w, img_h))?,
        exposure,
        specular: None,
    };
    let img = renderer.render_image(&gpu, &rscene, &params)?;
    let t_gpu = t1.elapsed().as_secs_f64();
    crate::output::save_png_atomic(&img, &a.output)?;
    if let Some(p) = &a.lightmap_out {
        write_lightmap_exr(p, &to_lightmap(&fin))?;
    }
    if let Some(p) = &a.first_order_out {
        write_lightmap_exr(p, &to_lightmap(&fo))?;
    }
    if let Some(p) = &a.transfer_input_out {
        let input = gpu.read_texel_image(
            "ortm.render.transfer_input",
            rscene.first_order.transfer_input(),
        )?;
        write_lightmap_exr(p, &to_lightmap(&input))?;
    }
    let stats = set.stats();
    println!(
        "{}: {} covered texels at {w}x{h}, {} lights, {} atlases of {}x{} ({}), {} pieces of {} maps",
        scene.name,
        grid.texels.len(),
        lights.len(),
        stats.atlases,
        set.atlas_size.0,
        set.atlas_size.1,
        match source {
            AtlasSource::Files => "from atlases.json",
            AtlasSource::PackedFromMaps => "packed from the maps",
        },
        stats.pieces,
        stats.maps
    );
    println!(
        "adapter {} ({:?}); {:?} transfer; exposure {exposure:.4}",
        gpu.adapter_info.name, gpu.adapter_info.backend, options.transfer.path,
    );
    print_power(&grid, &fo, &fin);
    println!(
        "wrote {} ({img_w}x{img_h}){}{}{}; load {t_load:.2} s, GPU {t_gpu:.2} s",
        a.output.display(),
        optional_path(a.lightmap_out.as_deref()),
        optional_path(a.first_order_out.as_deref()),
        optional_path(a.transfer_input_out.as_deref()),
    );
    Ok(())
}

/// The renderer's options: `--shadow-size` with as many layers as `lights` need, the
/// `--path` transfer implementation, the image size and layout.
fn renderer_options(
    a: &Args,
    gpu: &Gpu,
    lights: &[Light],
    (width, height): (u32, u32),
    samples: u32,
) -> RendererOptions {
    let best = TransferOptions::best_for(gpu);
    let transfer = match a.path {
        PathArg::Auto => best,
        PathArg::Blend => TransferOptions {
            path: TransferPath::Blend,
            ..best
        },
        PathArg::Compute => TransferOptions {
            path: TransferPath::Compute,
            ..best
        },
        PathArg::Rows => TransferOptions {
            path: TransferPath::Rows,
            ..best
        },
    };
    RendererOptions {
        first_order: FirstOrderOptions {
            shadow_map_size: a.shadow_size,
            max_shadow_layers: render::shadow_layers_for(lights),
            samples,
            ..Default::default()
        },
        transfer: TransferOptions {
            rows_prune: a.rows.rows_prune,
            ..transfer
        },
        display: DisplayOptions {
            width,
            height,
            side_by_side: a.side_by_side,
            direct: a.display.direct.direct(),
            sampling: a.display.filter.sampling(),
            ..Default::default()
        },
        ..Default::default()
    }
}

/// `--camera`, or the default camera framing `mesh` in one image (half of it side by side).
fn camera(a: &Args, mesh: &ortm::scene::Mesh, (img_w, img_h): (u32, u32)) -> Result<Camera> {
    let aspect = if a.side_by_side {
        (img_w / 2).max(1) as f32 / img_h as f32
    } else {
        img_w as f32 / img_h as f32
    };
    Ok(match &a.camera {
        Some(spec) => render::parse_camera(spec, a.fov, bounding_radius(mesh))?,
        None => render::default_camera(mesh, aspect, a.fov),
    })
}

/// `", PATH"` for an optional output file, else nothing.
fn optional_path(p: Option<&Path>) -> String {
    p.map(|p| format!(", {}", p.display())).unwrap_or_default()
}

/// Prints the first-order and final power `Σ B·A` (W, RGB) over the covered texels, the line
/// `ortm solve` prints.
pub fn print_power(grid: &TexelGrid, first_order: &TexelImage, final_map: &TexelImage) {
    let power = |img: &TexelImage| {
        let values: Vec<glam::Vec3> = grid
            .texels
            .iter()
            .map(|t| {
                let p = img.rgba[(t.y * img.width + t.x) as usize];
                glam::Vec3::new(p[0], p[1], p[2])
            })
            .collect();
        ortm::accuracy::compare::power_w(grid, &values).to_array()
    };
    println!(
        "first-order power {:.4?} W, final {:.4?} W (RGB)",
        power(first_order),
        power(final_map)
    );
}

/// Half the diagonal of the mesh's bounding box, metres.
pub fn bounding_radius(mesh: &ortm::scene::Mesh) -> f32 {
    mesh.bounding_sphere().map_or(1.0, |(_, r)| r)
}
