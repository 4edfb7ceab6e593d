//! The public tracing API: a scene on a device ([`Tracer`]), traced either by
//! kdtrace itself ([`Tracer::trace`]: upload rays, submit, wait, read the hits
//! back) or inside an engine's own command buffer ([`Tracer::record_trace`]).
//! The traversal kernels implement Horn, Sugerman, Houston & Hanrahan,
//! *Interactive k-D Tree GPU Raytracing* (I3D 2007), and kd-restart and
//! kd-backtrack of Foley & Sugerman (2005); see [`Variant`].
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
//! rewritten). Do not call [`Tracer::replace_scene`] or drop the tracer while a
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
    BINDING_CAREFUL, BINDING_COUNTERS, BINDING_HITS, BINDING_NODES, BINDING_NODE_BOXES, BINDING_ORDER, BINDING_PARENTS,
    BINDING_PRIM_INDICES, BINDING_RAYS, BINDING_ROPES, BINDING_TRIANGLES, CAREFUL_HEADER_WORDS, COUNTERS_PER_RAY,
    COUNTER_DROPS, COUNTER_LEAVES, COUNTER_NODES, COUNTER_RESTARTS, COUNTER_STEPS, COUNTER_TRIANGLES, ORDER_BINDINGS,
    ORDER_BINDING_BUCKETS, ORDER_BINDING_LIST, ORDER_BUCKETS, ORDER_STEP_COUNT, ORDER_STEP_SCAN, ORDER_STEP_SCATTER,
    ORDER_WORKGROUP_SIZE, PASS_CAREFUL, PASS_FAST, PASS_ONE, PRIM_INCOMPLETE, RQ_BINDINGS, RQ_BINDING_HITS,
    RQ_BINDING_PRIM_IDS, RQ_BINDING_RAYS, RQ_BINDING_SCENE, TRACE_BINDINGS, TRACE_SPECS, TRACE_SPEC_ANY_HIT,
    TRACE_SPEC_COUNTERS, TRACE_SPEC_PACKET_WIDTH, TRACE_SPEC_PASS, TRACE_SPEC_ROBUST, TRACE_SPEC_STACK_SIZE,
    TRACE_SPEC_VARIANT, TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::geom::{Aabb, Hit, Ray};
use crate::gpu::{
    check_range, in_order, shaders, Binding, Buffer, BufferRange, BufferSet, GpuContext, Kernel, KernelDesc, Timestamps,
};
use crate::kdtree::links::TreeLinks;
use crate::kdtree::traverse::Counters;
use crate::kdtree::{KdNode, KdTree};
use crate::ray_query::RayQueryScene;
use crate::traversal::{Traversal, Variant};

pub use crate::abi::TraceParams;

/// Options of one `trace` call.
#[derive(Clone, Copy, Debug)]
pub struct TraceOptions {
    /// Variant, short-stack size and closest/any-hit mode (specialization constants).
    pub traversal: Traversal,
    /// Write per-ray counters (a specialization constant: no cost when off).
    pub counters: bool,
    /// The order the rays are traced in (hits are written in ray order either way).
    pub order: RayOrder,
}

/// The order a batch is traced in. Hits and counters are the same in both: each
/// ray's trace is its own; the order changes how coherent a subgroup's rays are.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum RayOrder {
    /// The order of the ray range (camera rays in Morton order are coherent already).
    #[default]
    AsGiven,
    /// Sorted on the device first, by direction octant and origin cell
    /// (`glsl/order_rays.comp`: three small dispatches and a 4-byte index per ray,
    /// inside the same recording). kd-tree backend only. On lavapipe it pays for
    /// uniformly random rays on scenes whose tree overflows the caches (bunny 1.12×,
    /// dragon_200k 1.18×) and costs elsewhere: camera rays and diffuse bounces from
    /// camera hits are coherent already (docs/BENCH.md, "Ray order on the device").
    Coherent,
}

impl RayOrder {
    /// Both orders.
    pub const ALL: [RayOrder; 2] = [RayOrder::AsGiven, RayOrder::Coherent];

    /// The name on the command line: `as-given` or `coherent`.
    pub fn name(self) -> &'static str {
        match self {
            RayOrder::AsGiven => "as-given",
            RayOrder::Coherent => "coherent",
        }
    }
}

