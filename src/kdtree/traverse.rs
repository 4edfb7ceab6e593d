//! CPU twins of the GPU traversal variants in `glsl/traverse/`: the same
//! decoding, decisions, order and counters, in the same f32 arithmetic, so a
//! test can compare hits and counters per ray. Change both together.

use glam::Vec3;

use super::links::{TreeLinks, NO_ROPE};
use super::KdNode;
use crate::consts::{MAX_SHORT_STACK, MAX_STACK, MAX_TRAVERSAL_STEPS, PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};
use crate::geom::{Aabb, Hit, Ray, TriTest, WatertightRay, EDGE_GAMMA};

/// The traversal algorithms (specialization constant `VARIANT` of `trace.comp`),
/// each in its own file under `glsl/traverse/` with its twin below.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Variant {
    /// Full per-ray stack, front to back (pbrt-v3). The baseline.
    Stack,
    /// kd-restart (Foley & Sugerman 2005): no stack, restart at the root behind each leaf.
    Restart,
    /// kd-restart from the push-down node (Horn et al. 2007): the deepest node whose
    /// segment lay wholly in one child.
    PushDown,
    /// A short stack of `stack_size` entries that drops its oldest entry when full,
    /// with kd-restart from the root when it runs empty (Horn et al. 2007).
    ShortStack,
    /// Short stack plus push-down: the paper's best variant.
    PushDownShortStack,
    /// kd-backtrack (Foley & Sugerman 2005): climb parent links to the first
    /// ancestor whose box the ray leaves after the current leaf, then descend.
    Backtrack,
    /// Ropes (Popov et al. 2007): each leaf links its six faces to the neighbouring
    /// subtree; the ray walks from leaf to leaf without a stack.
    Ropes,
}

impl Variant {
    /// Every variant, in variant-id order (`stack` first).
    pub const ALL: [Variant; 7] = [
        Variant::Stack,
        Variant::Restart,
        Variant::PushDown,
        Variant::ShortStack,
        Variant::PushDownShortStack,
        Variant::Backtrack,
        Variant::Ropes,
    ];

    /// The value of the `VARIANT` specialization constant.
    pub fn id(self) -> u32 {
        use crate::consts::*;
        match self {
            Variant::Stack => VARIANT_STACK,
            Variant::Restart => VARIANT_RESTART,
            Variant::PushDown => VARIANT_PUSH_DOWN,
            Variant::ShortStack => VARIANT_SHORT_STACK,
            Variant::PushDownShortStack => VARIANT_PUSH_DOWN_SHORT_STACK,
            Variant::Backtrack => VARIANT_BACKTRACK,
            Variant::Ropes => VARIANT_ROPES,
        }
    }

    /// The name used on the command line.
    pub fn name(self) -> &'static str {
        match self {
            Variant::Stack => "stack",
            Variant::Restart => "restart",
            Variant::PushDown => "push-down",
            Variant::ShortStack => "short-stack",
            Variant::PushDownShortStack => "push-down-short-stack",
            Variant::Backtrack => "backtrack",
            Variant::Ropes => "ropes",
        }
    }

    /// True for the variants whose behaviour depends on the short-stack size.
    pub fn uses_short_stack(self) -> bool {
        matches!(self, Variant::ShortStack | Variant::PushDownShortStack)
    }

    /// True for the variants that read the side buffers of [`TreeLinks`].
    pub fn uses_links(self) -> bool {
        matches!(self, Variant::Backtrack | Variant::Ropes)
    }
}

impl std::fmt::Display for Variant {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Variant {
    type Err = crate::Error;
    fn from_str(s: &str) -> crate::Result<Self> {
        Variant::ALL.into_iter().find(|v| v.name() == s).ok_or_else(|| {
            let names: Vec<&str> = Variant::ALL.iter().map(|v| v.name()).collect();
            crate::Error::InvalidInput(format!("unknown traversal '{s}' ({})", names.join(", ")))
        })
    }
}

/// A traversal as the kernel's specialization constants select it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Traversal {
    /// The traversal algorithm.
    pub variant: Variant,
    /// Short-stack entries, 1..=`MAX_SHORT_STACK` (used by the short-stack variants).
    pub stack_size: u32,
    /// Any-hit (shadow-ray) mode: stop at the first hit in [tmin, tmax], not the closest.
    pub any_hit: bool,
    /// Lanes per packet (Horn et al.'s packets as aligned groups of subgroup lanes):
    /// 1 = single rays; 2, 4, 8, … up to the subgroup size for `stack`, `restart`,
    /// `push-down`, `short-stack` and `push-down-short-stack` (`backtrack` and `ropes`
    /// always trace single rays). The CPU twins trace single rays; packets must give
    /// the same hits.
    pub packet_width: u32,
    /// A required subgroup size (`VK_EXT_subgroup_size_control`); `None` = the device's.
    pub subgroup_size: Option<u32>,
    /// The robustness measures (default on): conservative split decisions
    /// (Ize 2013 in spirit), and the watertight test's f64 fallback whenever an
    /// edge function or the hit's distance to the ray's bounds lies within its
    /// rounding error. Off: plain f32 decisions and the f64 recompute only at an
    /// edge function of exactly 0 (Woop, Benthin & Wald 2013) — to measure what
    /// the measures cost. A specialization constant: no cost when off.
    ///
    /// With it on, the restart-based variants also restart exactly (see
    /// [`Traversal::follows_stack`]); off, they restart at a t value as in the papers.
    pub robust: bool,
}

impl Traversal {
    /// Closest hit with `variant`, the paper's short stack of 3, single rays.
    pub fn closest(variant: Variant) -> Self {
        Traversal { variant, stack_size: 3, any_hit: false, packet_width: 1, subgroup_size: None, robust: true }
    }

