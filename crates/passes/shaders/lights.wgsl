// Shared WGSL: light records and unshadowed irradiance, prepended to first_order.wgsl and
// display.wgsl by the Rust side (WGSL has no #include). Mirror: src/cpu/first_order.rs
// (`unshadowed_irradiance`).
// Units: positions metres, `radiance` = color·I (W/sr) for point/spot, color·E⊥ (W/m²) for
// directional; result irradiance E in W/m².

const LIGHT_POINT: u32 = 0u;
const LIGHT_SPOT: u32 = 1u;
const LIGHT_DIRECTIONAL: u32 = 2u;

// Must match `GpuLight` in src/first_order.rs (80 bytes).
struct GpuLight {
    // xyz: position in metres (point, spot); w unused.
    position: vec4<f32>,
    // xyz: unit spot axis, or unit travel direction (directional); w unused.
    direction: vec4<f32>,
    // rgb: color·intensity (W/sr) or color·irradiance (W/m²); a unused.
    radiance: vec4<f32>,
    // x: cos(outer), y: cos(inner) (spot); z: shadow texel size per metre of distance
    // (perspective maps); w: shadow texel size in metres (orthographic maps).
    cone: vec4<f32>,
    kind: u32,
    // First layer in the shadow-map array and number of layers (6 point, 1 otherwise).
    first_layer: u32,
    layer_count: u32,
    _pad: u32,
}

// Direction towards the light (unit) and the irradiance a surface facing it head-on would
// get (W/m²), before the cosine and shadowing.
struct Incident {
    to_light: vec3<f32>,
    e_normal: vec3<f32>,
}

fn light_incident(light: GpuLight, p: vec3<f32>) -> Incident {
    var inc: Incident;
    if (light.kind == LIGHT_DIRECTIONAL) {
        inc.to_light = -light.direction.xyz;
        inc.e_normal = light.radiance.rgb;
        return inc;
    }
    let l = light.position.xyz - p;
    let d2 = max(dot(l, l), 1e-12);
    inc.to_light = l * inverseSqrt(d2);
    var e = light.radiance.rgb / d2;
    if (light.kind == LIGHT_SPOT) {
        e *= smoothstep(light.cone.x, light.cone.y, dot(-inc.to_light, light.direction.xyz));
    }
    inc.e_normal = e;
    return inc;
}

// E = E_normal · max(n·ω, 0), unshadowed.
fn unshadowed_irradiance(light: GpuLight, p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    let inc = light_incident(light, p);
    return inc.e_normal * max(dot(n, inc.to_light), 0.0);
}
