//! The frame script ([`passes::frame::Renderer::encode_frame`]) on the demo scene: the final
//! map against the CPU mirror, a frame recorded stage by stage (as the benchmarks do) equal
//! to the whole frame, frame timestamps; the demo mesh itself; device loss turning into an
//! error.

mod common;

use common::demo::{demo_lights, floor_and_box, prepare_demo};
use common::gpu;
use glam::Vec3;
use passes::frame::{
    FRAME_TIMESTAMPS, FrameOptions, FrameParams, RenderScene, Renderer, RendererOptions, Stages,
};
use passes::timestamps::Timestamps;
use passes::transfer::{TransferOptions, TransferPath};
use passes::{Gpu, PassError, cpu};

#[test]
fn renderer_final_map_matches_mirror_and_stages_make_the_frame() {
    let gpu = gpu();
    let size = 64;
    let options = RendererOptions {
        // The blend path with `best_for`'s other settings (on a CPU adapter such as lavapipe
        // that is `best_for` itself; hardware GPUs default to the compute path).
        transfer: TransferOptions {
            path: TransferPath::Blend,
            ..TransferOptions::best_for(&gpu)
        },
        ..common::demo_renderer_options(64, 32)
    };
    let renderer = Renderer::new(&gpu, &options).unwrap();
    let (scene, atlases) = prepare_demo(&gpu, &renderer, size);
    let lights = demo_lights();

    let (fo, fin) = renderer.render_lightmaps(&gpu, &scene, &lights).unwrap();
    // `best_for` pairs pieces in the blend path (binary16 values, relative error ≤ 2⁻¹¹ per term; the blur's
    // terms are all positive, so the 1e-3 relative tolerance below covers it).
    let pairs = scene.transfer.paired.as_ref().map_or(0, |p| p.pairs);
    assert!(
        pairs > 0,
        "the default blend path must pair the demo's pieces"
    );
    let want = cpu::transfer::transfer(&scene.transfer.schedule, &atlases, &fo);
    let mut brighter = 0;
    for (g, w) in fin.rgba.iter().zip(&want.rgba) {
        for c in 0..4 {
            assert!(
                (g[c] - w[c]).abs() <= 1e-3 * w[c].abs().max(1e-3),
                "{g:?} vs {w:?}"
            );
        }
    }
    for (f, o) in fin.rgba.iter().zip(&fo.rgba) {
        brighter += (f[0] > o[0]) as usize;
    }
    assert!(
        brighter > 1000,
        "the transfer must add light ({brighter} texels)"
    );

    let params = FrameParams {
        lights: &lights,
        camera: common::demo_camera(),
        exposure: 1.0,
        specular: None,
    };
    assert_stages_make_the_frame(&gpu, &renderer, &scene, &params);
    assert_frame_timestamps(&gpu, &renderer, &scene, &params);
}

/// With an averaged first order (`FirstOrderOptions::samples = 3`) the pieces multiply the
/// averages and the final starts from the first order: `final = first_order + (T(input) −
/// input)`, `T` the mirror's transfer of the input, on both paths; translucent texels (the
/// box, given a diffusion length) take the average as their first order.
#[test]
fn averaged_first_order_feeds_the_transfer() {
    let gpu = gpu();
    let size = 64;
    let lights = demo_lights();
    for path in [TransferPath::Blend, TransferPath::Compute] {
        let mut options = common::demo_renderer_options(64, 32);
        options.first_order.samples = 3;
        options.transfer = TransferOptions {
            path,
            ..TransferOptions::best_for(&gpu)
        };
        let renderer = Renderer::new(&gpu, &options).unwrap();
        let (mut scene, atlases) = prepare_demo(&gpu, &renderer, size);
        // The box's charts (x ≥ 35 texels at W = 64) are translucent.
        let lengths: Vec<f32> = (0..size * size)
            .map(|i| if i % size >= 35 { 0.002 } else { 0.0 })
            .collect();
        renderer
            .set_diffusion_lengths(&gpu, &mut scene, &lengths)
            .unwrap();
        let (fo, fin) = renderer.render_lightmaps(&gpu, &scene, &lights).unwrap();
        let input = gpu
            .read_texel_image("test.input", scene.first_order.transfer_input())
            .unwrap();
        let t = cpu::transfer::transfer(&scene.transfer.schedule, &atlases, &input);
        let (mut opaque_differ, mut translucent) = (0, 0);
        for (i, &length) in lengths.iter().enumerate() {
            let (f, g, x, w) = (fo.rgba[i], fin.rgba[i], input.rgba[i], t.rgba[i]);
            for c in 0..3 {
                let want = f[c] + (w[c] - x[c]);
                assert!(
                    (g[c] - want).abs() <= 1e-3 * w[c].abs().max(1e-3),
                    "{path:?} texel {i} ch {c}: final {} want {want} (first order {}, input {}, T(input) {})",
                    g[c],
                    f[c],
                    x[c],
                    w[c]
                );
            }
            assert_eq!(g[3], f[3], "{path:?}: coverage of texel {i}");
            if f[3] > 0.0 && length > 0.0 {
                translucent += 1;
                assert_eq!(f, x, "{path:?}: translucent texel {i} takes the average");
            } else if f[3] > 0.0 && (f[0] - x[0]).abs() > 1e-3 * f[0].abs().max(1e-3) {
                opaque_differ += 1;
            }
        }
        assert!(
            translucent > 500 && opaque_differ > 20,
            "{path:?}: {translucent} translucent texels, {opaque_differ} opaque ones whose \
             average differs from the centre"
        );
    }
}

