// Pyramid pass: the area-weighted pyramid of the first-order lightmap, one dispatch per level.
// Mirror: src/cpu/pyramid.rs. Host side: src/pyramid.rs.
//
// cs_reduce (level ℓ, one invocation per block b of level ℓ):
//   ℓ = 1: s = Σ_{c ∈ 2b + {0,1}², c in the map} (w(c)·B_o(c), w(c))
//   ℓ ≥ 2: s = Σ_{c ∈ 2b + {0,1}², c in level ℓ−1} sums_{ℓ−1}(c)
//   sums_ℓ(b) = s; packed(origin_ℓ + b) = (s.rgb / s.a, s.a), or (0, 0, 0, s.a) when s.a = 0.
//
// Bindings (bind-group order = @binding order; must match `PyramidPass` layout in pyramid.rs):
//   group 0: 0 = Params (uniform), 1 = first-order map (RGBA32F, textureLoad),
//            2 = weights (R32Float, textureLoad), 3 = sums (storage, read_write, vec4 per block
//            of levels 1..=max, level after level), 4 = packed pyramid (storage texture, write)
// Coordinates: texel (x, y), y down, row 0 = v = 1. Means in W/m², weights in m².

// Must match `PyramidParams` in pyramid.rs (48 bytes).
struct Params {
    src_size: vec2<u32>,
    dst_size: vec2<u32>,
    src_base: u32,
    dst_base: u32,
    dst_origin: vec2<u32>,
    level: u32,
    _pad0: u32,
    _pad1: u32,
    _pad2: u32,
}

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var first_order: texture_2d<f32>;
@group(0) @binding(2) var weights: texture_2d<f32>;
@group(0) @binding(3) var<storage, read_write> sums: array<vec4<f32>>;
@group(0) @binding(4) var packed: texture_storage_2d<rgba32float, write>;

@compute @workgroup_size(8, 8)
fn cs_reduce(@builtin(global_invocation_id) gid: vec3<u32>) {
    let b = gid.xy;
    if (any(b >= params.dst_size)) {
        return;
    }
    var s = vec4<f32>(0.0);
    for (var dy = 0u; dy < 2u; dy++) {
        for (var dx = 0u; dx < 2u; dx++) {
            let c = 2u * b + vec2<u32>(dx, dy);
            if (any(c >= params.src_size)) {
                continue;
            }
            if (params.level == 1u) {
                let w = textureLoad(weights, vec2<i32>(c), 0).r;
                let f = textureLoad(first_order, vec2<i32>(c), 0).rgb;
                s += vec4<f32>(w * f, w);
            } else {
                s += sums[params.src_base + c.y * params.src_size.x + c.x];
            }
        }
    }
    sums[params.dst_base + b.y * params.dst_size.x + b.x] = s;
    var mean = vec3<f32>(0.0);
    if (s.a > 0.0) {
        mean = s.rgb / s.a;
    }
    textureStore(packed, vec2<i32>(params.dst_origin + b), vec4<f32>(mean, s.a));
}
