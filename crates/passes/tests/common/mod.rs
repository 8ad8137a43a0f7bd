//! Shared helpers of the integration tests: a seeded random generator (SplitMix64, so the
//! tests need no extra crates), GPU creation, and the demo scene ([`demo`]).

#![allow(dead_code, reason = "each test binary uses a different subset")]

pub mod demo;

use passes::Gpu;
use passes::gpu::ExclusiveGpu;

/// SplitMix64: tiny, seeded, good enough for test data.
pub struct Rng(u64);

impl Rng {
    /// A generator from a seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }
    /// Next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9e37_79b9_7f4a_7c15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
        z ^ (z >> 31)
    }
    /// Uniform in `[0, 1)`.
    pub fn f32(&mut self) -> f32 {
        (self.next_u64() >> 40) as f32 / (1u64 << 24) as f32
    }
    /// Uniform integer in `[lo, hi]`.
    pub fn range(&mut self, lo: i64, hi: i64) -> i64 {
        lo + (self.next_u64() % (hi - lo + 1) as u64) as i64
    }
}

/// The headless GPU (lavapipe on CI), one test's device at a time (`new_headless_exclusive`:
/// NVIDIA's driver crashes when test threads use devices at once). Panics with wgpu's advice
/// when there is none: GPU tests are never skipped.
pub fn gpu() -> ExclusiveGpu {
    Gpu::new_headless_exclusive().unwrap_or_else(|e| panic!("{e}"))
}

/// The adapter [`Gpu::new_headless`] picks, requested again with the same options to ask what
/// it offers (the device only has the optional features it was created with). Panics if
/// this is not the adapter `gpu` runs on.
fn adapter_of(gpu: &Gpu) -> wgpu::Adapter {
    let instance =
        wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
    let adapter = pollster::block_on(instance.request_adapter(&wgpu::RequestAdapterOptions {
        power_preference: wgpu::PowerPreference::HighPerformance,
        force_fallback_adapter: false,
        compatible_surface: None,
        apply_limit_buckets: false,
    }))
    .unwrap_or_else(|e| panic!("{e}"));
    let info = adapter.get_info();
    assert_eq!(
        (&info.name, info.backend),
        (&gpu.adapter_info.name, gpu.adapter_info.backend),
        "a second request picked another adapter"
    );
    adapter
}

/// Whether to test `what`, which needs the optional `feature`: true when the device has it.
/// When the device lacks it, a failure if the adapter offers it (the feature was not
/// requested at device creation, so the path would go untested on an adapter that can run
/// it); false with a note naming the adapter only where the adapter truly lacks it.
pub fn has_feature(gpu: &Gpu, feature: wgpu::Features, what: &str) -> bool {
    if gpu.device.features().contains(feature) {
        return true;
    }
    let adapter = adapter_of(gpu);
    assert!(
        !adapter.features().contains(feature),
        "{} offers {feature:?} but the device was created without it, so {what} would go untested",
        gpu.adapter_info.name
    );
    eprintln!(
        "note: {} ({:?}) lacks {feature:?}; {what} not tested",
        gpu.adapter_info.name, gpu.adapter_info.backend
    );
    false
}

/// Whether to test `what`, which reads RGBA32F and RGBA32Uint textures as read-only storage
/// textures in fragment shaders ([`passes::util::TexelReads::Storage`]): true when
/// [`Gpu::supports_storage_reads`]. Otherwise the adapter is asked independently (both
/// formats allow read-only storage access, fragment shaders may use storage, at least 4
/// storage textures per stage): a failure if it can, false with a note naming it if not.
pub fn has_storage_reads(gpu: &Gpu, what: &str) -> bool {
    if gpu.supports_storage_reads() {
        return true;
    }
    let adapter = adapter_of(gpu);
    let readable = [
        wgpu::TextureFormat::Rgba32Float,
        wgpu::TextureFormat::Rgba32Uint,
    ]
    .into_iter()
    .all(|f| {
        let ff = adapter.get_texture_format_features(f);
        ff.allowed_usages
            .contains(wgpu::TextureUsages::STORAGE_BINDING)
            && ff
                .flags
                .contains(wgpu::TextureFormatFeatureFlags::STORAGE_READ_ONLY)
    });
    let can = readable
        && adapter
            .get_downlevel_capabilities()
            .flags
            .contains(wgpu::DownlevelFlags::FRAGMENT_STORAGE)
        && adapter.limits().max_storage_textures_per_shader_stage >= 4;
    assert!(
        !can,
        "{} can read storage textures in fragment shaders but the device says it cannot, so {what} \
         would go untested",
        gpu.adapter_info.name
    );
    eprintln!(
        "note: {} ({:?}) cannot read storage textures in fragment shaders; {what} not tested",
        gpu.adapter_info.name, gpu.adapter_info.backend
    );
    false
}

