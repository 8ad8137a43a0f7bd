//! CPU mirror of the first-order pass (`shaders/first_order.wgsl`, `shaders/lights.wgsl`),
//! with *exact* shadows: brute-force ray/triangle tests against the mesh instead of shadow
//! maps (so GPU-vs-CPU differences away from shadow edges measure the shadow-map biases).
//!
//! Steps, as in the shader: rasterise the UV triangles at texel centres (the centre rule,
//! inclusive on edges), interpolate world position and normal barycentrically, renormalise
//! the normal, sum `E_light · visibility` over lights, output `(ρ·E, 1)`; uncovered texels
//! stay `(0, 0, 0, 0)`. Lights go through the same packing ([`crate::first_order::pack_lights`])
//! as on the GPU. Meant for small test meshes (cost = texels × lights × triangles).

use glam::{Vec2, Vec3};

use crate::first_order::{Bounds, GpuLight, LIGHT_DIRECTIONAL, LIGHT_SPOT, pack_lights};
use crate::types::{AlbedoMap, LightDesc, MeshData, TexelImage};

/// A covered texel: its coordinates and the interpolated surface point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct TexelSample {
    /// Column.
    pub x: u32,
    /// Row.
    pub y: u32,
    /// World position (m).
    pub position: Vec3,
    /// Unit normal.
    pub normal: Vec3,
    /// World area of the texel's square on its triangle (m²): the triangle's 3D area over
    /// its area in texels (`|∂P/∂x × ∂P/∂y|`, the G-buffer's `normal.w`).
    pub area_m2: f32,
}

/// Texels whose centre lies in a UV triangle (last triangle wins), with interpolated
/// position and normal — `vs_lightmap` + rasteriser.
pub fn rasterize_uv(mesh: &MeshData, width: u32, height: u32) -> Vec<TexelSample> {
    let mut owner: Vec<Option<TexelSample>> = vec![None; width as usize * height as usize];
    for tri in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| i as usize);
        // Texel space: (u·W, (1−v)·H).
        let ts = |i: usize| {
            let uv = mesh.lightmap_uvs[i];
            Vec2::new(uv[0] * width as f32, (1.0 - uv[1]) * height as f32)
        };
        let (pa, pb, pc) = (ts(a), ts(b), ts(c));
        let area = (pb - pa).perp_dot(pc - pa);
        if area == 0.0 {
            continue;
        }
        let lo = pa.min(pb).min(pc).floor().max(Vec2::ZERO);
        let hi = pa
            .max(pb)
            .max(pc)
            .ceil()
            .min(Vec2::new(width as f32, height as f32));
        for y in lo.y as u32..hi.y as u32 {
            for x in lo.x as u32..hi.x as u32 {
                let p = Vec2::new(x as f32 + 0.5, y as f32 + 0.5);
                let wa = (pc - pb).perp_dot(p - pb) / area;
                let wb = (pa - pc).perp_dot(p - pc) / area;
                let wc = 1.0 - wa - wb;
                if wa < 0.0 || wb < 0.0 || wc < 0.0 {
                    continue;
                }
                let pos = |i: usize| Vec3::from(mesh.positions_m[i]);
                let nor = |i: usize| Vec3::from(mesh.normals[i]);
                let position = wa * pos(a) + wb * pos(b) + wc * pos(c);
                let normal = (wa * nor(a) + wb * nor(b) + wc * nor(c)).normalize_or_zero();
                let area_m2 = (pos(b) - pos(a)).cross(pos(c) - pos(a)).length() / area.abs();
                owner[(y * width + x) as usize] = Some(TexelSample {
                    x,
                    y,
                    position,
                    normal,
                    area_m2,
                });
            }
        }
    }
    owner.into_iter().flatten().collect()
}

fn smoothstep(e0: f32, e1: f32, x: f32) -> f32 {
    let t = ((x - e0) / (e1 - e0)).clamp(0.0, 1.0);
    t * t * (3.0 - 2.0 * t)
}

/// Unit direction towards the light and the irradiance on a surface facing it
/// (`light_incident` in lights.wgsl).
pub fn light_incident(light: &GpuLight, p: Vec3) -> (Vec3, Vec3) {
    let radiance = Vec3::new(light.radiance[0], light.radiance[1], light.radiance[2]);
    let dir = Vec3::new(light.direction[0], light.direction[1], light.direction[2]);
    if light.kind == LIGHT_DIRECTIONAL {
        return (-dir, radiance);
    }
    let l = Vec3::new(light.position[0], light.position[1], light.position[2]) - p;
    let d2 = l.length_squared().max(1e-12);
    let to_light = l / d2.sqrt();
    let mut e = radiance / d2;
    if light.kind == LIGHT_SPOT {
        e *= smoothstep(light.cone[0], light.cone[1], (-to_light).dot(dir));
    }
    (to_light, e)
}

/// `E = E_normal · max(n·ω, 0)` without shadows (`unshadowed_irradiance` in lights.wgsl).
pub fn unshadowed_irradiance(light: &GpuLight, p: Vec3, n: Vec3) -> Vec3 {
    let (to_light, e) = light_incident(light, p);
    e * n.dot(to_light).max(0.0)
}