impl std::str::FromStr for RayOrder {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        RayOrder::ALL
            .into_iter()
            .find(|o| o.name() == s)
            .ok_or_else(|| Error::InvalidInput(format!("unknown ray order '{s}' (as-given, coherent)")))
    }
}

impl Default for TraceOptions {
    fn default() -> Self {
        TraceOptions { traversal: Traversal::closest(Variant::Stack), counters: false, order: RayOrder::AsGiven }
    }
}

impl TraceOptions {
    /// `traversal`, counters off, rays as given.
    pub fn new(traversal: Traversal) -> Self {
        TraceOptions { traversal, ..Default::default() }
    }

    /// `traversal` with per-ray counters, rays as given.
    pub fn counted(traversal: Traversal) -> Self {
        TraceOptions { traversal, counters: true, ..Default::default() }
    }

    /// Closest hit with `variant` (short stack of 3), counters off, rays as given.
    pub fn variant(variant: Variant) -> Self {
        TraceOptions::new(Traversal::closest(variant))
    }
}

/// What `trace` returns.
#[derive(Clone, Debug, Default)]
pub struct TraceResult {
    /// One hit per ray, in ray order.
    pub hits: Vec<Hit>,
    /// Per-ray counters when requested.
    pub counters: Option<Vec<Counters>>,
    /// GPU time of the trace dispatches alone (timestamps), when the device has timestamps.
    pub gpu_seconds: Option<f64>,
}

impl TraceResult {
    /// Indices of the rays that did not finish traversal (hit `prim_id` ==
    /// [`PRIM_INCOMPLETE`], `t` NaN): the step
    /// cap ([`MAX_TRAVERSAL_STEPS`](crate::consts::MAX_TRAVERSAL_STEPS)) or a
    /// driver's loop cut-off. Every other hit is a finished answer.
    pub fn incomplete(&self) -> Vec<usize> {
        incomplete_rays(&self.hits)
    }
}

/// Indices of the hits marked [`PRIM_INCOMPLETE`].
pub fn incomplete_rays(hits: &[Hit]) -> Vec<usize> {
    hits.iter().enumerate().filter(|(_, h)| h.prim_id == PRIM_INCOMPLETE).map(|(i, _)| i).collect()
}

/// Rays per dispatch. Bounded by the storage-buffer range and workgroup count limits.
const DEFAULT_CHUNK: usize = 1 << 20;

/// Bytes of one ray, one hit and one ray's counters in the kernel's buffers.
const RAY_BYTES: u64 = std::mem::size_of::<Ray>() as u64;
const HIT_BYTES: u64 = std::mem::size_of::<Hit>() as u64;
const COUNTER_BYTES: u64 = COUNTERS_PER_RAY as u64 * WORD_BYTES;
/// Bytes of a `uint` of the counters and the careful-pass list.
const WORD_BYTES: u64 = std::mem::size_of::<u32>() as u64;

/// How a [`Tracer`] finds hits. A tracer holds its scene in one backend's
/// acceleration structure, chosen when it is made ([`Tracer::with_backend`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Backend {
    /// kdtrace's own SAH kd-tree, traversed by its kernels (`glsl/trace.comp`):
    /// every [`Variant`], counters, the CPU twins.
    #[default]
    KdTree,
    /// The driver's acceleration structures traversed by ray queries
    /// (`VK_KHR_acceleration_structure`, `VK_KHR_ray_query`; [`crate::ray_query`]):
    /// the peer every traversal is compared with. Closest or any hit
    /// ([`Traversal::any_hit`]); the variant and its settings do not apply, and
    /// there are no per-ray counters. Devices without the extensions (Mesa
    /// lavapipe before 24) refuse it with `Error::DeviceLimit` naming them.
    RayQuery,
}

impl Backend {
    /// Every backend.
    pub const ALL: [Backend; 2] = [Backend::KdTree, Backend::RayQuery];

    /// The name on the command line: `kd-tree` or `ray-query`.
    pub fn name(self) -> &'static str {
        match self {
            Backend::KdTree => "kd-tree",
            Backend::RayQuery => "ray-query",
        }
    }
}

