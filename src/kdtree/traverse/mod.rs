//! CPU twins of the GPU traversal variants in `glsl/traverse/`: the same
//! decoding, decisions, order and counters, in the same f32 arithmetic, so a
//! test can compare hits and counters per ray. File for file: each module here
//! twins the GLSL piece of the same name (`segment`, `node`, `decide`, `seek`,
//! `leaf`, `boxes`) or variant (`stack`, `restart`, `push_down`, `short_stack`,
//! `backtrack`, `ropes`), and this file twins `trace.comp` (`trace_ray`,
//! `is_far`, `shift_to_scene`). Change both together.

mod backtrack;
mod boxes;
mod decide;
mod leaf;
mod node;
mod packet;
mod push_down;
mod restart;
mod ropes;
mod seek;
mod segment;
mod short_stack;
mod stack;

use glam::Vec3;

use super::links::TreeLinks;
use super::KdNode;
use crate::consts::{MAX_SHORT_STACK, PRIM_INCOMPLETE, PRIM_INVALID, PRIM_MISS};
use crate::ff::{exact_sum8, two_prod, Ff};
use crate::geom::{exponent_of, ff_ldexp, ldexp2, Aabb, Hit, Ray, WatertightRay};
use decide::T_EPS;
use leaf::Closest;
use segment::{clip_to_box, glsl_max, TraceRay};

pub use crate::traversal::{Traversal, Variant};
pub use node::Counters;
pub(crate) use segment::{widen_near, TFAR_SCALE};

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

/// Traces one ray: the CPU twin of `trace.comp`'s `trace_ray`. `traversal` may be a
/// plain [`Variant`] (closest hit, short stack of 3).
///
/// # Panics
/// When `Backtrack` or `Ropes` is asked for on a `SceneRef` without links.
pub fn trace_ray(scene: &SceneRef, ray: &Ray, traversal: impl Into<Traversal>) -> (Hit, Counters) {
    trace_ray_inner(scene, ray, traversal.into(), None)
}

/// [`trace_ray`] with the ray's control flow and node fetches appended to `log`
/// ([`FlowLog`]), for `kdtrace divergence`. Every single-ray variant logs.
pub fn trace_ray_logged(
    scene: &SceneRef,
    ray: &Ray,
    traversal: impl Into<Traversal>,
    log: &mut FlowLog,
) -> (Hit, Counters) {
    trace_ray_inner(scene, ray, traversal.into(), Some(log))
}

/// Traces one packet, the rays of consecutive lanes, as the GPU's packet kernel
/// of `traversal` does (`glsl/traverse/packet_stack.glsl` for `Stack`,
/// `packet_short_stack.glsl` for `Restart`, `PushDown` and the short stacks):
/// decisions by ballot over the packet. With `logs` (one per ray) each lane's
/// control flow is appended as in [`trace_ray_logged`]. Hits and counters equal
/// the GPU's bit for bit (tests/packets.rs). `None` for `Backtrack` and `Ropes`,
/// which have no packet kernel.
pub fn trace_packet_logged(
    scene: &SceneRef,
    rays: &[Ray],
    traversal: Traversal,
    logs: Option<&mut [FlowLog]>,
) -> Option<Vec<(Hit, Counters)>> {
    let size = match traversal.variant {
        Variant::Stack => None,
        Variant::Restart | Variant::PushDown => Some(0),
        Variant::ShortStack | Variant::PushDownShortStack => {
            Some(traversal.stack_size.clamp(1, MAX_SHORT_STACK) as usize)
        }
        Variant::Backtrack | Variant::Ropes => return None,
    };
    let setups: Vec<RaySetup> = rays.iter().map(|ray| setup_ray(scene, ray, traversal)).collect();
    let mut logs: Vec<Option<&mut FlowLog>> = match logs {
        Some(l) => l.iter_mut().map(Some).collect(),
        None => rays.iter().map(|_| None).collect(),
    };
    let mut lanes: Vec<packet::Lane> = setups
        .iter()
        .zip(logs.iter_mut())
        .map(|(s, log)| {
            let (t0, t1) = s.clipped.unwrap_or((0.0, 0.0));
            packet::Lane {
                r: s.r.clone(),
                alive: s.clipped.is_some(),
                t0,
                t1,
                best: Closest::none(s.best.t),
                c: Counters::default(),
                log: log.take(),
            }
        })
        .collect();
    let alive: Vec<bool> = lanes.iter().map(|l| l.alive).collect();
    let finished = match size {
        None => vec![packet::trace_packet_stack(scene, &mut lanes); rays.len()],
        Some(size) => {
            let push_down = matches!(traversal.variant, Variant::PushDown | Variant::PushDownShortStack);
            packet::trace_packet_short_stack(scene, &mut lanes, size, push_down, traversal.robust)
        }
    };
    Some(
        lanes
            .into_iter()
            .zip(&setups)
            .zip(alive.into_iter().zip(finished))
            .map(|((mut lane, setup), (alive, finished))| {
                if let Some(log) = lane.log.as_mut() {
                    log.finish();
                }
                let best = if alive { lane.best.hit } else { setup.best };
                (finish_hit(&lane.r, best, finished), lane.c)
            })
            .collect(),
    )
}

