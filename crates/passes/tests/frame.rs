//! The frame script ([`passes::frame::Renderer`]) and the benchmark report on the demo
//! scene, and device loss turning into an error.

mod common;

use common::gpu;
use passes::bench::{TimingSource, bench_frame};
use passes::demo::{blur_transfer, demo_lights, floor_and_box};
use passes::frame::{FrameParams, Renderer, RendererOptions};
use passes::transfer::{TransferOptions, TransferPath};
use passes::{PassError, cpu};

#[test]
fn renderer_final_map_matches_mirror_and_bench_reports_every_pass() {
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
    let (mesh, albedo) = floor_and_box(size);
    let (atlases, pieces) = blur_transfer([size, size], 2, 1, 0.02);
    let scene = renderer
        .prepare(&gpu, &mesh, &albedo, &atlases, &pieces)
        .unwrap();
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
    let report = bench_frame(&gpu, &renderer, &scene, &params, 2).unwrap();
    // first order (moving lights), transfer, dilation, display, roofline, first order
    // (static lights).
    assert_eq!(report.rows.len(), 6);
    assert!(
        report.rows[5].name.contains("static"),
        "{:?}",
        report.rows[5]
    );
    let expected_blends = scene.transfer.schedule.texel_blends() + (size * size) as u64;
    assert_eq!(report.rows[1].texel_blends, expected_blends);
    assert_eq!(
        report.timing == TimingSource::GpuTimestamps,
        gpu.supports_timestamps()
    );
    for r in &report.rows {
        assert!(r.ms.is_finite() && r.ms >= 0.0, "{r:?}");
    }
    assert!(report.to_string().contains("roofline"));
}

#[test]
fn lost_device_is_an_error_not_a_hang() {
    let gpu = gpu();
    gpu.device.destroy();
    let enc = gpu.device.create_command_encoder(&Default::default());
    let err = gpu.submit_and_wait("test.after_destroy", enc).unwrap_err();
    assert!(matches!(err, PassError::DeviceLost { .. }), "{err}");
}
