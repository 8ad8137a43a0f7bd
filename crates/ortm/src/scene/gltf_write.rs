//! Writes a mesh, its materials and lights as glTF 2.0: what `ortm unwrap` outputs and what
//! the tests generate their glTF files with.
//!
//! # Layout
//! One mesh with one triangle-list primitive per material, on the innermost of a chain of
//! nodes (each a translation and a uniform scale, [`GltfWrite::node_chain`]); the mesh's
//! positions are written as given (they are in that innermost node's frame). Every triangle
//! corner is its own vertex (no index sharing): `POSITION` (with min/max), `NORMAL`, and the
//! lightmap UV as both `TEXCOORD_0` and `TEXCOORD_1` (`v` flipped to glTF's down axis).
//! Materials become `baseColorFactor` (linear; an albedo texture is written as white with a
//! warning, textures are not copied). Lights go to `KHR_lights_punctual` nodes under the
//! root, converted back to candela and lux with [`super::gltf::LUMENS_PER_WATT`].
//!
//! The buffer is a GLB chunk (`.glb`), a `.bin` beside the `.gltf` ([`BufferMode::External`])
//! or a base64 `data:` URI inside it ([`BufferMode::Embedded`]).

use std::path::Path;

use glam::{Quat, Vec3};
use serde_json::{Value, json};

use super::gltf::LUMENS_PER_WATT;
use super::{Albedo, Light, Material, Mesh};

/// Where a `.gltf`'s buffer goes (a `.glb` always holds its own).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum BufferMode {
    /// A `.bin` file beside the `.gltf`, same stem.
    External,
    /// A base64 `data:` URI in the `.gltf`.
    Embedded,
}

/// What to write.
#[derive(Clone, Debug)]
pub struct GltfWrite<'a> {
    /// The mesh (positions in the innermost node's frame, metres at scale 1).
    pub mesh: &'a Mesh,
    /// Materials indexed by the triangles.
    pub materials: &'a [Material],
    /// Lights (world space).
    pub lights: &'a [Light],
    /// Nodes from the root inwards, each `(translation, uniform scale)`; empty = one node
    /// with the identity.
    pub node_chain: Vec<(Vec3, f32)>,
    /// Buffer placement for a `.gltf`.
    pub buffer: BufferMode,
}

/// Appends `data` to `bin` (4-byte aligned) as a buffer view and accessor; returns the
/// accessor index.
fn accessor(
    bin: &mut Vec<u8>,
    views: &mut Vec<Value>,
    accessors: &mut Vec<Value>,
    floats: &[f32],
    kind: &str,
    min_max: Option<(Vec3, Vec3)>,
) -> usize {
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let offset = bin.len();
    for f in floats {
        bin.extend_from_slice(&f.to_le_bytes());
    }
    let width = if kind == "VEC3" { 3 } else { 2 };
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": floats.len() * 4}));
    let mut a = json!({
        "bufferView": views.len() - 1,
        "componentType": 5126,
        "count": floats.len() / width,
        "type": kind,
    });
    if let Some((lo, hi)) = min_max {
        a["min"] = json!(lo.to_array());
        a["max"] = json!(hi.to_array());
    }
    accessors.push(a);
    accessors.len() - 1
}

/// One triangle-list primitive per material with triangles, its attributes appended to `bin`,
/// `views` and `accessors`.
fn primitives(
    w: &GltfWrite,
    bin: &mut Vec<u8>,
    views: &mut Vec<Value>,
    accessors: &mut Vec<Value>,
) -> Vec<Value> {
    let m = w.mesh;
    let mut primitives = Vec::new();
    for mat in 0..w.materials.len().max(1) as u32 {
        let tris: Vec<_> = m.triangles.iter().filter(|t| t.material == mat).collect();
        if tris.is_empty() {
            continue;
        }
        let (mut p, mut n, mut uv) = (Vec::new(), Vec::new(), Vec::new());
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for t in &tris {
            for k in 0..3 {
                let q = m.positions_m[t.position[k] as usize];
                lo = lo.min(q);
                hi = hi.max(q);
                p.extend(q.to_array());
                n.extend(m.normals[t.normal[k] as usize].to_array());
                let u = m.uvs[t.uv[k] as usize];
                uv.extend([u.x, 1.0 - u.y]);
            }
        }
        let pa = accessor(bin, views, accessors, &p, "VEC3", Some((lo, hi)));
        let na = accessor(bin, views, accessors, &n, "VEC3", None);
        let ua = accessor(bin, views, accessors, &uv, "VEC2", None);
        let mut prim = json!({
            "attributes": {"POSITION": pa, "NORMAL": na, "TEXCOORD_0": ua, "TEXCOORD_1": ua},
            "mode": 4,
        });
        if (mat as usize) < w.materials.len() {
            prim["material"] = json!(mat);
        }
        primitives.push(prim);
    }
    primitives
}