    /// True when this traversal visits the leaves a full stack visits, in the same
    /// order and with the same segments, and so returns the stack's hits bit for
    /// bit: `restart`, `push-down` and the short stacks on single rays with
    /// `robust` on. Their restarts do not start again at a t value (which cannot
    /// order cells that meet at a vertex or edge the ray passes within a float of)
    /// but descend again to the leaf just left to find the entry a full stack would
    /// pop next. `backtrack` and `ropes` (robust) keep their own walk and switch to
    /// exact restarts where a t value could not order the cells (a plane or a
    /// second exit face within rounding of t0, a ray inside a split plane), so
    /// they are watertight but may name another member of a tie. Packets restart
    /// at a t value.
    pub fn follows_stack(&self) -> bool {
        self.robust && !self.uses_packets() && !self.variant.uses_links()
    }

    /// True when the kernel traces packets with this traversal.
    pub fn uses_packets(&self) -> bool {
        self.packet_width > 1 && !self.variant.uses_links()
    }

    /// Checks the stack size and the packet width (a power of two; the device check
    /// against the subgroup size happens when the kernel is made).
    pub fn validate(&self) -> crate::Result<()> {
        if self.stack_size == 0 || self.stack_size > MAX_SHORT_STACK {
            return Err(crate::Error::InvalidInput(format!(
                "short-stack size {} is outside 1..={MAX_SHORT_STACK}",
                self.stack_size
            )));
        }
        if !self.packet_width.is_power_of_two() || self.packet_width > 128 {
            return Err(crate::Error::InvalidInput(format!(
                "packet width {} must be a power of two in 1..=128",
                self.packet_width
            )));
        }
        if let Some(size) = self.subgroup_size {
            if !size.is_power_of_two() || size > 128 {
                return Err(crate::Error::InvalidInput(format!("subgroup size {size} must be a power of two")));
            }
        }
        Ok(())
    }
}

impl From<Variant> for Traversal {
    fn from(variant: Variant) -> Self {
        Traversal::closest(variant)
    }
}

/// Per-ray counters, as written by the GPU when counters are on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Counters {
    /// Node fetches (interior and leaf), climbs of kd-backtrack included.
    pub nodes: u32,
    /// Leaves visited (their triangles tested).
    pub leaves: u32,
    /// Ray/triangle tests; in any-hit mode, up to and including the first hit.
    pub triangles: u32,
    /// Restarts (kd-restart, push-down, short stack running empty), backtracks or rope hops.
    pub restarts: u32,
    /// Traversal loop iterations.
    pub steps: u32,
    /// Short-stack entries dropped because the stack was full.
    pub drops: u32,
}

/// What a traversal needs: the tree, the triangles it indexes and the scene box.
#[derive(Clone, Copy)]
pub struct SceneRef<'a> {
    /// The tree's nodes, root first, depth-first order.
    pub nodes: &'a [KdNode],
    /// Triangle indices of the leaves, addressed by [`KdNode::prim_offset`] and [`KdNode::prim_count`].
    pub prim_indices: &'a [u32],
    /// Vertices of every triangle, indexed by triangle index.
    pub triangles: &'a [[Vec3; 3]],
    /// The tree's root box; rays are clipped to it first.
    pub bounds: Aabb,
    /// Side buffers; needed by `Backtrack` and `Ropes` only.
    pub links: Option<&'a TreeLinks>,
}

impl<'a> SceneRef<'a> {
    /// A view of `tree` over `triangles`, without side buffers.
    pub fn new(tree: &'a super::KdTree, triangles: &'a [[Vec3; 3]]) -> Self {
        SceneRef { nodes: &tree.nodes, prim_indices: &tree.prim_indices, triangles, bounds: tree.bounds, links: None }
    }

    /// The same view with side buffers.
    pub fn with_links(self, links: &'a TreeLinks) -> Self {
        SceneRef { links: Some(links), ..self }
    }
}

/// The ray as traversal sees it: `TraceRay` of common.glsl. Traversal t values
/// and hits are in the segment frame that `wr` defines (`t - wr.t_shift`, from
/// `wr.seg_origin + wr.seg_lo`); `tmin` and `tmax` in the ray's own parameter.
/// The CPU twin always traces as the careful pass does (SEGMENT_FRAME): where
/// the shader selects to save instructions, the values here are the same bits
/// (a subtraction of a zero `seg_lo`, `t_shift` or `t_err`).
struct TraceRay {
    wr: WatertightRay,
    /// [`Traversal::robust`]: the widening of the split decisions.
    eps: f32,
    /// Absolute error bound of a segment-frame plane distance (0 unless shifted).
    t_err: f32,
    /// Flat axes (bit per axis) of a shifted ray and the band of coordinates it
    /// may occupy along them (`flat_axes`, `band` in common.glsl).
    flat_axes: u32,
    band: Vec3,
    dir: Vec3,
    inv_dir: Vec3,
    tmin: f32,
    tmax: f32,
    any_hit: bool,
}

#[derive(PartialEq, Eq)]
enum Visit {
    Near,
    Far,
    Both,
    /// The ray lies in the split plane: both children with the same interval.
    BothSame,
}