impl std::fmt::Display for Backend {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Backend {
    type Err = Error;
    fn from_str(s: &str) -> Result<Self> {
        Backend::ALL
            .into_iter()
            .find(|b| b.name() == s)
            .ok_or_else(|| Error::InvalidInput(format!("unknown backend '{s}' (kd-tree, ray-query)")))
    }
}

/// A tracer's scene, in its backend's acceleration structure.
enum TracerScene {
    KdTree(Box<SceneBuffers>),
    RayQuery(Box<RayQueryScene>),
}

impl TracerScene {
    fn bounds(&self) -> Aabb {
        match self {
            TracerScene::KdTree(s) => s.bounds,
            TracerScene::RayQuery(s) => s.bounds,
        }
    }
}

/// A scene's device buffers.
struct SceneBuffers {
    nodes: Buffer,
    prim_indices: Buffer,
    triangles: Buffer,
    bounds: Aabb,
    /// Triangles of the scene.
    triangle_count: usize,
    /// The nodes, kept to build the side buffers if a variant needs them.
    host_nodes: Vec<KdNode>,
    /// Parent links, node boxes and ropes, uploaded on first use by `backtrack`/`ropes`.
    links: Option<[Buffer; 3]>,
}

impl SceneBuffers {
    /// Checks `tree` over `triangles` against the device's limits and uploads it
    /// ([`scene_device_bytes`] bytes).
    fn upload(ctx: &Arc<GpuContext>, tree: &KdTree, triangles: &[[Vec3; 3]]) -> Result<SceneBuffers> {
        if triangles.is_empty() || tree.bounds.is_empty() {
            return Err(Error::InvalidInput("the scene has no triangles that can be hit".into()));
        }
        tree.check(triangles.len()).map_err(|e| {
            Error::InvalidInput(format!("the kd-tree does not fit its {} triangles: {e}", triangles.len()))
        })?;
        // Triangle texels (R32G32B32A32_UINT) in prim_indices order, so a leaf's
        // triangles are contiguous and need no index load: (v0, prim), (v1, 0), (v2, 0).
        // Filled in parallel: one 48-byte record per reference, a million on a big scene.
        use rayon::prelude::*;
        let mut tri_texels = vec![[0u32; 4]; 3 * tree.prim_indices.len()];
        tri_texels.par_chunks_mut(3).zip(tree.prim_indices.par_iter()).for_each(|(out, &p)| {
            let [a, b, c] = triangles[p as usize].map(|v| v.to_array().map(f32::to_bits));
            out.copy_from_slice(&[[a[0], a[1], a[2], p], [b[0], b[1], b[2], 0], [c[0], c[1], c[2], 0]]);
        });
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

/// Bytes a [`Tracer`] uploads for a kd-tree scene (before the side buffers of
/// `backtrack` and `ropes`): the nodes (8 bytes each), the leaves' primitive
/// indices (4 bytes per reference) and a copy of each referenced triangle in leaf
/// order (48 bytes per reference: its three vertices as texels, so that a
/// leaf's triangles are contiguous and need no index load; docs/INTERNALS.md
/// says what a shared, indexed copy cost in speed).
pub fn scene_device_bytes(tree: &KdTree) -> u64 {
    let refs = tree.prim_indices.len() as u64;
    tree.nodes.len() as u64 * 8 + refs * 4 + refs * 48
}

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
}

/// Compiled trace pipelines of one context, independent of any scene: compile
/// them on another thread while the scene loads and its tree builds, then hand
/// them to the tracer ([`Tracer::adopt_pipelines`]). A [`Tracer`] also compiles
/// what it lacks on first use ([`Tracer::prepare`]).
pub struct TracePipelines {
    ctx: Arc<GpuContext>,
    /// By backend, traversal (normalized: settings a kernel ignores are reset)
    /// and counters; bindings refer to kernels by their index here.
    kernels: Vec<((Backend, Traversal, bool), TraceKernels)>,
    /// The ordering kernel's three steps (`RayOrder::Coherent`), compiled on first use.
    order: Option<Arc<[Kernel; 3]>>,
}

impl TracePipelines {
    /// No pipelines yet, for `ctx`.
    pub fn new(ctx: &Arc<GpuContext>) -> TracePipelines {
        TracePipelines { ctx: ctx.clone(), kernels: Vec::new(), order: None }
    }

