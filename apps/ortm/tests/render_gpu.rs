//! Acceptance tests of `ortm render`'s GPU path (wgpu on Mesa's lavapipe on CI; never
//! skipped: a machine without an adapter fails with the passes' installation advice).
//!
//! 1. The GPU final lightmap equals the CPU reference of Eq. 9 (`ortm::maps::apply`) applied
//!    to the GPU's own first-order lightmap (read back), for the Cornell box (32², 30
//!    jittered-grid offsets) and the subsurface head (64², 40 offsets), with real baked maps
//!    packed into atlases by `ortm::atlas::build_atlas_set`.
//! 2. The GPU first-order lightmap (shadow maps) equals `ortm::bake::lighting::first_order` (exact
//!    ray-cast shadows) on the Cornell box away from shadow edges.
//! 3. A rendered Cornell frame matches the stored reference `tests/data/render/cornell_frame.png`
//!    (tolerant metric). Regenerate it after an intended change of the display with
//!    `ORTM_UPDATE_REFERENCE=1 cargo test --test render_gpu reference_frame` and look at it.

mod common;

use glam::{IVec2, Vec3};
use ortm::atlas::build_atlas_set;
use ortm::bake::raycast::Visibility;
use ortm::bake::texels::TexelGrid;
use ortm::bake::transport::{Effects, Transport};
use ortm::bake::{BakeEvent, bake_maps};
use ortm::maps::TransferMap;
use ortm::render;
use ortm::scene::Scene;
use passes::display::{Camera, DisplayOptions};
use passes::first_order::FirstOrderOptions;
use passes::frame::{FrameParams, Renderer, RendererOptions};
use passes::gpu::ExclusiveGpu;
use passes::transfer::TransferOptions;
use passes::{Gpu, TexelImage};

/// One test's device at a time (`new_headless_exclusive`: NVIDIA's driver crashes when test
/// threads use devices at once).
fn gpu() -> ExclusiveGpu {
    Gpu::new_headless_exclusive().unwrap_or_else(|e| panic!("{e}"))
}

/// Scene, grid and baked maps (jittered-grid offsets, default effects, 8² coarse clusters).
fn bake(mut scene: Scene, size: u32, offsets: usize) -> (Scene, TexelGrid, Vec<TransferMap>) {
    scene.lightmap_size = (size, size);
    let grid = TexelGrid::build_with_size(&scene, size, size).unwrap();
    let transport = Transport::new(&scene, &grid, Effects::default(), 8);
    let list = ortm::bake::offsets::select_jittered_grid(size, size, offsets, 7).unwrap();
    let maps = bake_maps(
        &transport,
        &grid,
        &list,
        ortm::bake::CellRule::Integrated,
        &|_: BakeEvent| {},
    )
    .unwrap();
    (scene, grid, maps)
}

fn head(size: u32) -> Scene {
    let mut s = ortm::scene::load_scene(&common::data("render/head.toml")).unwrap();
    s.lightmap_size = (size, size);
    s
}

fn renderer(gpu: &Gpu, scene: &Scene, shadow: u32, display: DisplayOptions) -> Renderer {
    let options = RendererOptions {
        first_order: FirstOrderOptions {
            shadow_map_size: shadow,
            max_shadow_layers: render::shadow_layers_for(&scene.lights),
            ..Default::default()
        },
        transfer: TransferOptions::best_for(gpu),
        display,
        ..Default::default()
    };
    Renderer::new(gpu, &options).unwrap()
}

/// GPU `(first order, final)` lightmaps of the scene's lights with the maps packed in
/// `atlas`² atlases.
fn gpu_lightmaps(
    gpu: &Gpu,
    scene: &Scene,
    grid: &TexelGrid,
    maps: &[TransferMap],
    atlas: u32,
) -> (TexelImage, TexelImage) {
    let set = build_atlas_set(maps, atlas, atlas).unwrap();
    let (atlases, pieces) = render::transfer_inputs(&set, scene.lightmap_size).unwrap();
    let r = renderer(gpu, scene, 512, DisplayOptions::default());
    let rs = r
        .prepare(
            gpu,
            &render::mesh_data(&scene.mesh),
            &render::albedo_map(grid),
            &atlases,
            &pieces,
        )
        .unwrap();
    let lights: Vec<_> = scene.lights.iter().map(render::light_desc).collect();
    r.render_lightmaps(gpu, &rs, &lights).unwrap()
}