/// Traces one ray: the CPU twin of `trace.comp`'s `main`. `traversal` may be a
/// plain [`Variant`] (closest hit, short stack of 3).
///
/// # Panics
/// When `Backtrack` or `Ropes` is asked for on a `SceneRef` without links.
pub fn trace_ray(scene: &SceneRef, ray: &Ray, traversal: impl Into<Traversal>) -> (Hit, Counters) {
    let traversal = traversal.into();
    let mut best = Hit { t: ray.tmax, prim_id: PRIM_MISS, u: 0.0, v: 0.0 };
    let mut c = Counters::default();
    if !ray.is_valid() {
        best.prim_id = PRIM_INVALID;
    } else {
        let origin = Vec3::from(ray.origin);
        let dir = ray.traced_dir();
        let mut r = TraceRay {
            wr: WatertightRay { robust: traversal.robust, ..WatertightRay::new(origin, dir).with_tmax(ray.tmax) },
            eps: if traversal.robust { T_EPS } else { 0.0 },
            t_err: 0.0,
            flat_axes: 0,
            band: Vec3::ZERO,
            dir,
            // Clamped so that a plane through the origin gives t = 0, never 0 · inf.
            inv_dir: (Vec3::ONE / dir).clamp(Vec3::splat(-f32::MAX), Vec3::splat(f32::MAX)),
            tmin: ray.tmin,
            tmax: ray.tmax,
            any_hit: traversal.any_hit,
        };
        let mut clipped = clip_to_box(&r, &scene.bounds);
        if let (true, Some((t0, t1))) = (traversal.robust, clipped) {
            if is_far(&r, &scene.bounds, t0) {
                clipped = shift_to_scene(&mut r, &scene.bounds, t0, t1);
                best.t = ray.tmax - r.wr.t_shift; // the segment frame, like every hit below
            }
        }
        if let Some((t0, t1)) = clipped {
            let mut s = State { scene, r: &r, best: &mut best, closest: Closest::NONE, c: &mut c };
            let links = || scene.links.expect("Backtrack and Ropes need SceneRef::with_links");
            let size = traversal.stack_size.clamp(1, MAX_SHORT_STACK) as usize;
            let finished = match traversal.variant {
                Variant::Stack => trace_stack(&mut s, t0, t1),
                Variant::Restart => trace_restart(&mut s, t0, t1),
                Variant::PushDown => trace_push_down(&mut s, t0, t1),
                Variant::ShortStack => trace_short_stack(&mut s, t0, t1, size, false),
                Variant::PushDownShortStack => trace_short_stack(&mut s, t0, t1, size, true),
                Variant::Backtrack => trace_backtrack(&mut s, links(), t0, t1),
                Variant::Ropes => trace_ropes(&mut s, links(), t0, t1),
            };
            if !finished {
                best.prim_id = PRIM_INCOMPLETE;
            }
        }
        // Back to the ray's own parameter (one rounding, in f64).
        if r.wr.t_shift != 0.0 {
            best.t = (best.t as f64 + r.wr.t_shift as f64) as f32;
        }
    }
    if best.prim_id >= PRIM_INCOMPLETE {
        best.t = if best.prim_id == PRIM_MISS { f32::INFINITY } else { f32::NAN };
        best.u = 0.0;
        best.v = 0.0;
    }
    (best, c)
}

/// What every variant carries: the scene, the ray, the best hit and the counters.
struct State<'s, 'a> {
    scene: &'s SceneRef<'a>,
    r: &'s TraceRay,
    best: &'s mut Hit,
    closest: Closest,
    c: &'s mut Counters,
}

/// The best hit's reference (an index of `prim_indices`) and a bound on the
/// error of its `t`: `best_ref` and `best_err` in common.glsl.
#[derive(Clone, Copy)]
struct Closest {
    reference: u32,
    err: f32,
}

impl Closest {
    const NONE: Closest = Closest { reference: NO_REF, err: 0.0 };
}

/// No reference (`NO_REF` in common.glsl).
const NO_REF: u32 = u32::MAX;

impl State<'_, '_> {
    /// Fetches a node, counting the visit and the loop step.
    fn fetch(&mut self, node: u32) -> KdNode {
        self.c.steps += 1;
        self.c.nodes += 1;
        self.scene.nodes[node as usize]
    }

    /// The farthest `t` at which the closest hit's exact `t` may lie (`best_reach`
    /// in common.glsl): cells beyond it cannot hold a closer hit.
    fn reach(&self) -> f32 {
        self.best.t + self.closest.err
    }

    /// Tests a leaf; true when traversal is done: an any-hit found one, or the
    /// closest hit lies inside the leaf's segment (which ends at `t1`).
    fn leaf(&mut self, n: KdNode, t1: f32) -> bool {
        self.c.leaves += 1;
        intersect_leaf(self.scene, self.r, n, self.best, &mut self.closest, self.c);
        if self.r.any_hit {
            self.best.prim_id != PRIM_MISS
        } else {
            self.reach() <= t1
        }
    }
}

/// 1 + 2·gamma(3) with gamma(n) = n·u / (1 - n·u), u = 2^-24, rounded up: 1 + 3·2^-23
/// (Ize 2013). Widens the far bound so rounding never clips away a hit on the box.
const TFAR_SCALE: f32 = 1.0 + 3.0 * f32::EPSILON;

/// Distance (segment frame) to the plane `axis` = `plane`: `plane_t` in common.glsl.
fn plane_t(r: &TraceRay, axis: usize, plane: f32) -> f32 {
    ((plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis]) * r.inv_dir[axis]
}

/// `is_flat` in common.glsl (only a shifted ray has flat axes).
fn is_flat(r: &TraceRay, axis: usize) -> bool {
    (r.flat_axes >> axis) & 1 != 0
}

/// `flat_side` in common.glsl: -1 below `plane`, +1 above, 0 within the band.
fn flat_side(r: &TraceRay, axis: usize, plane: f32) -> i32 {
    let gap = (plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis];
    if gap > r.band[axis] {
        -1
    } else if gap < -r.band[axis] {
        1
    } else {
        0
    }
}

/// Twin of `is_far` in trace.comp: the box entry `t0` lies more than
/// [`SHIFT_DIAGONALS`](crate::consts::SHIFT_DIAGONALS) scene diagonals along the ray.
fn is_far(r: &TraceRay, b: &Aabb, t0: f32) -> bool {
    let ext = b.max - b.min;
    let diag2 = ext.x * ext.x + ext.y * ext.y + ext.z * ext.z;
    let dist = t0 * glsl_max(r.dir.x.abs(), glsl_max(r.dir.y.abs(), r.dir.z.abs()));
    let far2 = (crate::consts::SHIFT_DIAGONALS * crate::consts::SHIFT_DIAGONALS) as f32 * diag2;
    t0 > 0.0 && dist * dist > far2
}