/// A ray's control flow as the kernel's loops run it, for `kdtrace divergence`
/// (src/divergence.rs).
#[derive(Clone, Debug, Default)]
pub struct FlowLog {
    /// Per leaf visit that tested triangles: `[loop steps since the previous
    /// such visit (interior nodes, empty or skipped leaves), triangles tested]`;
    /// a last `[steps, 0]` for the steps after it. For a packet lane, one entry
    /// per leaf step of its packet in which any lane tested triangles (0 for
    /// this lane when it sat that leaf out), steps counted per packet step.
    pub rounds: Vec<[u32; 2]>,
    /// The node index of every fetch in order, with [`FlowLog::TESTED`] set on a
    /// leaf whose triangles this ray tested.
    pub fetches: Vec<u32>,
    /// Steps since the last entry of `rounds`.
    pending: u32,
}

impl FlowLog {
    /// The flag on a fetch whose leaf triangles were tested.
    pub const TESTED: u32 = 1 << 31;

    fn fetched(&mut self, node: u32) {
        self.pending += 1;
        self.fetches.push(node);
    }

    /// The last fetch was a leaf that tested `tris` triangles (0: it counts as a step).
    fn tested(&mut self, tris: u32) {
        if tris > 0 {
            self.rounds.push([self.pending - 1, tris]);
            self.pending = 0;
            if let Some(last) = self.fetches.last_mut() {
                *last |= Self::TESTED;
            }
        }
    }

    /// A packet leaf step that some lane's tests made a round: every lane closes one.
    fn packet_round(&mut self, tris: u32) {
        self.rounds.push([self.pending - 1, tris]);
        self.pending = 0;
        if let (1.., Some(last)) = (tris, self.fetches.last_mut()) {
            *last |= Self::TESTED;
        }
    }

    fn finish(&mut self) {
        if self.pending > 0 {
            self.rounds.push([self.pending, 0]);
            self.pending = 0;
        }
    }
}

/// A ray set up for traversal as trace.comp's `trace_ray` does it: the ray in
/// its segment frame, the clip of its segment (None: it misses the scene box)
/// and the closest hit so far (`t` in the segment frame).
struct RaySetup {
    r: TraceRay,
    clipped: Option<(f32, f32)>,
    best: Hit,
}

fn setup_ray(scene: &SceneRef, ray: &Ray, traversal: Traversal) -> RaySetup {
    let mut best = Hit { t: ray.tmax, prim_id: PRIM_MISS, u: 0.0, v: 0.0 };
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
    if !ray.is_valid() {
        best.prim_id = PRIM_INVALID;
        return RaySetup { r, clipped: None, best };
    }
    let mut clipped = clip_to_box(&r, &scene.bounds);
    if let (true, Some((t0, t1))) = (traversal.robust, clipped) {
        if is_far(&r, &scene.bounds, t0) {
            clipped = shift_to_scene(&mut r, &scene.bounds, t1);
            best.t = ray.tmax - r.wr.t_shift; // the segment frame, like every hit below
        }
    }
    // A closed segment (see trace.comp): one float more, when robust.
    if let (true, Some((t0, t1))) = (traversal.robust, clipped) {
        clipped = Some((t0, next_up(t1)));
        best.t = next_up(best.t);
    }
    RaySetup { r, clipped, best }
}

