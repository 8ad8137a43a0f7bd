//! Display pass: exact shading of uniform lightmaps against the CPU mirror, the
//! side-by-side layout, the specular term at a known pixel, every pixel of a magnified
//! lightmap against the CPU mirror's bilinear lookup (both lightmap filters), the diffuse and
//! specular pipelines agreeing, and an end-to-end frame (first order → dilate → display)
//! whose lit side is brighter.

mod common;

use common::demo::floor_and_box;
use common::gpu;
use glam::Vec3;
use passes::cpu::display::{bilinear, shade, specular, tonemap};
use passes::dilate::{DilateInputs, DilateOptions, DilatePass};
use passes::display::{
    BACKGROUND, Camera, DisplayInputs, DisplayOptions, DisplayPass, LightmapFilter, Specular,
};
use passes::first_order::{
    Bounds, FirstOrderInputs, FirstOrderOptions, FirstOrderPass, pack_lights,
};
use passes::{Gpu, LightDesc, MeshData, TexelImage};

fn uniform_map(gpu: &Gpu, b: [f32; 3]) -> wgpu::TextureView {
    lightmap_view(
        gpu,
        "test.uniform_map",
        64,
        &vec![[b[0], b[1], b[2], 1.0]; 64 * 64],
    )
}

/// Side of [`gradient_map`], texels.
const GRADIENT_SIDE: u32 = 64;

/// A lightmap that varies across texels: R = step·x, G = step·y, B = `b`, covered.
fn gradient_map(gpu: &Gpu, step: f32, b: f32) -> wgpu::TextureView {
    let n = GRADIENT_SIDE as usize;
    let texels: Vec<[f32; 4]> = (0..n * n)
        .map(|i| [(i % n) as f32 * step, (i / n) as f32 * step, b, 1.0])
        .collect();
    lightmap_view(gpu, "test.gradient", n as u32, &texels)
}

/// A `side × side` RGBA32F lightmap texture's view.
fn lightmap_view(gpu: &Gpu, label: &str, side: u32, texels: &[[f32; 4]]) -> wgpu::TextureView {
    let tex = gpu
        .create_rgba32f_texture(
            label,
            side,
            side,
            texels,
            wgpu::TextureUsages::TEXTURE_BINDING,
        )
        .unwrap();
    tex.create_view(&Default::default())
}

fn oblique_camera() -> Camera {
    Camera {
        eye: [2.0, 2.0, 3.0],
        target: [0.0, 0.2, 0.0],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 45.0,
        near: 0.05,
        far: 20.0,
    }
}

/// The lightmap filters to test: always the manual one, the hardware one with
/// `FLOAT32_FILTERABLE` (lavapipe has it; a failure where the adapter has it but the device
/// does not).
fn filters(gpu: &Gpu) -> Vec<LightmapFilter> {
    if common::has_feature(
        gpu,
        wgpu::Features::FLOAT32_FILTERABLE,
        "LightmapFilter::Hardware",
    ) {
        vec![LightmapFilter::Manual, LightmapFilter::Hardware]
    } else {
        vec![LightmapFilter::Manual]
    }
}