/// Twin of `shift_to_scene` in trace.comp: a far ray ([`is_far`]) is traversed
/// from its entry `t0` into the box, with the bound `t_err` and its flat axes;
/// returns the clip there (None: it misses after all). `t0`, `t1`: the clip in
/// the ray's own frame.
fn shift_to_scene(r: &mut TraceRay, b: &Aabb, t0: f32, t1: f32) -> Option<(f32, f32)> {
    let t_shift = t0 as f64;
    let mut hi = Vec3::ZERO;
    let mut lo = Vec3::ZERO;
    let mut seg_err = Vec3::ZERO;
    let mut e = 0.0f64;
    // Flat axes: see trace.comp.
    let s_max = (t1 as f64 - t0 as f64) + (t1.abs() as f64) * 2f64.powi(-20);
    for axis in 0..3 {
        let (o, d) = (r.wr.origin[axis] as f64, r.dir[axis] as f64);
        let p = o + t_shift * d;
        hi[axis] = p as f32;
        let rest = p - hi[axis] as f64;
        lo[axis] = rest as f32;
        let a = (hi[axis] as f64).abs() * 2f64.powi(-45) + (o.abs() + (t_shift * d).abs()) * 2f64.powi(-50);
        seg_err[axis] = (rest.abs() + a * 2f64.powi(20)) as f32;
        if r.dir[axis] == 0.0 {
            continue;
        }
        if a > T_EPS as f64 * s_max * d.abs() {
            r.flat_axes |= 1 << axis;
            r.band[axis] = ((a + d.abs() * s_max) * 1.000001) as f32;
        } else {
            e = e.max(a / d.abs());
        }
    }
    r.t_err = ((e * 1.000001) as f32).max(f32::MIN_POSITIVE);
    r.wr.seg_origin = hi;
    r.wr.seg_lo = lo;
    r.wr.seg_err = seg_err;
    r.wr.t_shift = t0;
    r.wr.seg_tmax = r.tmax - t0;
    clip_to_box(r, b)
}

/// Slab clip of [tmin, tmax] to the scene box; twin of `clip_to_box` in common.glsl.
fn clip_to_box(r: &TraceRay, b: &Aabb) -> Option<(f32, f32)> {
    let (mut t0, mut t1) = (r.tmin - r.wr.t_shift, r.tmax - r.wr.t_shift);
    for axis in 0..3 {
        let o = r.wr.seg_origin[axis];
        if r.dir[axis] == 0.0 {
            if o < b.min[axis] || o > b.max[axis] {
                return None;
            }
            continue;
        }
        if is_flat(r, axis) {
            if flat_side(r, axis, b.min[axis]) < 0 || flat_side(r, axis, b.max[axis]) > 0 {
                return None;
            }
            continue;
        }
        let ta = plane_t(r, axis, b.min[axis]);
        let tb = plane_t(r, axis, b.max[axis]);
        let tnear = glsl_min(ta, tb) - r.t_err;
        let tfar = glsl_max(ta, tb) * TFAR_SCALE + r.t_err;
        t0 = glsl_max(t0, tnear);
        t1 = glsl_min(t1, tfar);
    }
    (t0 <= t1).then_some((t0, t1))
}

/// True when a stack entry starting at `t0` can hold a hit closer than `best_t`
/// (`t0 < best_t`; false for NaN, as the shader's `!(t0 < best.t)` drops it).
fn starts_before(t0: f32, best_t: f32) -> bool {
    t0 < best_t
}

/// Twin of `restart_point` in common.glsl: the start of the segment after a
/// restart, the last leaf's exit or, when rounding put it at or before the
/// previous restart point, the next float after that point (progress).
fn restart_point(t_exit: f32, t_prev: f32) -> f32 {
    if t_exit > t_prev {
        return t_exit;
    }
    if t_prev == 0.0 {
        return f32::MIN_POSITIVE;
    }
    let bits = t_prev.to_bits();
    f32::from_bits(if t_prev > 0.0 { bits + 1 } else { bits - 1 })
}

/// Relative widening of the split decisions (`T_EPS` in common.glsl).
const T_EPS: f32 = 1.0 / (1u32 << crate::consts::TRAVERSAL_EPS_LOG2) as f32;

// GLSL's min(x, y) is `y < x ? y : x` and max(x, y) is `x < y ? y : x`.
fn glsl_min(x: f32, y: f32) -> f32 {
    if y < x {
        y
    } else {
        x
    }
}

fn glsl_max(x: f32, y: f32) -> f32 {
    if x < y {
        y
    } else {
        x
    }
}

/// The plane a segment ended at, for the tie rule of [`decide_children`] (the
/// `uvec2` planes of common.glsl): none (first descent, stacks: widened rule
/// only), any (after a restart whose plane is unknown, and the packet kernels:
/// every tie at t0 goes far), exact (the first descent of backtrack and ropes:
/// no near child behind t0), or (axis, split bits).
#[derive(Clone, Copy, Debug, PartialEq)]
enum ExitPlane {
    None,
    Any,
    Exact,
    Plane(usize, u32),
}

/// The split plane of an interior node.
fn node_plane(n: KdNode) -> ExitPlane {
    ExitPlane::Plane(n.axis(), n.split().to_bits())
}

