//! Conversion of ortm's types into the `passes` crate's inputs, and of its read-back back
//! into ortm's.
//!
//! # Data flow
//! ```text
//! Scene.mesh ──mesh_data──▶ MeshData        (one GPU vertex per distinct position/UV/normal corner)
//! TexelGrid ──albedo_map──▶ AlbedoMap       (ρ per texel; subsurface: effective albedo)
//! Scene materials + TexelGrid + Effects ──diffusion_lengths──▶ metres per texel (translucency)
//! Light ──light_desc──▶ LightDesc           (lights ──shadow_layers_for──▶ shadow-map layers)
//! AtlasSet ──transfer_inputs──▶ (Vec<AtlasData>, Vec<TransferPiece>)
//! TexelImage (read back) ──to_lightmap──▶ Lightmap
//! ```
//!
//! # Units and conventions
//! Nothing is rescaled or flipped: positions in metres, intensity in W/sr, irradiance and
//! lightmaps in W/m² on both sides, the same texel-centre convention (row 0 is `v = 1`), and
//! transfer pieces keep the bake's offset `Δt = (dx, dy)` in texels (`+dy` down).

use std::collections::HashMap;

use glam::Vec3;
use passes::{AlbedoMap, AtlasData, LightDesc, MeshData, TexelImage, TexelWeights, TransferPiece};

use super::RenderError;
use crate::Lightmap;
use crate::atlas::{AtlasPiece, AtlasSet};
use crate::bake::texels::TexelGrid;
use crate::bake::transport::Effects;
use crate::scene::{Light, Mesh, Scene};

/// Converts the scene mesh (per-corner position, UV and normal indices) into the passes'
/// indexed vertex layout: one vertex per distinct `(position, uv, normal)` index triple, in
/// order of first use, so shared corners stay shared and seams are split.
pub fn mesh_data(mesh: &Mesh) -> MeshData {
    let mut map: HashMap<[u32; 3], u32> = HashMap::new();
    let mut out = MeshData::default();
    out.indices.reserve(mesh.triangles.len() * 3);
    for t in &mesh.triangles {
        for k in 0..3 {
            let key = [t.position[k], t.uv[k], t.normal[k]];
            let next = out.positions_m.len() as u32;
            let ix = *map.entry(key).or_insert_with(|| {
                let get3 = |v: Option<&Vec3>| v.copied().unwrap_or(Vec3::ZERO).to_array();
                out.positions_m
                    .push(get3(mesh.positions_m.get(key[0] as usize)));
                out.lightmap_uvs.push(
                    mesh.uvs
                        .get(key[1] as usize)
                        .copied()
                        .unwrap_or_default()
                        .to_array(),
                );
                out.normals.push(get3(mesh.normals.get(key[2] as usize)));
                next
            });
            out.indices.push(ix);
        }
    }
    out
}

/// The per-texel reflectance ρ of the grid (`TexelGrid::albedo_map`: effective albedo for
/// subsurface materials, 0 on uncovered texels) as the first-order pass's albedo map.
pub fn albedo_map(grid: &TexelGrid) -> AlbedoMap {
    let m = grid.albedo_map();
    AlbedoMap {
        width: m.width,
        height: m.height,
        rgb: m.data,
    }
}