/// The whole frame, then the same frame one stage per submission (the benchmarks' way):
/// each stage reads what the previous one left in the scene; static lights give the same
/// image as moving ones.
fn assert_stages_make_the_frame(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    params: &FrameParams<'_>,
) {
    let frame = |stages: &[Stages], moving_lights: bool| {
        for &stages in stages {
            let mut enc = gpu.device.create_command_encoder(&Default::default());
            let options = FrameOptions {
                stages,
                moving_lights,
                ..Default::default()
            };
            renderer
                .encode_frame(gpu, &mut enc, scene, params, &options)
                .unwrap();
            gpu.submit_and_wait("test.frame", enc).unwrap();
        }
        gpu.read_rgba8("test.frame", scene.display.color()).unwrap()
    };
    let whole = frame(&[Stages::ALL], true);
    let staged = frame(
        &[
            Stages::FIRST_ORDER,
            Stages::TRANSFER,
            Stages::DILATE,
            Stages::DISPLAY,
        ],
        true,
    );
    assert_eq!(whole, staged, "stage by stage ≠ the whole frame");
    assert_eq!(
        frame(&[Stages::ALL], false),
        whole,
        "reused shadow maps (static lights) must give the same image"
    );
}

/// Timestamps between the stages, when the adapter has them (lavapipe does; a failure where
/// the adapter has them but the device does not).
fn assert_frame_timestamps(
    gpu: &Gpu,
    renderer: &Renderer,
    scene: &RenderScene,
    params: &FrameParams<'_>,
) {
    let wanted = wgpu::Features::TIMESTAMP_QUERY | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS;
    if common::has_feature(gpu, wanted, "frame timestamps") {
        assert!(gpu.supports_timestamps());
        let stamps = Timestamps::new(gpu, "test.timestamps", FRAME_TIMESTAMPS);
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let options = FrameOptions {
            timestamps: Some(&stamps),
            ..Default::default()
        };
        renderer
            .encode_frame(gpu, &mut enc, scene, params, &options)
            .unwrap();
        stamps.resolve(&mut enc);
        gpu.submit_and_wait("test.timestamps", enc).unwrap();
        let ms = stamps.intervals_ms(gpu, "test.timestamps").unwrap();
        assert_eq!(ms.len(), FRAME_TIMESTAMPS as usize - 1);
        for m in ms {
            assert!(m.is_finite() && m >= 0.0, "{m}");
        }
    }
}

#[test]
fn demo_mesh_is_valid_and_normals_match_winding() {
    let (m, a) = floor_and_box(64);
    m.validate().unwrap();
    assert_eq!(a.rgb.len(), 64 * 64);
    for tri in m.indices.chunks_exact(3) {
        let p = |i: u32| Vec3::from(m.positions_m[i as usize]);
        let geo = (p(tri[1]) - p(tri[0]))
            .cross(p(tri[2]) - p(tri[0]))
            .normalize();
        let n = Vec3::from(m.normals[tri[0] as usize]);
        assert!(
            (geo - n).length() < 1e-5,
            "CCW winding must face the normal"
        );
    }
    for uv in &m.lightmap_uvs {
        assert!((0.0..=1.0).contains(&uv[0]) && (0.0..=1.0).contains(&uv[1]));
    }
}

#[test]
fn lost_device_is_an_error_not_a_hang() {
    let gpu = gpu();
    gpu.device.destroy();
    let enc = gpu.device.create_command_encoder(&Default::default());
    let err = gpu.submit_and_wait("test.after_destroy", enc).unwrap_err();
    assert!(matches!(err, PassError::DeviceLost { .. }), "{err}");
}