/// Checks `gpu_final` against `maps::apply(maps, gpu_first_order)` texel by texel:
/// `|g − c| ≤ 1e-3·|c| + (2n + 1)·(2⁻²⁴·S(t) + 2⁻¹²⁶)`, with `n` the number of terms at `t` (first
/// order + one per map) and `S(t) = |B_o(t)| + Σ |map(t)·B_o(t+Δt)|`. The second term is the
/// forward error bound of f32 recursive summation of `n` products (one rounding per product
/// and per addition, the GPU's arithmetic; the CPU rounds once from f64): it only matters
/// where the terms cancel (subsurface maps hold the negative point mass at Δt = 0), where a
/// relative tolerance on the small result would be meaningless. `(2n + 1)·2⁻¹²⁶` more allows
/// for GPUs flushing subnormal results to zero (WGSL permits it; lavapipe does), one smallest
/// normal float per operation. The default blend path pairs pieces and stores their values as
/// binary16 with a per-piece power-of-two scale (`passes::pairing`): each value errs by at
/// most `2⁻¹¹·|v| + 2⁻²⁹·M` (M = the piece's largest |value|, bounded here by its map's), so
/// `2⁻¹¹·Σ|map(t)·B_o(t+Δt)| + 2⁻²⁹·Σ M·|B_o(t+Δt)|` more. Returns the number of texels
/// where the transfer added more than 1 % of the first order.
fn check_final(maps: &[TransferMap], fo: &TexelImage, fin: &TexelImage) -> usize {
    let b_o = render::to_lightmap(fo);
    let cpu = ortm::maps::apply(maps, &b_o).unwrap();
    let (w, h) = (b_o.width, b_o.height);
    let mut brighter = 0;
    let mut worst = 0f64;
    // Largest |value| of each map (over its texels and channels).
    let map_max: Vec<f64> = maps
        .iter()
        .map(|m| {
            let mut mx = 0f64;
            for y in 0..h {
                for x in 0..w {
                    for v in m.value_at(x, y) {
                        mx = mx.max((v as f64).abs());
                    }
                }
            }
            mx
        })
        .collect();
    for y in 0..h {
        for x in 0..w {
            let g = fin.get(x, y);
            let c = cpu.get(x, y);
            let bo = b_o.get(x, y);
            for ch in 0..3 {
                let mut s = bo[ch].abs() as f64;
                let mut n = 1;
                let mut products = 0f64;
                let mut scaled = 0f64;
                for (m, mx) in maps.iter().zip(&map_max) {
                    let p = IVec2::new(x as i32, y as i32) + m.offset;
                    let v = m.value_at(x, y)[ch] as f64;
                    if v != 0.0 {
                        let src = b_o.get_checked(p).map_or(0.0, |b| b[ch] as f64);
                        s += (v * src).abs();
                        products += (v * src).abs();
                        scaled += mx * src.abs();
                        n += 1;
                    }
                }
                let ops = (2 * n + 1) as f64;
                let binary16 = 2f64.powi(-11) * products + 2f64.powi(-29) * scaled;
                let tol = 1e-3 * c[ch].abs() as f64
                    + ops * (2f64.powi(-24) * s + 2f64.powi(-126))
                    + binary16;
                let err = (g[ch] as f64 - c[ch] as f64).abs();
                worst = worst.max(err / tol.max(f64::MIN_POSITIVE));
                assert!(
                    err <= tol,
                    "texel ({x}, {y}) channel {ch}: GPU {} vs CPU {} (|Δ| {err:.3e} > tol {tol:.3e}, \
                     {n} terms, Σ|terms| {s:.3e})",
                    g[ch],
                    c[ch]
                );
            }
            if c[1] as f64 > 1.01 * bo[1] as f64 + 1e-6 {
                brighter += 1;
            }
        }
    }
    eprintln!("final vs CPU apply: worst |Δ|/tol = {worst:.3e}");
    brighter
}

