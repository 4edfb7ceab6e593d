//! The public tracing API: a scene uploaded to a device, traced in batches.

use std::sync::Arc;

use ash::vk;
use bytemuck::{Pod, Zeroable};
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::consts::{
    COUNTERS_PER_RAY, COUNTER_DROPS, COUNTER_LEAVES, COUNTER_NODES, COUNTER_RESTARTS, COUNTER_STEPS, COUNTER_TRIANGLES,
    MAX_TRAVERSAL_STEPS, PRIM_INCOMPLETE, TRACE_BINDINGS, TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::geom::{Aabb, Hit, Ray};
use crate::gpu::{shaders, Buffer, BufferSet, GpuContext, Kernel, KernelDesc, Timestamps};
use crate::kdtree::links::TreeLinks;
use crate::kdtree::traverse::{Counters, Traversal, Variant};
use crate::kdtree::{KdNode, KdTree};

/// Push constants of `trace.comp` (`TraceParams` in glsl/shared/ray.glsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, Pod, Zeroable)]
pub struct TraceParams {
    pub scene_min: [f32; 4],
    pub scene_max: [f32; 4],
    pub ray_count: u32,
    pub pad: [u32; 3],
}

/// Options of one `trace` call.
#[derive(Clone, Copy, Debug)]
pub struct TraceOptions {
    /// Variant, short-stack size and closest/any-hit mode (specialization constants).
    pub traversal: Traversal,
    /// Write per-ray counters (a specialization constant: no cost when off).
    pub counters: bool,
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions { traversal: Traversal::closest(Variant::Stack), counters: false }
    }
}

impl TraceOptions {
    /// Closest hit with `variant` (short stack of 3), counters off.
    pub fn variant(variant: Variant) -> Self {
        TraceOptions { traversal: Traversal::closest(variant), counters: false }
    }
}

/// What `trace` returns.
#[derive(Clone, Debug, Default)]
pub struct TraceResult {
    pub hits: Vec<Hit>,
    /// Per-ray counters when requested.
    pub counters: Option<Vec<Counters>>,
    /// GPU time of the trace dispatches alone (timestamps), when the device has timestamps.
    pub gpu_seconds: Option<f64>,
}

/// Rays per dispatch. Bounded by the storage-buffer range and workgroup count limits.
const DEFAULT_CHUNK: usize = 1 << 20;

/// A scene on a device, ready to trace: the kd-tree nodes, primitive indices and
/// triangle vertices in device-local buffers.
pub struct Tracer {
    ctx: Arc<GpuContext>,
    nodes: Buffer,
    prim_indices: Buffer,
    triangles: Buffer,
    bounds: Aabb,
    /// The nodes, kept to build the side buffers if a variant needs them.
    host_nodes: Vec<KdNode>,
    /// Parent links, node boxes and ropes, uploaded on first use by `backtrack`/`ropes`.
    links: Option<[Buffer; 3]>,
    /// Bound in place of side buffers a variant does not read.
    dummy: Buffer,
    kernels: Vec<((Traversal, bool), Kernel)>,
    chunk: usize,
}

