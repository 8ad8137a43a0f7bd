//! GPU first-order pass vs its CPU mirror (exact, ray-traced shadows) on the floor-and-box
//! scene: (1) the demo lights — a point light outside the mesh's bounding sphere (one
//! shadow cone), a directional and a spot light; (2) a point light inside the bounding
//! sphere (six cube faces).
//!
//! Coverage must match exactly. Texels whose shadow state is the same at every point of a
//! disc of 4 shadow texels around them ("away from shadow edges") must agree within 1e-3
//! of their unshadowed value; texels near shadow edges are only counted.

mod common;

use common::demo::{demo_lights, floor_and_box};
use common::gpu;
use glam::Vec3;
use passes::AlbedoMap;
use passes::cpu::first_order as mirror;
use passes::first_order::{
    FirstOrderInputs, FirstOrderOptions, FirstOrderPass, FirstOrderScene, GpuLight,
    LIGHT_DIRECTIONAL, LIGHT_POINT, shadow_layers,
};
use passes::util::TexelReads;
use passes::{Gpu, LightDesc, MeshData, TexelImage};

const SIZE: u32 = 64;

/// The first-order lightmap of `scene` under `lights`: one encode, submit and read-back.
fn render_first_order(
    gpu: &Gpu,
    pass: &FirstOrderPass,
    scene: &FirstOrderScene,
    lights: &[LightDesc],
    label: &str,
) -> TexelImage {
    let mut enc = gpu.device.create_command_encoder(&Default::default());
    let out = pass
        .encode(gpu, &mut enc, &FirstOrderInputs { scene, lights })
        .unwrap();
    gpu.submit_and_wait(label, enc).unwrap();
    gpu.read_texel_image(label, &out.first_order_tex).unwrap()
}

#[test]
fn first_order_matches_ray_traced_mirror() {
    let lights = demo_lights();
    check(&lights, 1);
}

#[test]
fn point_light_inside_bounds_uses_cube_faces_and_matches_mirror() {
    let lights = [LightDesc::Point {
        position_m: [0.6, 0.9, -0.5],
        color: [1.0, 0.9, 0.8],
        intensity_w_sr: 3.0,
    }];
    check(&lights, 6);
}

/// A per-texel albedo pattern, so a wrong texel lookup shows.
fn patterned_albedo() -> AlbedoMap {
    let mut albedo = AlbedoMap::uniform(SIZE, SIZE, [0.0; 3]);
    for y in 0..SIZE {
        for x in 0..SIZE {
            albedo.rgb[(y * SIZE + x) as usize] = [
                0.3 + 0.1 * ((x * 7 + y * 3) % 5) as f32,
                0.6,
                0.4 + 0.1 * (y % 3) as f32,
            ];
        }
    }
    albedo
}

/// Both ways of reading the albedo and G-buffer textures give the lightmap `got`.
fn assert_texel_reads_agree(
    gpu: &Gpu,
    options: &FirstOrderOptions,
    (mesh, albedo): (&MeshData, &AlbedoMap),
    lights: &[LightDesc],
    got: &TexelImage,
) {
    for reads in [TexelReads::Sampled, TexelReads::Storage] {
        if reads == TexelReads::Storage
            && !common::has_storage_reads(gpu, "first-order storage reads")
        {
            continue;
        }
        let options = FirstOrderOptions {
            texel_reads: Some(reads),
            ..*options
        };
        let pass = FirstOrderPass::new(gpu, &options).unwrap();
        let scene = pass.prepare(gpu, mesh, albedo).unwrap();
        let other = render_first_order(gpu, &pass, &scene, lights, "test.first_order_reads");
        assert_eq!(&other, got, "{reads:?} texel reads");
    }
}

/// Shadow state at a surface point and on a disc of 4 shadow-map texels around it, over the
/// lights that face it: (the same for every point of the disc, shadowed by some light,
/// unshadowed irradiance summed over the lights).
fn shadow_state(
    mesh: &MeshData,
    lights: &[GpuLight],
    position: Vec3,
    normal: Vec3,
    shadow_map_size: u32,
) -> (bool, bool, Vec3) {
    let (t1, t2) = normal.any_orthonormal_pair();
    let mut stable = true;
    let mut any_shadowed = false;
    let mut unshadowed = Vec3::ZERO;
    for l in lights {
        let e = mirror::unshadowed_irradiance(l, position, normal);
        if e.max_element() <= 0.0 {
            continue;
        }
        unshadowed += e;
        let texel_m = if l.kind == LIGHT_DIRECTIONAL {
            l.cone[3] / shadow_map_size as f32
        } else {
            l.cone[2] * Vec3::from_slice(&l.position[..3]).distance(position)
                / shadow_map_size as f32
        };
        let r = 4.0 * texel_m;
        let v0 = mirror::occluded(mesh, l, position, normal);
        any_shadowed |= v0;
        for k in 0..8 {
            let a = k as f32 * std::f32::consts::TAU / 8.0;
            let q = position + r * (a.cos() * t1 + a.sin() * t2);
            if mirror::occluded(mesh, l, q, normal) != v0 {
                stable = false;
            }
        }
    }
    (stable, any_shadowed, unshadowed)
}

