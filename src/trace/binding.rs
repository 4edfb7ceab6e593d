//! Recording traces into a command buffer: [`TraceBinding`] and the
//! [`Tracer`] methods that make and record one.

use std::sync::Arc;

use ash::vk;
use gpu_allocator::MemoryLocation;

use crate::consts::{
    ARGS_BINDINGS, ARGS_BINDING_ARGS, ARGS_BINDING_SOURCE, BINDING_CAREFUL, BINDING_COUNTERS, BINDING_HITS,
    BINDING_INDIRECT, BINDING_NODES, BINDING_NODE_BOXES, BINDING_ORDER, BINDING_PARENTS, BINDING_PRIM_INDICES,
    BINDING_RAYS, BINDING_ROPES, BINDING_TRIANGLES, CAREFUL_HEADER_WORDS, INDIRECT_ORDER_ARGS, INDIRECT_WORDS,
    ORDER_BINDINGS, ORDER_BINDING_BUCKETS, ORDER_BINDING_INDIRECT, ORDER_BINDING_LIST, ORDER_BUCKETS,
    ORDER_WORKGROUP_SIZE, RQ_BINDINGS, RQ_BINDING_HITS, RQ_BINDING_INDIRECT, RQ_BINDING_PRIM_IDS, RQ_BINDING_RAYS,
    RQ_BINDING_SCENE, TRACE_BINDINGS,
};
use crate::error::{Error, Result};
use crate::gpu::{check_range, shaders, Binding, Buffer, BufferRange, BufferSet, GpuContext, Kernel, KernelDesc};

use super::options::{COUNTER_BYTES, HIT_BYTES, RAY_BYTES, WORD_BYTES};
use super::{Backend, RayOrder, TraceKernels, TraceOptions, TraceParams, Tracer, TracerScene};

/// The descriptor set of one traced configuration: the tracer's scene buffers,
/// your ray, hit (and counter) ranges, and the pipeline of one [`TraceOptions`].
/// Made by [`Tracer::bind`] or returned by [`Tracer::record_trace`]; recorded
/// with [`Tracer::record_binding`].
///
/// Dropping it destroys its descriptor set (and list buffer), so keep it until
/// every command buffer it was recorded into has completed. The descriptor set is
/// never rewritten, so it may be recorded into several command buffers, pending
/// ones included; but the careful pass's list buffer (robust single rays) is
/// shared by its recordings, so they must not execute at the same time on
/// different queues (on one queue the recorded barriers order them).
#[must_use = "the descriptor set must live until the command buffer that uses it completes"]
pub struct TraceBinding {
    pub(super) set: BufferSet,
    /// The careful pass's list (robust single rays): indirect arguments, count, ray indices.
    pub(super) careful: Option<Buffer>,
    /// `RayOrder::Coherent`: the ordering kernels, their descriptor set, the bucket
    /// counts and the order.
    pub(super) order: Option<OrderPass>,
    /// Device-counted traces ([`Tracer::bind_indirect`]): the arguments kernel,
    /// its descriptor set, the arguments and the caller's count range.
    pub(super) indirect: Option<IndirectArgs>,
    /// The hit and counter ranges bound (the counters: the caller's, or the
    /// tracer's `write_dummy`), which both passes of a robust trace write: the
    /// barrier between the passes names them.
    pub(super) hits: BufferRange,
    pub(super) counters: BufferRange,
    pub(super) kernel: usize,
    pub(super) pipeline: vk::Pipeline,
    pub(super) generation: u64,
    pub(super) capacity: u32,
    pub(super) options: TraceOptions,
}

/// The memory dependency of one of kdtrace's barriers on `range` alone: its
/// `src` accesses before, `dst` accesses after (no queue family transfer).
pub(crate) fn buffer_barrier(
    range: BufferRange,
    src: vk::AccessFlags,
    dst: vk::AccessFlags,
) -> vk::BufferMemoryBarrier<'static> {
    vk::BufferMemoryBarrier::default()
        .src_access_mask(src)
        .dst_access_mask(dst)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(range.buffer)
        .offset(range.offset)
        .size(range.range)
}

