//! A tracer's scene on the device: the kd-tree's buffers or the driver's
//! acceleration structure.

use std::sync::Arc;

use ash::vk;
use glam::Vec3;

use crate::error::{Error, Result};
use crate::geom::Aabb;
use crate::gpu::{Buffer, BufferRange, GpuContext};
use crate::kdtree::links::TreeLinks;
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
    /// ([`scene_device_bytes`] bytes), submitting the copies and waiting.
    pub(super) fn upload(ctx: &Arc<GpuContext>, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<SceneBuffers> {
        SceneBuffers::make(ctx, tree, triangles, |data, usage, name| Buffer::with_data(ctx, data, usage, name))
    }

    /// [`SceneBuffers::upload`] with the copies recorded into `cmd`, followed by
    /// one barrier that makes them visible to the trace kernels (buffer barriers
    /// on the new buffers only). With `links`, the side buffers of `backtrack`
    /// and `ropes` too. Returns the staging buffers, to keep until `cmd` completes.
    ///
    /// # Safety
    /// `cmd` is a command buffer of the context's device, recording, outside a render pass.
    pub(super) unsafe fn record_upload(
        ctx: &Arc<GpuContext>,
        cmd: vk::CommandBuffer,
        tree: &KdTree,
        triangles: &[[Vec3; 3]],
        links: bool,
    ) -> Result<(SceneBuffers, Vec<Buffer>)> {
        let mut staging = Vec::new();
        let mut upload = |data: &[u8], usage, name: &str| {
            // SAFETY: the caller's contract on `cmd`; the staging buffers are returned.
            let (buffer, stage) = unsafe { Buffer::with_data_recorded(ctx, cmd, data, usage, name) }?;
            staging.push(stage);
            Ok(buffer)
        };
        let mut scene = SceneBuffers::make(ctx, tree, triangles, &mut upload)?;
        if links {
            scene.links = Some(scene.make_links(ctx, &mut upload)?);
        }
        let mut barriers = vec![&scene.nodes, &scene.prim_indices, &scene.triangles];
        barriers.extend(scene.links.iter().flatten());
        let (write, read) = (vk::AccessFlags::TRANSFER_WRITE, vk::AccessFlags::SHADER_READ);
        let barriers: Vec<vk::BufferMemoryBarrier> =
            barriers.into_iter().map(|b| super::binding::buffer_barrier(BufferRange::whole(b), write, read)).collect();
        // SAFETY: `cmd` is recording (the caller's contract); the buffers are alive.
        unsafe {
            ctx.device.cmd_pipeline_barrier(
                cmd,
                vk::PipelineStageFlags::TRANSFER,
                vk::PipelineStageFlags::COMPUTE_SHADER,
                vk::DependencyFlags::empty(),
                &[],
                &barriers,
                &[],
            )
        };
        Ok((scene, staging))
    }

    fn make(
        ctx: &Arc<GpuContext>,
        tree: &KdTree,
        triangles: &[[Vec3; 3]],
        mut upload: impl FnMut(&[u8], vk::BufferUsageFlags, &str) -> Result<Buffer>,
    ) -> Result<SceneBuffers> {
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
            nodes: upload(bytemuck::cast_slice(&tree.nodes), texel_usage, "kd-tree nodes")?,
            prim_indices: upload(bytemuck::cast_slice(&tree.prim_indices), usage, "prim indices")?,
            triangles: upload(bytemuck::cast_slice(&tri_texels), texel_usage, "triangle texels")?,
            bounds: tree.bounds,
            triangle_count: triangles.len(),
            host_nodes: tree.nodes.clone(),
            links: None,
        })
    }

    /// The side buffers of `backtrack` and `ropes` (parent links, node boxes,
    /// ropes; Foley & Sugerman 2005, Popov et al. 2007), made by `upload`.
    pub(super) fn make_links(
        &self,
        ctx: &Arc<GpuContext>,
        mut upload: impl FnMut(&[u8], vk::BufferUsageFlags, &str) -> Result<Buffer>,
    ) -> Result<[Buffer; 3]> {
        let links = TreeLinks::new(&self.host_nodes, self.bounds);
        let limit = ctx.info.max_storage_buffer_range;
        let bytes = std::mem::size_of_val(links.boxes.as_slice()) as u64;
        if bytes > limit {
            return Err(Error::DeviceLimit(format!(
                "the node boxes take {bytes} bytes; the device allows {limit} per storage buffer"
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        Ok([
            upload(bytemuck::cast_slice(&links.parents), usage, "parents")?,
            upload(bytemuck::cast_slice(&links.boxes), usage, "node boxes")?,
            upload(bytemuck::cast_slice(&links.ropes), usage, "ropes")?,
        ])
    }

    /// Bytes of the buffers on the device.
    pub(super) fn bytes(&self) -> u64 {
        let links = self.links.as_ref().map_or(0, |l| l.iter().map(|b| b.size).sum());
        self.nodes.size + self.prim_indices.size + self.triangles.size + links
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
