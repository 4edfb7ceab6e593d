//! The compiled two-level pipelines of one context ([`TwoLevelPipelines`]).

use std::sync::Arc;

use ash::vk;

use crate::abi::TwoLevelParams;
use crate::consts::{
    TL_BINDINGS, TL_BINDING_GEOMETRIES, TL_BINDING_INSTANCES, TL_BINDING_NODES, TL_BINDING_ORDER, TL_BINDING_TOP,
    TL_BINDING_TRIANGLES, TL_SPEC_ONE_INSTANCE, TRACE_SPECS, TRACE_SPEC_ANY_HIT, TRACE_SPEC_COUNTERS,
    TRACE_SPEC_PACKET_WIDTH, TRACE_SPEC_PASS, TRACE_SPEC_ROBUST, TRACE_SPEC_STACK_SIZE, TRACE_WORKGROUP_SIZE,
};
use crate::error::{Error, Result};
use crate::gpu::{in_order, shaders, GpuContext, Kernel, KernelDesc};
use crate::trace::cached_args_kernel;
use crate::traversal::{Traversal, Variant};

/// Compiled two-level pipelines of one context, independent of any scene: one
/// set can serve several [`TwoLevelTracer`](super::TwoLevelTracer)s of a
/// context (e.g. the scenes of a double-buffered pair, or one per level of
/// detail), so that none compiles a pipeline another has
/// ([`TwoLevelTracer::shared_pipelines`](super::TwoLevelTracer::shared_pipelines),
/// [`TwoLevelTracer::adopt_pipelines`](super::TwoLevelTracer::adopt_pipelines)).
/// Cloning shares the pipelines (reference counts, no compile); a pipeline is
/// destroyed with the last tracer or set that holds it.
#[derive(Clone)]
pub struct TwoLevelPipelines {
    pub(super) ctx: Arc<GpuContext>,
    /// By traversal (normalized: settings the kernel ignores are reset);
    /// bindings refer to them by their index here.
    pub(super) kernels: Vec<TraversalPipelines>,
    /// The kernel of device-counted traces' arguments, compiled on first use.
    args: Option<Arc<Kernel>>,
}

/// The pipelines of one traversal: for scenes of any number of instances, and
/// (compiled while a scene has one instance) those without a top-level loop.
#[derive(Clone)]
pub(super) struct TraversalPipelines {
    key: Traversal,
    pub(super) general: Arc<Passes>,
    pub(super) one_instance: Option<Arc<Passes>>,
}

/// The pipelines of one traversal and scene shape: one pass, or for robust
/// traces a fast pass and a careful pass over the rays it lists (as `Tracer`'s).
pub(super) struct Passes {
    pub(super) main: Kernel,
    pub(super) careful: Option<Kernel>,
}

impl TwoLevelPipelines {
    /// No pipelines yet, for `ctx`.
    pub fn new(ctx: &Arc<GpuContext>) -> TwoLevelPipelines {
        TwoLevelPipelines { ctx: ctx.clone(), kernels: Vec::new(), args: None }
    }

    /// Compiles the pipelines of `traversal` (nothing when they are there): for
    /// scenes of several instances, and with `one_instance` also those for a
    /// scene of one. The errors of [`TwoLevelTracer::prepare`](super::TwoLevelTracer::prepare).
    pub fn prepare(&mut self, traversal: Traversal, one_instance: bool) -> Result<()> {
        self.kernel(traversal, one_instance).map(|_| ())
    }

    /// Adds the pipelines of `other` that this set lacks (shared, not copied).
    ///
    /// Errors: `Error::InvalidInput` when `other` was compiled for another context.
    pub fn merge(&mut self, other: TwoLevelPipelines) -> Result<()> {
        if !Arc::ptr_eq(&self.ctx, &other.ctx) {
            return Err(Error::InvalidInput("two-level pipelines of another Vulkan context".into()));
        }
        for entry in other.kernels {
            match self.kernels.iter_mut().find(|e| e.key == entry.key) {
                Some(mine) => {
                    if mine.one_instance.is_none() {
                        mine.one_instance = entry.one_instance;
                    }
                }
                None => self.kernels.push(entry),
            }
        }
        if self.args.is_none() {
            self.args = other.args;
        }
        Ok(())
    }