/// Twin of `decide_children` in common.glsl: (visit, near, far, t_split).
fn decide_children(
    r: &TraceRay,
    index: u32,
    n: KdNode,
    t0: f32,
    t1: f32,
    exit_plane: ExitPlane,
) -> (Visit, u32, u32, f32) {
    let axis = n.axis();
    let split = n.split();
    let o = r.wr.seg_origin[axis];
    let d = r.dir[axis];
    let below_first = !d.is_sign_negative();
    let (below, above) = (index + 1, n.above_child());
    let (near, far) = if below_first { (below, above) } else { (above, below) };
    // Clamped finite, so that the widening below never computes inf - inf.
    let ts = plane_t(r, axis, split).clamp(-f32::MAX, f32::MAX);
    // Conservative (see common.glsl): one child only beyond rounding; after a
    // restart, planes before t0 are passed, and so is the exit plane at t0.
    let (eps, err) = (r.eps, r.t_err);
    let (ts_lo, ts_hi) = (ts - eps * ts.abs() - err, ts + eps * ts.abs() + err);
    let (t0_lo, t1_hi) = (t0 - eps * t0.abs() - err, t1 + eps * t1.abs() + err);
    let far_only = match exit_plane {
        ExitPlane::None => ts_hi < t0_lo,
        ExitPlane::Any => ts <= t0,
        ExitPlane::Exact => ts < t0,
        ExitPlane::Plane(a, bits) => ts < t0 || (ts == t0 && a == axis && bits == split.to_bits()),
    };
    let flat = if is_flat(r, axis) { flat_side(r, axis, split) } else { 2 };
    let (visit, ts) = if d == 0.0 && o == split {
        (Visit::BothSame, ts)
    } else if flat == 0 {
        // A flat axis: by position (see common.glsl).
        (Visit::BothSame, ts)
    } else if flat != 2 {
        if (flat < 0) == below_first {
            (Visit::Near, f32::MAX)
        } else {
            (Visit::Far, -f32::MAX)
        }
    } else if ts_lo > t1_hi {
        (Visit::Near, ts)
    } else if far_only {
        (Visit::Far, ts)
    } else {
        // Both, with ts kept inside the segment (see common.glsl).
        (Visit::Both, glsl_min(glsl_max(ts, t0), t1))
    };
    (visit, near, far, ts)
}

/// Twin of `intersect_leaf` in common.glsl. Any-hit mode stops at the first hit.
/// The f32 tests first, then a second pass in f64 over the pairs they left
/// unsure and, when robust, over depth ties: hits whose f32 `t` lie within
/// rounding of the closest one's, ordered by their f64 `t` (see common.glsl).
fn intersect_leaf(scene: &SceneRef, r: &TraceRay, n: KdNode, best: &mut Hit, closest: &mut Closest, c: &mut Counters) {
    let offset = n.prim_offset() as usize;
    let count = n.prim_count() as usize;
    let triangle = |reference: u32| {
        let prim = scene.prim_indices[reference as usize];
        (prim, scene.triangles[prim as usize])
    };
    let in_ref = closest.reference;
    let mut unsure = 0usize;
    let mut first_unsure = count;
    let mut tie = false;
    for i in 0..count {
        let (prim, [v0, v1, v2]) = triangle((offset + i) as u32);
        match r.wr.intersect_f32(v0, v1, v2, r.tmin - r.wr.t_shift, best.t + closest.err) {
            TriTest::Hit(t, u, v, e) => {
                // [t - e, t + e] meets the closest hit's interval: order them in f64
                // (unless it is the same triangle, met again in another leaf).
                if r.wr.robust
                    && !r.any_hit
                    && closest.reference != NO_REF
                    && prim != best.prim_id
                    && t + e >= best.t - closest.err
                {
                    tie = true;
                }
                if t <= best.t {
                    *best = Hit { t, prim_id: prim, u, v };
                    *closest = Closest { reference: (offset + i) as u32, err: e };
                    if r.any_hit {
                        c.triangles += i as u32 + 1;
                        return;
                    }
                }
            }
            TriTest::Unsure => {
                first_unsure = first_unsure.min(i);
                unsure += 1;
            }
            TriTest::Miss => {}
        }
    }
    c.triangles += count as u32;
    if unsure == 0 && !tie {
        return;
    }
    // The second pass: the closest hit on entry (after a tie), the closest after
    // the f32 pass, then the leaf's triangles; each tested again (same bits).
    let window = best.t + closest.err;
    let w_ref = closest.reference;
    let before = [
        (tie && in_ref != NO_REF && in_ref != w_ref).then_some(in_ref),
        (!r.any_hit && w_ref != NO_REF).then_some(w_ref),
    ];
    let first = if tie { 0 } else { first_unsure };
    let mut bar = f64::INFINITY;
    let leaf = (first..count).map(|i| ((offset + i) as u32, true));
    // (reference, whether it is one of the leaf's triangles)
    for (reference, in_leaf) in before.into_iter().flatten().map(|r| (r, false)).chain(leaf) {
        if in_leaf && !(tie || unsure > 0) {
            break;
        }
        let (prim, [v0, v1, v2]) = triangle(reference);
        let result = r.wr.intersect_f32(v0, v1, v2, r.tmin - r.wr.t_shift, window);
        let unsure_pair = result == TriTest::Unsure;
        if unsure_pair && in_leaf {
            unsure -= 1;
        }
        let (mut hit, mut e) = match result {
            TriTest::Hit(t, u, v, e) if !in_leaf || (tie && reference != w_ref) => (Hit { t, prim_id: prim, u, v }, e),
            TriTest::Unsure => (Hit { t: f32::NAN, prim_id: prim, u: 0.0, v: 0.0 }, 0.0),
            _ => continue,
        };
        let t64 = match r.wr.intersect_f64(v0, v1, v2, r.tmin) {
            Some((t, u, v, t64, err64)) => {
                // An unsure pair takes the f64 answer; a certain f32 hit keeps its f32 values.
                if unsure_pair {
                    (hit, e) = (Hit { t, prim_id: prim, u, v }, EDGE_GAMMA * t.abs() + err64);
                }
                t64
            }
            None if unsure_pair => continue,
            None => hit.t as f64, // a certain f32 hit the f64 test rejects: keep its f32 t
        };
        if t64 <= bar {
            bar = t64;
            *best = hit;
            *closest = Closest { reference, err: e };
            if r.any_hit {
                return;
            }
        }
    }
}

/// Twin of `trace_stack` in glsl/traverse/stack.glsl.
fn trace_stack(s: &mut State, mut t0: f32, mut t1: f32) -> bool {
    let mut stack = [(0u32, 0f32, 0f32); MAX_STACK as usize];
    let mut sp = 0usize;
    let mut node = 0u32;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
            match visit {
                Visit::Near => node = near,
                Visit::Far => node = far,
                Visit::BothSame => {
                    stack[sp] = (far, t0, t1);
                    sp += 1;
                    node = near;
                }
                Visit::Both => {
                    stack[sp] = (far, ts, t1);
                    sp += 1;
                    node = near;
                    t1 = ts;
                }
            }
            continue;
        }
        if s.leaf(n, t1) {
            if s.r.any_hit {
                return true;
            }
            // Only entries starting before the hit can hold a closer one (stack.glsl).
            while sp > 0 && !starts_before(stack[sp - 1].1, s.reach()) {
                sp -= 1;
            }
        }
        if sp == 0 {
            return true;
        }
        sp -= 1;
        (node, t0, t1) = stack[sp];
    }
    false
}

