//! The indirect-light pass against its CPU mirror: on random maps directly, and inside the
//! frame (shown, then dilated) on the demo scene.

mod common;

use common::demo::{demo_lights, prepare_demo};
use common::{Rng, gpu};
use passes::frame::{FrameOptions, FrameParams, Renderer, Shown, Stages};
use passes::indirect::{IndirectInputs, IndirectPass};
use passes::{Gpu, TexelImage, cpu, util};

fn random_map(rng: &mut Rng, w: u32, h: u32) -> TexelImage {
    let mut img = TexelImage::new(w, h);
    for t in &mut img.rgba {
        *t = [
            4.0 * rng.f32() - 1.0,
            rng.f32(),
            10.0 * rng.f32(),
            (rng.f32() > 0.3) as u8 as f32,
        ];
    }
    img
}

fn upload(gpu: &Gpu, what: &str, img: &TexelImage) -> wgpu::Texture {
    gpu.create_rgba32f_texture(
        what,
        img.width,
        img.height,
        &img.rgba,
        wgpu::TextureUsages::TEXTURE_BINDING,
    )
    .unwrap()
}

#[test]
fn indirect_matches_mirror_on_random_maps() {
    let gpu = gpu();
    let pass = IndirectPass::new(&gpu).unwrap();
    let mut rng = Rng::new(14);
    // Not multiples of the 8×8 workgroup.
    for (w, h) in [(1, 1), (13, 7), (64, 40)] {
        let fo = random_map(&mut rng, w, h);
        let fin = random_map(&mut rng, w, h);
        let targets = pass.prepare(&gpu, [w, h]).unwrap();
        let (fo_tex, fin_tex) = (upload(&gpu, "fo", &fo), upload(&gpu, "final", &fin));
        let mut enc = gpu.device.create_command_encoder(&Default::default());
        let out = pass.encode(
            &gpu,
            &mut enc,
            &IndirectInputs {
                targets: &targets,
                first_order: &util::view(&fo_tex),
                final_map: &util::view(&fin_tex),
            },
        );
        gpu.submit_and_wait("test.indirect", enc).unwrap();
        let got = gpu.read_texel_image("indirect", &out.indirect_tex).unwrap();
        assert_eq!(got, cpu::indirect::indirect(&fo, &fin).unwrap(), "{w}×{h}");
    }
    let e = cpu::indirect::indirect(&TexelImage::new(2, 2), &TexelImage::new(2, 3)).unwrap_err();
    assert!(e.to_string().contains("2×3"), "{e}");
}

#[test]
fn frame_shows_the_dilated_indirect_map() {
    let gpu = gpu();
    let size = 64;
    let renderer = Renderer::new(&gpu, &common::demo_renderer_options(32, 16)).unwrap();
    let (scene, _) = prepare_demo(&gpu, &renderer, size);
    let lights = demo_lights();
    let params = FrameParams {
        lights: &lights,
        camera: common::demo_camera(),
        exposure: 1.0,
        specular: None,
    };
    let (fo, fin) = renderer.render_lightmaps(&gpu, &scene, &lights).unwrap();
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let options = FrameOptions {
        stages: Stages::ALL,
        shown: Shown::Indirect,
        ..Default::default()
    };
    let out = renderer
        .encode_frame(&gpu, &mut enc, &scene, &params, &options)
        .unwrap();
    gpu.submit_and_wait("test.frame", enc).unwrap();
    let got = gpu
        .read_texel_image("dilated indirect", &out.dilated_final_tex)
        .unwrap();
    let want = cpu::dilate::dilate(
        &cpu::indirect::indirect(&fo, &fin).unwrap(),
        &scene.dilate_plan,
    )
    .unwrap();
    assert_eq!(got, want);
    assert!(
        want.rgba.iter().filter(|t| t[0] > 0.0).count() > 1000,
        "the transfer adds light"
    );
}