/// Compares GPU and mirror for `lights`; the first light must be a point light whose
/// shadow takes `point_layers` layers.
fn check(lights: &[LightDesc], point_layers: u32) {
    let (mesh, _) = floor_and_box(SIZE);
    let albedo = patterned_albedo();
    let options = FirstOrderOptions {
        shadow_map_size: 512,
        max_shadow_layers: 8,
        ..Default::default()
    };

    let gpu = gpu();
    let pass = FirstOrderPass::new(&gpu, &options).unwrap();
    let scene = pass.prepare(&gpu, &mesh, &albedo).unwrap();
    let (g0, _) = shadow_layers(&lights[0], scene.bounds(), options.shadow_map_size);
    assert_eq!(g0.kind, LIGHT_POINT);
    assert_eq!(
        g0.layer_count, point_layers,
        "shadow layers of the point light"
    );
    let got = render_first_order(&gpu, &pass, &scene, lights, "test.first_order");
    assert_texel_reads_agree(&gpu, &options, (&mesh, &albedo), lights, &got);

    let want = mirror::first_order(&mesh, &albedo, lights);
    for (i, (g, w)) in got.rgba.iter().zip(&want.rgba).enumerate() {
        assert_eq!(g[3], w[3], "coverage differs at texel {i}");
        if w[3] == 0.0 {
            assert_eq!(*g, [0.0; 4], "uncovered texel {i} must stay zero");
        }
    }

    let gl = mirror::packed_lights(&mesh, lights);
    let (mut lit, mut shadowed, mut edge) = (0, 0, 0);
    for s in mirror::rasterize_uv(&mesh, SIZE, SIZE) {
        let (stable, any_shadowed, unshadowed) =
            shadow_state(&mesh, &gl, s.position, s.normal, options.shadow_map_size);
        if !stable {
            edge += 1;
            continue;
        }
        let rho = Vec3::from(albedo.rgb[(s.y * SIZE + s.x) as usize]);
        let scale = (rho * unshadowed).max_element();
        let (g, w) = (got.get(s.x, s.y), want.get(s.x, s.y));
        for c in 0..3 {
            assert!(
                (g[c] - w[c]).abs() <= 1e-3 * scale + 1e-6,
                "texel ({}, {}) ch {c}: gpu {} cpu {} (unshadowed {scale}, shadowed by some light: {any_shadowed})",
                s.x,
                s.y,
                g[c],
                w[c]
            );
        }
        if any_shadowed {
            shadowed += 1
        } else {
            lit += 1
        }
    }
    eprintln!(
        "first-order texels compared: lit {lit}, shadowed {shadowed}; skipped at shadow edges {edge}"
    );
    // The comparison must cover both cases and most texels.
    assert!(
        lit > 300 && shadowed > 100,
        "lit {lit}, shadowed {shadowed}, edge {edge}"
    );
    assert!(edge * 5 < lit + shadowed, "too many edge texels: {edge}");
}

/// Shadow maps are reused only while the lights stay put: lights A, then B, then A again
/// must give A's lightmap again, bit for bit, and B's twice the same.
#[test]
fn shadow_map_cache_follows_moving_lights() {
    let (mesh, albedo) = floor_and_box(SIZE);
    let a = demo_lights();
    let b = [LightDesc::Point {
        position_m: [-0.9, 1.1, 0.6],
        color: [1.0; 3],
        intensity_w_sr: 3.0,
    }];
    let options = FirstOrderOptions {
        shadow_map_size: 256,
        max_shadow_layers: 8,
        ..Default::default()
    };
    let gpu = gpu();
    let pass = FirstOrderPass::new(&gpu, &options).unwrap();
    let scene = pass.prepare(&gpu, &mesh, &albedo).unwrap();
    let render = |lights: &[LightDesc]| {
        render_first_order(&gpu, &pass, &scene, lights, "test.first_order_cache").rgba
    };
    let a1 = render(&a);
    let b1 = render(&b);
    let b2 = render(&b); // shadow maps reused
    let a2 = render(&a);
    scene.invalidate_shadow_maps();
    let a3 = render(&a);
    assert_ne!(a1, b1, "the two light sets must differ");
    assert_eq!(b1, b2);
    assert_eq!(a1, a2);
    assert_eq!(a1, a3);
}