/// What [`stack_successor`] found: the entry a full stack pops next, none (the
/// traversal is over), or the step limit.
enum Successor {
    None,
    /// `above`: the entries still pending above the one found.
    Found {
        node: u32,
        t0: f32,
        t1: f32,
        above: u32,
    },
    Cut,
}

/// Twin of the seek of common.glsl (`Seek`, `seek_step`), which the shaders run
/// inside their descent loop and this twin as a loop of its own (the same nodes in
/// the same order): the entry a full stack would pop after `leaf`, found by
/// descending again from `start` (segment `[s0, s1]`) along the path to the leaf
/// with the stack's decisions, stopping at the last of the `known` entries
/// pending on that path.
fn stack_successor(s: &mut State, start: u32, s0: f32, s1: f32, leaf: u32, known: u32, done: bool) -> Successor {
    let (mut node, mut t0, mut t1) = (start, s0, s1);
    let mut pending = 0u32;
    let mut found = Successor::None;
    while node != leaf && pending < known {
        if s.c.steps >= MAX_TRAVERSAL_STEPS {
            return Successor::Cut;
        }
        let n = s.fetch(node);
        let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
        let child = if leaf >= n.above_child() { n.above_child() } else { node + 1 };
        if matches!(visit, Visit::Both | Visit::BothSame) {
            let far_t0 = if visit == Visit::Both { ts } else { t0 };
            if child == near {
                if !done || starts_before(far_t0, s.reach()) {
                    found = Successor::Found { node: far, t0: far_t0, t1, above: pending };
                }
                pending += 1;
                if visit == Visit::Both {
                    t1 = ts;
                }
            } else {
                t0 = far_t0;
            }
        }
        node = child;
    }
    found
}

/// Twin of `trace_restart_exact` in glsl/traverse/restart.glsl: `restart` and
/// `push-down` with exact restarts (robust mode), visiting what `trace_stack` visits.
/// `t_from`: leaves whose segment ends before it (less the widening) are done
/// already (the fallback of robust backtrack and ropes); `-f32::MAX` for none.
fn trace_restart_exact(s: &mut State, mut t0: f32, mut t1: f32, use_push_down: bool, t_from: f32) -> bool {
    let t_from_lo = t_from - T_EPS * t_from.abs() - s.r.t_err;
    let mut node = 0u32;
    let (mut restart_node, mut restart_t0, mut restart_t1) = (0u32, t0, t1);
    let mut push_down = use_push_down;
    // Entries a full stack would hold, and whether the ray ever lay in a split plane.
    let (mut pending, mut in_plane) = (0u32, false);
    while s.c.steps < MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
            if visit == Visit::Both && ts < t_from_lo {
                node = far; // the near side ends before t_from: done already
                t0 = ts;
            } else {
                node = if visit == Visit::Far { far } else { near };
                if visit == Visit::Both {
                    t1 = ts;
                }
                if matches!(visit, Visit::Both | Visit::BothSame) {
                    pending += 1;
                    push_down = false;
                }
                in_plane |= visit == Visit::BothSame;
            }
            if push_down {
                (restart_node, restart_t0, restart_t1) = (node, t0, t1);
            }
            continue;
        }
        let done = s.leaf(n, t1);
        if done && s.r.any_hit {
            return true;
        }
        if pending == 0 || (done && !in_plane) {
            return true;
        }
        match stack_successor(s, restart_node, restart_t0, restart_t1, node, pending, done) {
            Successor::None => return true,
            Successor::Cut => return false,
            Successor::Found { node: next, t0: n0, t1: n1, above } => {
                (node, t0, t1) = (next, n0, n1);
                pending = above;
                push_down = use_push_down && above == 0;
                if push_down {
                    (restart_node, restart_t0, restart_t1) = (node, t0, t1);
                }
            }
        }
        s.c.restarts += 1;
    }
    false
}

/// Twin of `trace_restart` in glsl/traverse/restart.glsl.
fn trace_restart(s: &mut State, mut t0: f32, t1_scene: f32) -> bool {
    if s.r.wr.robust {
        return trace_restart_exact(s, t0, t1_scene, false, -f32::MAX);
    }
    let mut node = 0u32;
    let mut t1 = t1_scene;
    let mut t0_restart = t0; // where the segment started at the last restart
    let mut exit_plane = ExitPlane::None; // the plane the last leaf was left through
    let mut t1_plane = ExitPlane::None; // the plane the current segment ends at
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, exit_plane);
            match visit {
                Visit::Far => node = far,
                Visit::Both => {
                    node = near;
                    t1 = ts;
                    t1_plane = node_plane(n);
                }
                Visit::Near | Visit::BothSame => node = near,
            }
            continue;
        }
        if s.leaf(n, t1) || t1 >= t1_scene {
            return true;
        }
        t0 = restart_point(t1, t0_restart);
        t0_restart = t0;
        t1 = glsl_min(t1_scene, s.reach());
        node = 0;
        exit_plane = if t1_plane == ExitPlane::None { ExitPlane::Any } else { t1_plane };
        t1_plane = ExitPlane::None;
        s.c.restarts += 1;
    }
    false
}