/// The hit as the kernel writes it: back in the ray's own parameter, cut-short
/// traversals marked, no `t`, `u`, `v` without a hit.
fn finish_hit(r: &TraceRay, mut best: Hit, finished: bool) -> Hit {
    if !finished && best.prim_id != PRIM_INVALID {
        best.prim_id = PRIM_INCOMPLETE;
    }
    // Back to the ray's own parameter (one rounding: an f32 sum is correctly rounded).
    if r.wr.t_shift != 0.0 {
        best.t += r.wr.t_shift;
    }
    if best.prim_id >= PRIM_INCOMPLETE {
        best.t = if best.prim_id == PRIM_MISS { f32::INFINITY } else { f32::NAN };
        best.u = 0.0;
        best.v = 0.0;
    }
    best
}

fn trace_ray_inner(
    scene: &SceneRef,
    ray: &Ray,
    traversal: Traversal,
    mut log: Option<&mut FlowLog>,
) -> (Hit, Counters) {
    let RaySetup { r, clipped, mut best } = setup_ray(scene, ray, traversal);
    let mut c = Counters::default();
    let mut finished = true;
    if let Some((t0, t1)) = clipped {
        let mut s = State { scene, r: &r, best: Closest::none(best.t), c: &mut c, log: log.as_deref_mut() };
        let links = || scene.links.expect("Backtrack and Ropes need SceneRef::with_links");
        let size = traversal.stack_size.clamp(1, MAX_SHORT_STACK) as usize;
        finished = match traversal.variant {
            Variant::Stack => stack::trace_stack(&mut s, t0, t1),
            Variant::Restart => restart::trace_restart(&mut s, t0, t1),
            Variant::PushDown => push_down::trace_push_down(&mut s, t0, t1),
            Variant::ShortStack => short_stack::trace_short_stack(&mut s, t0, t1, size, false),
            Variant::PushDownShortStack => short_stack::trace_short_stack(&mut s, t0, t1, size, true),
            Variant::Backtrack => backtrack::trace_backtrack(&mut s, links(), t0, t1),
            Variant::Ropes => ropes::trace_ropes(&mut s, links(), t0, t1),
        };
        best = s.best.hit;
    }
    if let Some(log) = log {
        log.finish();
    }
    (finish_hit(&r, best, finished), c)
}

/// What every variant carries: the scene, the ray, the closest hit (`Closest`,
/// passed `inout` in the GLSL) and the counters.
struct State<'s, 'a> {
    scene: &'s SceneRef<'a>,
    r: &'s TraceRay,
    best: Closest,
    c: &'s mut Counters,
    /// The control flow, when asked ([`trace_ray_logged`]).
    log: Option<&'s mut FlowLog>,
}

/// Twin of `next_up` in trace.comp: the next float above `x` (`f32::MIN_POSITIVE`
/// above a zero; infinities and NaN unchanged).
fn next_up(x: f32) -> f32 {
    if x.is_infinite() || x.is_nan() {
        x
    } else if x == 0.0 {
        f32::MIN_POSITIVE
    } else {
        f32::from_bits(if x > 0.0 { x.to_bits() + 1 } else { x.to_bits() - 1 })
    }
}

