//! What one trace is asked for and what it returns: [`TraceOptions`],
//! [`RayOrder`], [`TraceResult`], [`Backend`].

use crate::consts::{COUNTERS_PER_RAY, PRIM_INCOMPLETE};
use crate::error::{Error, Result};
use crate::geom::{Hit, Ray};
use crate::kdtree::traverse::Counters;
use crate::traversal::{Traversal, Variant};

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
    /// Robust single rays: how many rays the fast pass listed for the careful
    /// pass, which traces them again from scratch (a ray it could not decide in
    /// f32: an origin within rounding of a triangle's plane, an edge or vertex met
    /// within rounding, a tie in depth, a far origin). `None` for the kernels
    /// without a careful pass (`--plain`, packets, the ray-query backend). Many
    /// listed rays mean slow rays, not wrong ones: see docs/EMBEDDING.md, "Rays
    /// that leave a surface".
    pub careful_rays: Option<u64>,
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
pub(super) const DEFAULT_CHUNK: usize = 1 << 20;

/// Bytes of one ray, one hit and one ray's counters in the kernel's buffers.
pub(super) const RAY_BYTES: u64 = std::mem::size_of::<Ray>() as u64;
pub(super) const HIT_BYTES: u64 = std::mem::size_of::<Hit>() as u64;
pub(super) const COUNTER_BYTES: u64 = COUNTERS_PER_RAY as u64 * WORD_BYTES;
/// Bytes of a `uint` of the counters and the careful-pass list.
pub(super) const WORD_BYTES: u64 = std::mem::size_of::<u32>() as u64;

/// How a [`Tracer`](super::Tracer) finds hits. A tracer holds its scene in one backend's
/// acceleration structure, chosen when it is made ([`Tracer::with_backend`](super::Tracer::with_backend)).
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