/// Twin of `trace_push_down` in glsl/traverse/push_down.glsl.
fn trace_push_down(s: &mut State, mut t0: f32, t1_scene: f32) -> bool {
    if s.r.wr.robust {
        return trace_restart_exact(s, t0, t1_scene, true, -f32::MAX);
    }
    let mut node = 0u32;
    let mut t1 = t1_scene;
    let mut t0_restart = t0; // where the segment started at the last restart
    let mut exit_plane = ExitPlane::None; // the plane the last leaf was left through
    let mut t1_plane = ExitPlane::None; // the plane the current segment ends at
    let mut restart_node = 0u32;
    let mut push_down = true;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, exit_plane);
            match visit {
                Visit::Far => node = far,
                Visit::Near => node = near,
                Visit::Both => {
                    node = near;
                    t1 = ts;
                    t1_plane = node_plane(n);
                    push_down = false;
                }
                Visit::BothSame => {
                    node = near;
                    push_down = false;
                }
            }
            if push_down {
                restart_node = node;
            }
            continue;
        }
        if s.leaf(n, t1) || t1 >= t1_scene {
            return true;
        }
        t0 = restart_point(t1, t0_restart);
        t0_restart = t0;
        t1 = glsl_min(t1_scene, s.reach());
        node = restart_node;
        push_down = true;
        exit_plane = if t1_plane == ExitPlane::None { ExitPlane::Any } else { t1_plane };
        t1_plane = ExitPlane::None;
        s.c.restarts += 1;
    }
    false
}

/// Twin of `trace_short_stack` in glsl/traverse/short_stack.glsl: a ring buffer of
/// `size` entries; a push onto a full stack overwrites the oldest entry.
fn trace_short_stack(s: &mut State, mut t0: f32, t1_scene: f32, size: usize, use_push_down: bool) -> bool {
    let mut stack = [(0u32, 0f32, 0f32, ExitPlane::None); MAX_SHORT_STACK as usize];
    let mut head = 0usize; // next slot to write
    let mut count = 0usize;
    let mut node = 0u32;
    let mut t1 = t1_scene;
    let mut t0_restart = t0; // where the segment started at the last restart
    let mut exit_plane = ExitPlane::None; // the plane the last leaf was left through
    let mut t1_plane = ExitPlane::None; // the plane the current segment ends at
    let mut restart_node = 0u32;
    // The restart node's stack segment (exact restarts).
    let (mut restart_t0, mut restart_t1) = (t0, t1_scene);
    let mut push_down = use_push_down;
    // Exact restarts: entries pending below the short stack, and whether the ray
    // ever lay in a split plane (see trace_restart_exact).
    let (mut dropped, mut in_plane) = (0u32, false);
    while s.c.steps < MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, exit_plane);
            in_plane |= visit == Visit::BothSame;
            let mut push = |entry: (u32, f32, f32, ExitPlane), c: &mut Counters| {
                if count == size {
                    c.drops += 1;
                    dropped += 1;
                } else {
                    count += 1;
                }
                stack[head] = entry;
                head = (head + 1) % size;
            };
            match visit {
                Visit::Far => node = far,
                Visit::Near => node = near,
                Visit::Both => {
                    push((far, ts, t1, t1_plane), s.c);
                    node = near;
                    t1 = ts;
                    t1_plane = node_plane(n);
                    push_down = false;
                }
                Visit::BothSame => {
                    push((far, t0, t1, t1_plane), s.c);
                    node = near;
                    push_down = false;
                }
            }
            if push_down {
                (restart_node, restart_t0, restart_t1) = (node, t0, t1);
            }
            continue;
        }
        let done = s.leaf(n, t1);
        if done {
            if s.r.any_hit {
                return true;
            }
            // As in trace_stack: only entries starting before the hit can hold a closer one.
            while count > 0 && !starts_before(stack[(head + size - 1) % size].1, s.reach()) {
                head = (head + size - 1) % size;
                count -= 1;
            }
            if count == 0 && (!s.r.wr.robust || dropped == 0 || !in_plane) {
                return true;
            }
        }
        if count > 0 {
            head = (head + size - 1) % size;
            count -= 1;
            (node, t0, t1, t1_plane) = stack[head];
            continue;
        }
        if s.r.wr.robust {
            if dropped == 0 {
                return true;
            }
            match stack_successor(s, restart_node, restart_t0, restart_t1, node, dropped, done) {
                Successor::None => return true,
                Successor::Cut => return false,
                Successor::Found { node: next, t0: n0, t1: n1, above } => {
                    (node, t0, t1) = (next, n0, n1);
                    dropped = above;
                    push_down = use_push_down && above == 0;
                    if push_down {
                        (restart_node, restart_t0, restart_t1) = (node, t0, t1);
                    }
                }
            }
            s.c.restarts += 1;
            continue;
        }
        if t1 >= t1_scene {
            return true;
        }
        t0 = restart_point(t1, t0_restart);
        t0_restart = t0;
        t1 = glsl_min(t1_scene, s.reach());
        node = restart_node;
        push_down = use_push_down;
        exit_plane = if t1_plane == ExitPlane::None { ExitPlane::Any } else { t1_plane };
        t1_plane = ExitPlane::None;
        s.c.restarts += 1;
    }
    false
}

/// Exit distance of the ray from a node box: the nearest far plane, its face
/// (2·axis + 1 for the max face) and the next far plane (+inf when none). Axes
/// with a zero direction component never end the segment. Twin of `box_exit` in
/// common.glsl.
fn box_exit(r: &TraceRay, b: &[f32; 6]) -> (f32, usize, f32) {
    let mut t_exit = f32::INFINITY;
    let mut t_next = f32::INFINITY;
    let mut face = 0usize;
    let mut flat_face = false;
    for axis in 0..3 {
        if r.dir[axis] == 0.0 {
            continue;
        }
        if is_flat(r, axis) {
            flat_face = flat_face || flat_side(r, axis, b[axis]) == 0 || flat_side(r, axis, b[axis + 3]) == 0;
            continue;
        }
        let positive = r.dir[axis] > 0.0;
        let plane = if positive { b[3 + axis] } else { b[axis] };
        let t = plane_t(r, axis, plane);
        if t < t_exit {
            t_next = t_exit;
            t_exit = t;
            face = 2 * axis + positive as usize;
        } else if t < t_next {
            t_next = t;
        }
    }
    if flat_face {
        t_next = t_exit;
    }
    (t_exit, face, t_next)
}