fn render(
    gpu: &Gpu,
    mesh: &MeshData,
    options: DisplayOptions,
    inputs: impl FnOnce(&passes::display::DisplayScene, &mut dyn FnMut(&DisplayInputs<'_>)),
) -> image::RgbaImage {
    render_with(gpu, LightmapFilter::best_for(gpu), mesh, options, inputs)
}

fn render_with(
    gpu: &Gpu,
    filter: LightmapFilter,
    mesh: &MeshData,
    options: DisplayOptions,
    inputs: impl FnOnce(&passes::display::DisplayScene, &mut dyn FnMut(&DisplayInputs<'_>)),
) -> image::RgbaImage {
    let pass = DisplayPass::with_filter(gpu, &options, filter).unwrap();
    assert_eq!(pass.filter(), filter);
    let scene = pass.prepare(gpu, mesh).unwrap();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let mut out = None;
    inputs(&scene, &mut |i| {
        out = Some(pass.encode(gpu, &mut enc, i).unwrap())
    });
    let out = out.unwrap();
    gpu.submit_and_wait("test.display", enc).unwrap();
    gpu.read_rgba8("test.display", &out.color_tex).unwrap()
}

fn close(a: [u8; 4], b: [u8; 4], tol: i32) -> bool {
    a.iter()
        .zip(&b)
        .all(|(x, y)| (*x as i32 - *y as i32).abs() <= tol)
}

#[test]
fn uniform_lightmap_and_side_by_side_shade_exactly() {
    let gpu = gpu();
    let (mesh, _) = floor_and_box(64);
    let (b1, b2) = ([2.0, 1.0, 0.5], [0.3, 3.0, 9.0]);
    let (v1, v2) = (uniform_map(&gpu, b1), uniform_map(&gpu, b2));
    let (s1, s2) = (shade(b1, 1.5), shade(b2, 1.5));
    for filter in filters(&gpu) {
        uniform_side_by_side(&gpu, filter, &mesh, (&v1, s1), (&v2, s2));
    }
}

fn uniform_side_by_side(
    gpu: &Gpu,
    filter: LightmapFilter,
    mesh: &MeshData,
    (v1, s1): (&wgpu::TextureView, [u8; 4]),
    (v2, s2): (&wgpu::TextureView, [u8; 4]),
) {
    let img = render_with(
        gpu,
        filter,
        mesh,
        DisplayOptions {
            width: 128,
            height: 64,
            side_by_side: true,
            direct: passes::display::DirectLight::Lightmap,
            ..Default::default()
        },
        |scene, draw| {
            draw(&DisplayInputs {
                scene,
                final_lightmap: v2,
                lightmap_size: [64, 64],
                first_order: Some(v1),
                camera: oblique_camera(),
                exposure: 1.5,
                lights: &[],
                specular: None,
                direct: None,
            })
        },
    );
    let mut mesh_px = [0usize; 2];
    for y in 0..64 {
        for x in 0..64 {
            let l = img.get_pixel(x, y).0;
            let r = img.get_pixel(x + 64, y).0;
            // Same camera in both halves: same coverage.
            assert_eq!(
                l == BACKGROUND,
                r == BACKGROUND,
                "coverage differs at ({x}, {y})"
            );
            if l != BACKGROUND {
                assert!(
                    close(l, s1, 1),
                    "{filter:?}: left ({x}, {y}) {l:?} vs {s1:?}"
                );
                assert!(
                    close(r, s2, 1),
                    "{filter:?}: right ({x}, {y}) {r:?} vs {s2:?}"
                );
                mesh_px[0] += 1;
            }
        }
    }
    assert!(
        mesh_px[0] > 64 * 64 / 8,
        "{filter:?}: mesh covers too little: {mesh_px:?}"
    );
}

#[test]
fn specular_highlight_matches_mirror_at_centre() {
    // Camera straight above the floor centre... the box is there, so look at a floor
    // point beside it: eye above (−0.6, 0, −0.6), directional light straight down: at the
    // centre pixel h = n and the highlight is maximal.
    let gpu = gpu();
    let (mesh, _) = floor_and_box(64);
    let b = [0.5, 0.5, 0.5];
    let map = uniform_map(&gpu, b);
    let target = [-0.6, 0.0, -0.6];
    let eye = [-0.6, 1.5, -0.6];
    let lights = [LightDesc::Directional {
        direction: [0.0, -1.0, 0.0],
        color: [1.0; 3],
        irradiance_w_m2: 2.0,
    }];
    let spec = Specular {
        strength: 0.04,
        shininess: 32.0,
    };
    for filter in filters(&gpu) {
        let img = render_with(
            &gpu,
            filter,
            &mesh,
            DisplayOptions {
                width: 33,
                height: 33,
                side_by_side: false,
                direct: passes::display::DirectLight::Lightmap,
                ..Default::default()
            },
            |scene, draw| {
                draw(&DisplayInputs {
                    scene,
                    final_lightmap: &map,
                    lightmap_size: [64, 64],
                    first_order: None,
                    camera: Camera {
                        eye,
                        target,
                        up: [0.0, 0.0, -1.0],
                        fov_y_deg: 30.0,
                        near: 0.05,
                        far: 10.0,
                    },
                    exposure: 1.0,
                    lights: &lights,
                    specular: Some(spec),
                    direct: None,
                })
            },
        );
        let (gl, _) = pack_lights(&lights, &Bounds::of(&mesh.positions_m), 1, 99).unwrap();
        let s = specular(
            &gl,
            Vec3::from(target),
            Vec3::Y,
            Vec3::from(eye),
            spec.strength,
            spec.shininess,
        );
        let pi = std::f32::consts::PI;
        let want = tonemap([b[0] / pi + s.x, b[1] / pi + s.y, b[2] / pi + s.z], 1.0);
        let got = img.get_pixel(16, 16).0;
        assert!(
            close(got, want, 2),
            "{filter:?}: centre {got:?} vs {want:?}"
        );
        // And the highlight is visible: brighter than the diffuse-only value.
        assert!(got[0] > shade(b, 1.0)[0] + 5, "{filter:?}");
    }
}

/// Mean R+G+B of the mesh (non-background) pixels in columns `x0..x1` of a frame; at least
/// 100 such pixels.
fn mean_mesh_rgb(img: &image::RgbaImage, x0: u32, x1: u32) -> f64 {
    let mut s = 0.0;
    let mut n = 0.0;
    for y in 0..img.height() {
        for x in x0..x1 {
            let p = img.get_pixel(x, y).0;
            if p != BACKGROUND {
                s += p[0] as f64 + p[1] as f64 + p[2] as f64;
                n += 1.0;
            }
        }
    }
    assert!(n > 100.0, "columns {x0}..{x1}: too few mesh pixels ({n})");
    s / n
}

/// One scenario chained by hand (first order → dilation → display, each pass's inputs spelled
/// out, as a caller without `Renderer` would): it reads best as one function.
#[test]
fn end_to_end_frame_lit_side_is_brighter() {
    let gpu = gpu();
    let (mesh, albedo) = floor_and_box(64);
    // A point light low over the +x edge of the floor.
    let lights = [LightDesc::Point {
        position_m: [0.9, 0.6, 0.0],
        color: [1.0; 3],
        intensity_w_sr: 1.0,
    }];
    let fo_pass = FirstOrderPass::new(
        &gpu,
        &FirstOrderOptions {
            shadow_map_size: 256,
            max_shadow_layers: 6,
            ..Default::default()
        },
    )
    .unwrap();
    let fo_scene = fo_pass.prepare(&gpu, &mesh, &albedo).unwrap();
    let dil = DilatePass::new(&gpu, &DilateOptions::default()).unwrap();
    // The dilation plan needs the coverage: one first-order map, read back.
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let fo = fo_pass
        .encode(
            &gpu,
            &mut enc,
            &FirstOrderInputs {
                scene: &fo_scene,
                lights: &lights,
            },
        )
        .unwrap();
    gpu.submit_and_wait("test.coverage", enc).unwrap();
    let coverage = gpu
        .read_texel_image("test.coverage", &fo.first_order_tex)
        .unwrap();
    let targets = dil.prepare(&gpu, &dil.plan(&coverage).unwrap()).unwrap();
    let disp = DisplayPass::new(
        &gpu,
        &DisplayOptions {
            width: 96,
            height: 96,
            side_by_side: false,
            direct: passes::display::DirectLight::Lightmap,
            ..Default::default()
        },
    )
    .unwrap();
    let d_scene = disp.prepare(&gpu, &mesh).unwrap();

    // The first-order map read back above stays in its texture: dilate and display it.
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let fo_view = fo.first_order_tex.create_view(&Default::default());
    let dilated = dil.encode(
        &gpu,
        &mut enc,
        &DilateInputs {
            targets: &targets,
            source: &fo_view,
        },
    );
    let dview = dilated.dilated_tex.create_view(&Default::default());
    // Looking down at the floor with image-right = +x.
    let camera = Camera {
        eye: [0.0, 3.0, 0.0],
        target: [0.0, 0.0, 0.0],
        up: [0.0, 0.0, -1.0],
        fov_y_deg: 45.0,
        near: 0.05,
        far: 10.0,
    };
    let out = disp
        .encode(
            &gpu,
            &mut enc,
            &DisplayInputs {
                scene: &d_scene,
                final_lightmap: &dview,
                lightmap_size: [64, 64],
                first_order: None,
                camera,
                exposure: 4.0,
                lights: &lights,
                specular: None,
                direct: None,
            },
        )
        .unwrap();
    gpu.submit_and_wait("test.frame", enc).unwrap();
    let img = gpu.read_rgba8("test.frame", &out.color_tex).unwrap();

    let (left, right) = (mean_mesh_rgb(&img, 0, 32), mean_mesh_rgb(&img, 64, 96));
    assert!(
        right > left + 30.0,
        "lit (+x) side {right} not brighter than {left}"
    );
}

/// Back-face culling of a closed outward mesh seen from outside changes no pixel: the same
/// boxes drawn with culling (closed) and with both sides (the same mesh opened by a hidden
/// triangle inside a box), under a lightmap that differs per chart, give the same image.
#[test]
fn back_face_culling_of_closed_mesh_changes_no_pixel() {
    let gpu = gpu();
    let boxes = [
        ([0.0, 0.25, 0.0], [0.25, 0.25, 0.25]),
        ([0.6, 0.1, -0.3], [0.2, 0.1, 0.3]),
    ];
    let closed = common::closed_boxes(&boxes);
    let open = common::opened(&closed, [0.0, 0.25, 0.0]);
    assert!(closed.is_closed_outward());
    assert!(!open.is_closed_outward());
    // A lightmap that varies across texels (so front and back faces would shade differently).
    let view = gradient_map(&gpu, 0.05, 1.0);
    let options = DisplayOptions {
        width: 160,
        height: 120,
        side_by_side: false,
        direct: passes::display::DirectLight::Lightmap,
        ..Default::default()
    };
    let draw_with = |mesh: &MeshData| {
        render(&gpu, mesh, options, |scene, draw| {
            draw(&DisplayInputs {
                scene,
                final_lightmap: &view,
                lightmap_size: [GRADIENT_SIDE, GRADIENT_SIDE],
                first_order: None,
                camera: oblique_camera(),
                exposure: 1.0,
                lights: &[],
                specular: None,
                direct: None,
            })
        })
    };
    let (a, b) = (draw_with(&closed), draw_with(&open));
    let covered = a.pixels().filter(|p| p.0 != BACKGROUND).count();
    assert!(
        covered > 160 * 120 / 50,
        "boxes cover only {covered} pixels"
    );
    let differ = a
        .pixels()
        .zip(b.pixels())
        .filter(|(p, q)| !close(p.0, q.0, 0))
        .count();
    assert_eq!(differ, 0, "{differ} of {covered} mesh pixels changed");
}

/// A square in the z = 0 plane, normal +z, larger than the view of [`facing_camera`]: UV is
/// `0.5 + K·(x, y)`, so the image shows UVs from −0.1 to 1.1 (border clamping included).
const QUAD_HALF_M: f32 = 1.0;
const FACING_DIST_M: f32 = 2.0;
const FACING_FOV_DEG: f32 = 40.0;

fn uv_per_metre() -> f32 {
    // Half the view at z = 0 spans UV 0.6 from the centre.
    0.6 / (FACING_DIST_M * (0.5 * FACING_FOV_DEG.to_radians()).tan())
}

fn facing_quad() -> MeshData {
    let (q, k) = (QUAD_HALF_M, uv_per_metre());
    let corners = [[-q, -q], [q, -q], [q, q], [-q, q]];
    MeshData {
        positions_m: corners.iter().map(|c| [c[0], c[1], 0.0]).collect(),
        normals: vec![[0.0, 0.0, 1.0]; 4],
        lightmap_uvs: corners
            .iter()
            .map(|c| [0.5 + k * c[0], 0.5 + k * c[1]])
            .collect(),
        indices: vec![0, 1, 2, 0, 2, 3],
    }
}

fn facing_camera() -> Camera {
    Camera {
        eye: [0.0, 0.0, FACING_DIST_M],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: FACING_FOV_DEG,
        near: 0.1,
        far: 10.0,
    }
}

/// UV seen at the centre of pixel `(px, py)` of a `size`² image of [`facing_quad`] (the
/// plane is parallel to the image, so perspective-correct interpolation is affine there).
fn facing_uv(px: u32, py: u32, size: u32) -> [f32; 2] {
    let half = FACING_DIST_M * (0.5 * FACING_FOV_DEG.to_radians()).tan();
    let x = ((px as f32 + 0.5) / size as f32 * 2.0 - 1.0) * half;
    let y = (1.0 - (py as f32 + 0.5) / size as f32 * 2.0) * half;
    let k = uv_per_metre();
    [0.5 + k * x, 0.5 + k * y]
}

/// An 8×8 lightmap of smooth, strongly varying radiosity (W/m², about 0.1 to 35), so the
/// magnified image has many distinct values and a nearest lookup would be far off.
fn smooth_map() -> TexelImage {
    let n = 8u32;
    let rgba = (0..n * n)
        .map(|i| {
            let (x, y) = ((i % n) as f32, (i / n) as f32);
            [
                (2.5 * (0.9 * x + 0.4 * y).sin()).exp(),
                (2.0 * (0.7 * y - 0.3 * x).cos()).exp(),
                0.3 + 0.4 * x,
                1.0,
            ]
        })
        .collect();
    TexelImage {
        width: n,
        height: n,
        rgba,
    }
}

/// Every pixel of a magnified lightmap equals the CPU mirror (bilinear between texel centres
/// with edge clamping, `B/π`, exposure, Reinhard, sRGB) within 1/255, with the hardware
/// sampler and with the manual lookup.
#[test]
fn magnified_lightmap_matches_cpu_bilinear_for_each_filter() {
    let gpu = gpu();
    let map = smooth_map();
    let tex = gpu
        .create_rgba32f_texture(
            "test.smooth_map",
            map.width,
            map.height,
            &map.rgba,
            wgpu::TextureUsages::TEXTURE_BINDING,
        )
        .unwrap();
    let view = tex.create_view(&Default::default());
    let size = 96u32;
    let exposure = 0.8;
    let mesh = facing_quad();
    for filter in filters(&gpu) {
        let img = render_with(
            &gpu,
            filter,
            &mesh,
            DisplayOptions {
                width: size,
                height: size,
                side_by_side: false,
                direct: passes::display::DirectLight::Lightmap,
                ..Default::default()
            },
            |scene, draw| {
                draw(&DisplayInputs {
                    scene,
                    final_lightmap: &view,
                    lightmap_size: [map.width, map.height],
                    first_order: None,
                    camera: facing_camera(),
                    exposure,
                    lights: &[],
                    specular: None,
                    direct: None,
                })
            },
        );
        let (mut worst, mut off_by_one) = (0i32, 0usize);
        let mut distinct = std::collections::HashSet::new();
        for py in 0..size {
            for px in 0..size {
                let got = img.get_pixel(px, py).0;
                let want = shade(bilinear(&map, facing_uv(px, py, size)), exposure);
                for c in 0..3 {
                    let d = (got[c] as i32 - want[c] as i32).abs();
                    worst = worst.max(d);
                    off_by_one += usize::from(d == 1);
                }
                assert!(
                    close(got, want, 1),
                    "{filter:?}: pixel ({px}, {py}) {got:?} vs CPU {want:?}"
                );
                distinct.insert(got);
            }
        }
        eprintln!(
            "{filter:?}: worst |Δ| {worst}/255, {off_by_one} of {} channels off by one, {} \
             distinct colours",
            3 * size * size,
            distinct.len()
        );
        assert!(
            distinct.len() > 2000,
            "{filter:?}: only {} distinct colours: the lightmap is not resolved",
            distinct.len()
        );
    }
}

/// The specular pipeline (`vs_main` + `fs_*_specular`) with `k_s = 0` draws the same image
/// as the diffuse pipeline (`vs_uv`, no light loop): same coverage, same colours.
#[test]
fn specular_pipeline_with_zero_strength_matches_diffuse_pipeline() {
    let gpu = gpu();
    let (mesh, _) = floor_and_box(64);
    let view = gradient_map(&gpu, 0.1, 2.0);
    let lights = [LightDesc::Point {
        position_m: [0.3, 1.0, 0.2],
        color: [1.0; 3],
        intensity_w_sr: 3.0,
    }];
    for filter in filters(&gpu) {
        let draw_with = |spec: Option<Specular>| {
            render_with(
                &gpu,
                filter,
                &mesh,
                DisplayOptions {
                    width: 160,
                    height: 120,
                    side_by_side: false,
                    direct: passes::display::DirectLight::Lightmap,
                    ..Default::default()
                },
                |scene, draw| {
                    draw(&DisplayInputs {
                        scene,
                        final_lightmap: &view,
                        lightmap_size: [GRADIENT_SIDE, GRADIENT_SIDE],
                        first_order: None,
                        camera: oblique_camera(),
                        exposure: 0.7,
                        lights: &lights,
                        specular: spec,
                        direct: None,
                    })
                },
            )
        };
        let diffuse = draw_with(None);
        let zero = draw_with(Some(Specular {
            strength: 0.0,
            shininess: 16.0,
        }));
        let lit = draw_with(Some(Specular {
            strength: 0.5,
            shininess: 16.0,
        }));
        let covered = diffuse.pixels().filter(|p| p.0 != BACKGROUND).count();
        assert!(
            covered > 160 * 120 / 8,
            "{filter:?}: covers {covered} pixels"
        );
        let differ = diffuse
            .pixels()
            .zip(zero.pixels())
            .filter(|(a, b)| a.0 != b.0)
            .count();
        assert_eq!(differ, 0, "{filter:?}: {differ} of {covered} pixels differ");
        // The specular pipeline does add light when k_s > 0.
        let brighter = diffuse
            .pixels()
            .zip(lit.pixels())
            .filter(|(a, b)| b.0[0] > a.0[0] + 2)
            .count();
        assert!(brighter > 100, "{filter:?}: highlight on {brighter} pixels");
    }
}
