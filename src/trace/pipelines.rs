//! The compiled trace pipelines of one context ([`TracePipelines`]).

use std::sync::Arc;

use ash::vk;

use crate::consts::{
    BINDING_NODES, BINDING_TRIANGLES, ORDER_BINDINGS, ORDER_STEP_COUNT, ORDER_STEP_SCAN, ORDER_STEP_SCATTER,
    ORDER_WORKGROUP_SIZE, PASS_CAREFUL, PASS_FAST, PASS_ONE, TRACE_BINDINGS, TRACE_SPECS, TRACE_SPEC_ANY_HIT,
    TRACE_SPEC_COUNTERS, TRACE_SPEC_PACKET_WIDTH, TRACE_SPEC_PASS, TRACE_SPEC_ROBUST, TRACE_SPEC_STACK_SIZE,
    TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::gpu::{in_order, shaders, GpuContext, Kernel, KernelDesc};
use crate::traversal::{Traversal, Variant};

use super::{Backend, RayOrder, TraceOptions, TraceParams};

/// Compiled trace pipelines of one context, independent of any scene: compile
/// them on another thread while the scene loads and its tree builds, then hand
/// them to the tracer ([`Tracer::adopt_pipelines`](super::Tracer::adopt_pipelines)). A [`Tracer`](super::Tracer) also compiles
/// what it lacks on first use ([`Tracer::prepare`](super::Tracer::prepare)).
///
/// Cloning shares the compiled pipelines (reference counts, no compile): one set
/// can serve several tracers of a context, e.g. the two scenes of a
/// double-buffered pair ([`Tracer::shared_pipelines`](super::Tracer::shared_pipelines)).
/// A pipeline is destroyed with the last tracer or set that holds it.
#[derive(Clone)]
pub struct TracePipelines {
    pub(super) ctx: Arc<GpuContext>,
    /// By backend, traversal (normalized: settings a kernel ignores are reset)
    /// and counters; bindings refer to kernels by their index here.
    pub(super) kernels: Vec<((Backend, Traversal, bool), Arc<TraceKernels>)>,
    /// The ordering kernel's three steps (`RayOrder::Coherent`), compiled on first use.
    pub(super) order: Option<Arc<[Kernel; 3]>>,
    /// The arguments kernel of device-counted traces
    /// ([`Tracer::record_binding_indirect`](super::Tracer::record_binding_indirect)), compiled on first use.
    pub(super) args: Option<Arc<Kernel>>,
}

impl TracePipelines {
    /// No pipelines yet, for `ctx`.
    pub fn new(ctx: &Arc<GpuContext>) -> TracePipelines {
        TracePipelines { ctx: ctx.clone(), kernels: Vec::new(), order: None, args: None }
    }

    /// Compiles the pipelines that tracing with `backend` and `options` needs
    /// (nothing when they are there). The errors of [`Tracer::prepare`](super::Tracer::prepare).
    pub fn prepare(&mut self, backend: Backend, options: &TraceOptions) -> Result<()> {
        if options.order == RayOrder::Coherent {
            self.order_kernels(backend)?;
        }
        self.kernel(backend, options.traversal, options.counters).map(|_| ())
    }

    /// Adds the pipelines of `other` that this set lacks (shared, not copied):
    /// e.g. a set kept for a whole program gathers what its tracers compiled
    /// ([`Tracer::shared_pipelines`](super::Tracer::shared_pipelines)).
    ///
    /// Errors: `Error::InvalidInput` when `other` was compiled for another context.
    pub fn merge(&mut self, other: TracePipelines) -> Result<()> {
        if !Arc::ptr_eq(&self.ctx, &other.ctx) {
            return Err(Error::InvalidInput("trace pipelines of another Vulkan context".into()));
        }
        for (key, kernels) in other.kernels {
            if !self.kernels.iter().any(|(k, _)| *k == key) {
                self.kernels.push((key, kernels));
            }
        }
        if self.order.is_none() {
            self.order = other.order;
        }
        if self.args.is_none() {
            self.args = other.args;
        }
        Ok(())
    }

    /// The arguments kernel of device-counted traces (glsl/indirect_args.comp),
    /// compiled on first use.
    pub(super) fn args_kernel(&mut self) -> Result<Arc<Kernel>> {
        super::binding::cached_args_kernel(&self.ctx, &mut self.args)
    }

    /// The ordering kernel's steps (count, scan, scatter), compiled on first use.
    pub(super) fn order_kernels(&mut self, backend: Backend) -> Result<Arc<[Kernel; 3]>> {
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
    pub(super) fn kernel(&mut self, backend: Backend, traversal: Traversal, counters: bool) -> Result<usize> {
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
            // One module per variant (build.rs).
            spirv: shaders::TRACE[key.variant.id() as usize],
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
                (TRACE_SPEC_COUNTERS, counters as u32),
                (TRACE_SPEC_STACK_SIZE, key.stack_size),
                (TRACE_SPEC_ANY_HIT, key.any_hit as u32),
                (TRACE_SPEC_PACKET_WIDTH, key.packet_width),
                (TRACE_SPEC_ROBUST, key.robust as u32),
                (TRACE_SPEC_PASS, pass),
            ])
        };
        let ctx = &self.ctx;
        let (main, careful) = compile_passes(key.robust && !key.uses_packets(), |pass| {
            Kernel::new(ctx, &KernelDesc { spec_constants: &spec(pass), ..desc.clone() })
        })?;
        let kernels = TraceKernels { main, careful };
        self.kernels.push(((Backend::KdTree, key, counters), Arc::new(kernels)));
        Ok(self.kernels.len() - 1)
    }

    /// The ray-query kernel of closest or any hit (no counters, one pass).
    pub(super) fn ray_query_kernel(&mut self, any_hit: bool, counters: bool) -> Result<usize> {
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
        self.kernels.push((key, Arc::new(TraceKernels { main, careful: None })));
        Ok(self.kernels.len() - 1)
    }
}

/// The pipelines of one traversal and counter setting: one pass, or for robust
/// single rays a fast pass and a careful pass over the rays the fast one listed
/// (dispatched indirectly). On SIMD drivers, which run every branch of a kernel
/// under a mask, one kernel holding both traces would pay for the careful one
/// in every subgroup; two kernels pay for it only where rays need it.
pub(super) struct TraceKernels {
    pub(super) main: Kernel,
    pub(super) careful: Option<Kernel>,
}

/// A kernel's passes from `compile(pass)`: with `two_passes` (robust single
/// rays) the fast and the careful pass, compiled side by side on two threads;
/// else the one pass. Shared by [`TracePipelines`] and the two-level tracer.
pub(crate) fn compile_passes(
    two_passes: bool,
    compile: impl Fn(u32) -> Result<Kernel> + Sync,
) -> Result<(Kernel, Option<Kernel>)> {
    if !two_passes {
        return Ok((compile(PASS_ONE)?, None));
    }
    let (main, careful) = std::thread::scope(|s| {
        let careful = s.spawn(|| compile(PASS_CAREFUL));
        let main = compile(PASS_FAST);
        (main, careful.join().unwrap_or_else(|panic| std::panic::resume_unwind(panic)))
    });
    Ok((main?, Some(careful?)))
}