/// Shadow maps of a closed outward mesh lit from outside its bounds are drawn with back
/// faces culled; the lightmap must be the same as with both sides drawn (the same mesh
/// opened by a hidden triangle inside the slab), for point, spot and directional lights,
/// and the small box must really shadow the slab. The box sinks 2 cm into the slab, so the
/// slab top under it lies between the box's front and back faces: culling the wrong side
/// (front faces) would light it.
#[test]
fn back_face_culled_shadow_maps_change_no_texel() {
    let boxes = [
        ([0.0, -0.05, 0.0], [1.0, 0.05, 1.0]),
        ([0.1, 0.18, 0.0], [0.2, 0.2, 0.2]),
    ];
    let closed = common::closed_boxes(&boxes);
    let open = common::opened(&closed, [0.0, -0.05, 0.0]);
    assert!(closed.is_closed_outward() && !open.is_closed_outward());
    let size = 128u32;
    let albedo = AlbedoMap::uniform(size, size, [0.5, 0.5, 0.5]);
    let lights = [
        LightDesc::Point {
            position_m: [0.4, 2.2, 0.3],
            color: [1.0; 3],
            intensity_w_sr: 2.0,
        },
        LightDesc::Spot {
            position_m: [-0.8, 1.5, -0.5],
            direction: [0.8, -1.5, 0.5],
            color: [1.0; 3],
            intensity_w_sr: 2.0,
            inner_deg: 30.0,
            outer_deg: 50.0,
        },
        LightDesc::Directional {
            direction: [0.3, -1.0, 0.2],
            color: [1.0; 3],
            irradiance_w_m2: 1.0,
        },
    ];
    let options = FirstOrderOptions {
        shadow_map_size: 512,
        max_shadow_layers: 16,
        ..Default::default()
    };
    let gpu = gpu();
    let pass = FirstOrderPass::new(&gpu, &options).unwrap();
    let render = |mesh: &MeshData, lights: &[LightDesc]| {
        let scene = pass.prepare(&gpu, mesh, &albedo).unwrap();
        render_first_order(&gpu, &pass, &scene, lights, "test.first_order_cull")
    };
    for (i, light) in lights.iter().enumerate() {
        let (a, b) = (render(&closed, &[*light]), render(&open, &[*light]));
        assert_eq!(a.rgba.len(), b.rgba.len());
        let max = a.rgba.iter().map(|p| p[0]).fold(0.0f32, f32::max);
        assert!(max > 0.0, "light {i} lights nothing");
        for (k, (p, q)) in a.rgba.iter().zip(&b.rgba).enumerate() {
            assert!(
                (p[0] - q[0]).abs() <= 1e-6 * max && p[3] == q[3],
                "light {i}, texel {k}: culled {p:?} vs both sides {q:?}"
            );
        }
        // The slab's top face (chart cell 2: x in [32, 48), y in [0, 16)) has both lit and
        // shadowed texels.
        let top: Vec<f32> = (2..14)
            .flat_map(|y| (34..46).map(move |x| (x, y)))
            .map(|(x, y)| a.get(x, y)[0])
            .collect();
        let lit = top.iter().filter(|&&v| v > 0.25 * max).count();
        let dark = top.iter().filter(|&&v| v < 0.05 * max).count();
        assert!(
            lit > 0 && dark > 0,
            "light {i}: lit {lit}, dark {dark} on the slab top"
        );
    }
}