impl Tracer {
    /// Uploads `tree` (built over `triangles`) to the context's device.
    pub fn new(ctx: &Arc<GpuContext>, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<Tracer> {
        if triangles.is_empty() || tree.bounds.is_empty() {
            return Err(Error::InvalidInput("the scene has no triangles that can be hit".into()));
        }
        let verts: Vec<f32> = triangles.iter().flat_map(|t| t.iter().flat_map(|v| v.to_array())).collect();
        let limit = ctx.info.max_storage_buffer_range;
        let sizes = [
            ("kd-tree nodes", std::mem::size_of_val(tree.nodes.as_slice())),
            ("primitive indices", std::mem::size_of_val(tree.prim_indices.as_slice())),
            ("triangle vertices", std::mem::size_of_val(verts.as_slice())),
        ];
        for (what, bytes) in sizes {
            if bytes as u64 > limit {
                return Err(Error::DeviceLimit(format!(
                    "the scene's {what} take {bytes} bytes; {} allows {limit} per storage buffer (maxStorageBufferRange)",
                    ctx.info.name
                )));
            }
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let nodes = Buffer::with_data(ctx, bytemuck::cast_slice(&tree.nodes), usage, "kd-tree nodes")?;
        let prim_indices = Buffer::with_data(ctx, bytemuck::cast_slice(&tree.prim_indices), usage, "prim indices")?;
        let triangles = Buffer::with_data(ctx, bytemuck::cast_slice(&verts), usage, "triangle vertices")?;
        let dummy = Buffer::new(ctx, 4, usage, MemoryLocation::GpuOnly, "unused side buffer")?;
        // Rays (32 B), hits (16 B) and counters per chunk must fit the storage range,
        // and the dispatch must fit the workgroup count limit.
        let per_ray = (COUNTERS_PER_RAY * 4) as u64;
        let by_range = (limit / per_ray.max(32)) as usize;
        let by_groups = ctx.info.max_workgroup_count_x as usize * TRACE_WORKGROUP_SIZE as usize;
        let chunk = DEFAULT_CHUNK.min(by_range).min(by_groups).max(TRACE_WORKGROUP_SIZE as usize);
        Ok(Tracer {
            ctx: ctx.clone(),
            nodes,
            prim_indices,
            triangles,
            bounds: tree.bounds,
            host_nodes: tree.nodes.clone(),
            links: None,
            dummy,
            kernels: Vec::new(),
            chunk,
        })
    }

    /// The context this tracer runs on.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// Rays traced per dispatch.
    pub fn chunk_size(&self) -> usize {
        self.chunk
    }

    /// Limits the rays per dispatch (tests use it to exercise chunking).
    pub fn set_chunk_size(&mut self, rays: usize) {
        self.chunk = rays.clamp(1, self.chunk.max(1));
    }

    /// Uploads the side buffers of `backtrack` and `ropes` once.
    fn ensure_links(&mut self) -> Result<()> {
        if self.links.is_some() {
            return Ok(());
        }
        let links = TreeLinks::new(&self.host_nodes, self.bounds);
        let limit = self.ctx.info.max_storage_buffer_range;
        if std::mem::size_of_val(links.boxes.as_slice()) as u64 > limit {
            return Err(Error::DeviceLimit(format!(
                "the node boxes take {} bytes; the device allows {limit} per storage buffer",
                std::mem::size_of_val(links.boxes.as_slice())
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        self.links = Some([
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.parents), usage, "parents")?,
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.boxes), usage, "node boxes")?,
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.ropes), usage, "ropes")?,
        ]);
        Ok(())
    }

    fn kernel(&mut self, traversal: Traversal, counters: bool) -> Result<usize> {
        traversal.validate()?;
        // Variants that ignore the stack size share one pipeline.
        let key = Traversal {
            stack_size: if traversal.variant.uses_short_stack() { traversal.stack_size } else { 1 },
            ..traversal
        };
        if let Some(i) = self.kernels.iter().position(|(k, _)| *k == (key, counters)) {
            return Ok(i);
        }
        let kernel = Kernel::new(
            &self.ctx,
            &KernelDesc {
                name: "trace",
                spirv: shaders::TRACE,
                bindings: TRACE_BINDINGS,
                push_constant_size: std::mem::size_of::<TraceParams>() as u32,
                spec_constants: &[key.variant.id(), counters as u32, key.stack_size, key.any_hit as u32],
                workgroup_size: TRACE_WORKGROUP_SIZE,
                required_subgroup_size: None,
            },
        )?;
        self.kernels.push(((key, counters), kernel));
        Ok(self.kernels.len() - 1)
    }

    /// Traces `rays` (any number: they go in chunks) and returns the closest hit of
    /// each. Rays that did not finish traversal make this an `Error::Incomplete`.
    pub fn trace(&mut self, rays: &[Ray], options: &TraceOptions) -> Result<TraceResult> {
        self.trace_with_progress(rays, options, |_| {})
    }