/// Möller–Trumbore: distance along `dir` to the triangle, if hit with `t > 0`.
fn ray_triangle(o: Vec3, dir: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Option<f32> {
    let e1 = b - a;
    let e2 = c - a;
    let pv = dir.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-12 {
        return None;
    }
    let inv = 1.0 / det;
    let tv = o - a;
    let u = tv.dot(pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = tv.cross(e1);
    let v = dir.dot(qv) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(qv) * inv;
    (t > 0.0).then_some(t)
}

/// Whether the segment from `p` (nudged 0.1 mm along `n`) towards the light is blocked
/// by any triangle of the mesh.
pub fn occluded(mesh: &MeshData, light: &GpuLight, p: Vec3, n: Vec3) -> bool {
    let (to_light, _) = light_incident(light, p);
    let o = p + n * 1e-4;
    let max_t = if light.kind == LIGHT_DIRECTIONAL {
        f32::INFINITY
    } else {
        (Vec3::new(light.position[0], light.position[1], light.position[2]) - o).length()
    };
    mesh.indices.chunks_exact(3).any(|tri| {
        let v = |i: u32| Vec3::from(mesh.positions_m[i as usize]);
        ray_triangle(o, to_light, v(tri[0]), v(tri[1]), v(tri[2]))
            .is_some_and(|t| t < max_t * (1.0 - 1e-5))
    })
}

/// The packed lights used by both GPU and mirror.
pub fn packed_lights(mesh: &MeshData, lights: &[LightDesc]) -> Vec<GpuLight> {
    let bounds = Bounds::of(&mesh.positions_m);
    pack_lights(lights, &bounds, 1, u32::MAX)
        .map(|(l, _)| l)
        .unwrap_or_default()
}

/// Irradiance at `s` from the packed lights, with exact shadows (W/m²).
fn irradiance(mesh: &MeshData, lights: &[GpuLight], s: &TexelSample) -> Vec3 {
    let mut e = Vec3::ZERO;
    for light in lights {
        let e_light = unshadowed_irradiance(light, s.position, s.normal);
        if e_light.max_element() > 0.0 && !occluded(mesh, light, s.position, s.normal) {
            e += e_light;
        }
    }
    e
}

/// The first-order lightmap with exact shadows (`fs_lightmap` with ray-traced visibility).
pub fn first_order(mesh: &MeshData, albedo: &AlbedoMap, lights: &[LightDesc]) -> TexelImage {
    let gl = packed_lights(mesh, lights);
    let mut out = TexelImage::new(albedo.width, albedo.height);
    for s in rasterize_uv(mesh, albedo.width, albedo.height) {
        let rho = Vec3::from(albedo.rgb[(s.y * albedo.width + s.x) as usize]);
        let b = rho * irradiance(mesh, &gl, &s);
        *out.at_mut(s.x, s.y) = [b.x, b.y, b.z, 1.0];
    }
    out
}

/// The averaged first-order pass (`fs_lightmap_averaged`, `samples` odd) with exact
/// shadows: returns `(first order, transfer input)`. The mesh is rasterised at `samples×`
/// the albedo's size; a texel is covered when its centre sub-texel is, its input is `ρ` times
/// the irradiance averaged over its covered sub-texels weighted by their world areas, and its
/// first order `ρ` times the centre's irradiance — or the average where `translucent` (one
/// flag per texel, row-major) says so.
pub fn first_order_averaged(
    mesh: &MeshData,
    albedo: &AlbedoMap,
    translucent: Option<&[bool]>,
    lights: &[LightDesc],
    samples: u32,
) -> (TexelImage, TexelImage) {
    assert!(!samples.is_multiple_of(2), "samples must be odd");
    let gl = packed_lights(mesh, lights);
    let (w, h) = (albedo.width, albedo.height);
    let n = samples;
    // Per texel: centre irradiance (if covered), Σ area·E, Σ area.
    let mut acc = vec![(None::<Vec3>, Vec3::ZERO, 0.0f32); w as usize * h as usize];
    for s in rasterize_uv(mesh, w * n, h * n) {
        let e = irradiance(mesh, &gl, &s);
        let slot = &mut acc[((s.y / n) * w + s.x / n) as usize];
        if s.x % n == n / 2 && s.y % n == n / 2 {
            slot.0 = Some(e);
        }
        slot.1 += s.area_m2 * e;
        slot.2 += s.area_m2;
    }
    let mut first = TexelImage::new(w, h);
    let mut input = TexelImage::new(w, h);
    for (i, (centre, sum, area)) in acc.into_iter().enumerate() {
        let Some(centre) = centre else { continue };
        let mean = if area > 0.0 { sum / area } else { centre };
        let rho = Vec3::from(albedo.rgb[i]);
        let own = if translucent.is_some_and(|t| t[i]) {
            mean
        } else {
            centre
        };
        let (x, y) = (i as u32 % w, i as u32 / w);
        *first.at_mut(x, y) = (rho * own).extend(1.0).to_array();
        *input.at_mut(x, y) = (rho * mean).extend(1.0).to_array();
    }
    (first, input)
}