    /// Compiles the pipelines that tracing with `backend` and `options` needs
    /// (nothing when they are there). The errors of [`Tracer::prepare`].
    pub fn prepare(&mut self, backend: Backend, options: &TraceOptions) -> Result<()> {
        if options.order == RayOrder::Coherent {
            self.order_kernels(backend)?;
        }
        self.kernel(backend, options.traversal, options.counters).map(|_| ())
    }

    /// The ordering kernel's steps (count, scan, scatter), compiled on first use.
    fn order_kernels(&mut self, backend: Backend) -> Result<Arc<[Kernel; 3]>> {
        if backend != Backend::KdTree {
            return Err(Error::InvalidInput(
                "RayOrder::Coherent is for the kd-tree backend (the ray-query kernel traces rays as given)".into(),
            ));
        }
        if let Some(k) = &self.order {
            return Ok(k.clone());
        }
        let kernel = |step: u32| {
            // One specialization constant, ORDER_SPEC_STEP (id 0).
            let spec = [step];
            Kernel::new(
                &self.ctx,
                &KernelDesc {
                    name: "order_rays",
                    spirv: shaders::ORDER_RAYS,
                    bindings: ORDER_BINDINGS,
                    push_constant_size: std::mem::size_of::<TraceParams>() as u32,
                    spec_constants: &spec,
                    workgroup_size: ORDER_WORKGROUP_SIZE,
                    required_subgroup_size: None,
                    texel_buffers: &[],
                    acceleration_structures: &[],
                    required_subgroup_operations: vk::SubgroupFeatureFlags::empty(),
                },
            )
        };
        let kernels = Arc::new([kernel(ORDER_STEP_COUNT)?, kernel(ORDER_STEP_SCAN)?, kernel(ORDER_STEP_SCATTER)?]);
        self.order = Some(kernels.clone());
        Ok(kernels)
    }

    /// The index of the kernels of `backend`, `traversal` and `counters`,
    /// compiled on first use.
    fn kernel(&mut self, backend: Backend, traversal: Traversal, counters: bool) -> Result<usize> {
        traversal.validate()?;
        if backend == Backend::RayQuery {
            return self.ray_query_kernel(traversal.any_hit, counters);
        }
        // Variants that ignore the stack size or packets share one pipeline.
        let key = Traversal {
            stack_size: if traversal.variant.uses_short_stack() { traversal.stack_size } else { 1 },
            packet_width: if traversal.uses_packets() { traversal.packet_width } else { 1 },
            ..traversal
        };
        let subgroup = key.subgroup_size.unwrap_or(self.ctx.info.subgroup_size);
        if key.packet_width > subgroup || TRACE_WORKGROUP_SIZE % subgroup != 0 {
            return Err(Error::DeviceLimit(format!(
                "packet width {} needs subgroups of at least that many lanes (and dividing the workgroup of {}); {} runs subgroups of {}",
                key.packet_width, TRACE_WORKGROUP_SIZE, self.ctx.info.name, subgroup
            )));
        }
        if let Some(i) = self.kernels.iter().position(|(k, _)| *k == (Backend::KdTree, key, counters)) {
            return Ok(i);
        }
        let desc = KernelDesc {
            name: "trace",
            spirv: shaders::TRACE,
            bindings: TRACE_BINDINGS,
            push_constant_size: std::mem::size_of::<TraceParams>() as u32,
            spec_constants: &[],
            workgroup_size: TRACE_WORKGROUP_SIZE,
            required_subgroup_size: key.subgroup_size,
            texel_buffers: &[
                (BINDING_NODES, vk::Format::R32G32_UINT),
                (BINDING_TRIANGLES, vk::Format::R32G32B32A32_UINT),
            ],
            acceleration_structures: &[],
            // Packets decide by ballots.
            required_subgroup_operations: if key.packet_width > 1 {
                vk::SubgroupFeatureFlags::BASIC | vk::SubgroupFeatureFlags::BALLOT
            } else {
                vk::SubgroupFeatureFlags::empty()
            },
        };
        let spec = |pass: u32| {
            in_order::<_, { TRACE_SPECS as usize }>([
                (TRACE_SPEC_VARIANT, key.variant.id()),
                (TRACE_SPEC_COUNTERS, counters as u32),
                (TRACE_SPEC_STACK_SIZE, key.stack_size),
                (TRACE_SPEC_ANY_HIT, key.any_hit as u32),
                (TRACE_SPEC_PACKET_WIDTH, key.packet_width),
                (TRACE_SPEC_ROBUST, key.robust as u32),
                (TRACE_SPEC_PASS, pass),
            ])
        };
        let kernels = if key.robust && !key.uses_packets() {
            // Robust single rays: the fast and the careful pass, compiled side by side.
            let (fast_spec, careful_spec) = (spec(PASS_FAST), spec(PASS_CAREFUL));
            let ctx = &self.ctx;
            let (main, careful) = std::thread::scope(|s| {
                let careful =
                    s.spawn(|| Kernel::new(ctx, &KernelDesc { spec_constants: &careful_spec, ..desc.clone() }));
                let main = Kernel::new(ctx, &KernelDesc { spec_constants: &fast_spec, ..desc.clone() });
                (main, careful.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)))
            });
            TraceKernels { main: main?, careful: Some(careful?) }
        } else {
            let one = spec(PASS_ONE);
            TraceKernels {
                main: Kernel::new(&self.ctx, &KernelDesc { spec_constants: &one, ..desc.clone() })?,
                careful: None,
            }
        };
        self.kernels.push(((Backend::KdTree, key, counters), kernels));
        Ok(self.kernels.len() - 1)
    }