/// The plane of face `face` of a box, as [`node_plane`] names split planes
/// (twin of `box_face_plane` in common.glsl).
fn box_face_plane(b: &[f32; 6], face: usize) -> ExitPlane {
    let axis = face / 2;
    ExitPlane::Plane(axis, b[axis + if face % 2 == 1 { 3 } else { 0 }].to_bits())
}

/// Twin of `near_t0` in common.glsl: `ts` within the widening of `t0`.
fn near_t0(r: &TraceRay, ts: f32, t0: f32) -> bool {
    (ts - t0).abs() <= T_EPS * glsl_min(glsl_max(ts.abs(), t0.abs()), f32::MAX) + r.t_err
}

/// Twin of `ambiguous_decision` in common.glsl: a ray inside the split plane, or
/// a plane within rounding of t0 that is not `crossed`.
fn ambiguous_decision(r: &TraceRay, visit: &Visit, n: KdNode, ts: f32, t0: f32, crossed: ExitPlane) -> bool {
    match visit {
        Visit::BothSame => true,
        Visit::Near => false,
        _ => near_t0(r, ts, t0) && node_plane(n) != crossed,
    }
}

/// Twin of `trace_backtrack` in glsl/traverse/backtrack.glsl.
fn trace_backtrack(s: &mut State, links: &TreeLinks, mut t0: f32, t1_scene: f32) -> bool {
    let t_scene0 = t0;
    let robust = s.r.wr.robust;
    let mut node = 0u32;
    let mut t1 = t1_scene;
    // No near child behind t0 on the first descent; after a hop, ties at t0 go far.
    let mut exit_plane = ExitPlane::Exact;
    let mut t1_plane = ExitPlane::None; // robust: the plane the segment ends at, when known
    let mut crossed = ExitPlane::None; // robust: the plane the last leaf was left through
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, exit_plane);
            if robust && ambiguous_decision(s.r, &visit, n, ts, t0, crossed) {
                return trace_restart_exact(s, t_scene0, t1_scene, true, t0);
            }
            match visit {
                Visit::Far => node = far,
                Visit::Both => {
                    node = near;
                    // A split clamped into the segment names no plane the segment ends at.
                    t1_plane = if ts == t0 || ts == t1 { ExitPlane::None } else { node_plane(n) };
                    t1 = ts;
                }
                Visit::Near | Visit::BothSame => node = near,
            }
            continue;
        }
        if s.leaf(n, t1) || t1 >= t1_scene {
            return true;
        }
        if robust {
            // Left near an edge or corner of the leaf's box: a second face within rounding.
            let (leaf_exit, _, t_next) = box_exit(s.r, &links.boxes[node as usize]);
            if near_t0(s.r, t_next, leaf_exit) {
                return trace_restart_exact(s, t_scene0, t1_scene, true, t1);
            }
        }
        // Climb to the first ancestor the ray leaves after t1.
        t0 = t1;
        crossed = t1_plane;
        let mut exit = t0;
        let mut face = 0;
        let mut depth = 0;
        let mut ambiguous = false;
        while exit <= t0 && node != 0 && depth < MAX_STACK {
            node = links.parents[node as usize];
            s.c.nodes += 1;
            let b = &links.boxes[node as usize];
            (exit, face, _) = box_exit(s.r, b);
            if robust && near_t0(s.r, exit, t0) && box_face_plane(b, face) != crossed {
                ambiguous = true;
            }
            depth += 1;
        }
        if exit <= t0 && node != 0 && depth < MAX_STACK {
            return false; // climb cut short
        }
        if ambiguous {
            return trace_restart_exact(s, t_scene0, t1_scene, true, t0);
        }
        if exit <= t0 {
            return true; // the root's box ends here: nothing left
        }
        t1 = glsl_min(glsl_min(exit, t1_scene), s.reach());
        t1_plane = if t1 == exit { box_face_plane(&links.boxes[node as usize], face) } else { ExitPlane::None };
        exit_plane = ExitPlane::Any;
        s.c.restarts += 1;
    }
    false
}

/// Twin of `trace_ropes` in glsl/traverse/ropes.glsl.
fn trace_ropes(s: &mut State, links: &TreeLinks, mut t0: f32, t1_scene: f32) -> bool {
    let t_scene0 = t0;
    let robust = s.r.wr.robust;
    let mut node = 0u32;
    let mut t1 = t1_scene;
    // No near child behind t0 on the first descent; after a hop, ties at t0 go far.
    let mut exit_plane = ExitPlane::Exact;
    let mut crossed = ExitPlane::None; // robust: the face the last leaf was left through
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, exit_plane);
            if robust && ambiguous_decision(s.r, &visit, n, ts, t0, crossed) {
                return trace_restart_exact(s, t_scene0, t1_scene, true, t0);
            }
            match visit {
                Visit::Far => node = far,
                Visit::Both => {
                    node = near;
                    t1 = ts;
                }
                Visit::Near | Visit::BothSame => node = near,
            }
            continue;
        }
        // The leaf's own exit, from its box: ropes leave the ancestors' planes behind.
        let b = &links.boxes[node as usize];
        let (exit, face, t_next) = box_exit(s.r, b);
        let leaf_t1 = glsl_min(glsl_min(exit, t1_scene), t1);
        if s.leaf(n, leaf_t1) || leaf_t1 >= t1_scene {
            return true;
        }
        if robust && (leaf_t1 != exit || near_t0(s.r, t_next, exit) || near_t0(s.r, exit, t0)) {
            // Left near an edge or corner of the leaf (or a sliver of it).
            return trace_restart_exact(s, t_scene0, t1_scene, true, glsl_max(t0, leaf_t1));
        }
        let next = links.ropes[node as usize][face];
        if next == NO_ROPE {
            return true;
        }
        crossed = box_face_plane(b, face);
        // Never step backwards: keep t0 when rounding puts the exit behind it.
        t0 = glsl_max(t0, leaf_t1);
        t1 = glsl_min(t1_scene, s.reach());
        node = next;
        exit_plane = ExitPlane::Any;
        s.c.restarts += 1;
    }
    false
}
