// Shared by transfer.wgsl and transfer_pair.wgsl (the host prepends it to each, after
// transfer_params.wgsl; WGSL has no includes): the instanced quad both draw.
// Coordinates: texel (x, y), y down, row 0 = v = 1; framebuffer pixel (x, y) is texel (x, y)
// of the accumulation target (the lightmap, with the receiver-block grids below it).

// Texel-space point (x right, y down, in texels) to clip space.
fn texel_to_clip(p: vec2<f32>) -> vec4<f32> {
    let size = vec2<f32>(params.target_size);
    return vec4<f32>(2.0 * p.x / size.x - 1.0, 1.0 - 2.0 * p.y / size.y, 0.0, 1.0);
}

// Vertex `vi` (0–5: two triangles) of the quad covering texels [dst, dst + size): the
// rasteriser's pixel-centre rule selects exactly those texels.
fn quad_clip(vi: u32, dst: vec2<u32>, size: vec2<u32>) -> vec4<f32> {
    var corners = array<vec2<f32>, 6>(
        vec2<f32>(0.0, 0.0), vec2<f32>(1.0, 0.0), vec2<f32>(0.0, 1.0),
        vec2<f32>(0.0, 1.0), vec2<f32>(1.0, 0.0), vec2<f32>(1.0, 1.0),
    );
    return texel_to_clip(vec2<f32>(dst) + corners[vi] * vec2<f32>(size));
}