/// Diffusion length per lightmap texel (metres, row-major, 0 on diffuse materials): for a
/// subsurface material the longest of its channels' `1/σ_tr`, the distance over which the
/// dipole profile falls by `e`. The renderer takes texels with a length as translucent (their
/// first order the scattered average of the transfer's input, their diffused light kept on
/// screen where it spreads over more than a pixel: `passes::frame::Renderer::set_diffusion_lengths`).
/// `None` when no texel is subsurface, or when the bake's maps do not hold the subsurface term
/// (`effects`, [`super::effects_of`]): the texels are then opaque, their first order the
/// centre's and their light the maps' interreflection alone, as `ortm solve --effects
/// radiosity` gives it.
pub fn diffusion_lengths(scene: &Scene, grid: &TexelGrid, effects: Effects) -> Option<Vec<f32>> {
    if !effects.subsurface {
        return None;
    }
    let per_material: Vec<f32> = scene
        .materials
        .iter()
        .map(|m| {
            m.subsurface.as_ref().map_or(0.0, |s| {
                let p = crate::scene::subsurface::Profile::new(s);
                p.channels
                    .iter()
                    .map(|c| (1.0 / c.sigma_tr.max(1e-12)) as f32)
                    .fold(0.0, f32::max)
            })
        })
        .collect();
    if per_material.iter().all(|&l| l == 0.0) {
        return None;
    }
    let mut out = vec![0.0; (grid.width * grid.height) as usize];
    for t in &grid.texels {
        out[(t.y * grid.width + t.x) as usize] = per_material
            .get(t.material as usize)
            .copied()
            .unwrap_or(0.0);
    }
    Some(out)
}

/// The texel areas of the grid (m², 0 on uncovered texels) as the weights of the first-order
/// pyramid that multi-resolution maps read ([`crate::maps::levels`]).
pub fn texel_weights(grid: &TexelGrid) -> TexelWeights {
    TexelWeights {
        width: grid.width,
        height: grid.height,
        weights: grid.area_map(),
    }
}

/// One ortm light as a passes light (same units and models; see `ortm::bake::lighting`).
pub fn light_desc(light: &Light) -> LightDesc {
    match *light {
        Light::Point {
            position_m,
            color,
            intensity_w_sr,
        } => LightDesc::Point {
            position_m: position_m.to_array(),
            color: color.to_array(),
            intensity_w_sr,
        },
        Light::Spot {
            position_m,
            direction,
            color,
            intensity_w_sr,
            inner_deg,
            outer_deg,
        } => LightDesc::Spot {
            position_m: position_m.to_array(),
            direction: direction.to_array(),
            color: color.to_array(),
            intensity_w_sr,
            inner_deg,
            outer_deg,
        },
        Light::Directional {
            direction,
            color,
            irradiance_w_m2,
        } => LightDesc::Directional {
            direction: direction.to_array(),
            color: color.to_array(),
            irradiance_w_m2,
        },
    }
}

/// Shadow-map layers the first-order pass needs for `lights` (6 per point light, 1 per spot
/// or directional light), at least 1.
pub fn shadow_layers_for(lights: &[Light]) -> u32 {
    lights.iter().map(Light::shadow_layers).sum::<u32>().max(1)
}

/// One atlas piece as a passes transfer piece (same fields: atlas, source rectangle in the
/// atlas, destination in the lightmap — in receiver blocks for receiver level `r > 0` —, offset
/// `Δt` in texels or level-`ℓ` blocks, level, receiver level).
pub fn transfer_piece(p: &AtlasPiece) -> TransferPiece {
    TransferPiece {
        atlas: p.atlas,
        src_x: p.src_x,
        src_y: p.src_y,
        w: p.w,
        h: p.h,
        dst_x: p.dst_x,
        dst_y: p.dst_y,
        offset: p.offset,
        level: p.level,
        receiver_level: p.receiver_level,
    }
}

