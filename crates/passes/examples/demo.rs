//! Renders the built-in floor-and-box scene (side by side: first order | final with a
//! synthetic blur transfer) to a PNG and prints a benchmark table.
//!
//! `cargo run -p passes --release --example demo -- [out.png] [lightmap size] [blur radius] [f16|f32|unpaired|compute]` (f32 = `TransferOptions::best_for`: on lavapipe the paired blend path, on a hardware GPU the compute path; unpaired = the blend path without pairing)

use passes::bench::bench_frame;
use passes::demo::{blur_transfer, demo_lights, floor_and_box};
use passes::display::{Camera, DisplayOptions};
use passes::first_order::FirstOrderOptions;
use passes::frame::{FrameParams, Renderer, RendererOptions};
use passes::transfer::{AccumFormat, TransferOptions, TransferPath};
use passes::{Gpu, PassError};

fn main() -> Result<(), PassError> {
    let args: Vec<String> = std::env::args().collect();
    let out = args.get(1).cloned().unwrap_or_else(|| "demo.png".into());
    let size: u32 = args.get(2).and_then(|s| s.parse().ok()).unwrap_or(256);
    let radius: i32 = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(4);
    let mode = args.get(4).cloned().unwrap_or_else(|| "f32".into());

    let gpu = Gpu::new_headless()?;
    let transfer = match mode.as_str() {
        "f16" => TransferOptions {
            path: TransferPath::Blend,
            accum_format: AccumFormat::Rgba16Float,
            pair_pieces: false,
            ..TransferOptions::best_for(&gpu)
        },
        "compute" => TransferOptions {
            path: TransferPath::Compute,
            accum_format: AccumFormat::Rgba32Float,
            pair_pieces: false,
            ..TransferOptions::best_for(&gpu)
        },
        "unpaired" => TransferOptions {
            path: TransferPath::Blend,
            pair_pieces: false,
            ..TransferOptions::best_for(&gpu)
        },
        _ => TransferOptions::best_for(&gpu),
    };
    let options = RendererOptions {
        first_order: FirstOrderOptions {
            shadow_map_size: 1024,
            ..Default::default()
        },
        transfer,
        display: DisplayOptions {
            width: 1024,
            height: 512,
            side_by_side: true,
        },
        ..Default::default()
    };
    let renderer = Renderer::new(&gpu, &options)?;
    let (mesh, albedo) = floor_and_box(size);
    let n = (2 * radius + 1) * (2 * radius + 1) - 1;
    let (atlases, pieces) = blur_transfer([size, size], radius, 1, 0.5 / n as f32);
    let scene = renderer.prepare(&gpu, &mesh, &albedo, &atlases, &pieces)?;
    let lights = demo_lights();
    let params = FrameParams {
        lights: &lights,
        camera: Camera {
            eye: [2.2, 1.8, 2.6],
            target: [0.0, 0.2, 0.0],
            up: [0.0, 1.0, 0.0],
            fov_y_deg: 40.0,
            near: 0.05,
            far: 20.0,
        },
        exposure: 1.0,
        specular: None,
    };
    let img = renderer.render_image(&gpu, &scene, &params)?;
    img.save(&out).map_err(|e| PassError::Readback {
        what: out.clone(),
        message: e.to_string(),
    })?;
    println!("wrote {out}");
    // Accuracy of the final map against the CPU mirror on the GPU's own first-order map.
    let (fo, fin) = renderer.render_lightmaps(&gpu, &scene, &lights)?;
    let want = passes::cpu::transfer::transfer(&scene.transfer.schedule, &atlases, &fo);
    let (mut max_rel, mut sum_rel, mut n) = (0f64, 0f64, 0usize);
    for (g, w) in fin.rgba.iter().zip(&want.rgba) {
        for c in 0..3 {
            if w[c] > 1e-3 {
                let r = ((g[c] - w[c]).abs() / w[c]) as f64;
                max_rel = max_rel.max(r);
                sum_rel += r;
                n += 1;
            }
        }
    }
    println!(
        "final vs CPU mirror: max rel err {max_rel:.3e}, mean {:.3e} over {n} values",
        sum_rel / n.max(1) as f64
    );
    let report = bench_frame(&gpu, &renderer, &scene, &params, 5)?;
    print!("{report}");
    Ok(())
}
