// Shared WGSL: the first-order pass's per-frame uniforms and shadow maps, and the shadowed
// visibility of a light at a surface point. Prepended (after lights.wgsl) to first_order.wgsl
// (SHADOW_GROUP = 0) and display.wgsl (SHADOW_GROUP = 2, the per-pixel direct light) by the
// Rust side, which also replaces MAX_LAYERS by FirstOrderOptions::max_shadow_layers. Both
// passes bind the same buffers and textures (`FirstOrderScene`), so a texel of the lightmap
// and a pixel of the display see the same shadow test.
// Mirror: src/cpu/first_order.rs (`occluded`: exact ray-cast shadows instead of maps).

// Must match `FirstOrderParams` in first_order.rs (32 bytes).
struct Params {
    lightmap_size: vec2<u32>,
    light_count: u32,
    shadow_size: u32,
    // Normal offset of shadow lookups in shadow texels.
    normal_offset_texels: f32,
    _pad0: f32,
    _pad1: f32,
    _pad2: f32,
}

@group(SHADOW_GROUP) @binding(0) var<uniform> params: Params;
// Uniform, not storage, arrays: llvmpipe reads storage buffers lane by lane.
@group(SHADOW_GROUP) @binding(1) var<uniform> lights: array<GpuLight, MAX_LAYERS>;
@group(SHADOW_GROUP) @binding(2) var<uniform> layer_view_proj: array<mat4x4<f32>, MAX_LAYERS>;
@group(SHADOW_GROUP) @binding(4) var shadow_maps: texture_depth_2d_array;
@group(SHADOW_GROUP) @binding(5) var shadow_sampler: sampler_comparison;

// Cube face of a direction, in the order +X, −X, +Y, −Y, +Z, −Z (must match
// `point_face_dirs` in first_order.rs).
fn cube_face(v: vec3<f32>) -> u32 {
    let a = abs(v);
    if (a.x >= a.y && a.x >= a.z) {
        return select(1u, 0u, v.x > 0.0);
    }
    if (a.y >= a.z) {
        return select(3u, 2u, v.y > 0.0);
    }
    return select(5u, 4u, v.z > 0.0);
}

// Fraction of the light reaching p (1 lit, 0 shadowed; 2×2 hardware PCF in between).
// Biases: the lookup point moves off the surface along n by normal_offset_texels shadow
// texels (the world size of a texel at that distance), and the shadow pass adds a
// slope-scaled depth bias (FirstOrderOptions::slope_bias).
fn shadow_visibility(light: GpuLight, p: vec3<f32>, n: vec3<f32>) -> f32 {
    var texel_m = light.cone.w;
    if (light.kind != LIGHT_DIRECTIONAL) {
        texel_m = light.cone.z * distance(p, light.position.xyz);
    }
    let q = p + n * (params.normal_offset_texels * texel_m);
    var layer = light.first_layer;
    if (light.kind == LIGHT_POINT && light.layer_count == 6u) {
        layer += cube_face(q - light.position.xyz);
    }
    let clip = layer_view_proj[layer] * vec4<f32>(q, 1.0);
    if (clip.w <= 0.0) {
        return 1.0;
    }
    let ndc = clip.xyz / clip.w;
    let uv = vec2<f32>(0.5 * ndc.x + 0.5, 0.5 - 0.5 * ndc.y);
    if (any(uv < vec2<f32>(0.0)) || any(uv > vec2<f32>(1.0)) || ndc.z > 1.0 || ndc.z < 0.0) {
        return 1.0; // outside the map: nothing there can occlude (maps bound the scene)
    }
    return textureSampleCompareLevel(shadow_maps, shadow_sampler, uv, i32(layer), ndc.z);
}

// Irradiance (W/m²) of every light at p with normal n (unit), shadowed.
fn shadowed_irradiance(p: vec3<f32>, n: vec3<f32>) -> vec3<f32> {
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < params.light_count; i++) {
        let light = lights[i];
        let e_light = unshadowed_irradiance(light, p, n);
        if (any(e_light > vec3<f32>(0.0))) {
            e += e_light * shadow_visibility(light, p, n);
        }
    }
    return e;
}
