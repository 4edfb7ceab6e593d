//! The public tracing API: a scene on a device ([`Tracer`]), traced either by
//! kdtrace itself ([`Tracer::trace`]: upload rays, submit, wait, read the hits
//! back) or inside an engine's own command buffer ([`Tracer::record_trace`]).
//! The traversal kernels implement Horn, Sugerman, Houston & Hanrahan,
//! *Interactive k-D Tree GPU Raytracing* (I3D 2007), and kd-restart and
//! kd-backtrack of Foley & Sugerman (2005); see [`Variant`](crate::traversal::Variant).
//!
//! # Backends
//!
//! A tracer holds its scene in one [`Backend`]'s acceleration structure, chosen
//! when it is made: kdtrace's kd-tree ([`Tracer::new`]) or the driver's own BVH
//! traversed by ray queries ([`Tracer::ray_query`], the peer every traversal is
//! compared with; [`crate::ray_query`]). Everything after that is shared: the
//! ray and hit buffers and records, [`Tracer::bind`], [`Tracer::record_binding`],
//! [`Tracer::record_trace`] and its barrier contract, [`Tracer::trace`], scene
//! replacement, and so the renderer and every command. The backend belongs to
//! the tracer rather than to each trace's [`TraceOptions`] because the two
//! acceleration structures are built and uploaded differently (a ray-query
//! tracer needs no kd-tree), and a binding already names its tracer's kernels.
//! With the ray query, [`TraceOptions::traversal`] only chooses closest or any
//! hit, and counters are refused (the driver's traversal is opaque).
//!
//! # Scene lifecycle
//!
//! 1. **Build** the kd-tree on the CPU with [`KdTree::build`] (SAH, Wald & Havran
//!    2006), or **load** a prebuilt one: a [`KdTree`] is plain data (`nodes`,
//!    `prim_indices`, `bounds`) that you may store and reassemble.
//! 2. **Upload** it with [`Tracer::new`]: nodes, primitive indices and triangle
//!    vertices go to device-local buffers. The tree's structure is checked first
//!    ([`KdTree::check`]), so a corrupt prebuilt tree is an error, not a GPU fault.
//!    This submits copies on the context's queue and waits for them.
//! 3. **Replace** the scene with [`Tracer::replace_scene`]: same checks and upload;
//!    pipelines are kept, the old buffers are freed, bindings made before are refused.
//!    In an engine's frame, [`Tracer::record_replace_scene`] records the upload into
//!    your command buffer instead (no submit, no wait) and keeps the old buffers
//!    until you say the frame completed ([`Tracer::release_retired`]).
//! 4. **Drop** the tracer: its buffers, pipelines and descriptor-set layouts are
//!    destroyed and its allocations freed. Nothing else remains: kdtrace has no
//!    global state, and descriptor sets live in the [`TraceBinding`]s you hold.
//!
//! # Recording into your command buffer
//!
//! [`Tracer::record_trace`] records into `cmd` the trace of `count` rays ([`Ray`],
//! 32 bytes each) read from a range of your buffer, writing `count` hits ([`Hit`],
//! 16 bytes each) into a range of another (or of the same buffer, not
//! overlapping). It never submits or waits, but it allocates the small buffers of
//! the binding it makes (the careful pass's list; with [`RayOrder::Coherent`] the
//! order and its buckets): a renderer makes a binding once with [`Tracer::bind`]
//! and records it each frame with [`Tracer::record_binding`], which allocates
//! nothing. With the
//! robustness measures on and single rays (the default) it records two compute
//! dispatches: a fast pass, and an indirect careful pass over the rays the fast
//! one listed in the binding's own list buffer, which it empties first
//! (`vkCmdUpdateBuffer`), with barriers between these steps that order them
//! (and an earlier recording's careful pass before the list is emptied again).
//! Otherwise it records one dispatch and no barrier. With [`RayOrder::Coherent`]
//! the trace is preceded by the ordering of the rays: a `vkCmdFillBuffer` of the
//! binding's bucket buffer and three small dispatches (count, scan, place), each
//! followed by a barrier, and one before the fill that orders an earlier
//! recording's use of the bucket buffer.
//!
//! kdtrace's barriers cover only its own work: they are buffer memory barriers
//! naming the binding's own buffers (the careful list, the buckets, the order)
//! and, between the fast and the careful pass, the hit and counter ranges the
//! fast pass has just written; never a global memory barrier. So they never make
//! your writes visible to the trace, and a barrier of yours that is missing is
//! reported by synchronization validation (`SYNC-HAZARD-READ-AFTER-WRITE` on the
//! ray binding) with every option, not only where the trace records no barrier.
//! (Like any pipeline barrier they also order execution of all earlier commands;
//! do not count on that either.) Synchronisation of your buffers is yours, as
//! follows.
//!
//! - **Before**: make your writes of the rays available to the compute shader
//!   stage, and finish earlier accesses of the hit range, e.g. a
//!   `vkCmdPipelineBarrier` from the stage that wrote the rays (`COMPUTE_SHADER`
//!   with `SHADER_WRITE`, `TRANSFER` with `TRANSFER_WRITE`, ...) to
//!   `COMPUTE_SHADER` with `SHADER_READ | SHADER_WRITE`, as a global
//!   `vk::MemoryBarrier` or as `vk::BufferMemoryBarrier`s on your ray and hit
//!   ranges. Host writes to mapped memory are made visible by the submission itself.
//! - **After**: before anything reads the hits (or counters), a barrier from
//!   `COMPUTE_SHADER`/`SHADER_WRITE` to the reader's stage and access
//!   (`COMPUTE_SHADER`/`SHADER_READ`, `TRANSFER`/`TRANSFER_READ`, `HOST`/`HOST_READ`).
//!   Before you overwrite the rays again, an execution dependency after `COMPUTE_SHADER`.
//! - **State**: the dispatches bind kdtrace's compute pipelines, its descriptor
//!   set 0 and its push constants in `cmd`; rebind your own compute state after them.
//! - **Queues**: `cmd` must come from a pool of a compute-capable queue family of
//!   the context's device; buffers with exclusive sharing must be owned by that
//!   family. The scene buffers need no barrier (their upload was waited for).
//! - **Results**: hits are written as the kernel writes them: `prim_id` is a
//!   triangle index or [`consts::PRIM_MISS`](crate::consts::PRIM_MISS),
//!   [`consts::PRIM_INVALID`](crate::consts::PRIM_INVALID) or
//!   [`consts::PRIM_INCOMPLETE`](crate::consts::PRIM_INCOMPLETE) (a traversal that did not
//!   finish: the step cap or a driver loop cut-off; the other rays' hits are
//!   good). [`Tracer::trace`] returns such rays marked the same way, never fails
//!   the batch for them: see [`TraceResult::incomplete`].
//!
//! # Lifetimes
//!
//! The descriptor set of a recorded trace lives in the [`TraceBinding`] that
//! `record_trace` returns. Until the command buffer has completed (or is reset
//! without being submitted), keep alive: that binding, the [`Tracer`] (its scene
//! buffers and pipeline), and your ray and hit buffers. Typically the binding goes
//! into your per-frame "delete when this frame's fence signals" list. To avoid
//! creating a descriptor set per frame, make a binding once with [`Tracer::bind`]
//! and record it every frame with [`Tracer::record_binding`] (it may be recorded
//! into any number of command buffers, also pending ones, since it is never
//! rewritten). Do not call [`Tracer::replace_scene`] (use
//! [`Tracer::record_replace_scene`]) or drop the tracer while a
//! recorded trace is pending on the GPU. A binding holds the context (an `Arc`),
//! so drop bindings, tracers and the context before you destroy an adopted device.
//!
//! # Threads
//!
//! [`Tracer`] and [`TraceBinding`] are `Send + Sync`; methods that change the
//! tracer take `&mut self`. Several tracers may share one [`GpuContext`] and be
//! created, used and dropped on different threads at once: the context
//! serialises its own queue submissions and command-pool use with mutexes
//! (see [`GpuContext::queue_lock`] for sharing the queue with an engine).

