//! A two-level scene on a device ([`TwoLevelTracer`]): every geometry's nodes
//! and triangle references in one texel buffer each, the geometries, the
//! instances, the top-level BVH and its leaves' order in texel buffers too
//! (lavapipe loads storage-buffer structs a word and a lane at a time), traced by
//! glsl/trace_twolevel.comp with the answers of [`TwoLevelScene::trace`].

use std::sync::Arc;

use ash::vk;
use bytemuck::Zeroable;
use gpu_allocator::MemoryLocation;

use super::pipelines::{Passes, TwoLevelPipelines};
use super::{InstanceHit, TwoLevelScene};
use crate::abi::{GpuGeometry, GpuInstance, GpuInstanceHit, TopNode, TwoLevelParams};
use crate::consts::{
    CAREFUL_HEADER_WORDS, INDIRECT_WORDS, MAX_TOP_STACK, TL_BINDINGS, TL_BINDING_CAREFUL, TL_BINDING_GEOMETRIES,
    TL_BINDING_HITS, TL_BINDING_INDIRECT, TL_BINDING_INSTANCES, TL_BINDING_NODES, TL_BINDING_ORDER, TL_BINDING_TOP,
    TL_BINDING_TRIANGLES,
};
use crate::error::{Error, Result};
use crate::geom::Ray;
use crate::gpu::{Buffer, BufferRange, BufferSet, GpuContext, Timestamps};
use crate::trace::{buffer_barrier, record_careful_count_copy, record_fast_then_careful, IndirectArgs};
use crate::traversal::Traversal;

/// What [`TwoLevelTracer::trace_stats`] returns.
#[derive(Clone, Debug)]
pub struct TwoLevelTraceResult {
    /// One hit per ray, in ray order.
    pub hits: Vec<InstanceHit>,
    /// GPU time of the trace dispatches (timestamps), where the queue has them.
    pub gpu_seconds: Option<f64>,
    /// Robust traces: how many rays the fast pass listed for the careful pass
    /// (as [`crate::trace::TraceResult::careful_rays`]); `None` for `--plain`.
    pub careful_rays: Option<u64>,
}

/// A [`TwoLevelScene`] on a device. Geometries are uploaded once;
/// [`TwoLevelTracer::set_instances`] uploads only the instances and the top
/// level, in place while they fit (bindings stay valid).
///
/// Trace with [`TwoLevelTracer::trace`] (uploads the rays, submits, waits), or
/// in an engine's command buffer with [`TwoLevelTracer::bind`] and
/// [`TwoLevelTracer::record_binding`] under the contract of
/// [`crate::trace::Tracer::record_trace`]: make your ray writes visible to
/// `COMPUTE_SHADER` reads before, and the hits to their reader after; the
/// recording binds kdtrace's pipeline, set 0 and push constants. A plain trace
/// is one dispatch; a robust trace records two, as `Tracer` does (a fast pass,
/// and an indirect careful pass over the rays it listed), with kdtrace's own
/// buffer barriers on the binding's list and your hit range between them.
/// Rays counted on the device (e.g. appended by your shading pass) are traced
/// with [`TwoLevelTracer::bind_indirect`] and
/// [`TwoLevelTracer::record_binding_indirect`], with no readback.
pub struct TwoLevelTracer {
    ctx: Arc<GpuContext>,
    nodes: Buffer,
    triangles: Buffer,
    geometries: Buffer,
    geometry_count: usize,
    /// Instances, top-level nodes and the leaves' instance order, with room for
    /// `capacity` instances.
    instances: Buffer,
    top: Buffer,
    order: Buffer,
    capacity: usize,
    top_node_count: u32,
    /// Incremented when the instance buffers are reallocated: older bindings are refused.
    generation: u64,
    /// Pipelines by traversal, compiled on first use: the general one, and while
    /// the scene has one instance those without a top-level loop.
    pipelines: TwoLevelPipelines,
    /// The scene has exactly one instance.
    one_instance: bool,
    /// Buffers a recorded update replaced or staged through, each under the
    /// frame value that may still use them ([`TwoLevelTracer::release_retired`]).
    retired: Vec<(u64, Buffer)>,
    /// Bound at `TL_BINDING_INDIRECT` by host-counted bindings (never read).
    dummy: Buffer,
}