/// The atlases and pieces of `set` as passes inputs, after checking that every atlas holds
/// `atlas_size` texels, every piece lies inside its atlas and the lightmap (a piece of receiver
/// level `r > 0`: inside the `⌈W/2^r⌉ × ⌈H/2^r⌉` grid of receiver blocks), and the lightmap
/// size is `lightmap_size`.
pub fn transfer_inputs(
    set: &AtlasSet,
    lightmap_size: (u32, u32),
) -> Result<(Vec<AtlasData>, Vec<TransferPiece>), RenderError> {
    let bad = |problem: String| RenderError::BadAtlas { problem };
    if set.lightmap_size != lightmap_size {
        return Err(bad(format!(
            "made for a {}×{} lightmap but the scene's lightmap is {}×{}",
            set.lightmap_size.0, set.lightmap_size.1, lightmap_size.0, lightmap_size.1
        )));
    }
    let (aw, ah) = set.atlas_size;
    let texels = aw as usize * ah as usize;
    let mut atlases = Vec::with_capacity(set.atlases.len());
    for (i, a) in set.atlases.iter().enumerate() {
        if a.len() != texels {
            return Err(bad(format!(
                "atlas {i} holds {} texels, expected {aw}×{ah} = {texels}",
                a.len()
            )));
        }
        atlases.push(AtlasData {
            width: aw,
            height: ah,
            rgb: a.clone(),
        });
    }
    let inside = |o: u32, len: u32, size: u32| o as u64 + len as u64 <= size as u64;
    let pieces = set
        .pieces
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let (lw, lh) = crate::maps::receiver_grid(lightmap_size, p.receiver_level);
            if p.receiver_level > p.level
                || p.atlas as usize >= atlases.len()
                || !inside(p.src_x, p.w, aw)
                || !inside(p.src_y, p.h, ah)
                || !inside(p.dst_x, p.w, lw)
                || !inside(p.dst_y, p.h, lh)
            {
                return Err(bad(format!(
                    "piece {i} (map {}, atlas {}, {}×{} from ({}, {}) to ({}, {}), receiver level \
                     {} of level {}) lies outside its atlas or the lightmap's {lw}×{lh} grid",
                    p.map_index,
                    p.atlas,
                    p.w,
                    p.h,
                    p.src_x,
                    p.src_y,
                    p.dst_x,
                    p.dst_y,
                    p.receiver_level,
                    p.level
                )));
            }
            Ok(transfer_piece(p))
        })
        .collect::<Result<Vec<_>, _>>()?;
    Ok((atlases, pieces))
}

/// The RGB part of a read-back texel image as a [`Lightmap`] (alpha, the coverage, dropped).
pub fn to_lightmap(img: &TexelImage) -> Lightmap {
    Lightmap {
        width: img.width,
        height: img.height,
        data: img.rgba.iter().map(|p| [p[0], p[1], p[2]]).collect(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scene::MeshTriangle;
    use glam::Vec2;

    #[test]
    fn mesh_corners_are_shared_only_when_all_three_indices_agree() {
        // Two triangles sharing positions 0 and 2; the shared edge has one UV seam at
        // position 2 (uv 2 vs uv 3), so 0 is shared and 2 is split.
        let mesh = Mesh {
            positions_m: vec![Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::ONE],
            uvs: vec![Vec2::ZERO, Vec2::X, Vec2::Y, Vec2::ONE],
            normals: vec![Vec3::Z],
            triangles: vec![
                MeshTriangle {
                    position: [0, 1, 2],
                    uv: [0, 1, 2],
                    normal: [0; 3],
                    material: 0,
                },
                MeshTriangle {
                    position: [0, 2, 3],
                    uv: [0, 3, 3],
                    normal: [0; 3],
                    material: 0,
                },
            ],
        };
        let d = mesh_data(&mesh);
        d.validate().unwrap();
        assert_eq!(d.positions_m.len(), 5);
        assert_eq!(d.indices, vec![0, 1, 2, 0, 3, 4]);
        // Every corner reproduces the mesh's attributes exactly.
        for (t, tri) in mesh.triangles.iter().enumerate() {
            for k in 0..3 {
                let v = d.indices[3 * t + k] as usize;
                assert_eq!(
                    d.positions_m[v],
                    mesh.positions_m[tri.position[k] as usize].to_array()
                );
                assert_eq!(d.lightmap_uvs[v], mesh.uvs[tri.uv[k] as usize].to_array());
                assert_eq!(
                    d.normals[v],
                    mesh.normals[tri.normal[k] as usize].to_array()
                );
            }
        }
    }
}