/// Twin of `is_far` in ray_setup.glsl: the box entry `t0` lies more than
/// [`SHIFT_DIAGONALS`](crate::consts::SHIFT_DIAGONALS) scene diagonals along the ray.
/// Lengths scaled by a power of two (the box's largest extent to `[1, 2)`), so
/// that the squares neither overflow nor underflow (see trace.comp).
fn is_far(r: &TraceRay, b: &Aabb, t0: f32) -> bool {
    let ext = b.max - b.min;
    let s = exponent_of(glsl_max(ext.x, glsl_max(ext.y, ext.z)));
    let e = Vec3::new(ldexp2(ext.x, -s), ldexp2(ext.y, -s), ldexp2(ext.z, -s));
    let diag2 = e.x * e.x + e.y * e.y + e.z * e.z;
    let dist = ldexp2(t0 * glsl_max(r.dir.x.abs(), glsl_max(r.dir.y.abs(), r.dir.z.abs())), -s);
    let far2 = (crate::consts::SHIFT_DIAGONALS * crate::consts::SHIFT_DIAGONALS) as f32 * diag2;
    t0 > 0.0 && dist * dist > far2
}

/// Twin of `shift_to_scene` in trace.comp: a far ray ([`is_far`]) is traversed
/// from its point at `t_shift`, just before the box on its dominant axis,
/// summed exactly and rounded once (see trace.comp), with the
/// bound `t_err` and its flat axes; returns the clip there (None: it misses
/// after all). `t1`: the clip's end in the ray's own frame.
fn shift_to_scene(r: &mut TraceRay, b: &Aabb, t1: f32) -> Option<(f32, f32)> {
    let k = r.wr.kz;
    let (o, d) = (r.wr.origin, r.dir);
    // A plane a little before the near face (see trace.comp).
    let margin = (b.max[k] - b.min[k]) * (1.0 / 128.0)
        + b.min[k].abs() * 2f32.powi(-20)
        + b.max[k].abs() * 2f32.powi(-20)
        + f32::MIN_POSITIVE;
    let c = if d[k] > 0.0 { b.min[k] - margin } else { b.max[k] + margin };
    // Scaled inputs: d[k] in [1, 2), the origin and c below 2^100.
    let eq = exponent_of(d[k].abs());
    let om = glsl_max(glsl_max(o.x.abs(), o.y.abs()), glsl_max(o.z.abs(), c.abs()));
    let eo = (exponent_of(om) - 99).max(0);
    let ds = [0, 1, 2].map(|i| ldexp2(d[i], -eq));
    let os = [0, 1, 2].map(|i| ldexp2(o[i], -eo));
    let cs = ldexp2(c, -eo);
    // The frame's origin: o + t_shift·d summed exactly, rounded once (see trace.comp).
    let t_shift = ldexp2(Ff::diff(cs, os[k]).div(Ff::from_f32(ds[k])).hi, eo - eq);
    let ts = ldexp2(t_shift, eq - eo);
    let (mut hi, mut lo, mut a) = (Vec3::ZERO, Vec3::ZERO, Vec3::ZERO);
    for j in 0..3 {
        let step = two_prod(ts, ds[j]);
        let p = ff_ldexp(exact_sum8([os[j], step.hi, step.lo, 0.0, 0.0, 0.0, 0.0, 0.0]), eo);
        (hi[j], lo[j]) = (p.hi, p.lo);
        a[j] = (p.hi.abs() * 2f32.powi(-45)) + ldexp2(1.0, eo - 120);
    }
    // Flat axes: see trace.comp.
    let s_max = (t1 - t_shift) + t1.abs() * 2f32.powi(-20);
    let mut e = 0.0f32;
    for axis in 0..3 {
        if r.dir[axis] == 0.0 {
            continue;
        }
        if a[axis] > T_EPS * s_max * d[axis].abs() {
            r.flat_axes |= 1 << axis;
            r.band[axis] = (a[axis] + d[axis].abs() * s_max) * 1.000001;
        } else {
            e = glsl_max(e, a[axis] * (1.0 / d[axis].abs()));
        }
    }
    r.t_err = glsl_max(e * 1.000001, f32::MIN_POSITIVE);
    r.wr.seg_origin = hi;
    r.wr.seg_lo = lo;
    r.wr.seg_err = lo.abs() + a * 1_048_576.0;
    r.wr.t_shift = t_shift;
    r.wr.seg_tmax = r.tmax - t_shift;
    clip_to_box(r, b)
}
