//! The blend roofline: `draws` full-screen triangles writing a constant with additive
//! blending (`roofline.wgsl`) into a target of the transfer pass's accumulation format —
//! pure blended framebuffer writes with no texture reads, the upper bound on texel blends
//! per second the blend path can reach on this adapter.

use passes::{Gpu, PassError, util};

use super::timing::{BenchRow, Statistic, TimingSource, time_encoded};

/// Times `draws` full-screen additive blends into a `size` target of `format`; texel
/// blends per run = `size.x · size.y · draws`.
pub fn bench_blend_roofline(
    gpu: &Gpu,
    size: [u32; 2],
    format: wgpu::TextureFormat,
    draws: u32,
    iterations: u32,
    statistic: Statistic,
) -> Result<(BenchRow, TimingSource), PassError> {
    gpu.check_texture_size("roofline target", size[0], size[1])?;
    let device = &gpu.device;
    let pipeline = gpu.scoped("ortm.bench.new", || {
        let source = [util::FULLSCREEN_WGSL, include_str!("roofline.wgsl")].concat();
        let module = util::shader(device, "ortm.bench.shader", &source);
        util::fullscreen_pipeline(
            device,
            "ortm.bench.roofline_pipeline",
            None,
            &module,
            "fs_const",
            format,
            Some(util::ADDITIVE),
        )
    })?;
    let target = util::texture_2d(
        device,
        "ortm.bench.roofline_target",
        size,
        format,
        wgpu::TextureUsages::RENDER_ATTACHMENT,
    );
    let view = util::view(&target);
    let (ms, source, cpu) =
        time_encoded(gpu, "ortm.bench.roofline", iterations, statistic, |enc| {
            let mut pass = util::clear_pass(enc, "ortm.bench.roofline_pass", &view);
            pass.set_pipeline(&pipeline);
            for _ in 0..draws {
                pass.draw(0..3, 0..1);
            }
            Ok(())
        })?;
    let blends = size[0] as u64 * size[1] as u64 * draws as u64;
    Ok((
        BenchRow::new(
            format!("roofline: {draws}× full-screen blend {format:?}"),
            ms,
            blends,
        )
        .with_cpu(cpu),
        source,
    ))
}
