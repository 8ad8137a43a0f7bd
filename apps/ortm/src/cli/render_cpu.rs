//! `ortm render` where no GPU adapter exists (a fresh machine without a Vulkan driver): the
//! same outputs from the CPU mirrors of the passes, slower, so that the README's first command
//! runs its main job anywhere. Chosen only by `--path auto`; the command says which ran.
//!
//! # Data flow (each step the CPU mirror of a GPU pass)
//! - first order: [`ortm::bake::lighting::first_order`], ray-cast shadows through the mesh's
//!   BVH (exact visibility instead of shadow maps), W/m² per covered texel;
//! - transfer (Eq. 9): [`ortm::atlas::apply_atlas_pieces`] over every atlas piece, as the
//!   viewer's CPU mirror does;
//! - dilation: [`passes::cpu::dilate::dilate`] with the renderer's default gutter rings;
//! - display: one ray per pixel centre from the camera ([`Visibility::closest_triangle_hit`]
//!   in place of rasterisation), the hit's lightmap UV looked up with
//!   [`passes::cpu::display::bilinear`] and shaded with [`passes::cpu::display::shade`]
//!   (`B/π`, exposure, Reinhard, sRGB); misses show [`passes::display::BACKGROUND`].
//!
//! The lightmaps match the GPU's up to shadow-map aliasing; the frame up to rasterisation
//! rules at silhouettes.

use anyhow::Result;
use glam::{Vec2, Vec3};
use image::RgbaImage;
use ortm::atlas::{AtlasSet, apply_atlas_pieces};
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::Effects;
use ortm::scene::{Light, Mesh};
use passes::TexelImage;
use passes::dilate::{DilateOptions, DilatePlan};
use passes::display::{BACKGROUND, Camera};
use rayon::prelude::*;

/// The CPU mirrors' outputs: first-order and final lightmaps (undilated, W/m², alpha =
/// coverage), the same as the GPU renderer's read-backs.
pub struct CpuLightmaps {
    /// First order with ray-cast shadows.
    pub first_order: TexelImage,
    /// First order plus every map's transfer (Eq. 9) of the transfer's input.
    pub final_map: TexelImage,
    /// The transfer's input (the first order averaged over each texel's square).
    pub transfer_input: TexelImage,
}

/// First-order and final lightmaps of `lights` on the CPU (see the module docs), the
/// transfer's input averaged over `samples × samples` sub-texels per texel (odd; 1: the
/// centres) as `--first-order-samples` makes the GPU's (translucent texels: those of a
/// subsurface material when the maps hold the subsurface term, `effects`, as the display's
/// diffusion lengths say).
pub fn lightmaps(
    scene: &ortm::scene::Scene,
    grid: &TexelGrid,
    set: &AtlasSet,
    lights: &[Light],
    samples: u32,
    effects: Effects,
) -> Result<CpuLightmaps> {
    use ortm::bake::lighting;
    let vis = Visibility::new(&scene.mesh);
    let (values, input) =
        lighting::first_order_and_input(scene, grid, lights, &vis, samples, |m| {
            effects.subsurface && scene.is_translucent(m)
        })?;
    let first = lighting::to_lightmap(grid, &values);
    let input_map = lighting::to_lightmap(grid, &input);
    let fin = apply_atlas_pieces(set, |_| true, &input_map, Some(&grid.area_map()))?;
    let mut fin_values = lighting::from_lightmap(grid, &fin);
    lighting::with_first_order(&mut fin_values, &values, &input);
    let fin = lighting::to_lightmap(grid, &fin_values);
    let to_image = |map: &ortm::Lightmap| {
        let mut img = TexelImage::new(grid.width, grid.height);
        for t in &grid.texels {
            let i = (t.y * grid.width + t.x) as usize;
            let v = map.data[i];
            img.rgba[i] = [v[0], v[1], v[2], 1.0];
        }
        img
    };
    Ok(CpuLightmaps {
        first_order: to_image(&first),
        final_map: to_image(&fin),
        transfer_input: to_image(&input_map),
    })
}

/// The displayed frame of `maps` seen by `camera`: `size` pixels, the first order left of the
/// final when `side_by_side`, at `exposure` (multiplying `B/π`).
pub fn frame(
    grid: &TexelGrid,
    mesh: &Mesh,
    maps: &CpuLightmaps,
    camera: &Camera,
    (width, height): (u32, u32),
    side_by_side: bool,
    exposure: f32,
) -> Result<RgbaImage> {
    let covered: Vec<bool> = maps.final_map.rgba.iter().map(|p| p[3] > 0.0).collect();
    let plan = DilatePlan::new(
        grid.width,
        grid.height,
        &covered,
        DilateOptions::default().rings,
    )?;
    let final_d = passes::cpu::dilate::dilate(&maps.final_map, &plan)?;
    let first_d = passes::cpu::dilate::dilate(&maps.first_order, &plan)?;
    let vis = Visibility::new(mesh);
    let view_w = if side_by_side {
        (width / 2).max(1)
    } else {
        width
    };
    let rows: Vec<Vec<[u8; 4]>> = (0..height)
        .into_par_iter()
        .map(|y| {
            (0..width)
                .map(|x| {
                    let (map, vx) = if side_by_side && x < view_w {
                        (&first_d, x)
                    } else if side_by_side {
                        (&final_d, x - view_w)
                    } else {
                        (&final_d, x)
                    };
                    let uv = pixel_uv(&vis, mesh, camera, (vx, y), (view_w, height));
                    uv.map_or(BACKGROUND, |uv| {
                        passes::cpu::display::shade(
                            passes::cpu::display::bilinear(map, uv.to_array()),
                            exposure,
                        )
                    })
                })
                .collect()
        })
        .collect();
    let mut img = RgbaImage::new(width, height);
    for (y, row) in rows.iter().enumerate() {
        for (x, px) in row.iter().enumerate() {
            img.put_pixel(x as u32, y as u32, image::Rgba(*px));
        }
    }
    Ok(img)
}