use std::sync::Arc;

use ash::vk;
use glam::Vec3;
use gpu_allocator::MemoryLocation;

use crate::consts::{
    COUNTERS_PER_RAY, COUNTER_DROPS, COUNTER_LEAVES, COUNTER_NODES, COUNTER_RESTARTS, COUNTER_STEPS, COUNTER_TRIANGLES,
    TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::geom::{Aabb, Hit, Ray};
use crate::gpu::{Buffer, BufferRange, GpuContext, Timestamps};
use crate::kdtree::traverse::Counters;
use crate::kdtree::KdTree;
use crate::ray_query::RayQueryScene;

pub use crate::abi::TraceParams;

mod binding;
mod options;
mod pipelines;
pub(crate) mod scene;

pub use binding::TraceBinding;
pub(crate) use binding::{
    buffer_barrier, cached_args_kernel, record_careful_count_copy, record_fast_then_careful, IndirectArgs,
};
pub use options::{incomplete_rays, Backend, RayOrder, TraceOptions, TraceResult};
use options::{COUNTER_BYTES, DEFAULT_CHUNK, HIT_BYTES, RAY_BYTES, WORD_BYTES};
pub(crate) use pipelines::compile_passes;
use pipelines::TraceKernels;
pub use pipelines::TracePipelines;
pub use scene::scene_device_bytes;
use scene::{SceneBuffers, TracerScene};

/// A scene on a device, ready to trace: the kd-tree nodes, primitive indices and
/// triangle vertices in device-local buffers, and the trace pipelines compiled so
/// far (one per traversal variant and counter setting, made on first use).
///
/// See the [module docs](self) for the scene lifecycle, the barrier and lifetime
/// contract of [`Tracer::record_trace`], and thread safety (`Send + Sync`).
pub struct Tracer {
    ctx: Arc<GpuContext>,
    scene: TracerScene,
    /// Incremented by `replace_scene`; bindings of an older scene are refused.
    generation: u64,
    /// Bound in place of buffers a dispatch does not use: `dummy` at the bindings
    /// the kernel only reads (side buffers, the order), `write_dummy` at those it
    /// may write (counters, the careful list). Apart, so that no recording reads
    /// what another wrote as validation counts writes (every writable binding a
    /// kernel uses): recordings need no barrier between them for these.
    dummy: Buffer,
    write_dummy: Buffer,
    pipelines: TracePipelines,
    chunk: usize,
    /// Scenes replaced by [`Tracer::record_replace_scene`] and its staging
    /// buffers, each under the frame value that may still use them.
    retired: Vec<(u64, Retired)>,
}

/// What a recorded scene replacement leaves for [`Tracer::release_retired`].
struct Retired {
    scene: TracerScene,
    staging: Vec<Buffer>,
}

impl Tracer {
    /// Uploads `tree` (built over `triangles`, or loaded) to the context's device.
    /// Submits the copies on the context's queue and waits for them.
    ///
    /// Errors: `Error::InvalidInput` for an empty scene or a tree whose structure
    /// does not fit `triangles` ([`KdTree::check`]); `Error::DeviceLimit` when a
    /// buffer exceeds `maxStorageBufferRange`.
    pub fn new(ctx: &Arc<GpuContext>, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<Tracer> {
        Tracer::from_scene(ctx, TracerScene::KdTree(Box::new(SceneBuffers::upload(ctx, tree, triangles)?)))
    }

    /// A tracer of `triangles` with the ray-query backend ([`Backend::RayQuery`]):
    /// builds the driver's acceleration structures over them (sorted for build
    /// quality; see [`crate::ray_query`]). Submits on the context's queue and waits.
    ///
    /// Errors: `Error::DeviceLimit` naming the extensions the device lacks (or a
    /// limit the scene exceeds); `Error::InvalidInput` for a scene without a
    /// triangle that can be hit.
    pub fn ray_query(ctx: &Arc<GpuContext>, triangles: &[[Vec3; 3]]) -> Result<Tracer> {
        Tracer::from_scene(ctx, TracerScene::RayQuery(Box::new(RayQueryScene::upload(ctx, triangles)?)))
    }

    /// A tracer with `backend`: [`Tracer::new`] over `tree` for the kd-tree,
    /// [`Tracer::ray_query`] for ray queries (which do not use `tree`).
    pub fn with_backend(
        ctx: &Arc<GpuContext>,
        backend: Backend,
        tree: &KdTree,
        triangles: &[[Vec3; 3]],
    ) -> Result<Tracer> {
        match backend {
            Backend::KdTree => Tracer::new(ctx, tree, triangles),
            Backend::RayQuery => Tracer::ray_query(ctx, triangles),
        }
    }

    fn from_scene(ctx: &Arc<GpuContext>, scene: TracerScene) -> Result<Tracer> {
        let unused = |name| Buffer::new(ctx, 16, vk::BufferUsageFlags::STORAGE_BUFFER, MemoryLocation::GpuOnly, name);
        let (dummy, write_dummy) = (unused("unused binding")?, unused("unused written binding")?);
        // Rays (32 B), hits (16 B) and counters per chunk must fit the storage range,
        // and the dispatch must fit the workgroup count limit.
        let limit = ctx.info.max_storage_buffer_range;
        let by_range = (limit / COUNTER_BYTES.max(RAY_BYTES)) as usize;
        let by_groups = ctx.info.max_workgroup_count_x as usize * TRACE_WORKGROUP_SIZE as usize;
        let chunk = DEFAULT_CHUNK.min(by_range).min(by_groups).max(TRACE_WORKGROUP_SIZE as usize);
        Ok(Tracer {
            ctx: ctx.clone(),
            scene,
            generation: 0,
            dummy,
            write_dummy,
            pipelines: TracePipelines::new(ctx),
            chunk,
            retired: Vec::new(),
        })
    }

    /// Replaces the scene with `tree` over `triangles` (same checks and upload as
    /// [`Tracer::new`]); compiled pipelines are kept. On error the old scene stays.
    /// Bindings made before are refused afterwards ([`Tracer::bind`] again).
    ///
    /// No trace recorded with this tracer may be pending on the GPU: the old scene
    /// buffers are destroyed here.
    ///
    /// With the ray-query backend, `tree` is not used: the driver's structures
    /// are built anew over `triangles`.
    pub fn replace_scene(&mut self, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<()> {
        self.scene = match self.scene {
            TracerScene::KdTree(_) => TracerScene::KdTree(Box::new(SceneBuffers::upload(&self.ctx, tree, triangles)?)),
            TracerScene::RayQuery(_) => TracerScene::RayQuery(Box::new(RayQueryScene::upload(&self.ctx, triangles)?)),
        };
        self.generation += 1;
        Ok(())
    }

    /// [`Tracer::replace_scene`] without a hidden submit or wait, for an engine's
    /// frame: records the upload of `tree` over `triangles` into `cmd`, followed
    /// by a barrier that makes it visible to the trace kernels (buffer barriers
    /// on the new buffers only), and makes it the tracer's scene at once, so that
    /// traces recorded after it (in `cmd` or in later submissions) trace it. When
    /// the old scene had the side buffers of `backtrack`/`ropes`, the new one gets
    /// them in the same recording. Bindings made before are refused afterwards
    /// ([`Tracer::bind`] again); those already recorded keep the old scene.
    ///
    /// The old scene's buffers and the staging buffers are retired under `frame`
    /// (any value that grows with your frames: a frame index, a timeline
    /// semaphore value) and destroyed by [`Tracer::release_retired`] once you
    /// say that frame has completed, so frames in flight stay valid.
    ///
    /// Errors: those of [`Tracer::new`] (nothing is recorded then and the old scene
    /// stays); `Error::InvalidInput` on the ray-query backend (its builds are not
    /// recorded yet: use [`Tracer::replace_scene`]).
    ///
    /// # Safety
    /// `cmd` is a command buffer of the context's device, from a pool of a
    /// compute-capable queue family, in the recording state, outside a render
    /// pass. `cmd` must complete before `release_retired` is called with a value
    /// of `frame` or more, and before the tracer is dropped. Until `cmd` has been
    /// submitted and has completed, trace the new scene only from command buffers
    /// submitted after it on the same queue: [`Tracer::trace`] submits on its own
    /// and would read the buffers before their copies ran.
    pub unsafe fn record_replace_scene(
        &mut self,
        cmd: vk::CommandBuffer,
        tree: &KdTree,
        triangles: &[[Vec3; 3]],
        frame: u64,
    ) -> Result<()> {
        let TracerScene::KdTree(old) = &self.scene else {
            return Err(Error::InvalidInput(
                "recorded scene updates are for the kd-tree backend; the ray-query backend replaces with replace_scene"
                    .into(),
            ));
        };
        // SAFETY: the caller's contract on `cmd`.
        let (scene, staging) =
            unsafe { SceneBuffers::record_upload(&self.ctx, cmd, tree, triangles, old.links.is_some()) }?;
        let old = std::mem::replace(&mut self.scene, TracerScene::KdTree(Box::new(scene)));
        self.retired.push((frame, Retired { scene: old, staging }));
        self.generation += 1;
        Ok(())
    }

    /// Destroys what [`Tracer::record_replace_scene`] retired under frame values
    /// up to `completed` (their command buffers have completed); returns how many
    /// replaced scenes were released.
    pub fn release_retired(&mut self, completed: u64) -> usize {
        release_frames(&mut self.retired, completed)
    }

    /// Bytes on the device still held by retired scenes and staging buffers.
    pub fn retired_bytes(&self) -> u64 {
        let scene = |s: &TracerScene| match s {
            TracerScene::KdTree(s) => s.bytes(),
            TracerScene::RayQuery(s) => s.device_bytes(),
        };
        self.retired.iter().map(|(_, r)| scene(&r.scene) + r.staging.iter().map(|b| b.size).sum::<u64>()).sum()
    }

    /// The backend this tracer traces with.
    pub fn backend(&self) -> Backend {
        match self.scene {
            TracerScene::KdTree(_) => Backend::KdTree,
            TracerScene::RayQuery(_) => Backend::RayQuery,
        }
    }

    /// The context this tracer runs on.
    pub fn context(&self) -> &Arc<GpuContext> {
        &self.ctx
    }

    /// The box around the scene's triangles (rays are clipped to it).
    pub fn bounds(&self) -> Aabb {
        self.scene.bounds()
    }

    /// Bytes of the scene's buffers on the device (what [`scene_device_bytes`]
    /// predicts for a kd-tree scene; the ray-query backend's: its vertex buffer
    /// and acceleration structures), side buffers of `backtrack`/`ropes` included
    /// once uploaded.
    pub fn device_bytes(&self) -> u64 {
        match &self.scene {
            TracerScene::KdTree(s) => s.bytes(),
            TracerScene::RayQuery(s) => s.device_bytes(),
        }
    }

    /// Triangles of the scene this tracer holds.
    pub fn triangle_count(&self) -> usize {
        match &self.scene {
            TracerScene::KdTree(s) => s.triangle_count,
            TracerScene::RayQuery(s) => s.triangle_count,
        }
    }

    /// Rays traced per dispatch.
    pub fn chunk_size(&self) -> usize {
        self.chunk
    }

    /// Limits the rays per dispatch (tests use it to exercise chunking).
    pub fn set_chunk_size(&mut self, rays: usize) {
        self.chunk = rays.clamp(1, self.chunk.max(1));
    }

    /// Takes over pipelines compiled in advance ([`TracePipelines`]) for the
    /// same context, or shared by another tracer ([`Tracer::shared_pipelines`]);
    /// those it already has are kept (bindings stay valid).
    ///
    /// Errors: `Error::InvalidInput` when they were compiled for another context.
    pub fn adopt_pipelines(&mut self, pipelines: TracePipelines) -> Result<()> {
        self.pipelines.merge(pipelines)
    }

    /// The pipelines this tracer has compiled so far, shared, not copied: give
    /// them to another tracer of the same context ([`Tracer::adopt_pipelines`])
    /// and it compiles none of them again (a double-buffered scene: the next
    /// frame's tracer adopts the current one's).
    pub fn shared_pipelines(&self) -> TracePipelines {
        self.pipelines.clone()
    }

    /// Compiles the pipeline of `options` and, for `backtrack` and `ropes`, uploads
    /// their side buffers (parent links, node boxes, ropes; Foley & Sugerman 2005,
    /// Popov et al. 2007), which submits on the context's queue and waits. Call it
    /// at load time so that [`Tracer::record_trace`] finds everything ready.
    pub fn prepare(&mut self, options: &TraceOptions) -> Result<()> {
        self.pipelines.kernel(self.backend(), options.traversal, options.counters)?;
        if options.traversal.variant.uses_links() {
            self.ensure_links()?;
        }
        Ok(())
    }

    /// Uploads the side buffers of `backtrack` and `ropes` once (kd-tree backend).
    fn ensure_links(&mut self) -> Result<()> {
        let TracerScene::KdTree(scene) = &mut self.scene else { return Ok(()) };
        if scene.links.is_none() {
            let ctx = &self.ctx;
            scene.links = Some(scene.make_links(ctx, |data, usage, name| Buffer::with_data(ctx, data, usage, name))?);
        }
        Ok(())
    }
    /// Traces `rays` (any number: they go in chunks) and returns the closest hit of
    /// each. A ray that did not finish traversal is returned marked
    /// [`PRIM_INCOMPLETE`](crate::consts::PRIM_INCOMPLETE) (see
    /// [`TraceResult::incomplete`]); the batch never fails for it.
    /// The convenient path: kdtrace uploads the rays, submits on the context's
    /// queue, waits and reads the hits back (built on [`Tracer::bind`] and
    /// [`Tracer::record_binding`]).
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
        let chunk = self.chunk.min(rays.len()).max(1);
        let ctx = self.ctx.clone();
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        let mut ray_buf = Buffer::new(&ctx, chunk as u64 * RAY_BYTES, usage, MemoryLocation::CpuToGpu, "rays")?;
        let hit_buf = Buffer::new(&ctx, chunk as u64 * HIT_BYTES, usage, MemoryLocation::GpuToCpu, "hits")?;
        let counter_buf = match options.counters {
            true => Some(Buffer::new(&ctx, chunk as u64 * COUNTER_BYTES, usage, MemoryLocation::GpuToCpu, "counters")?),
            false => None,
        };
        // SAFETY: kdtrace's own storage buffers, alive until after the last
        // submission below, which is waited for.
        let binding = unsafe {
            self.bind(
                BufferRange::whole(&ray_buf),
                BufferRange::whole(&hit_buf),
                counter_buf.as_ref().map(BufferRange::whole),
                options,
            )?
        };
        let timestamps = Timestamps::new(&ctx, 2)?;
        // The careful pass's count (word CAREFUL_COUNT of its list), copied back per batch
        // (a host round trip `Tracer::trace` makes anyway; recorded bindings have none).
        let careful_count = match &binding.careful {
            Some(_) => Some(Buffer::new(
                &ctx,
                WORD_BYTES,
                vk::BufferUsageFlags::TRANSFER_DST,
                MemoryLocation::GpuToCpu,
                "careful-pass count",
            )?),
            None => None,
        };

        let mut result = TraceResult {
            hits: Vec::with_capacity(rays.len()),
            counters: options.counters.then(|| Vec::with_capacity(rays.len())),
            gpu_seconds: timestamps.as_ref().map(|_| 0.0),
            careful_rays: careful_count.as_ref().map(|_| 0),
        };
        for batch in rays.chunks(chunk) {
            ray_buf.write(0, bytemuck::cast_slice(batch))?;
            let count = batch.len() as u32;
            let kernel = self.check_binding(&binding, count)?;
            ctx.submit_and_wait(|cmd| {
                // SAFETY: `cmd` is recording; the binding was checked; its buffers
                // outlive the submission, which `submit_and_wait` waits for.
                unsafe {
                    if let Some(ts) = &timestamps {
                        ts.record_reset(cmd);
                        ts.record(cmd, 0);
                    }
                    self.record_unchecked(cmd, kernel, &binding, binding::BatchCount::Host(count));
                    if let Some(ts) = &timestamps {
                        ts.record(cmd, 1);
                    }
                    if let (Some(list), Some(count)) = (&binding.careful, &careful_count) {
                        binding::record_careful_count_copy(&ctx.device, cmd, list, count);
                    }
                    // Make the shader writes visible to the host reads below.
                    ctx.record_host_read_barrier(cmd);
                }
            })?;
            if let (Some(ts), Some(total)) = (&timestamps, result.gpu_seconds.as_mut()) {
                *total += ts.seconds_between(0, 1)?;
            }
            if ctx.timestamps_unreliable() {
                result.gpu_seconds = None;
            }
            if let (Some(total), Some(count)) = (result.careful_rays.as_mut(), &careful_count) {
                let word: &[u32] = bytemuck::cast_slice(count.read(0, WORD_BYTES as usize)?);
                *total += word[0] as u64;
            }
            let hits: &[Hit] = bytemuck::cast_slice(hit_buf.read(0, batch.len() * HIT_BYTES as usize)?);
            result.hits.extend_from_slice(hits);
            if let (Some(out), Some(counter_buf)) = (result.counters.as_mut(), &counter_buf) {
                let raw: &[u32] = bytemuck::cast_slice(counter_buf.read(0, batch.len() * COUNTER_BYTES as usize)?);
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

/// Drops the entries of `retired` kept under frame values up to `completed`;
/// returns how many went (`release_retired` of [`Tracer`] and of the two-level tracer).
pub(crate) fn release_frames<T>(retired: &mut Vec<(u64, T)>, completed: u64) -> usize {
    let before = retired.len();
    retired.retain(|(frame, _)| *frame > completed);
    before - retired.len()
}
