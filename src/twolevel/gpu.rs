//! A two-level scene on a device ([`TwoLevelTracer`]): every geometry's nodes
//! and triangle references in one texel buffer each, the geometries, the
//! instances and the top-level BVH in storage buffers, traced by
//! glsl/trace_twolevel.comp with the answers of [`TwoLevelScene::trace`].

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use super::{InstanceHit, TwoLevelScene};
use crate::abi::{GpuGeometry, GpuInstance, GpuInstanceHit, TopNode, TwoLevelParams};
use crate::consts::{
    MAX_TOP_STACK, PASS_ONE, TL_BINDINGS, TL_BINDING_NODES, TL_BINDING_TRIANGLES, TRACE_SPECS, TRACE_SPEC_ANY_HIT,
    TRACE_SPEC_COUNTERS, TRACE_SPEC_PACKET_WIDTH, TRACE_SPEC_PASS, TRACE_SPEC_ROBUST, TRACE_SPEC_STACK_SIZE,
    TRACE_SPEC_VARIANT, TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::geom::Ray;
use crate::gpu::{in_order, shaders, Buffer, BufferSet, GpuContext, Kernel, KernelDesc};
use crate::traversal::{Traversal, Variant};

/// A [`TwoLevelScene`] on a device. Geometries are uploaded once;
/// [`TwoLevelTracer::set_instances`] uploads only the instances and the top
/// level. Traces with [`TwoLevelTracer::trace`] (submits and waits).
pub struct TwoLevelTracer {
    ctx: Arc<GpuContext>,
    nodes: Buffer,
    triangles: Buffer,
    geometries: Buffer,
    geometry_count: usize,
    instances: Buffer,
    top: Buffer,
    order: Buffer,
    top_node_count: u32,
    /// Pipelines by traversal, compiled on first use.
    kernels: Vec<(Traversal, Kernel)>,
}

const TEXEL: vk::BufferUsageFlags = vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
const STORAGE: vk::BufferUsageFlags = vk::BufferUsageFlags::STORAGE_BUFFER;

impl TwoLevelTracer {
    /// Uploads `scene`: its geometries' trees and triangles, its instances and
    /// its top level. Submits copies on the context's queue and waits.
    ///
    /// Errors: `Error::DeviceLimit` when the nodes or triangle references of all
    /// geometries together exceed `maxTexelBufferElements`, or a buffer the
    /// device's allocation or storage-range limits.
    pub fn new(ctx: &Arc<GpuContext>, scene: &TwoLevelScene) -> Result<TwoLevelTracer> {
        let mut nodes: Vec<[u32; 2]> = Vec::new();
        let mut texels: Vec<[u32; 4]> = Vec::new();
        let mut geometries = Vec::with_capacity(scene.geometries.len());
        for g in &scene.geometries {
            let b = g.tree.bounds;
            geometries.push(GpuGeometry {
                bounds_min: [b.min.x, b.min.y, b.min.z, 0.0],
                bounds_max: [b.max.x, b.max.y, b.max.z, 0.0],
                node_base: nodes.len() as u32,
                texel_base: (texels.len() / 3) as u32,
                id: g.id,
                pad: 0,
            });
            nodes.extend(bytemuck::cast_slice::<_, [u32; 2]>(&g.tree.nodes));
            texels.extend(crate::trace::scene::triangle_texels(&g.tree, &g.triangles));
        }
        let limit = ctx.info.max_texel_buffer_elements;
        for (what, count) in [("kd-tree nodes", nodes.len()), ("triangle texels", texels.len())] {
            if count as u64 > limit {
                return Err(Error::DeviceLimit(format!(
                    "the geometries' {what} take {count} texels together; {} allows {limit} per texel buffer (maxTexelBufferElements)",
                    ctx.info.name
                )));
            }
        }
        let nodes = Buffer::with_data(ctx, bytemuck::cast_slice(&nodes), TEXEL, "two-level nodes")?;
        let triangles = Buffer::with_data(ctx, bytemuck::cast_slice(&texels), TEXEL, "two-level triangles")?;
        let geometry_count = geometries.len();
        let geometries = Buffer::with_data(ctx, bytemuck::cast_slice(&geometries), STORAGE, "two-level geometries")?;
        let (instances, top, order, top_node_count) = upload_instances(ctx, scene)?;
        Ok(TwoLevelTracer {
            ctx: ctx.clone(),
            nodes,
            triangles,
            geometries,
            geometry_count,
            instances,
            top,
            order,
            top_node_count,
            kernels: Vec::new(),
        })
    }

    /// Uploads the instances and the top level of `scene`, which must hold the
    /// geometries this tracer was made with (after [`TwoLevelScene::set_instances`]).
    /// Submits and waits; no trace of this tracer may be pending.
    pub fn set_instances(&mut self, scene: &TwoLevelScene) -> Result<()> {
        if scene.geometries.len() != self.geometry_count {
            return Err(Error::InvalidInput(format!(
                "the scene has {} geometries; this tracer was made with {}",
                scene.geometries.len(),
                self.geometry_count
            )));
        }
        (self.instances, self.top, self.order, self.top_node_count) = upload_instances(&self.ctx, scene)?;
        Ok(())
    }

    /// Bytes of the scene on the device (nodes, triangle texels, geometries,
    /// instances, top level).
    pub fn device_bytes(&self) -> u64 {
        [&self.nodes, &self.triangles, &self.geometries, &self.instances, &self.top, &self.order]
            .iter()
            .map(|b| b.size)
            .sum()
    }

    /// The closest (or, for an any-hit traversal, any) hit of each world ray
    /// among the instances visible to `mask`: the answers of
    /// [`TwoLevelScene::trace`] bit for bit. Submits and waits.
    ///
    /// Errors: `Error::InvalidInput` for a traversal without a two-level kernel
    /// (`backtrack`, `ropes`, packets) or an invalid one.
    pub fn trace(&mut self, rays: &[Ray], mask: u8, traversal: Traversal) -> Result<Vec<InstanceHit>> {
        traversal.validate()?;
        if matches!(traversal.variant, Variant::Backtrack | Variant::Ropes) || traversal.uses_packets() {
            return Err(Error::InvalidInput(format!(
                "{:?}{} has no two-level kernel: the GPU traces stack, restart, push-down and the short stacks with single rays",
                traversal.variant,
                if traversal.uses_packets() { " with packets" } else { "" }
            )));
        }
        if rays.is_empty() {
            return Ok(Vec::new());
        }
        let key = Traversal {
            stack_size: if traversal.variant.uses_short_stack() { traversal.stack_size } else { 1 },
            packet_width: 1,
            subgroup_size: None,
            ..traversal
        };
        let kernel = match self.kernels.iter().position(|(k, _)| *k == key) {
            Some(i) => i,
            None => {
                self.kernels.push((key, self.kernel(key)?));
                self.kernels.len() - 1
            }
        };
        let kernel = &self.kernels[kernel].1;
        let ray_bytes: &[u8] = bytemuck::cast_slice(rays);
        let mut ray_buf =
            Buffer::new(&self.ctx, ray_bytes.len() as u64, STORAGE, MemoryLocation::CpuToGpu, "two-level rays")?;
        ray_buf.write(0, ray_bytes)?;
        let hit_bytes = (rays.len() * std::mem::size_of::<GpuInstanceHit>()) as u64;
        let hit_buf = Buffer::new(&self.ctx, hit_bytes, STORAGE, MemoryLocation::GpuToCpu, "two-level hits")?;
        let set = BufferSet::new(
            &self.ctx,
            kernel,
            &[
                &self.nodes,
                &self.triangles,
                &ray_buf,
                &hit_buf,
                &self.geometries,
                &self.instances,
                &self.top,
                &self.order,
            ],
        )?;
        let params = TwoLevelParams {
            ray_count: rays.len() as u32,
            mask: u32::from(mask),
            top_nodes: self.top_node_count,
            pad: 0,
        };
        self.ctx.submit_and_wait(|cmd| {
            // SAFETY: `cmd` is recording; the set's buffers outlive the wait.
            unsafe { kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&params), rays.len() as u32) };
        })?;
        let hits: &[GpuInstanceHit] = bytemuck::cast_slice(hit_buf.read(0, hit_bytes as usize)?);
        Ok(hits.iter().map(InstanceHit::from).collect())
    }

    fn kernel(&self, key: Traversal) -> Result<Kernel> {
        let spec = in_order::<_, { TRACE_SPECS as usize }>([
            (TRACE_SPEC_VARIANT, key.variant.id()),
            (TRACE_SPEC_COUNTERS, 0),
            (TRACE_SPEC_STACK_SIZE, key.stack_size),
            (TRACE_SPEC_ANY_HIT, key.any_hit as u32),
            (TRACE_SPEC_PACKET_WIDTH, 1),
            (TRACE_SPEC_ROBUST, key.robust as u32),
            (TRACE_SPEC_PASS, PASS_ONE),
        ]);
        Kernel::new(
            &self.ctx,
            &KernelDesc {
                name: "trace_twolevel",
                spirv: shaders::TRACE_TWOLEVEL,
                bindings: TL_BINDINGS,
                push_constant_size: std::mem::size_of::<TwoLevelParams>() as u32,
                spec_constants: &spec,
                workgroup_size: TRACE_WORKGROUP_SIZE,
                texel_buffers: &[
                    (TL_BINDING_NODES, vk::Format::R32G32_UINT),
                    (TL_BINDING_TRIANGLES, vk::Format::R32G32B32A32_UINT),
                ],
                ..Default::default()
            },
        )
    }
}

