// Indirect light: out = final − first order (RGB, W/m²), alpha = first-order coverage.
// Host side: src/indirect.rs; CPU mirror: src/cpu/indirect.rs.
//
// Bindings (group 0, must match `IndirectPass` in indirect.rs): 0 = first-order map,
// 1 = final map (both float textures of the lightmap size, textureLoad), 2 = output
// (RGBA32F storage texture, write).
@group(0) @binding(0) var first_order: texture_2d<f32>;
@group(0) @binding(1) var final_map: texture_2d<f32>;
@group(0) @binding(2) var out_map: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = textureDimensions(out_map);
    if (id.x >= size.x || id.y >= size.y) {
        return;
    }
    let p = vec2<i32>(id.xy);
    let a = textureLoad(first_order, p, 0);
    let b = textureLoad(final_map, p, 0);
    textureStore(out_map, p, vec4<f32>(b.rgb - a.rgb, a.a));
}