#[test]
fn cornell_final_lightmap_equals_cpu_apply_of_gpu_first_order() {
    let gpu = gpu();
    let (scene, grid, maps) = bake(ortm::scene::cornell_box(32), 32, 30);
    let (fo, fin) = gpu_lightmaps(&gpu, &scene, &grid, &maps, 256);
    let brighter = check_final(&maps, &fo, &fin);
    assert!(
        brighter > grid.texels.len() / 4,
        "interreflection must brighten many texels ({brighter} of {})",
        grid.texels.len()
    );
}

#[test]
fn head_final_lightmap_equals_cpu_apply_of_gpu_first_order() {
    let gpu = gpu();
    let (scene, grid, maps) = bake(head(64), 64, 40);
    assert!(
        maps.iter().any(|m| m.offset == IVec2::ZERO
            && m.crops().iter().flat_map(|c| &c.data).any(|v| v[0] < 0.0)),
        "the skin's Δt = 0 map must carry the negative subsurface point mass"
    );
    let (fo, fin) = gpu_lightmaps(&gpu, &scene, &grid, &maps, 1024);
    let lit = fo.rgba.iter().filter(|p| p[1] > 0.0).count();
    assert!(
        lit > grid.texels.len() / 5,
        "the head must be lit ({lit} texels)"
    );
    check_final(&maps, &fo, &fin);
}

/// One pass: the CPU reference, the per-texel light masks that find shadow edges and the GPU
/// lightmap are compared texel by texel in a single loop.
#[test]
fn cornell_first_order_matches_ray_cast_shadows_away_from_edges() {
    let gpu = gpu();
    let size = 64;
    let mut scene = ortm::scene::cornell_box(size);
    scene.lightmap_size = (size, size);
    let grid = TexelGrid::build(&scene).unwrap();
    let vis = Visibility::new(&scene.mesh);
    let cpu = ortm::bake::lighting::to_lightmap(
        &grid,
        &ortm::bake::lighting::first_order(&grid, &scene.lights, &vis),
    );
    // Per-texel light mask: bit l set when light l reaches the texel (front-facing and unoccluded).
    let mut mask = vec![u32::MAX; (size * size) as usize];
    for t in &grid.texels {
        let mut m = 0;
        for (l, light) in scene.lights.iter().enumerate() {
            let e = ortm::bake::lighting::irradiance_unshadowed(t, light);
            if e != Vec3::ZERO && ortm::bake::lighting::light_visible(t, light, &vis) {
                m |= 1 << l;
            }
        }
        mask[(t.y * size + t.x) as usize] = m;
    }
    let r = renderer(&gpu, &scene, 1024, DisplayOptions::default());
    let rs = r
        .prepare(
            &gpu,
            &render::mesh_data(&scene.mesh),
            &render::albedo_map(&grid),
            &[],
            &[],
        )
        .unwrap();
    let lights: Vec<_> = scene.lights.iter().map(render::light_desc).collect();
    let (fo, _) = r.render_lightmaps(&gpu, &rs, &lights).unwrap();

    let max = cpu.data.iter().flatten().fold(0f32, |a, &b| a.max(b));
    let (mut compared, mut shadowed) = (0usize, 0usize);
    for t in &grid.texels {
        let g = fo.get(t.x, t.y);
        assert_eq!(
            g[3], 1.0,
            "texel ({}, {}) covered on the CPU but not the GPU",
            t.x, t.y
        );
        let m = mask[(t.y * size + t.x) as usize];
        let edge = (-1..=1).any(|dy| {
            (-1..=1).any(|dx| {
                grid.at(t.x as i32 + dx, t.y as i32 + dy).is_some_and(|j| {
                    let n = &grid.texels[j as usize];
                    mask[(n.y * size + n.x) as usize] != m
                })
            })
        });
        if edge {
            continue;
        }
        compared += 1;
        shadowed += (m == 0) as usize;
        let c = cpu.get(t.x, t.y);
        for ch in 0..3 {
            // 1e-3 relative (f32 light evaluation, interpolated vs stored texel positions)
            // plus 1e-5 of the map's maximum for texels at grazing angles where E → 0.
            let tol = 1e-3 * c[ch].abs() + 1e-5 * max;
            assert!(
                (g[ch] - c[ch]).abs() <= tol,
                "texel ({}, {}) ch {ch}: GPU {} vs ray-cast {} (mask {m})",
                t.x,
                t.y,
                g[ch],
                c[ch]
            );
        }
    }
    let covered_gpu = fo.rgba.iter().filter(|p| p[3] == 1.0).count();
    assert_eq!(covered_gpu, grid.texels.len(), "coverage differs");
    let fraction = compared as f64 / grid.texels.len() as f64;
    eprintln!(
        "first order: compared {compared} of {} covered texels ({:.1} %), {shadowed} of them in shadow",
        grid.texels.len(),
        100.0 * fraction
    );
    assert!(
        fraction > 0.8,
        "too few texels away from shadow edges: {fraction}"
    );
    assert!(
        shadowed > 20,
        "the blocks must cast shadows that are compared too"
    );
}

