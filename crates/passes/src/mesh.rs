//! The scene mesh on the GPU: uploaded once per scene by [`GpuMesh::upload`] and shared
//! (the buffers are reference-counted handles) by the first-order pass (texel G-buffer,
//! shadow maps) and the display pass.
//!
//! # Buffers
//! - `vertices`: interleaved [`Vertex`] (position m, unit normal, lightmap UV), 32 bytes;
//! - `positions`: positions only (`[f32; 3]`, m), for the shadow pass's depth-only draws;
//! - `indices`: `u32`, three per triangle, CCW from the side the normals point to.
//!
//! Beside them, on the CPU, the positions, normals and triangles (with their planes and UV
//! boxes) that the display's split reads ([`DisplaySplit`]).

use std::sync::Arc;

use crate::display_split::DisplaySplit;
use crate::error::PassError;
use crate::first_order::{Bounds, Vertex};
use crate::gpu::Gpu;
use crate::types::MeshData;
use crate::util;

/// A validated mesh uploaded to the GPU.
#[derive(Clone, Debug)]
pub struct GpuMesh {
    pub(crate) vertices: wgpu::Buffer,
    pub(crate) positions: wgpu::Buffer,
    pub(crate) indices: wgpu::Buffer,
    pub(crate) index_count: u32,
    /// The triangles as the display's split needs them.
    pub(crate) split: Arc<DisplaySplit>,
    /// Axis-aligned bounds of the positions (shadow frusta, back-face culling).
    pub(crate) bounds: Bounds,
    /// [`MeshData::is_closed_outward`]: back faces may be culled for a light or an eye
    /// outside the bounds.
    pub(crate) closed_outward: bool,
}

impl GpuMesh {
    /// Validates `mesh` and uploads its vertex, position and index buffers.
    pub fn upload(gpu: &Gpu, mesh: &MeshData) -> Result<Self, PassError> {
        mesh.validate()?;
        let device = &gpu.device;
        let verts: Vec<Vertex> = (0..mesh.positions_m.len())
            .map(|i| Vertex {
                position: mesh.positions_m[i],
                normal: mesh.normals[i],
                uv: mesh.lightmap_uvs[i],
            })
            .collect();
        let buffer =
            |label: &str, bytes: &[u8], usage| util::buffer_init(device, label, bytes, usage);
        Ok(Self {
            vertices: buffer(
                "ortm.mesh.vertices",
                bytemuck::cast_slice(&verts),
                wgpu::BufferUsages::VERTEX,
            ),
            positions: buffer(
                "ortm.mesh.positions",
                bytemuck::cast_slice(&mesh.positions_m),
                wgpu::BufferUsages::VERTEX,
            ),
            indices: buffer(
                "ortm.mesh.indices",
                bytemuck::cast_slice(&mesh.indices),
                wgpu::BufferUsages::INDEX,
            ),
            index_count: mesh.indices.len() as u32,
            split: Arc::new(DisplaySplit::build(mesh)),
            bounds: Bounds::of(&mesh.positions_m),
            closed_outward: mesh.is_closed_outward(),
        })
    }

    /// Mesh bounds.
    pub fn bounds(&self) -> &Bounds {
        &self.bounds
    }

    /// The triangles as the display's split needs them.
    pub fn split(&self) -> &DisplaySplit {
        &self.split
    }
}