/// The instances, top-level nodes and leaf order of `scene` in device buffers.
fn upload_instances(ctx: &Arc<GpuContext>, scene: &TwoLevelScene) -> Result<(Buffer, Buffer, Buffer, u32)> {
    let instances: Vec<GpuInstance> = scene
        .placed
        .iter()
        .map(|p| {
            let m = &p.to_object;
            GpuInstance {
                row0: m[0],
                row1: m[1],
                row2: m[2],
                geometry: p.instance.geometry as u32,
                instance_id: p.instance.instance_id,
                mask: u32::from(p.instance.mask),
                pad: 0,
            }
        })
        .collect();
    let top: Vec<TopNode> = scene
        .nodes
        .iter()
        .map(|n| TopNode {
            bounds_min: [n.bounds.min.x, n.bounds.min.y, n.bounds.min.z, n.condition],
            bounds_max: [n.bounds.max.x, n.bounds.max.y, n.bounds.max.z, 0.0],
            index: n.index,
            count: n.count,
            pad0: 0,
            pad1: 0,
        })
        .collect();
    // The kernel's stack holds at most the BVH's depth + 1 entries (median splits:
    // about log2 of the instance count).
    let depth = bvh_depth(&scene.nodes, 0);
    if !scene.nodes.is_empty() && depth + 1 >= MAX_TOP_STACK as usize {
        return Err(Error::InvalidInput(format!(
            "the top level is {depth} nodes deep; the kernel's stack holds {MAX_TOP_STACK}"
        )));
    }
    Ok((
        Buffer::with_data(ctx, bytemuck::cast_slice(&instances), STORAGE, "two-level instances")?,
        Buffer::with_data(ctx, bytemuck::cast_slice(&top), STORAGE, "two-level top level")?,
        Buffer::with_data(ctx, bytemuck::cast_slice(&scene.order), STORAGE, "two-level instance order")?,
        top.len() as u32,
    ))
}

/// Depth of the BVH below node `n` (a leaf: 1).
fn bvh_depth(nodes: &[super::BvhNode], n: usize) -> usize {
    match nodes.get(n) {
        None => 0,
        Some(node) if node.count > 0 => 1,
        Some(node) => 1 + bvh_depth(nodes, n + 1).max(bvh_depth(nodes, node.index as usize)),
    }
}

impl From<&GpuInstanceHit> for InstanceHit {
    fn from(h: &GpuInstanceHit) -> InstanceHit {
        InstanceHit {
            t: h.t,
            instance_id: h.instance_id,
            geometry_id: h.geometry_id,
            prim_index: h.prim_index,
            u: h.u,
            v: h.v,
            front_face: h.front_face != 0,
            instance_index: h.instance_index,
        }
    }
}