/// The averaged pass (`samples = 3`) against the mirror's [`mirror::first_order_averaged`]:
/// coverage exactly, and both outputs — the first order (centres on opaque texels, averages
/// on the translucent box top) and the transfer's input (averages) — within 1e-3 of their
/// unshadowed value on texels whose every sub-texel is away from shadow edges. The averages
/// must differ from the centres where the light varies within a texel (the spot's rim, the
/// point light's falloff), and equal them on the box top only there.
#[test]
fn averaged_first_order_matches_ray_traced_mirror() {
    const N: u32 = 3;
    let lights = demo_lights();
    let (mesh, _) = floor_and_box(SIZE);
    let albedo = patterned_albedo();
    // The box's top face: the 12×12 chart at (36, 2) (floor_and_box's layout at W = 64).
    let top = |x: u32, y: u32| (36..48).contains(&x) && (2..14).contains(&y);
    let translucent: Vec<bool> = (0..SIZE * SIZE).map(|i| top(i % SIZE, i / SIZE)).collect();
    let options = FirstOrderOptions {
        shadow_map_size: 512,
        max_shadow_layers: 8,
        samples: N,
        ..Default::default()
    };
    let gpu = gpu();
    let pass = FirstOrderPass::new(&gpu, &options).unwrap();
    let mut scene = pass.prepare(&gpu, &mesh, &albedo).unwrap();
    pass.set_translucent(&gpu, &mut scene, &translucent)
        .unwrap();
    let got = render_first_order(&gpu, &pass, &scene, &lights, "test.averaged");
    let got_input = gpu
        .read_texel_image("test.averaged_input", scene.transfer_input())
        .unwrap();
    let (want, want_input) =
        mirror::first_order_averaged(&mesh, &albedo, Some(&translucent), &lights, N);
    let centres = mirror::first_order(&mesh, &albedo, &lights);
    for (i, ((g, gi), w)) in got
        .rgba
        .iter()
        .zip(&got_input.rgba)
        .zip(&want.rgba)
        .enumerate()
    {
        assert_eq!(g[3], w[3], "coverage differs at texel {i}");
        assert_eq!(gi[3], w[3], "input coverage differs at texel {i}");
        assert_eq!(
            w[3], centres.rgba[i][3],
            "the centre rule decides coverage ({i})"
        );
        if w[3] == 0.0 {
            assert_eq!((*g, *gi), ([0.0; 4], [0.0; 4]), "uncovered texel {i}");
        }
    }
    // Texels whose sub-texels are all away from shadow edges, with their largest unshadowed
    // first order.
    let gl = mirror::packed_lights(&mesh, &lights);
    let mut scale = vec![0.0f32; (SIZE * SIZE) as usize];
    let mut stable = vec![true; (SIZE * SIZE) as usize];
    for s in mirror::rasterize_uv(&mesh, SIZE * N, SIZE * N) {
        let i = ((s.y / N) * SIZE + s.x / N) as usize;
        let (ok, _, unshadowed) =
            shadow_state(&mesh, &gl, s.position, s.normal, options.shadow_map_size);
        stable[i] &= ok;
        scale[i] = scale[i].max((Vec3::from(albedo.rgb[i]) * unshadowed).max_element());
    }
    let (mut compared, mut averaged_differ, mut top_texels) = (0, 0, 0);
    for (i, w) in want.rgba.iter().enumerate() {
        if w[3] == 0.0 || !stable[i] {
            continue;
        }
        compared += 1;
        for (name, g, w) in [
            ("first order", got.rgba[i], *w),
            ("input", got_input.rgba[i], want_input.rgba[i]),
        ] {
            for c in 0..3 {
                assert!(
                    (g[c] - w[c]).abs() <= 1e-3 * scale[i] + 1e-6,
                    "{name} texel {i} ch {c}: gpu {} cpu {} (scale {})",
                    g[c],
                    w[c],
                    scale[i]
                );
            }
        }
        let (x, y) = (i as u32 % SIZE, i as u32 / SIZE);
        let differ = (0..3)
            .any(|c| (want_input.rgba[i][c] - centres.rgba[i][c]).abs() > 1e-3 * scale[i] + 1e-6);
        averaged_differ += differ as usize;
        if top(x, y) {
            top_texels += 1;
            assert_eq!(
                got.rgba[i], got_input.rgba[i],
                "translucent texel {i}: the average"
            );
        } else {
            assert_eq!(
                w, &centres.rgba[i],
                "opaque texel {i}: the centre's first order"
            );
        }
    }
    eprintln!(
        "averaged first order: {compared} texels compared, {averaged_differ} whose average \
         differs from the centre, {top_texels} translucent"
    );
    assert!(
        compared > 1000 && top_texels > 50,
        "{compared} / {top_texels}"
    );
    assert!(
        averaged_differ > 40,
        "{averaged_differ} averaged texels differ"
    );
}

#[test]
fn even_or_too_many_samples_are_refused() {
    let gpu = gpu();
    for samples in [0, 2, 9] {
        let options = FirstOrderOptions {
            samples,
            ..Default::default()
        };
        let e = FirstOrderPass::new(&gpu, &options).unwrap_err().to_string();
        assert!(e.contains("samples") && e.contains("odd"), "{samples}: {e}");
    }
}