/// The lightmap UV seen through the centre of pixel `(x, y)` of a `w × h` view (row 0 at the
/// top), or `None` where the ray misses the mesh within the camera's depth range.
fn pixel_uv(
    vis: &Visibility,
    mesh: &Mesh,
    camera: &Camera,
    (x, y): (u32, u32),
    (w, h): (u32, u32),
) -> Option<Vec2> {
    let eye = Vec3::from(camera.eye);
    let forward = (Vec3::from(camera.target) - eye).normalize();
    let right = forward.cross(Vec3::from(camera.up)).normalize();
    let up = right.cross(forward);
    let tan = (camera.fov_y_deg.to_radians() * 0.5).tan();
    let aspect = w as f32 / h as f32;
    let ndc_x = (x as f32 + 0.5) / w as f32 * 2.0 - 1.0;
    let ndc_y = 1.0 - (y as f32 + 0.5) / h as f32 * 2.0;
    let dir = (forward + right * (ndc_x * tan * aspect) + up * (ndc_y * tan)).normalize();
    // The near and far planes are distances along the view axis; convert for this ray.
    let along = dir.dot(forward).max(1e-6);
    let hit = vis.closest_triangle_hit(
        eye,
        dir,
        (camera.near / along, camera.far / along),
        u32::MAX,
    )?;
    let tri = &mesh.triangles[hit.triangle as usize];
    let uv = (0..3).fold(Vec2::ZERO, |acc, k| {
        acc + mesh.uvs[tri.uv[k] as usize] * hit.barycentrics[k]
    });
    Some(uv)
}

/// What `ortm render` hands over when it falls back to the CPU.
pub struct CpuRender<'a> {
    /// The bake's lightmap texels.
    pub grid: &'a TexelGrid,
    /// The scene's mesh.
    pub mesh: &'a Mesh,
    /// The scene (materials: which texels are translucent).
    pub scene: &'a ortm::scene::Scene,
    /// The effects the bake's maps hold (translucent texels only with the subsurface term).
    pub effects: Effects,
    /// `--first-order-samples`.
    pub first_order_samples: u32,
    /// The bake's atlases (from `atlases.json` or packed in memory).
    pub set: &'a AtlasSet,
    /// The lights.
    pub lights: &'a [Light],
    /// The camera of the frame.
    pub camera: Camera,
    /// Frame size, pixels.
    pub size: (u32, u32),
    /// First order left of final.
    pub side_by_side: bool,
    /// `--exposure` (`None`: automatic).
    pub exposure: Option<f32>,
    /// The frame PNG.
    pub output: &'a std::path::Path,
    /// `--lightmap-out`.
    pub lightmap_out: Option<&'a std::path::Path>,
    /// `--first-order-out`.
    pub first_order_out: Option<&'a std::path::Path>,
    /// `--transfer-input-out`.
    pub transfer_input_out: Option<&'a std::path::Path>,
}

/// Renders on the CPU and writes the outputs `ortm render` writes, saying that the CPU mirrors
/// ran and why.
pub fn run(r: &CpuRender, why: &passes::PassError) -> Result<()> {
    eprintln!(
        "note: {why}\nnote: rendering on the CPU mirrors of the passes instead (ray-cast \
         shadows, all light from the lightmaps as with --direct lightmap; slower than a GPU); \
         --path blend or --path compute requires a GPU"
    );
    let t = std::time::Instant::now();
    let maps = lightmaps(
        r.scene,
        r.grid,
        r.set,
        r.lights,
        r.first_order_samples,
        r.effects,
    )?;
    let exposure = r
        .exposure
        .unwrap_or_else(|| ortm::render::auto_exposure(&maps.final_map));
    let img = frame(
        r.grid,
        r.mesh,
        &maps,
        &r.camera,
        r.size,
        r.side_by_side,
        exposure,
    )?;
    crate::output::save_png_atomic(&img, r.output)?;
    let to_map = ortm::render::to_lightmap;
    if let Some(p) = r.lightmap_out {
        ortm::render::write_lightmap_exr(p, &to_map(&maps.final_map))?;
    }
    if let Some(p) = r.first_order_out {
        ortm::render::write_lightmap_exr(p, &to_map(&maps.first_order))?;
    }
    if let Some(p) = r.transfer_input_out {
        ortm::render::write_lightmap_exr(p, &to_map(&maps.transfer_input))?;
    }
    println!(
        "renderer: CPU mirrors of the passes (no GPU adapter); {} covered texels at {}x{}, {} \
         lights; exposure {exposure:.4}",
        r.grid.texels.len(),
        r.grid.width,
        r.grid.height,
        r.lights.len()
    );
    super::render::print_power(r.grid, &maps.first_order, &maps.final_map);
    let extra: String = [r.lightmap_out, r.first_order_out, r.transfer_input_out]
        .into_iter()
        .flatten()
        .map(|p| format!(", {}", p.display()))
        .collect();
    println!(
        "wrote {} ({}x{}){extra}; CPU {:.2} s",
        r.output.display(),
        r.size.0,
        r.size.1,
        t.elapsed().as_secs_f64()
    );
    Ok(())
}