/// Records a robust trace's two passes over descriptor set `set` (both kernels
/// share its layout): the careful list emptied (indirect arguments 0, 1, 1;
/// count 0) once an earlier recording's passes are done with it, the fast pass
/// over `count` rays (or indirectly over the arguments at `fast_args`), then the careful pass dispatched indirectly over the rays
/// it listed. Every barrier is a buffer barrier on `list` or on the `rewritten`
/// ranges the careful pass writes again after the fast one (hits, counters),
/// never a global one. Used by `Tracer` and the two-level tracer.
///
/// # Safety
/// `cmd` is recording, outside a render pass, on a compute queue of `device`;
/// the kernels, `set` and the buffers live until it completes; `list` holds
/// the header and one word per listed ray.
#[allow(clippy::too_many_arguments)]
pub(crate) unsafe fn record_fast_then_careful(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    set: vk::DescriptorSet,
    push: &[u8],
    count: u32,
    fast_args: Option<(vk::Buffer, u64)>,
    [fast, careful]: [&Kernel; 2],
    list: &Buffer,
    rewritten: &[BufferRange],
) {
    let barrier = |src: vk::PipelineStageFlags, dst: vk::PipelineStageFlags, buffers: &[vk::BufferMemoryBarrier]| {
        // SAFETY: `cmd` is recording and the buffers live (the caller's contract).
        unsafe { device.cmd_pipeline_barrier(cmd, src, dst, vk::DependencyFlags::empty(), &[], buffers, &[]) };
    };
    let (compute, transfer) = (vk::PipelineStageFlags::COMPUTE_SHADER, vk::PipelineStageFlags::TRANSFER);
    let (write, read_write) =
        (vk::AccessFlags::SHADER_WRITE, vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE);
    let range = BufferRange::whole(list);
    // A memory dependency before the reset, since the kernels' binding of the
    // list is writable (synchronization validation counts the careful pass's
    // use as a write).
    let indirect = compute | vk::PipelineStageFlags::DRAW_INDIRECT;
    barrier(indirect, transfer, &[buffer_barrier(range, write, vk::AccessFlags::TRANSFER_WRITE)]);
    let empty: [u32; CAREFUL_HEADER_WORDS as usize] = [0, 1, 1, 0];
    // SAFETY: the caller's contract; the list holds at least the header.
    unsafe { device.cmd_update_buffer(cmd, list.buffer, 0, bytemuck::cast_slice(&empty)) };
    barrier(transfer, compute, &[buffer_barrier(range, vk::AccessFlags::TRANSFER_WRITE, read_write)]);
    // SAFETY: the caller's contract.
    unsafe {
        match fast_args {
            None => fast.record_dispatch(cmd, set, push, count),
            Some((args, offset)) => fast.record_dispatch_indirect(cmd, set, push, args, offset),
        }
    };
    // The careful pass reads the list (as indirect arguments too) and rewrites
    // ranges the fast pass has just written: kdtrace's own writes of the
    // caller's ranges (any access of the caller's before the fast pass was
    // checked there).
    let mut barriers = vec![buffer_barrier(range, write, vk::AccessFlags::INDIRECT_COMMAND_READ | read_write)];
    barriers.extend(rewritten.iter().map(|&r| buffer_barrier(r, write, write)));
    barrier(compute, indirect, &barriers);
    // SAFETY: the caller's contract; the list holds the indirect arguments.
    unsafe { careful.record_dispatch_indirect(cmd, set, push, list.buffer, 0) };
}

/// The arguments of a device-counted binding ([`Tracer::bind_indirect`],
/// `TwoLevelTracer::bind_indirect`).
pub(crate) struct IndirectArgs {
    pub(super) kernel: Arc<Kernel>,
    pub(super) set: BufferSet,
    /// `INDIRECT_WORDS` words: the trace dispatch, the count, the ordering dispatch.
    pub(crate) args: Buffer,
    /// The caller's counts.
    pub(super) source: BufferRange,
}

/// Records the copy of a careful list's count (word `CAREFUL_COUNT`) into the
/// first word of `dst`, after the passes that wrote it (a barrier first).
///
/// # Safety
/// `cmd` is recording; both buffers outlive its execution.
pub(crate) unsafe fn record_careful_count_copy(
    device: &ash::Device,
    cmd: vk::CommandBuffer,
    list: &Buffer,
    dst: &Buffer,
) {
    let barrier =
        buffer_barrier(BufferRange::whole(list), vk::AccessFlags::SHADER_WRITE, vk::AccessFlags::TRANSFER_READ);
    let region = vk::BufferCopy { src_offset: u64::from(crate::consts::CAREFUL_COUNT) * 4, dst_offset: 0, size: 4 };
    // SAFETY: forwarded from the caller.
    unsafe {
        device.cmd_pipeline_barrier(
            cmd,
            vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::DRAW_INDIRECT,
            vk::PipelineStageFlags::TRANSFER,
            vk::DependencyFlags::empty(),
            &[],
            &[barrier],
            &[],
        );
        device.cmd_copy_buffer(cmd, list.buffer, dst.buffer, &[region]);
    }
}

/// The arguments kernel kept in `slot`, compiled there on first use (the
/// trace and two-level pipeline sets each keep one).
pub(crate) fn cached_args_kernel(ctx: &Arc<GpuContext>, slot: &mut Option<Arc<Kernel>>) -> Result<Arc<Kernel>> {
    if let Some(k) = slot {
        return Ok(k.clone());
    }
    Ok(slot.insert(Arc::new(compile_args_kernel(ctx)?)).clone())
}