/// Axis-aligned boxes `(centre, half extents)` in metres as one closed mesh with outward CCW
/// faces, 4 vertices per face (so positions repeat across faces, as at UV seams). Face `k`
/// of all boxes gets the lightmap chart at cell `k` of an 8×8 grid (one cell = 1/8 of the
/// map, a 1/64-map margin inside it).
pub fn closed_boxes(boxes: &[([f32; 3], [f32; 3])]) -> passes::MeshData {
    use glam::Vec3;
    let mut mesh = passes::MeshData::default();
    let mut cell = 0u32;
    for &(c, h) in boxes {
        let (c, h) = (Vec3::from(c), Vec3::from(h));
        // (normal, t, b) with t × b = normal.
        let faces = [
            (Vec3::X, Vec3::NEG_Z, Vec3::Y),
            (Vec3::NEG_X, Vec3::Z, Vec3::Y),
            (Vec3::Y, Vec3::X, Vec3::NEG_Z),
            (Vec3::NEG_Y, Vec3::X, Vec3::Z),
            (Vec3::Z, Vec3::X, Vec3::Y),
            (Vec3::NEG_Z, Vec3::NEG_X, Vec3::Y),
        ];
        for (n, t, b) in faces {
            let base = mesh.positions_m.len() as u32;
            let (gx, gy) = ((cell % 8) as f32, (cell / 8) as f32);
            for (s, r) in [(0.0f32, 0.0f32), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)] {
                let p = c + (n + t * (2.0 * s - 1.0) + b * (2.0 * r - 1.0)) * h;
                mesh.positions_m.push(p.into());
                mesh.normals.push(n.into());
                let u = (gx + 0.125 + 0.75 * s) / 8.0;
                let v = 1.0 - (gy + 0.125 + 0.75 * (1.0 - r)) / 8.0;
                mesh.lightmap_uvs.push([u, v]);
            }
            mesh.indices
                .extend([base, base + 1, base + 2, base, base + 2, base + 3]);
            cell += 1;
        }
    }
    mesh
}

/// `mesh` plus one tiny triangle at `at` (metres) with UVs outside the map: the mesh is no
/// longer closed, so no pass culls back faces, while what is rendered stays the same when
/// `at` lies inside a closed part (the triangle is hidden there, covers no texel and does
/// not change the bounds).
pub fn opened(mesh: &passes::MeshData, at: [f32; 3]) -> passes::MeshData {
    let mut m = mesh.clone();
    let base = m.positions_m.len() as u32;
    for d in [[0.0, 0.0, 0.0], [0.01, 0.0, 0.0], [0.0, 0.01, 0.0]] {
        m.positions_m
            .push([at[0] + d[0], at[1] + d[1], at[2] + d[2]]);
        m.normals.push([0.0, 0.0, 1.0]);
        m.lightmap_uvs.push([2.0, 2.0]);
    }
    m.indices.extend([base, base + 1, base + 2]);
    m
}

/// Renderer options of the frame tests on the demo scene: 256² shadow maps of 8 layers, a
/// side-by-side display of `width × height` pixels, the rest default.
pub fn demo_renderer_options(width: u32, height: u32) -> passes::RendererOptions {
    passes::RendererOptions {
        first_order: passes::first_order::FirstOrderOptions {
            shadow_map_size: 256,
            max_shadow_layers: 8,
            ..Default::default()
        },
        display: passes::display::DisplayOptions {
            width,
            height,
            side_by_side: true,
            ..Default::default()
        },
        ..Default::default()
    }
}

/// The camera the frame tests view the demo scene with.
pub fn demo_camera() -> passes::display::Camera {
    passes::display::Camera {
        eye: [2.0, 2.0, 3.0],
        target: [0.0; 3],
        up: [0.0, 1.0, 0.0],
        fov_y_deg: 45.0,
        near: 0.05,
        far: 20.0,
    }
}