#[test]
fn reference_frame_matches_stored_png() {
    let gpu = gpu();
    let (scene, grid, maps) = bake(ortm::scene::cornell_box(32), 32, 30);
    let set = build_atlas_set(&maps, 256, 256).unwrap();
    let (atlases, pieces) = render::transfer_inputs(&set, scene.lightmap_size).unwrap();
    let display = DisplayOptions {
        width: 256,
        height: 128,
        side_by_side: true,
    };
    let r = renderer(&gpu, &scene, 512, display);
    let rs = r
        .prepare(
            &gpu,
            &render::mesh_data(&scene.mesh),
            &render::albedo_map(&grid),
            &atlases,
            &pieces,
        )
        .unwrap();
    let lights: Vec<_> = scene.lights.iter().map(render::light_desc).collect();
    let camera: Camera = render::default_camera(&scene.mesh, 1.0, 40.0);
    let img = r
        .render_image(
            &gpu,
            &rs,
            &FrameParams {
                lights: &lights,
                camera,
                exposure: 0.04,
                specular: None,
            },
        )
        .unwrap();
    let path = common::data("render/cornell_frame.png");
    if std::env::var_os("ORTM_UPDATE_REFERENCE").is_some() {
        img.save(&path).unwrap();
        eprintln!("wrote {}", path.display());
    }
    let want = image::open(&path)
        .unwrap_or_else(|e| {
            panic!(
                "cannot read {} ({e}); regenerate it with ORTM_UPDATE_REFERENCE=1 cargo test \
                 --test render_gpu reference_frame",
                path.display()
            )
        })
        .to_rgba8();
    assert_eq!(want.dimensions(), img.dimensions());
    let mut diffs: Vec<u8> = img
        .as_raw()
        .iter()
        .zip(want.as_raw())
        .map(|(a, b)| a.abs_diff(*b))
        .collect();
    let mean = diffs.iter().map(|&d| d as f64).sum::<f64>() / diffs.len() as f64;
    let k = diffs.len() * 99 / 100;
    let p99 = *diffs.select_nth_unstable(k).1;
    eprintln!("frame vs reference: mean |Δ| {mean:.3}/255, 99th percentile {p99}/255");
    assert!(mean < 2.0, "mean abs diff {mean}/255 ≥ 2/255");
    assert!(p99 < 10, "99th percentile {p99}/255 ≥ 10/255");
    // The image is not blank: the lit box differs from the background in most of its area.
    let bg = passes::display::BACKGROUND;
    let non_bg = img.pixels().filter(|p| p.0 != bg).count();
    assert!(
        non_bg > (256 * 128) / 4,
        "only {non_bg} non-background pixels"
    );
}

#[test]
fn lightmap_size_mismatch_between_atlases_and_scene_is_an_error() {
    let (_, _, maps) = bake(ortm::scene::cornell_box(32), 32, 4);
    let set = build_atlas_set(&maps, 128, 128).unwrap();
    let e = render::transfer_inputs(&set, (64, 64))
        .unwrap_err()
        .to_string();
    assert!(e.contains("32×32") && e.contains("64×64"), "{e}");
}