    /// `trace`, calling `progress(rays_done)` after each chunk.
    pub fn trace_with_progress(
        &mut self,
        rays: &[Ray],
        options: &TraceOptions,
        mut progress: impl FnMut(usize),
    ) -> Result<TraceResult> {
        let kernel_index = self.kernel(options.traversal, options.counters)?;
        if options.traversal.variant.uses_links() {
            self.ensure_links()?;
        }
        let chunk = self.chunk.min(rays.len()).max(1);
        let ctx = self.ctx.clone();
        let mut ray_buf = Buffer::new(
            &ctx,
            (chunk * 32) as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::CpuToGpu,
            "rays",
        )?;
        let hit_buf = Buffer::new(
            &ctx,
            (chunk * 16) as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::GpuToCpu,
            "hits",
        )?;
        let counter_bytes = if options.counters { chunk * COUNTERS_PER_RAY as usize * 4 } else { 4 };
        let counter_buf = Buffer::new(
            &ctx,
            counter_bytes as u64,
            vk::BufferUsageFlags::STORAGE_BUFFER,
            MemoryLocation::GpuToCpu,
            "counters",
        )?;
        let kernel = &self.kernels[kernel_index].1;
        let [parents, boxes, ropes] = match (&self.links, options.traversal.variant.uses_links()) {
            (Some([p, b, r]), true) => [p, b, r],
            _ => [&self.dummy; 3],
        };
        let set = BufferSet::new(
            &ctx,
            kernel,
            &[
                &self.nodes,
                &self.prim_indices,
                &self.triangles,
                &ray_buf,
                &hit_buf,
                &counter_buf,
                parents,
                boxes,
                ropes,
            ],
        )?;
        let timestamps = Timestamps::new(&ctx, 2)?;

        let mut result = TraceResult {
            hits: Vec::with_capacity(rays.len()),
            counters: options.counters.then(|| Vec::with_capacity(rays.len())),
            gpu_seconds: timestamps.as_ref().map(|_| 0.0),
        };
        let b = self.bounds;
        for (chunk_index, batch) in rays.chunks(chunk).enumerate() {
            ray_buf.write(0, bytemuck::cast_slice(batch))?;
            let params = TraceParams {
                scene_min: [b.min.x, b.min.y, b.min.z, 0.0],
                scene_max: [b.max.x, b.max.y, b.max.z, 0.0],
                ray_count: batch.len() as u32,
                pad: [0; 3],
            };
            ctx.submit_and_wait(|cmd| {
                // SAFETY: `cmd` is recording; the set's buffers outlive the submission,
                // which `submit_and_wait` waits for.
                unsafe {
                    if let Some(ts) = &timestamps {
                        ts.record_reset(cmd);
                        ts.record(cmd, 0);
                    }
                    kernel.record_dispatch(cmd, set.set, bytemuck::bytes_of(&params), batch.len() as u32);
                    if let Some(ts) = &timestamps {
                        ts.record(cmd, 1);
                    }
                    // Make the shader writes visible to the host reads below.
                    let barrier = vk::MemoryBarrier::default()
                        .src_access_mask(vk::AccessFlags::SHADER_WRITE)
                        .dst_access_mask(vk::AccessFlags::HOST_READ);
                    ctx.device.cmd_pipeline_barrier(
                        cmd,
                        vk::PipelineStageFlags::COMPUTE_SHADER,
                        vk::PipelineStageFlags::HOST,
                        vk::DependencyFlags::empty(),
                        &[barrier],
                        &[],
                        &[],
                    );
                }
            })?;
            if let (Some(ts), Some(total)) = (&timestamps, result.gpu_seconds.as_mut()) {
                *total += ts.seconds_between(0, 1)?;
            }
            let hits: &[Hit] = bytemuck::cast_slice(hit_buf.read(0, batch.len() * 16)?);
            if let Some(first) = hits.iter().position(|h| h.prim_id == PRIM_INCOMPLETE) {
                let count = hits.iter().filter(|h| h.prim_id == PRIM_INCOMPLETE).count();
                return Err(Error::Incomplete { count, first: chunk_index * chunk + first, cap: MAX_TRAVERSAL_STEPS });
            }
            result.hits.extend_from_slice(hits);
            if let Some(out) = result.counters.as_mut() {
                let raw: &[u32] =
                    bytemuck::cast_slice(counter_buf.read(0, batch.len() * COUNTERS_PER_RAY as usize * 4)?);
                out.extend(raw.chunks_exact(COUNTERS_PER_RAY as usize).map(|c| Counters {
                    nodes: c[COUNTER_NODES as usize],
                    leaves: c[COUNTER_LEAVES as usize],
                    triangles: c[COUNTER_TRIANGLES as usize],
                    restarts: c[COUNTER_RESTARTS as usize],
                    steps: c[COUNTER_STEPS as usize],
                    drops: c[COUNTER_DROPS as usize],
                }));
            }
            progress(result.hits.len());
        }
        Ok(result)
    }
}