/// The document's JSON and binary buffer.
fn document(w: &GltfWrite) -> (Value, Vec<u8>) {
    let (mut bin, mut views, mut accessors) = (Vec::new(), Vec::new(), Vec::new());
    let primitives = primitives(w, &mut bin, &mut views, &mut accessors);
    let materials: Vec<Value> = w
        .materials
        .iter()
        .map(|mat| {
            let c = match &mat.albedo {
                Albedo::Constant(c) => *c,
                Albedo::Texture(_) => Vec3::ONE,
            };
            json!({
                "name": mat.name,
                "pbrMetallicRoughness": {
                    "baseColorFactor": [c.x, c.y, c.z, 1.0],
                    "metallicFactor": 0.0,
                    "roughnessFactor": 1.0,
                },
            })
        })
        .collect();
    let (mut nodes, mut lights) = (Vec::new(), Vec::new());
    let chain = if w.node_chain.is_empty() {
        vec![(Vec3::ZERO, 1.0)]
    } else {
        w.node_chain.clone()
    };
    for (i, (t, s)) in chain.iter().enumerate() {
        let mut node = json!({"translation": t.to_array(), "scale": [s, s, s]});
        if i + 1 < chain.len() {
            node["children"] = json!([i + 1]);
        } else {
            node["mesh"] = json!(0);
        }
        nodes.push(node);
    }
    let mut roots = vec![0];
    for l in w.lights {
        let (node, light) = light_json(l);
        lights.push(light);
        let mut node = node;
        node["extensions"] = json!({"KHR_lights_punctual": {"light": lights.len() - 1}});
        nodes.push(node);
        roots.push(nodes.len() - 1);
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "ortm"},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": [{"primitives": primitives}],
        "materials": materials,
        "accessors": accessors,
        "bufferViews": views,
        "buffers": [{"byteLength": bin.len()}],
    });
    if !lights.is_empty() {
        doc["extensionsUsed"] = json!(["KHR_lights_punctual"]);
        doc["extensions"] = json!({"KHR_lights_punctual": {"lights": lights}});
    }
    (doc, bin)
}

/// A light's node (translation, rotation taking −Z to its direction) and its JSON.
fn light_json(l: &Light) -> (Value, Value) {
    let node = |p: Vec3, d: Vec3| {
        let q = Quat::from_rotation_arc(Vec3::NEG_Z, d.normalize());
        json!({"translation": p.to_array(), "rotation": q.to_array()})
    };
    match *l {
        Light::Point {
            position_m,
            color,
            intensity_w_sr,
        } => (
            node(position_m, Vec3::NEG_Z),
            json!({"type": "point", "color": color.to_array(),
                   "intensity": intensity_w_sr * LUMENS_PER_WATT}),
        ),
        Light::Spot {
            position_m,
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
        } => (
            node(position_m, direction),
            json!({"type": "spot", "color": color.to_array(),
                   "intensity": intensity_w_sr * LUMENS_PER_WATT,
                   "spot": {"innerConeAngle": inner_deg.to_radians(),
                            "outerConeAngle": outer_deg.to_radians()}}),
        ),
        Light::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => (
            node(Vec3::ZERO, direction),
            json!({"type": "directional", "color": color.to_array(),
                   "intensity": irradiance_w_m2 * LUMENS_PER_WATT}),
        ),
    }
}

/// Standard base64 (with padding) of `bytes`.
fn base64(bytes: &[u8]) -> String {
    const A: &[u8; 64] = b"ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/";
    let mut out = String::with_capacity(bytes.len().div_ceil(3) * 4);
    for c in bytes.chunks(3) {
        let n = (c[0] as u32) << 16
            | (*c.get(1).unwrap_or(&0) as u32) << 8
            | *c.get(2).unwrap_or(&0) as u32;
        for k in 0..4 {
            if k <= c.len() {
                out.push(A[(n >> (18 - 6 * k) & 63) as usize] as char);
            } else {
                out.push('=');
            }
        }
    }
    out
}

/// Writes `w` to `path`: binary glTF when it ends in `.glb`, else JSON glTF with its buffer
/// placed by [`GltfWrite::buffer`].
pub fn write_gltf(path: &Path, w: &GltfWrite) -> std::io::Result<()> {
    let (mut doc, bin) = document(w);
    let is_glb = path
        .extension()
        .is_some_and(|e| e.eq_ignore_ascii_case("glb"));
    if is_glb {
        let mut json = serde_json::to_vec(&doc)?;
        while !json.len().is_multiple_of(4) {
            json.push(b' ');
        }
        let mut bin = bin;
        while !bin.len().is_multiple_of(4) {
            bin.push(0);
        }
        let total = 12 + 8 + json.len() + 8 + bin.len();
        let mut out = Vec::with_capacity(total);
        out.extend_from_slice(b"glTF");
        out.extend_from_slice(&2u32.to_le_bytes());
        out.extend_from_slice(&(total as u32).to_le_bytes());
        out.extend_from_slice(&(json.len() as u32).to_le_bytes());
        out.extend_from_slice(b"JSON");
        out.extend_from_slice(&json);
        out.extend_from_slice(&(bin.len() as u32).to_le_bytes());
        out.extend_from_slice(b"BIN\0");
        out.extend_from_slice(&bin);
        return std::fs::write(path, out);
    }
    match w.buffer {
        BufferMode::External => {
            let bin_path = path.with_extension("bin");
            let name = bin_path
                .file_name()
                .map_or_else(String::new, |f| f.to_string_lossy().into_owned());
            doc["buffers"][0]["uri"] = json!(name);
            std::fs::write(&bin_path, &bin)?;
        }
        BufferMode::Embedded => {
            doc["buffers"][0]["uri"] = json!(format!(
                "data:application/octet-stream;base64,{}",
                base64(&bin)
            ));
        }
    }
    std::fs::write(path, serde_json::to_vec_pretty(&doc)?)
}

#[cfg(test)]
mod tests {
    #[test]
    fn base64_matches_rfc4648_vectors() {
        // RFC 4648 §10 test vectors.
        for (i, o) in [
            ("", ""),
            ("f", "Zg=="),
            ("fo", "Zm8="),
            ("foo", "Zm9v"),
            ("foob", "Zm9vYg=="),
            ("fooba", "Zm9vYmE="),
            ("foobar", "Zm9vYmFy"),
        ] {
            assert_eq!(super::base64(i.as_bytes()), o);
        }
    }
}