    /// The ray-query kernel of closest or any hit (no counters, one pass).
    fn ray_query_kernel(&mut self, any_hit: bool, counters: bool) -> Result<usize> {
        if counters {
            return Err(Error::InvalidInput(
                "the ray-query backend has no per-ray counters (the driver's traversal is opaque)".into(),
            ));
        }
        // Keyed by the mode alone: the variant and its settings do not apply.
        let key = (Backend::RayQuery, Traversal { any_hit, ..Traversal::closest(Variant::Stack) }, false);
        if let Some(i) = self.kernels.iter().position(|(k, _)| *k == key) {
            return Ok(i);
        }
        let main = crate::ray_query::kernel(&self.ctx, any_hit)?;
        self.kernels.push((key, TraceKernels { main, careful: None }));
        Ok(self.kernels.len() - 1)
    }
}

/// The pipelines of one traversal and counter setting: one pass, or for robust
/// single rays a fast pass and a careful pass over the rays the fast one listed
/// (dispatched indirectly). On SIMD drivers, which run every branch of a kernel
/// under a mask, one kernel holding both traces would pay for the careful one
/// in every subgroup; two kernels pay for it only where rays need it.
struct TraceKernels {
    main: Kernel,
    careful: Option<Kernel>,
}

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
    set: BufferSet,
    /// The careful pass's list (robust single rays): indirect arguments, count, ray indices.
    careful: Option<Buffer>,
    /// `RayOrder::Coherent`: the ordering kernels, their descriptor set, the bucket
    /// counts and the order.
    order: Option<OrderPass>,
    /// The hit and counter ranges bound (the counters: the caller's, or the
    /// tracer's `write_dummy`), which both passes of a robust trace write: the
    /// barrier between the passes names them.
    hits: BufferRange,
    counters: BufferRange,
    kernel: usize,
    pipeline: vk::Pipeline,
    generation: u64,
    capacity: u32,
    options: TraceOptions,
}

/// The memory dependency of one of kdtrace's barriers on `range` alone: its
/// `src` accesses before, `dst` accesses after (no queue family transfer).
fn buffer_barrier(range: BufferRange, src: vk::AccessFlags, dst: vk::AccessFlags) -> vk::BufferMemoryBarrier<'static> {
    vk::BufferMemoryBarrier::default()
        .src_access_mask(src)
        .dst_access_mask(dst)
        .src_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .dst_queue_family_index(vk::QUEUE_FAMILY_IGNORED)
        .buffer(range.buffer)
        .offset(range.offset)
        .size(range.range)
}