/// The device records of a scene's instances and top level.
struct InstanceRecords {
    instances: Vec<GpuInstance>,
    top: Vec<TopNode>,
}

/// The descriptor set of a two-level trace: the tracer's scene buffers, your ray
/// and hit ranges and one traversal's pipeline. Keep it until every command
/// buffer it was recorded into has completed.
#[must_use = "the descriptor set must live until the command buffer that uses it completes"]
pub struct TwoLevelBinding {
    set: BufferSet,
    /// The careful pass's list (header and, for robust traces, one word per ray).
    list: Buffer,
    /// The bound hit range (the barrier between the fast and the careful pass names it).
    hits: BufferRange,
    kernel: usize,
    generation: u64,
    /// Rays the bound ranges hold.
    capacity: u32,
    /// A device-counted binding's arguments ([`TwoLevelTracer::bind_indirect`]).
    indirect: Option<IndirectArgs>,
}

const TEXEL: vk::BufferUsageFlags = vk::BufferUsageFlags::STORAGE_TEXEL_BUFFER;
const STORAGE: vk::BufferUsageFlags = vk::BufferUsageFlags::STORAGE_BUFFER;
const RAY_BYTES: u64 = std::mem::size_of::<Ray>() as u64;
const HIT_BYTES: u64 = std::mem::size_of::<GpuInstanceHit>() as u64;

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
        // A texel buffer holds at least one texel (a scene without geometries or triangles).
        if geometries.is_empty() {
            geometries.push(GpuGeometry::zeroed());
        }
        if texels.is_empty() {
            texels.push([0; 4]);
        }
        let capacity = scene.placed.len().max(1);
        let [instances, top, order] = instance_buffers(ctx, capacity)?;
        let mut tracer = TwoLevelTracer {
            ctx: ctx.clone(),
            nodes: Buffer::with_data(ctx, bytemuck::cast_slice(&nodes), TEXEL, "two-level nodes")?,
            triangles: Buffer::with_data(ctx, bytemuck::cast_slice(&texels), TEXEL, "two-level triangles")?,
            geometries: Buffer::with_data(ctx, bytemuck::cast_slice(&geometries), TEXEL, "two-level geometries")?,
            geometry_count: scene.geometries.len(),
            instances,
            top,
            order,
            capacity,
            top_node_count: 0,
            generation: 0,
            pipelines: TwoLevelPipelines::new(ctx),
            one_instance: false,
            retired: Vec::new(),
            dummy: Buffer::new(
                ctx,
                u64::from(INDIRECT_WORDS) * 4,
                STORAGE,
                MemoryLocation::GpuOnly,
                "two-level unused arguments",
            )?,
        };
        tracer.set_instances(scene)?;
        Ok(tracer)
    }

    /// Uploads the instances and the top level of `scene`, which must hold the
    /// geometries this tracer was made with (after [`TwoLevelScene::set_instances`]).
    /// Written in place while they fit the buffers (bindings made before stay
    /// valid); more instances than ever before reallocate them, and bindings made
    /// before are then refused. Submits and waits: no trace of this tracer may be
    /// pending. When the scene comes to hold exactly one instance, the pipelines
    /// without a top-level loop are compiled here for the traversals compiled so
    /// far (once each).
    pub fn set_instances(&mut self, scene: &TwoLevelScene) -> Result<()> {
        let records = self.records(scene)?;
        if records.instances.len() > self.capacity {
            let capacity = records.instances.len().next_power_of_two();
            [self.instances, self.top, self.order] = instance_buffers(&self.ctx, capacity)?;
            self.capacity = capacity;
            self.generation += 1;
        }
        if let Some((staging, copies)) = self.stage(&records, scene)? {
            self.ctx.submit_and_wait(|cmd| {
                for (target, region) in &copies {
                    // SAFETY: both buffers are alive and large enough; `cmd` is recording.
                    unsafe { self.ctx.device.cmd_copy_buffer(cmd, staging.buffer, *target, &[*region]) };
                }
            })?;
        }
        self.top_node_count = records.top.len() as u32;
        self.one_instance = records.instances.len() == 1;
        self.pipelines.compile_one_instance(self.one_instance)?;
        Ok(())
    }

    /// [`TwoLevelTracer::set_instances`] recorded into your command buffer `cmd`
    /// (no submit, no wait): copies from a staging buffer into the instance
    /// buffers, between two barriers of kdtrace's own on those buffers (earlier
    /// traces' reads before the copies, the copies before later traces' reads).
    /// So within `cmd` and after it on the queue, traces recorded before read the
    /// old instances and traces recorded after read the new ones. The staging
    /// buffer (and, when more instances than ever before reallocate the buffers,
    /// the old ones) is kept under `frame` until [`TwoLevelTracer::release_retired`]
    /// says that frame has completed; bindings made before a reallocation are then
    /// refused. Like [`TwoLevelTracer::set_instances`] it may compile the
    /// one-instance pipelines (a stall of a few seconds on lavapipe, once).
    ///
    /// # Safety
    /// `cmd` is recording, outside a render pass, on the queue family the traces
    /// are recorded on; this tracer lives until it completes.
    pub unsafe fn record_set_instances(
        &mut self,
        cmd: vk::CommandBuffer,
        scene: &TwoLevelScene,
        frame: u64,
    ) -> Result<()> {
        let records = self.records(scene)?;
        if records.instances.len() > self.capacity {
            let capacity = records.instances.len().next_power_of_two();
            let fresh = instance_buffers(&self.ctx, capacity)?;
            let [instances, top, order] = fresh;
            for old in [
                std::mem::replace(&mut self.instances, instances),
                std::mem::replace(&mut self.top, top),
                std::mem::replace(&mut self.order, order),
            ] {
                self.retired.push((frame, old));
            }
            self.capacity = capacity;
            self.generation += 1;
        }
        if let Some((staging, copies)) = self.stage(&records, scene)? {
            let device = &self.ctx.device;
            // kdtrace's own barriers on the instance buffers only (trace::buffer_barrier).
            let barriers = |src: vk::AccessFlags, dst: vk::AccessFlags| -> Vec<vk::BufferMemoryBarrier> {
                copies
                    .iter()
                    .map(|(buffer, region)| buffer_barrier(BufferRange::new(*buffer, 0, region.size), src, dst))
                    .collect()
            };
            // SAFETY: the caller vouches for `cmd`; the buffers live until it completes
            // (the staging buffer is retired under `frame`).
            unsafe {
                device.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &barriers(vk::AccessFlags::empty(), vk::AccessFlags::TRANSFER_WRITE),
                    &[],
                );
                for (target, region) in &copies {
                    device.cmd_copy_buffer(cmd, staging.buffer, *target, &[*region]);
                }
                device.cmd_pipeline_barrier(
                    cmd,
                    vk::PipelineStageFlags::TRANSFER,
                    vk::PipelineStageFlags::COMPUTE_SHADER,
                    vk::DependencyFlags::empty(),
                    &[],
                    &barriers(vk::AccessFlags::TRANSFER_WRITE, vk::AccessFlags::SHADER_READ),
                    &[],
                );
            }
            self.retired.push((frame, staging));
        }
        self.top_node_count = records.top.len() as u32;
        self.one_instance = records.instances.len() == 1;
        self.pipelines.compile_one_instance(self.one_instance)?;
        Ok(())
    }

    /// Destroys what recorded updates retired under frames up to `completed`;
    /// returns how many buffers went.
    pub fn release_retired(&mut self, completed: u64) -> usize {
        crate::trace::release_frames(&mut self.retired, completed)
    }

    /// Bytes on the device still held for recorded updates.
    pub fn retired_bytes(&self) -> u64 {
        self.retired.iter().map(|(_, b)| b.size).sum()
    }

    /// The device records of `scene`'s instances and top level, checked.
    fn records(&self, scene: &TwoLevelScene) -> Result<InstanceRecords> {
        if scene.geometries.len() != self.geometry_count {
            return Err(Error::InvalidInput(format!(
                "the scene has {} geometries; this tracer was made with {}",
                scene.geometries.len(),
                self.geometry_count
            )));
        }
        // The kernel's stack holds at most the BVH's depth + 1 entries (median
        // splits: about log2 of the instance count).
        let depth = bvh_depth(&scene.nodes, 0);
        if depth + 1 >= MAX_TOP_STACK as usize {
            return Err(Error::InvalidInput(format!(
                "the top level is {depth} nodes deep; the kernel's stack holds {MAX_TOP_STACK}"
            )));
        }
        let instances = scene
            .placed
            .iter()
            .map(|p| GpuInstance {
                row0: p.to_object[0],
                row1: p.to_object[1],
                row2: p.to_object[2],
                geometry: p.instance.geometry as u32,
                instance_id: p.instance.instance_id,
                mask: u32::from(p.instance.mask),
                identity: super::is_identity(&p.to_object) as u32,
            })
            .collect();
        let top = scene
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
        Ok(InstanceRecords { instances, top })
    }

    /// A staging buffer holding `records` and the scene's leaf order, with the
    /// copies into the instance buffers; `None` when there is nothing to copy.
    #[allow(clippy::type_complexity)]
    fn stage(
        &self,
        records: &InstanceRecords,
        scene: &TwoLevelScene,
    ) -> Result<Option<(Buffer, Vec<(vk::Buffer, vk::BufferCopy)>)>> {
        let parts: [&[u8]; 3] = [
            bytemuck::cast_slice(&records.instances),
            bytemuck::cast_slice(&records.top),
            bytemuck::cast_slice(&scene.order),
        ];
        let total: usize = parts.iter().map(|p| p.len()).sum();
        if total == 0 {
            return Ok(None);
        }
        let mut staging = Buffer::new(
            &self.ctx,
            total as u64,
            vk::BufferUsageFlags::TRANSFER_SRC,
            MemoryLocation::CpuToGpu,
            "two-level instance staging",
        )?;
        let mut offset = 0;
        let mut copies = Vec::new();
        for (part, target) in parts.iter().zip([&self.instances, &self.top, &self.order]) {
            if !part.is_empty() {
                staging.write(offset, part)?;
                let region = vk::BufferCopy { src_offset: offset as u64, dst_offset: 0, size: part.len() as u64 };
                copies.push((target.buffer, region));
            }
            offset += part.len();
        }
        Ok(Some((staging, copies)))
    }

    /// Uploads `scene` again after [`TwoLevelScene::set_geometry`] (every
    /// geometry's nodes and triangles, and the instances); the compiled pipelines
    /// are kept. Submits and waits: no trace of this tracer may be pending;
    /// bindings made before are refused (bind again), and buffers retired by
    /// recorded updates stay until [`TwoLevelTracer::release_retired`].
    pub fn set_geometries(&mut self, scene: &TwoLevelScene) -> Result<()> {
        let mut fresh = TwoLevelTracer::new(&self.ctx, scene)?;
        fresh.pipelines = self.pipelines.clone();
        fresh.retired = std::mem::take(&mut self.retired);
        fresh.generation = self.generation + 1;
        fresh.pipelines.compile_one_instance(fresh.one_instance)?;
        *self = fresh;
        Ok(())
    }

    /// Bytes of the scene on the device: nodes, triangle texels, geometries,
    /// and the instance buffers (with their spare room).
    pub fn device_bytes(&self) -> u64 {
        [&self.nodes, &self.triangles, &self.geometries, &self.instances, &self.top, &self.order]
            .iter()
            .map(|b| b.size)
            .sum()
    }

    /// Compiles the pipeline of `traversal` (done on first use otherwise).
    ///
    /// Errors: `Error::InvalidInput` for a traversal without a two-level kernel
    /// (`backtrack`, `ropes`, packets) or an invalid one.
    pub fn prepare(&mut self, traversal: Traversal) -> Result<()> {
        self.pipelines.kernel(traversal, self.one_instance).map(|_| ())
    }

    /// The pipelines this tracer has compiled so far, shared, not copied: give
    /// them to another tracer of the same context
    /// ([`TwoLevelTracer::adopt_pipelines`]) and it compiles none of them again.
    pub fn shared_pipelines(&self) -> TwoLevelPipelines {
        self.pipelines.clone()
    }

    /// The compute pipeline that recording `binding` now dispatches first (the
    /// same handle in every tracer that shares its pipelines:
    /// [`TwoLevelTracer::shared_pipelines`]).
    pub fn binding_pipeline(&self, binding: &TwoLevelBinding) -> vk::Pipeline {
        self.passes(binding).main.pipeline
    }

    /// The passes recording `binding` dispatches: without the top-level loop
    /// while the scene has one instance and they are compiled.
    fn passes(&self, binding: &TwoLevelBinding) -> &Passes {
        let entry = &self.pipelines.kernels[binding.kernel];
        match &entry.one_instance {
            Some(one) if self.one_instance => one,
            _ => &entry.general,
        }
    }

    /// Takes over pipelines compiled by another tracer of the same context, or
    /// in advance ([`TwoLevelPipelines::prepare`]); those it has are kept
    /// (bindings stay valid). Nothing is compiled here; while the scene has one
    /// instance, binding or preparing a traversal compiles its one-instance
    /// pipelines if the adopted set lacks them.
    ///
    /// Errors: `Error::InvalidInput` when they were compiled for another context.
    pub fn adopt_pipelines(&mut self, pipelines: TwoLevelPipelines) -> Result<()> {
        self.pipelines.merge(pipelines)
    }

    /// The closest (or, for an any-hit traversal, any) hit of each world ray
    /// among the instances visible to `mask`: the answers of
    /// [`TwoLevelScene::trace`] bit for bit. Submits and waits.
    ///
    /// Errors: those of [`TwoLevelTracer::prepare`].
    pub fn trace(&mut self, rays: &[Ray], mask: u8, traversal: Traversal) -> Result<Vec<InstanceHit>> {
        Ok(self.trace_timed(rays, mask, traversal)?.0)
    }

    /// [`TwoLevelTracer::trace`] and the dispatch's GPU time in seconds (`None`
    /// where the queue has no timestamps).
    pub fn trace_timed(
        &mut self,
        rays: &[Ray],
        mask: u8,
        traversal: Traversal,
    ) -> Result<(Vec<InstanceHit>, Option<f64>)> {
        let result = self.trace_stats(rays, mask, traversal)?;
        Ok((result.hits, result.gpu_seconds))
    }

    /// [`TwoLevelTracer::trace`] with what [`crate::trace::Tracer::trace`] also
    /// reports: the GPU time and, for robust traces, how many rays the fast pass
    /// listed for the careful pass ([`crate::trace::TraceResult::careful_rays`]).
    pub fn trace_stats(&mut self, rays: &[Ray], mask: u8, traversal: Traversal) -> Result<TwoLevelTraceResult> {
        self.prepare(traversal)?;
        if rays.is_empty() {
            let careful_rays = traversal.robust.then_some(0);
            return Ok(TwoLevelTraceResult { hits: Vec::new(), gpu_seconds: None, careful_rays });
        }
        let ray_bytes: &[u8] = bytemuck::cast_slice(rays);
        let mut ray_buf =
            Buffer::new(&self.ctx, ray_bytes.len() as u64, STORAGE, MemoryLocation::CpuToGpu, "two-level rays")?;
        ray_buf.write(0, ray_bytes)?;
        let hit_bytes = rays.len() as u64 * HIT_BYTES;
        let hit_buf = Buffer::new(&self.ctx, hit_bytes, STORAGE, MemoryLocation::GpuToCpu, "two-level hits")?;
        // SAFETY: both buffers are this tracer's own storage buffers, alive until the wait.
        let binding = unsafe { self.bind(BufferRange::whole(&ray_buf), BufferRange::whole(&hit_buf), traversal)? };
        let timestamps = Timestamps::new(&self.ctx, 2)?;
        // The careful pass's count (word CAREFUL_COUNT of the list), copied back.
        let careful_count = match traversal.robust {
            true => Some(Buffer::new(
                &self.ctx,
                4,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
                "two-level careful count",
            )?),
            false => None,
        };
        let mut recorded = Ok(());
        self.ctx.submit_and_wait(|cmd| {
            // SAFETY: `cmd` is recording; the binding's buffers outlive the wait.
            unsafe {
                if let Some(t) = &timestamps {
                    t.record_reset(cmd);
                    t.record(cmd, 0);
                }
                recorded = self.record_binding(cmd, &binding, rays.len() as u32, mask);
                if let Some(t) = &timestamps {
                    t.record(cmd, 1);
                }
                if let Some(count) = &careful_count {
                    record_careful_count_copy(&self.ctx.device, cmd, &binding.list, count);
                }
                // Make the shader and transfer writes visible to the host reads below.
                self.ctx.record_host_read_barrier(cmd);
            }
        })?;
        recorded?;
        let gpu_seconds = match &timestamps {
            Some(t) if !self.ctx.timestamps_unreliable() => Some(t.seconds_between(0, 1)?),
            _ => None,
        };
        let careful_rays = match &careful_count {
            Some(count) => Some(u64::from(bytemuck::cast_slice::<u8, u32>(count.read(0, 4)?)[0])),
            None => None,
        };
        let hits: &[GpuInstanceHit] = bytemuck::cast_slice(hit_buf.read(0, hit_bytes as usize)?);
        Ok(TwoLevelTraceResult { hits: hits.iter().map(InstanceHit::from).collect(), gpu_seconds, careful_rays })
    }

    /// A binding of your ray range (32-byte [`Ray`]s, world space) and hit range
    /// (32-byte [`GpuInstanceHit`]s) for `traversal`, to record with
    /// [`TwoLevelTracer::record_binding`] as often as you like.
    ///
    /// # Safety
    /// Both ranges lie in live storage buffers of this tracer's device (offsets
    /// aligned to `minStorageBufferOffsetAlignment`) that outlive the binding's
    /// use by any command buffer; they do not overlap.
    pub unsafe fn bind(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        traversal: Traversal,
    ) -> Result<TwoLevelBinding> {
        // SAFETY: forwarded from the caller.
        unsafe { self.bind_inner(rays, hits, None, traversal) }
    }

    /// [`TwoLevelTracer::bind`] for device-counted traces: the binding can also
    /// be recorded with [`TwoLevelTracer::record_binding_indirect`], which traces
    /// as many rays as a `u32` of `counts` says when the trace runs (written by
    /// an earlier pass of yours on the device), with no readback, as
    /// [`crate::trace::Tracer::bind_indirect`] does for one level. It adds a
    /// 32-byte arguments buffer and the descriptor set of the small kernel that
    /// fills it.
    ///
    /// Errors: those of [`TwoLevelTracer::bind`]; `counts` must hold a whole
    /// `u32` at a multiple of 4 bytes.
    ///
    /// # Safety
    /// As [`TwoLevelTracer::bind`], and `counts` (a range of a storage buffer of
    /// this device) stays alive while the binding is used.
    pub unsafe fn bind_indirect(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counts: BufferRange,
        traversal: Traversal,
    ) -> Result<TwoLevelBinding> {
        // SAFETY: forwarded from the caller.
        unsafe { self.bind_inner(rays, hits, Some(counts), traversal) }
    }

    /// `bind`, and `bind_indirect` with `counts`.
    unsafe fn bind_inner(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counts: Option<BufferRange>,
        traversal: Traversal,
    ) -> Result<TwoLevelBinding> {
        if rays.overlaps(&hits) {
            return Err(Error::InvalidInput("the ray and hit ranges overlap".into()));
        }
        let kernel = self.pipelines.kernel(traversal, self.one_instance)?;
        let capacity = (rays.range / RAY_BYTES).min(hits.range / HIT_BYTES).min(u64::from(u32::MAX)) as u32;
        // Robust traces list rays for the careful pass; plain ones bind a list
        // they never touch.
        let words = CAREFUL_HEADER_WORDS as u64 + if traversal.robust { u64::from(capacity) } else { 0 };
        let usage = STORAGE
            | vk::BufferUsageFlags::INDIRECT_BUFFER
            | vk::BufferUsageFlags::TRANSFER_DST
            | vk::BufferUsageFlags::TRANSFER_SRC;
        let list = Buffer::new(&self.ctx, words * 4, usage, MemoryLocation::GpuOnly, "two-level careful list")?;
        let mut ranges = [rays; TL_BINDINGS as usize];
        for (binding, buffer) in [
            (TL_BINDING_NODES, &self.nodes),
            (TL_BINDING_TRIANGLES, &self.triangles),
            (TL_BINDING_GEOMETRIES, &self.geometries),
            (TL_BINDING_INSTANCES, &self.instances),
            (TL_BINDING_TOP, &self.top),
            (TL_BINDING_ORDER, &self.order),
            (TL_BINDING_CAREFUL, &list),
        ] {
            ranges[binding as usize] = BufferRange::whole(buffer);
        }
        ranges[TL_BINDING_HITS as usize] = hits;
        let indirect = match counts {
            None => None,
            Some(source) => {
                let args_kernel = self.pipelines.args_kernel()?;
                // SAFETY: the caller vouches for `source`.
                Some(unsafe { IndirectArgs::new(&self.ctx, args_kernel, source)? })
            }
        };
        ranges[TL_BINDING_INDIRECT as usize] = BufferRange::whole(match &indirect {
            Some(i) => &i.args,
            None => &self.dummy,
        });
        // SAFETY: the scene buffers and the list are this tracer's; the caller vouches for the rest.
        let set = unsafe { BufferSet::from_ranges(&self.ctx, &self.pipelines.kernels[kernel].general.main, &ranges)? };
        Ok(TwoLevelBinding { set, list, hits, kernel, generation: self.generation, capacity, indirect })
    }

    /// Records into `cmd` the two-level trace of the first `count` rays of
    /// `binding`'s ray range, visible to the instances whose mask shares a bit
    /// with `mask`: one dispatch, or two for a robust trace (see the type docs);
    /// nothing for `count` 0.
    ///
    /// Errors: `Error::InvalidInput` for a binding made before the instance
    /// buffers were reallocated, or more rays than its ranges hold.
    ///
    /// # Safety
    /// `cmd` is recording, outside a render pass, from a compute-capable queue
    /// family of this device; the binding, this tracer and the bound buffers
    /// live until it completes; the barriers of the type docs are yours.
    pub unsafe fn record_binding(
        &self,
        cmd: vk::CommandBuffer,
        binding: &TwoLevelBinding,
        count: u32,
        mask: u8,
    ) -> Result<()> {
        // SAFETY: forwarded from the caller.
        unsafe { self.record_inner(cmd, binding, count, None, mask) }
    }

    /// Records into `cmd` the two-level trace of as many rays of `binding`'s
    /// ray range as the `u32` at word `word` of its count range says when the
    /// trace runs (at most the ranges' capacity: rays past it are not traced),
    /// visible to `mask`; the binding comes from
    /// [`TwoLevelTracer::bind_indirect`]. Nothing is read back: first a
    /// one-invocation kernel turns the count into the binding's arguments (with
    /// a buffer barrier on them before and after), then the passes of
    /// [`TwoLevelTracer::record_binding`] are dispatched indirectly. Never
    /// submits or waits.
    ///
    /// Barriers are yours as for [`TwoLevelTracer::record_binding`], and the
    /// count is one more input: make your write of it available to
    /// `COMPUTE_SHADER` with `SHADER_READ` before this recording, and do not
    /// write it again before an execution dependency after `COMPUTE_SHADER`.
    ///
    /// Errors (nothing is recorded then): those of
    /// [`TwoLevelTracer::record_binding`]; `Error::InvalidInput` when `binding`
    /// was not made by [`TwoLevelTracer::bind_indirect`] or `word` lies past
    /// its count range.
    ///
    /// # Safety
    /// As [`TwoLevelTracer::record_binding`]; the count range's buffer too must
    /// stay alive until `cmd` has completed.
    pub unsafe fn record_binding_indirect(
        &self,
        cmd: vk::CommandBuffer,
        binding: &TwoLevelBinding,
        word: u32,
        mask: u8,
    ) -> Result<()> {
        let Some(i) = &binding.indirect else {
            return Err(Error::InvalidInput(
                "record_binding_indirect needs a binding made by TwoLevelTracer::bind_indirect".into(),
            ));
        };
        i.check_word(word)?;
        // SAFETY: forwarded from the caller.
        unsafe { self.record_inner(cmd, binding, binding.capacity, Some(word), mask) }
    }

    /// `record_binding` over `count` rays, or with `word` the device-counted
    /// trace of at most `count` (the capacity) rays.
    unsafe fn record_inner(
        &self,
        cmd: vk::CommandBuffer,
        binding: &TwoLevelBinding,
        count: u32,
        word: Option<u32>,
        mask: u8,
    ) -> Result<()> {
        if binding.generation != self.generation {
            return Err(Error::InvalidInput(
                "the binding was made before set_instances reallocated the instance buffers: bind again".into(),
            ));
        }
        if count > binding.capacity {
            return Err(Error::InvalidInput(format!("{count} rays; the bound ranges hold {}", binding.capacity)));
        }
        let indirect = word.and_then(|w| binding.indirect.as_ref().map(|i| (i, w)));
        if count > 0 {
            let params = TwoLevelParams {
                ray_count: count,
                mask: u32::from(mask),
                top_nodes: self.top_node_count,
                indirect: indirect.is_some() as u32,
            };
            let push = bytemuck::bytes_of(&params);
            let passes = self.passes(binding);
            let fast_args = indirect.map(|(i, _)| (i.args.buffer, 0));
            // SAFETY: the caller vouches for `cmd` and the lifetimes.
            unsafe {
                if let Some((i, word)) = indirect {
                    i.record(&self.ctx.device, cmd, word, binding.capacity);
                }
                match (&passes.careful, fast_args) {
                    (Some(careful), _) => record_fast_then_careful(
                        &self.ctx.device,
                        cmd,
                        binding.set.set,
                        push,
                        count,
                        fast_args,
                        [&passes.main, careful],
                        &binding.list,
                        &[binding.hits],
                    ),
                    (None, Some((args, offset))) => {
                        passes.main.record_dispatch_indirect(cmd, binding.set.set, push, args, offset)
                    }
                    (None, None) => passes.main.record_dispatch(cmd, binding.set.set, push, count),
                }
            }
        }
        Ok(())
    }
}

/// Device-local texel buffers for `capacity` instances: instances, top-level
/// nodes (fewer than 2 per instance) and the leaves' instance order.
fn instance_buffers(ctx: &Arc<GpuContext>, capacity: usize) -> Result<[Buffer; 3]> {
    let usage = TEXEL | vk::BufferUsageFlags::TRANSFER_DST;
    let n = capacity as u64;
    let buffer = |bytes: u64, name: &str| Buffer::new(ctx, bytes, usage, MemoryLocation::GpuOnly, name);
    Ok([
        buffer(n * std::mem::size_of::<GpuInstance>() as u64, "two-level instances")?,
        buffer(2 * n * std::mem::size_of::<TopNode>() as u64, "two-level top level")?,
        buffer(n * 4, "two-level instance order")?,
    ])
}

/// Depth of the BVH below node `n` (a leaf: 1; none: 0).
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