    /// The index of the pipelines of `traversal`, compiled on first use (with
    /// `one_instance`, those for a scene of one instance too).
    pub(super) fn kernel(&mut self, traversal: Traversal, one_instance: bool) -> Result<usize> {
        traversal.validate()?;
        if matches!(traversal.variant, Variant::Backtrack | Variant::Ropes) || traversal.uses_packets() {
            return Err(Error::InvalidInput(format!(
                "{:?}{} has no two-level kernel: the GPU traces stack, restart, push-down and the short stacks with single rays",
                traversal.variant,
                if traversal.uses_packets() { " with packets" } else { "" }
            )));
        }
        let key = Traversal {
            stack_size: if traversal.variant.uses_short_stack() { traversal.stack_size } else { 1 },
            packet_width: 1,
            subgroup_size: None,
            ..traversal
        };
        let index = match self.kernels.iter().position(|e| e.key == key) {
            Some(i) => i,
            None => {
                let general = Arc::new(compile_passes(&self.ctx, key, false)?);
                self.kernels.push(TraversalPipelines { key, general, one_instance: None });
                self.kernels.len() - 1
            }
        };
        let entry = &mut self.kernels[index];
        if one_instance && entry.one_instance.is_none() {
            entry.one_instance = Some(Arc::new(compile_passes(&self.ctx, key, true)?));
        }
        Ok(index)
    }

    /// When `one_instance` (the scene has one instance), the one-instance
    /// pipelines of every traversal compiled so far (what `record_binding` then
    /// dispatches).
    pub(super) fn compile_one_instance(&mut self, one_instance: bool) -> Result<()> {
        if !one_instance {
            return Ok(());
        }
        for entry in self.kernels.iter_mut().filter(|e| e.one_instance.is_none()) {
            entry.one_instance = Some(Arc::new(compile_passes(&self.ctx, entry.key, true)?));
        }
        Ok(())
    }

    /// The arguments kernel of device-counted traces, compiled on first use.
    pub(super) fn args_kernel(&mut self) -> Result<Arc<Kernel>> {
        cached_args_kernel(&self.ctx, &mut self.args)
    }
}

/// The pipelines of `key` (normalized) for a scene of one instance or any: for
/// robust traces the fast and the careful pass, compiled side by side.
fn compile_passes(ctx: &Arc<GpuContext>, key: Traversal, one_instance: bool) -> Result<Passes> {
    let (main, careful) = crate::trace::compile_passes(key.robust, |pass| compile(ctx, key, one_instance, pass))?;
    Ok(Passes { main, careful })
}

/// The two-level pipeline of `key` (normalized) and `pass`, for a scene of one
/// instance or any.
fn compile(ctx: &Arc<GpuContext>, key: Traversal, one_instance: bool, pass: u32) -> Result<Kernel> {
    let spec = in_order::<_, { TRACE_SPECS as usize + 1 }>([
        (TRACE_SPEC_COUNTERS, 0),
        (TRACE_SPEC_STACK_SIZE, key.stack_size),
        (TRACE_SPEC_ANY_HIT, key.any_hit as u32),
        (TRACE_SPEC_PACKET_WIDTH, 1),
        (TRACE_SPEC_ROBUST, key.robust as u32),
        (TRACE_SPEC_PASS, pass),
        (TL_SPEC_ONE_INSTANCE, one_instance as u32),
    ]);
    // One module per variant (build.rs); the two-level variants come first.
    let spirv = shaders::TRACE_TWOLEVEL
        .get(key.variant.id() as usize)
        .ok_or_else(|| Error::InvalidInput(format!("the two-level kernel has no {} traversal", key.variant.name())))?;
    Kernel::new(
        ctx,
        &KernelDesc {
            name: "trace_twolevel",
            spirv,
            bindings: TL_BINDINGS,
            push_constant_size: std::mem::size_of::<TwoLevelParams>() as u32,
            spec_constants: &spec,
            workgroup_size: TRACE_WORKGROUP_SIZE,
            // Every scene buffer is a texel buffer (see the kernel's bindings).
            texel_buffers: &[
                (TL_BINDING_NODES, vk::Format::R32G32_UINT),
                (TL_BINDING_TRIANGLES, vk::Format::R32G32B32A32_UINT),
                (TL_BINDING_GEOMETRIES, vk::Format::R32G32B32A32_UINT),
                (TL_BINDING_INSTANCES, vk::Format::R32G32B32A32_UINT),
                (TL_BINDING_TOP, vk::Format::R32G32B32A32_UINT),
                (TL_BINDING_ORDER, vk::Format::R32_UINT),
            ],
            ..Default::default()
        },
    )
}