/// The ordering dispatches of a binding (`RayOrder::Coherent`).
struct OrderPass {
    kernels: Arc<[Kernel; 3]>,
    set: BufferSet,
    buckets: Buffer,
    /// The order, bound in both sets.
    list: Buffer,
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
            TracerScene::KdTree(s) => {
                let links = s.links.as_ref().map_or(0, |l| l.iter().map(|b| b.size).sum());
                s.nodes.size + s.prim_indices.size + s.triangles.size + links
            }
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
    /// same context; those it already has are kept (bindings stay valid).
    ///
    /// Errors: `Error::InvalidInput` when they were compiled for another context.
    pub fn adopt_pipelines(&mut self, pipelines: TracePipelines) -> Result<()> {
        if !Arc::ptr_eq(&self.ctx, &pipelines.ctx) {
            return Err(Error::InvalidInput("trace pipelines of another Vulkan context".into()));
        }
        for (key, kernels) in pipelines.kernels {
            if !self.pipelines.kernels.iter().any(|(k, _)| *k == key) {
                self.pipelines.kernels.push((key, kernels));
            }
        }
        Ok(())
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
        if scene.links.is_some() {
            return Ok(());
        }
        let links = TreeLinks::new(&scene.host_nodes, scene.bounds);
        let limit = self.ctx.info.max_storage_buffer_range;
        if std::mem::size_of_val(links.boxes.as_slice()) as u64 > limit {
            return Err(Error::DeviceLimit(format!(
                "the node boxes take {} bytes; the device allows {limit} per storage buffer",
                std::mem::size_of_val(links.boxes.as_slice())
            )));
        }
        let usage = vk::BufferUsageFlags::STORAGE_BUFFER;
        scene.links = Some([
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.parents), usage, "parents")?,
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.boxes), usage, "node boxes")?,
            Buffer::with_data(&self.ctx, bytemuck::cast_slice(&links.ropes), usage, "ropes")?,
        ]);
        Ok(())
    }

    /// Makes the descriptor set that traces rays from `rays` into `hits` (and
    /// per-ray counters into `counters`, [`COUNTERS_PER_RAY`] u32 each, when
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
        unsafe { self.bind_inner(rays, hits, counters, options, true) }
    }

    /// `bind`; `upload`: whether missing side buffers may be uploaded (submits).
    unsafe fn bind_inner(
        &mut self,
        rays: BufferRange,
        hits: BufferRange,
        counters: Option<BufferRange>,
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
        let scene = match &self.scene {
            TracerScene::KdTree(scene) => scene,
            TracerScene::RayQuery(scene) => {
                let k = &self.pipelines.kernels[kernel].1;
                let mut bindings = [Binding::Buffer(rays); RQ_BINDINGS as usize];
                bindings[RQ_BINDING_SCENE as usize] = Binding::AccelerationStructure(scene.accel.top_level());
                bindings[RQ_BINDING_PRIM_IDS as usize] = Binding::Buffer(BufferRange::whole(&scene.prim_ids));
                bindings[RQ_BINDING_RAYS as usize] = Binding::Buffer(rays);
                bindings[RQ_BINDING_HITS as usize] = Binding::Buffer(hits);
                // SAFETY: the structures and the prim-id buffer are this tracer's;
                // the caller vouches for `rays` and `hits`.
                let set = unsafe { BufferSet::from_bindings(&self.ctx, &k.main, &bindings)? };
                return Ok(TraceBinding {
                    set,
                    careful: None,
                    order: None,
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
                    | vk::BufferUsageFlags::TRANSFER_DST;
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
    fn check_binding(&self, binding: &TraceBinding, count: u32) -> Result<&TraceKernels> {
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
    unsafe fn record_unchecked(
        &self,
        cmd: vk::CommandBuffer,
        kernels: &TraceKernels,
        binding: &TraceBinding,
        count: u32,
    ) {
        let b = self.scene.bounds();
        let params = TraceParams {
            scene_min: [b.min.x, b.min.y, b.min.z, 0.0],
            scene_max: [b.max.x, b.max.y, b.max.z, 0.0],
            ray_count: count,
            pad0: 0,
            ordered: binding.order.is_some() as u32,
            pad2: 0,
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
        // SAFETY: forwarded from the caller; the list buffers live in the binding.
        unsafe {
            if let Some(order) = &binding.order {
                // The coherent order: count the buckets, scan them, place the rays.
                // The fill waits for an earlier recording's steps over the buckets.
                let (buckets, list) = (BufferRange::whole(&order.buckets), BufferRange::whole(&order.list));
                barrier(compute, transfer, &[buffer_barrier(buckets, write, vk::AccessFlags::TRANSFER_WRITE)]);
                device.cmd_fill_buffer(cmd, order.buckets.buffer, 0, vk::WHOLE_SIZE, 0);
                barrier(transfer, compute, &[buffer_barrier(buckets, vk::AccessFlags::TRANSFER_WRITE, read_write)]);
                let [count_step, scan_step, scatter_step] = &*order.kernels;
                let step = |k: &Kernel, threads: u32| {
                    k.record_dispatch(cmd, order.set.set, push, threads);
                    barrier(
                        compute,
                        compute,
                        &[buffer_barrier(buckets, write, read_write), buffer_barrier(list, write, read_write)],
                    );
                };
                step(count_step, count);
                step(scan_step, ORDER_WORKGROUP_SIZE);
                step(scatter_step, count);
            }
            let (Some(careful), Some(list_buffer)) = (&kernels.careful, &binding.careful) else {
                kernels.main.record_dispatch(cmd, binding.set.set, push, count);
                return;
            };
            let list = BufferRange::whole(list_buffer);
            // Empty the list (indirect arguments 0, 1, 1; count 0) once an earlier
            // recording's passes are done with it: a memory dependency, since the
            // kernel's binding of the list is writable (synchronization validation
            // counts the careful pass's use as a write).
            let stage = compute | vk::PipelineStageFlags::DRAW_INDIRECT;
            barrier(stage, transfer, &[buffer_barrier(list, write, vk::AccessFlags::TRANSFER_WRITE)]);
            let empty: [u32; CAREFUL_HEADER_WORDS as usize] = [0, 1, 1, 0];
            device.cmd_update_buffer(cmd, list.buffer, 0, bytemuck::cast_slice(&empty));
            barrier(transfer, compute, &[buffer_barrier(list, vk::AccessFlags::TRANSFER_WRITE, read_write)]);
            kernels.main.record_dispatch(cmd, binding.set.set, push, count);
            // The careful pass reads the list (as indirect arguments too) and
            // rewrites the hits (and counters) of the rays it lists, which the fast
            // pass has written: kdtrace's own writes of the caller's ranges (any
            // access of the caller's before the fast pass was checked there).
            let list_args = buffer_barrier(list, write, vk::AccessFlags::INDIRECT_COMMAND_READ | read_write);
            let hits = buffer_barrier(binding.hits, write, write);
            barrier(compute, stage, &[list_args, hits, buffer_barrier(binding.counters, write, write)]);
            careful.record_dispatch_indirect(cmd, binding.set.set, push, list.buffer, 0);
        }
    }

    /// Records the trace of the first `count` rays of `binding`'s ray range into
    /// `cmd` (nothing for `count == 0`). Never submits or waits. The caller's
    /// barriers before and after are those of [`Tracer::record_trace`]; see the
    /// [module docs](self) for them and the state it changes in `cmd`.
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
            unsafe { self.record_unchecked(cmd, kernel, binding, count) };
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
    /// Barriers are yours around it (details in the [module docs](self)):
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
            let binding = self.bind_inner(rays, hits, None, options, false)?;
            self.record_binding(cmd, &binding, count)?;
            Ok(binding)
        }
    }

    /// Traces `rays` (any number: they go in chunks) and returns the closest hit of
    /// each. A ray that did not finish traversal is returned marked
    /// [`PRIM_INCOMPLETE`] (see
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

        let mut result = TraceResult {
            hits: Vec::with_capacity(rays.len()),
            counters: options.counters.then(|| Vec::with_capacity(rays.len())),
            gpu_seconds: timestamps.as_ref().map(|_| 0.0),
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
                    self.record_unchecked(cmd, kernel, &binding, count);
                    if let Some(ts) = &timestamps {
                        ts.record(cmd, 1);
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