/// The kernel that turns a caller's count into a binding's arguments
/// (glsl/indirect_args.comp).
fn compile_args_kernel(ctx: &Arc<GpuContext>) -> Result<Kernel> {
    Kernel::new(
        ctx,
        &KernelDesc {
            name: "indirect_args",
            spirv: shaders::INDIRECT_ARGS,
            bindings: ARGS_BINDINGS,
            push_constant_size: 8,
            spec_constants: &[],
            workgroup_size: 1,
            required_subgroup_size: None,
            texel_buffers: &[],
            acceleration_structures: &[],
            required_subgroup_operations: vk::SubgroupFeatureFlags::empty(),
        },
    )
}

impl IndirectArgs {
    /// The arguments buffer and its descriptor set for the count range `source`.
    ///
    /// Errors: `Error::InvalidInput` when `source` holds no whole `u32` at a
    /// multiple of 4 bytes or lies outside its buffer.
    ///
    /// # Safety
    /// `source` is a range of a live storage buffer of `ctx`'s device that
    /// outlives the arguments' use.
    pub(crate) unsafe fn new(ctx: &Arc<GpuContext>, kernel: Arc<Kernel>, source: BufferRange) -> Result<IndirectArgs> {
        check_range(ctx, "counts", &source)?;
        if source.range < WORD_BYTES || source.offset % WORD_BYTES != 0 {
            return Err(Error::InvalidInput(format!(
                "the counts range ({} bytes at offset {}) must hold a whole u32 at a multiple of 4 bytes",
                source.range, source.offset
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER | vk::BufferUsageFlags::INDIRECT_BUFFER;
        let bytes = u64::from(INDIRECT_WORDS) * WORD_BYTES;
        let args = Buffer::new(ctx, bytes, usage, MemoryLocation::GpuOnly, "indirect trace arguments")?;
        let mut ranges = [source; ARGS_BINDINGS as usize];
        ranges[ARGS_BINDING_SOURCE as usize] = source;
        ranges[ARGS_BINDING_ARGS as usize] = BufferRange::whole(&args);
        // SAFETY: the arguments buffer is ours; the caller vouches for `source`.
        let set = unsafe { BufferSet::from_ranges(ctx, &kernel, &ranges)? };
        Ok(IndirectArgs { kernel, set, args, source })
    }

    /// `Error::InvalidInput` when word `word` lies past the count range.
    pub(crate) fn check_word(&self, word: u32) -> Result<()> {
        if (u64::from(word) + 1) * WORD_BYTES > self.source.range {
            return Err(Error::InvalidInput(format!(
                "count word {word} lies past the binding's count range of {} bytes",
                self.source.range
            )));
        }
        Ok(())
    }

    /// Records the one-invocation dispatch that turns the count at word `word`
    /// into the arguments (clamped to `capacity`), with a buffer barrier on them
    /// before (an earlier recording's dispatches have read them) and after (for
    /// the indirect dispatches and the kernels' reads of the count).
    ///
    /// # Safety
    /// `cmd` is recording, outside a render pass, on a compute queue of
    /// `device`; these arguments and their source live until it completes.
    pub(crate) unsafe fn record(&self, device: &ash::Device, cmd: vk::CommandBuffer, word: u32, capacity: u32) {
        let (compute, indirect) = (
            vk::PipelineStageFlags::COMPUTE_SHADER,
            vk::PipelineStageFlags::COMPUTE_SHADER | vk::PipelineStageFlags::DRAW_INDIRECT,
        );
        let write = vk::AccessFlags::SHADER_WRITE;
        let read = vk::AccessFlags::INDIRECT_COMMAND_READ | vk::AccessFlags::SHADER_READ;
        let args = [buffer_barrier(BufferRange::whole(&self.args), write, write)];
        let push: [u32; 2] = [word, capacity];
        // SAFETY: the caller's contract.
        unsafe {
            device.cmd_pipeline_barrier(cmd, indirect, compute, vk::DependencyFlags::empty(), &[], &args, &[]);
            self.kernel.record_dispatch(cmd, self.set.set, bytemuck::bytes_of(&push), 1);
            let args = [buffer_barrier(BufferRange::whole(&self.args), write, read)];
            device.cmd_pipeline_barrier(cmd, compute, indirect, vk::DependencyFlags::empty(), &[], &args, &[]);
        }
    }
}

/// How many rays a recording traces: a count known when recording, or the
/// `u32` at word `word` of a device-counted binding's count range, read when
/// the trace runs.
#[derive(Clone, Copy, Debug)]
pub(super) enum BatchCount {
    Host(u32),
    Device { word: u32 },
}

/// The ordering dispatches of a binding (`RayOrder::Coherent`).
pub(super) struct OrderPass {
    pub(super) kernels: Arc<[Kernel; 3]>,
    pub(super) set: BufferSet,
    pub(super) buckets: Buffer,
    /// The order, bound in both sets.
    pub(super) list: Buffer,
}

impl TraceBinding {
    /// The most rays one recording of this binding may trace: the fewest whole
    /// rays, hits (and counter records) its ranges hold.
    pub fn capacity(&self) -> u32 {
        self.capacity
    }

    /// The options it was bound with.
    pub fn options(&self) -> &TraceOptions {
        &self.options
    }

    /// The compute pipeline its first pass runs (the same handle in every tracer
    /// that shares its pipelines: [`Tracer::shared_pipelines`]).
    pub fn pipeline(&self) -> vk::Pipeline {
        self.pipeline
    }
}

impl std::fmt::Debug for TraceBinding {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("TraceBinding")
            .field("set", &self.set.set)
            .field("capacity", &self.capacity)
            .field("options", &self.options)
            .finish_non_exhaustive()
    }
}

impl Tracer {
    /// Makes the descriptor set that traces rays from `rays` into `hits` (and
    /// per-ray counters into `counters`, [`COUNTERS_PER_RAY`](crate::consts::COUNTERS_PER_RAY) u32 each, when
    /// `options.counters` is on: a counter range is required then, and refused
    /// otherwise) with the traversal of `options`, for [`Tracer::record_binding`].
    /// Compiles the pipeline on first use; for `backtrack` and `ropes` it may
    /// upload side buffers (see [`Tracer::prepare`]), which submits and waits.
    ///
    /// Errors: `Error::DeviceLimit` for an offset that is not a multiple of
    /// `minStorageBufferOffsetAlignment` or a range beyond `maxStorageBufferRange`;
    /// `Error::InvalidInput` for empty or overlapping ranges, a range too small for
    /// one ray, or a counter range that does not match `options.counters`.
    ///
    /// # Safety
    /// Each range's buffer must be a live buffer of the context's device, created
    /// with `STORAGE_BUFFER` usage, bound to memory and at least `offset + range`
    /// bytes long, and it must stay alive while the binding is used by any
    /// command buffer.
    pub unsafe fn bind(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counters: Option<BufferRange>,
        options: &TraceOptions,
    ) -> Result<TraceBinding> {
        // SAFETY: forwarded from the caller.
        unsafe { self.bind_inner(rays, hits, counters, None, options, true) }
    }

    /// [`Tracer::bind`] for device-counted traces: the binding can also be
    /// recorded with [`Tracer::record_binding_indirect`], which traces as many
    /// rays as a `u32` of `counts` says when the trace runs (written by an
    /// earlier pass of yours on the device, e.g. an atomic counter of rays
    /// appended by a shading pass), with no readback to the host. It adds a
    /// 32-byte arguments buffer and a descriptor set for the small kernel that
    /// fills it ([`Tracer::record_binding_indirect`] says what it records).
    ///
    /// Errors: those of [`Tracer::bind`]; `counts` must hold a whole `u32`.
    ///
    /// # Safety
    /// As [`Tracer::bind`], and `counts` (a range of a storage buffer of the
    /// context's device) stays alive while the binding is used.
    pub unsafe fn bind_indirect(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counters: Option<BufferRange>,
        counts: BufferRange,
        options: &TraceOptions,
    ) -> Result<TraceBinding> {
        // SAFETY: forwarded from the caller.
        unsafe { self.bind_inner(rays, hits, counters, Some(counts), options, true) }
    }

    /// `bind` (`bind_indirect` with `counts`); `upload`: whether missing side
    /// buffers may be uploaded (submits).
    pub(super) unsafe fn bind_inner(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counters: Option<BufferRange>,
        counts: Option<BufferRange>,
        options: &TraceOptions,
        upload: bool,
    ) -> Result<TraceBinding> {
        match (options.counters, counters.is_some()) {
            (true, false) => {
                return Err(Error::InvalidInput(
                    "TraceOptions::counters is on but no counter range was given (Tracer::bind takes one)".into(),
                ))
            }
            (false, true) => {
                return Err(Error::InvalidInput("a counter range was given but TraceOptions::counters is off".into()))
            }
            _ => {}
        }
        let kernel = self.pipelines.kernel(self.backend(), options.traversal, options.counters)?;
        let order_kernels = match options.order {
            RayOrder::AsGiven => None,
            RayOrder::Coherent => Some(self.pipelines.order_kernels(self.backend())?),
        };
        let uses_links = self.backend() == Backend::KdTree && options.traversal.variant.uses_links();
        if uses_links && matches!(&self.scene, TracerScene::KdTree(s) if s.links.is_none()) {
            if !upload {
                return Err(Error::InvalidInput(format!(
                    "the {} traversal needs side buffers that are not uploaded yet, and recording never submits: \
                     call Tracer::prepare with these options first",
                    options.traversal.variant
                )));
            }
            self.ensure_links()?;
        }

        let mut named = vec![("rays", rays, RAY_BYTES), ("hits", hits, HIT_BYTES)];
        named.extend(counters.map(|c| ("counters", c, COUNTER_BYTES)));
        for (what, range, _) in &named {
            check_range(&self.ctx, what, range)?;
        }
        // trace.comp reads rays as 64-bit words.
        if rays.offset % 8 != 0 {
            return Err(Error::InvalidInput(format!(
                "the rays range must start at a multiple of 8 bytes, got offset {}",
                rays.offset
            )));
        }
        for (i, (a, ra, _)) in named.iter().enumerate() {
            for (b, rb, _) in &named[i + 1..] {
                if ra.overlaps(rb) {
                    return Err(Error::InvalidInput(format!(
                        "the {a} range ({}..{}) overlaps the {b} range ({}..{}) of the same buffer",
                        ra.offset,
                        ra.end(),
                        rb.offset,
                        rb.end()
                    )));
                }
            }
        }
        let capacity = named.iter().map(|(_, r, bytes)| r.range / bytes).min().unwrap_or(0);
        if capacity == 0 {
            let (what, r, bytes) = named.iter().find(|(_, r, bytes)| r.range < *bytes).unwrap_or(&named[0]);
            return Err(Error::InvalidInput(format!(
                "the {what} range of {} bytes holds no whole record of {bytes} bytes",
                r.range
            )));
        }

        let capacity = capacity.min(u32::MAX as u64) as u32;
        let indirect = match counts {
            None => None,
            Some(source) => {
                let kernel = self.pipelines.args_kernel()?;
                // SAFETY: the caller vouches for `source`.
                Some(unsafe { IndirectArgs::new(&self.ctx, kernel, source)? })
            }
        };
        let indirect_range = match &indirect {
            Some(i) => BufferRange::whole(&i.args),
            None => BufferRange::whole(&self.dummy),
        };
        let scene = match &self.scene {
            TracerScene::KdTree(scene) => scene,
            TracerScene::RayQuery(scene) => {
                let k = &self.pipelines.kernels[kernel].1;
                let mut bindings = [Binding::Buffer(rays); RQ_BINDINGS as usize];
                bindings[RQ_BINDING_SCENE as usize] = Binding::AccelerationStructure(scene.accel.top_level());
                bindings[RQ_BINDING_PRIM_IDS as usize] = Binding::Buffer(BufferRange::whole(&scene.prim_ids));
                bindings[RQ_BINDING_RAYS as usize] = Binding::Buffer(rays);
                bindings[RQ_BINDING_HITS as usize] = Binding::Buffer(hits);
                bindings[RQ_BINDING_INDIRECT as usize] = Binding::Buffer(indirect_range);
                // SAFETY: the structures and the prim-id buffer are this tracer's;
                // the caller vouches for `rays` and `hits`.
                let set = unsafe { BufferSet::from_bindings(&self.ctx, &k.main, &bindings)? };
                return Ok(TraceBinding {
                    set,
                    careful: None,
                    order: None,
                    indirect,
                    hits,
                    counters: counters.unwrap_or(BufferRange::whole(&self.write_dummy)),
                    kernel,
                    pipeline: k.main.pipeline,
                    generation: self.generation,
                    capacity,
                    options: *options,
                });
            }
        };
        let mut ranges = [BufferRange::whole(&self.dummy); TRACE_BINDINGS as usize];
        ranges[BINDING_NODES as usize] = BufferRange::whole(&scene.nodes);
        ranges[BINDING_PRIM_INDICES as usize] = BufferRange::whole(&scene.prim_indices);
        ranges[BINDING_TRIANGLES as usize] = BufferRange::whole(&scene.triangles);
        ranges[BINDING_RAYS as usize] = rays;
        ranges[BINDING_HITS as usize] = hits;
        let counters = counters.unwrap_or(BufferRange::whole(&self.write_dummy));
        ranges[BINDING_COUNTERS as usize] = counters;
        ranges[BINDING_CAREFUL as usize] = BufferRange::whole(&self.write_dummy);
        ranges[BINDING_INDIRECT as usize] = indirect_range;
        if let (true, Some([parents, boxes, ropes])) = (uses_links, &scene.links) {
            ranges[BINDING_PARENTS as usize] = BufferRange::whole(parents);
            ranges[BINDING_NODE_BOXES as usize] = BufferRange::whole(boxes);
            ranges[BINDING_ROPES as usize] = BufferRange::whole(ropes);
        }
        let k = &self.pipelines.kernels[kernel].1;
        let careful = match k.careful {
            Some(_) => {
                let bytes = (CAREFUL_HEADER_WORDS as u64 + capacity as u64) * WORD_BYTES;
                let usage = vk::BufferUsageFlags::STORAGE_BUFFER
                    | vk::BufferUsageFlags::INDIRECT_BUFFER
                    | vk::BufferUsageFlags::TRANSFER_DST
                    | vk::BufferUsageFlags::TRANSFER_SRC;
                let list = Buffer::new(&self.ctx, bytes, usage, MemoryLocation::GpuOnly, "careful-pass list")?;
                check_range(&self.ctx, "careful-pass list", &BufferRange::whole(&list))?;
                ranges[BINDING_CAREFUL as usize] = BufferRange::whole(&list);
                Some(list)
            }
            None => None,
        };
        let order = match order_kernels {
            None => None,
            Some(kernels) => {
                let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
                let bytes = ORDER_BUCKETS as u64 * WORD_BYTES;
                let buckets = Buffer::new(
                    &self.ctx,
                    bytes,
                    usage | vk::BufferUsageFlags::TRANSFER_DST,
                    MemoryLocation::GpuOnly,
                    "ray-order buckets",
                )?;
                let list =
                    Buffer::new(&self.ctx, capacity as u64 * WORD_BYTES, usage, MemoryLocation::GpuOnly, "ray order")?;
                check_range(&self.ctx, "ray order", &BufferRange::whole(&list))?;
                ranges[BINDING_ORDER as usize] = BufferRange::whole(&list);
                let mut order_ranges = [rays; ORDER_BINDINGS as usize];
                order_ranges[ORDER_BINDING_BUCKETS as usize] = BufferRange::whole(&buckets);
                order_ranges[ORDER_BINDING_LIST as usize] = BufferRange::whole(&list);
                order_ranges[ORDER_BINDING_INDIRECT as usize] = indirect_range;
                // SAFETY: the bucket and order buffers are this tracer's; the caller
                // vouches for `rays`. The three steps share one binding layout.
                let set = unsafe { BufferSet::from_ranges(&self.ctx, &kernels[0], &order_ranges)? };
                Some(OrderPass { kernels, set, buckets, list })
            }
        };
        // SAFETY: the scene, dummy and list buffers are this tracer's; the caller
        // vouches for `rays`, `hits` and `counters`.
        let set = unsafe { BufferSet::from_ranges(&self.ctx, &k.main, &ranges)? };
        Ok(TraceBinding {
            set,
            careful,
            order,
            indirect,
            hits,
            counters,
            kernel,
            pipeline: k.main.pipeline,
            generation: self.generation,
            capacity,
            options: *options,
        })
    }

    /// The kernel of `binding`, after checking it belongs to this tracer's current
    /// scene and holds `count` rays.
    pub(super) fn check_binding(&self, binding: &TraceBinding, count: u32) -> Result<&TraceKernels> {
        let kernel = match self.pipelines.kernels.get(binding.kernel) {
            Some((_, k)) if k.main.pipeline == binding.pipeline => k,
            _ => return Err(Error::InvalidInput("the binding was made by another tracer".into())),
        };
        if binding.generation != self.generation {
            return Err(Error::InvalidInput(
                "the binding was made before Tracer::replace_scene: bind the new scene again".into(),
            ));
        }
        if count > binding.capacity {
            return Err(Error::InvalidInput(format!(
                "{count} rays exceed the {} rays the binding's ray, hit and counter ranges hold",
                binding.capacity
            )));
        }
        Ok(kernel)
    }

    /// Records the dispatches of a checked binding: one, or for robust single rays
    /// the fast pass and the careful pass over the rays it listed, with the
    /// barriers between them.
    ///
    /// # Safety
    /// `cmd` is recording; `kernels` and `binding` passed `check_binding` for `count`.
    pub(super) unsafe fn record_unchecked(
        &self,
        cmd: vk::CommandBuffer,
        kernels: &TraceKernels,
        binding: &TraceBinding,
        count: BatchCount,
    ) {
        let b = self.scene.bounds();
        let (ray_count, indirect) = match count {
            BatchCount::Host(n) => (n, None),
            BatchCount::Device { word } => (binding.capacity, binding.indirect.as_ref().map(|i| (i, word))),
        };
        let params = TraceParams {
            scene_min: [b.min.x, b.min.y, b.min.z, 0.0],
            scene_max: [b.max.x, b.max.y, b.max.z, 0.0],
            ray_count,
            pad0: 0,
            ordered: binding.order.is_some() as u32,
            indirect: indirect.is_some() as u32,
        };
        let push = bytemuck::bytes_of(&params);
        let device = &self.ctx.device;
        // Every barrier names the buffers it orders (buffer memory barriers, never
        // a global memory barrier): the binding's own, and between the two passes
        // of a robust trace the hit and counter ranges the fast pass has just
        // written. The caller's writes before the recording (of its rays, or of its
        // hits before the fast pass) are thus never made visible by kdtrace: a
        // missing barrier of the caller's is reported by synchronization
        // validation in every mode (tests/embed.rs checks robust, plain, ordered).
        let barrier = |src_stage, dst_stage, buffers: &[vk::BufferMemoryBarrier]| {
            // SAFETY: `cmd` is recording (the caller's contract); the buffers are
            // live (the binding's own, or its ranges, which the caller vouched for).
            unsafe {
                device.cmd_pipeline_barrier(cmd, src_stage, dst_stage, vk::DependencyFlags::empty(), &[], buffers, &[])
            };
        };
        let (compute, transfer) = (vk::PipelineStageFlags::COMPUTE_SHADER, vk::PipelineStageFlags::TRANSFER);
        let (write, read_write) =
            (vk::AccessFlags::SHADER_WRITE, vk::AccessFlags::SHADER_READ | vk::AccessFlags::SHADER_WRITE);
        // A dispatch over the batch: direct over `ray_count` invocations, or
        // indirect from the arguments at word `at`.
        let dispatch = |k: &Kernel, set: vk::DescriptorSet, at: u32| match indirect {
            // SAFETY: the caller's contract; the arguments were written above.
            Some((i, _)) => unsafe {
                k.record_dispatch_indirect(cmd, set, push, i.args.buffer, u64::from(at) * WORD_BYTES)
            },
            // SAFETY: the caller's contract.
            None => unsafe { k.record_dispatch(cmd, set, push, ray_count) },
        };
        // SAFETY: forwarded from the caller; the list buffers live in the binding.
        unsafe {
            if let Some((i, word)) = indirect {
                // The arguments from the caller's count.
                i.record(device, cmd, word, binding.capacity);
            }
            if let Some(order) = &binding.order {
                // The coherent order: count the buckets, scan them, place the rays.
                // The fill waits for an earlier recording's steps over the buckets.
                let (buckets, list) = (BufferRange::whole(&order.buckets), BufferRange::whole(&order.list));
                barrier(compute, transfer, &[buffer_barrier(buckets, write, vk::AccessFlags::TRANSFER_WRITE)]);
                device.cmd_fill_buffer(cmd, order.buckets.buffer, 0, vk::WHOLE_SIZE, 0);
                barrier(transfer, compute, &[buffer_barrier(buckets, vk::AccessFlags::TRANSFER_WRITE, read_write)]);
                let [count_step, scan_step, scatter_step] = &*order.kernels;
                let after_step = || {
                    barrier(
                        compute,
                        compute,
                        &[buffer_barrier(buckets, write, read_write), buffer_barrier(list, write, read_write)],
                    )
                };
                dispatch(count_step, order.set.set, INDIRECT_ORDER_ARGS);
                after_step();
                scan_step.record_dispatch(cmd, order.set.set, push, ORDER_WORKGROUP_SIZE);
                after_step();
                dispatch(scatter_step, order.set.set, INDIRECT_ORDER_ARGS);
                after_step();
            }
            let (Some(careful), Some(list_buffer)) = (&kernels.careful, &binding.careful) else {
                dispatch(&kernels.main, binding.set.set, 0);
                return;
            };
            let rewritten = [binding.hits, binding.counters];
            record_fast_then_careful(
                device,
                cmd,
                binding.set.set,
                push,
                ray_count,
                indirect.map(|(i, _)| (i.args.buffer, 0)),
                [&kernels.main, careful],
                list_buffer,
                &rewritten,
            );
        }
    }

    /// Records into `cmd` the trace of as many rays of `binding`'s ray range as
    /// the `u32` at word `word` of its count range says when the trace runs
    /// (at most [`TraceBinding::capacity`]: rays past it are not traced); the
    /// binding comes from [`Tracer::bind_indirect`]. Nothing is read back: the
    /// dispatches are indirect. Recorded before the trace's own dispatches: a
    /// one-invocation kernel that turns the count into the binding's arguments,
    /// with a buffer barrier on them before and after. Never submits or waits.
    ///
    /// Barriers are yours as for [`Tracer::record_trace`], and the count is one
    /// more input: make your write of it available to `COMPUTE_SHADER` with
    /// `SHADER_READ` before this recording, and do not write it again before an
    /// execution dependency after `COMPUTE_SHADER`.
    ///
    /// Errors (nothing is recorded then): those of [`Tracer::record_binding`];
    /// `Error::InvalidInput` when `binding` was not made by
    /// [`Tracer::bind_indirect`] or `word` lies past its count range.
    ///
    /// # Safety
    /// As [`Tracer::record_binding`]; the count range's buffer too must stay alive
    /// until `cmd` has completed.
    pub unsafe fn record_binding_indirect(
        &self,
        cmd: vk::CommandBuffer,
        binding: &TraceBinding,
        word: u32,
    ) -> Result<()> {
        let kernel = self.check_binding(binding, 0)?;
        let Some(i) = &binding.indirect else {
            return Err(Error::InvalidInput(
                "record_binding_indirect needs a binding made by Tracer::bind_indirect".into(),
            ));
        };
        i.check_word(word)?;
        // SAFETY: checked above; the caller vouches for `cmd` and lifetimes.
        unsafe { self.record_unchecked(cmd, kernel, binding, BatchCount::Device { word }) };
        Ok(())
    }

    /// Records the trace of the first `count` rays of `binding`'s ray range into
    /// `cmd` (nothing for `count == 0`). Never submits or waits. The caller's
    /// barriers before and after are those of [`Tracer::record_trace`]; see the
    /// [module docs](super) for them and the state it changes in `cmd`.
    ///
    /// Errors (nothing is recorded then): `Error::InvalidInput` when `binding` was
    /// made by another tracer or before [`Tracer::replace_scene`], or `count`
    /// exceeds [`TraceBinding::capacity`].
    ///
    /// # Safety
    /// `cmd` must be a command buffer of the context's device in the recording
    /// state, outside a render pass, from a pool of a compute-capable queue family.
    /// `binding`, this tracer and the buffers of the binding's ranges must stay
    /// alive (and the scene unreplaced) until `cmd` has completed.
    pub unsafe fn record_binding(&self, cmd: vk::CommandBuffer, binding: &TraceBinding, count: u32) -> Result<()> {
        let kernel = self.check_binding(binding, count)?;
        if count > 0 {
            // SAFETY: checked above; the caller vouches for `cmd` and lifetimes.
            unsafe { self.record_unchecked(cmd, kernel, binding, BatchCount::Host(count)) };
        }
        Ok(())
    }

    /// Records into your command buffer `cmd` the trace of `count` rays read from
    /// `rays` into hits written to `hits` (`count` × 32 and × 16 bytes at least),
    /// with the traversal of `options`: [`Tracer::bind`] then
    /// [`Tracer::record_binding`]. Counters are off in this mode
    /// (`options.counters` must be false; `bind` takes a counter range). Never
    /// submits or waits: a `backtrack` or `ropes` traversal needs
    /// [`Tracer::prepare`] first.
    ///
    /// Barriers are yours around it (details in the [module docs](super)):
    /// - **before**, one from the stage and access that wrote the rays (and last
    ///   used the hit range) to `COMPUTE_SHADER` with `SHADER_READ | SHADER_WRITE`,
    ///   e.g. `COMPUTE_SHADER`/`SHADER_WRITE` after a raygen shader or
    ///   `TRANSFER`/`TRANSFER_WRITE` after a copy;
    /// - **after**, one from `COMPUTE_SHADER`/`SHADER_WRITE` to whatever reads the
    ///   hits, and an execution dependency after `COMPUTE_SHADER` before the rays
    ///   are written again.
    ///
    /// kdtrace's own barriers are buffer memory barriers on its own buffers (and,
    /// between its two passes, on the hits it has just written): they never stand
    /// in for yours, so leaving one out is reported by synchronization validation
    /// whatever `options` say.
    ///
    /// Returns the binding holding the descriptor set: keep it until `cmd` completes.
    ///
    /// # Safety
    /// As [`Tracer::bind`] for the ranges and [`Tracer::record_binding`] for `cmd`:
    /// valid handles of the context's device, `cmd` recording outside a render
    /// pass, and the buffers, the returned binding and this tracer alive until
    /// `cmd` has completed.
    pub unsafe fn record_trace(
        &mut self,
        cmd: vk::CommandBuffer,
        rays: BufferRange,
        hits: BufferRange,
        count: u32,
        options: &TraceOptions,
    ) -> Result<TraceBinding> {
        if options.counters {
            return Err(Error::InvalidInput(
                "record_trace writes no counters: use Tracer::bind with a counter range, then record_binding".into(),
            ));
        }
        // SAFETY: forwarded from the caller.
        unsafe {
            let binding = self.bind_inner(rays, hits, None, None, options, false)?;
            self.record_binding(cmd, &binding, count)?;
            Ok(binding)
        }
    }
}
