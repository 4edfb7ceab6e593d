//! A tracer's scene on the device: the kd-tree's buffers or the driver's
//! acceleration structure.

use std::sync::Arc;

use ash::vk;
use glam::Vec3;

use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::gpu::{Buffer, GpuContext};
use crate::kdtree::{KdNode, KdTree};
use crate::ray_query::RayQueryScene;

/// A tracer's scene, in its backend's acceleration structure.
pub(super) enum TracerScene {
    KdTree(Box<SceneBuffers>),
    RayQuery(Box<RayQueryScene>),
}

impl TracerScene {
    pub(super) fn bounds(&self) -> Aabb {
        match self {
            TracerScene::KdTree(s) => s.bounds,
            TracerScene::RayQuery(s) => s.bounds,
        }
    }
}

/// A scene's device buffers.
pub(super) struct SceneBuffers {
    pub(super) nodes: Buffer,
    pub(super) prim_indices: Buffer,
    pub(super) triangles: Buffer,
    pub(super) bounds: Aabb,
    /// Triangles of the scene.
    pub(super) triangle_count: usize,
    /// The nodes, kept to build the side buffers if a variant needs them.
    pub(super) host_nodes: Vec<KdNode>,
    /// Parent links, node boxes and ropes, uploaded on first use by `backtrack`/`ropes`.
    pub(super) links: Option<[Buffer; 3]>,
}

impl SceneBuffers {
    /// Checks `tree` over `triangles` against the device's limits and uploads it
    /// ([`scene_device_bytes`] bytes).
    pub(super) fn upload(ctx: &Arc<GpuContext>, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<SceneBuffers> {
        if triangles.is_empty() || tree.bounds.is_empty() {
            return Err(Error::InvalidInput("the scene has no triangles that can be hit".into()));
        }
        tree.check(triangles.len()).map_err(|e| {
            Error::InvalidInput(format!("the kd-tree does not fit its {} triangles: {e}", triangles.len()))
        })?;
        let tri_texels = triangle_texels(tree, triangles);
        let limit = ctx.info.max_storage_buffer_range;
        let bytes = std::mem::size_of_val(tree.prim_indices.as_slice());
        if bytes as u64 > limit {
            return Err(Error::DeviceLimit(format!(
                "the scene's primitive indices take {bytes} bytes; {} allows {limit} per storage buffer (maxStorageBufferRange)",
                ctx.info.name
            )));
        }
        let texel_limit = ctx.info.max_texel_buffer_elements;
        for (what, texels) in [("kd-tree nodes", tree.nodes.len()), ("triangle texels", tri_texels.len())] {
            if texels as u64 > texel_limit {
                return Err(Error::DeviceLimit(format!(
                    "the scene's {what} take {texels} texels; {} allows {texel_limit} per texel buffer (maxTexelBufferElements)",
                    ctx.info.name
                )));
            }
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let texel_usage = vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
        Ok(SceneBuffers {
            nodes: Buffer::with_data(ctx, bytemuck::cast_slice(&tree.nodes), texel_usage, "kd-tree nodes")?,
            prim_indices: Buffer::with_data(ctx, bytemuck::cast_slice(&tree.prim_indices), usage, "prim indices")?,
            triangles: Buffer::with_data(ctx, bytemuck::cast_slice(&tri_texels), texel_usage, "triangle texels")?,
            bounds: tree.bounds,
            triangle_count: triangles.len(),
            host_nodes: tree.nodes.clone(),
            links: None,
        })
    }
}

/// The triangle texels (R32G32B32A32_UINT) in `prim_indices` order, so a
/// leaf's triangles are contiguous and need no index load: (v0, prim), (v1, 0),
/// (v2, 0) per reference. Filled in parallel: a million references on a big scene.
pub(crate) fn triangle_texels(tree: &KdTree, triangles: &[[Vec3; 3]]) -> Vec<[u32; 4]> {
    use rayon::prelude::*;
    let mut tri_texels = vec![[0u32; 4]; 3 * tree.prim_indices.len()];
    tri_texels.par_chunks_mut(3).zip(tree.prim_indices.par_iter()).for_each(|(out, &p)| {
        let [a, b, c] = triangles[p as usize].map(|v| v.to_array().map(f32::to_bits));
        out.copy_from_slice(&[[a[0], a[1], a[2], p], [b[0], b[1], b[2], 0], [c[0], c[1], c[2], 0]]);
    });
    tri_texels
}

/// Bytes a [`Tracer`](super::Tracer) uploads for a kd-tree scene (before the side buffers of
/// `backtrack` and `ropes`): the nodes (8 bytes each), the leaves' primitive
/// indices (4 bytes per reference) and a copy of each referenced triangle in leaf
/// order (48 bytes per reference: its three vertices as texels, so that a
/// leaf's triangles are contiguous and need no index load; docs/INTERNALS.md
/// says what a shared, indexed copy cost in speed).
pub fn scene_device_bytes(tree: &KdTree) -> u64 {
    let refs = tree.prim_indices.len() as u64;
    tree.nodes.len() as u64 * 8 + refs * 4 + refs * 48
}
