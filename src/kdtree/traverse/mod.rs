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
use crate::geom::{Aabb, Hit, Ray, WatertightRay};
use decide::T_EPS;
use leaf::Closest;
use segment::{clip_to_box, glsl_max, TraceRay};

pub use crate::traversal::{Traversal, Variant};
pub use node::Counters;

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
            let mut s = State { scene, r: &r, best: Closest::none(best.t), c: &mut c };
            let links = || scene.links.expect("Backtrack and Ropes need SceneRef::with_links");
            let size = traversal.stack_size.clamp(1, MAX_SHORT_STACK) as usize;
            let finished = match traversal.variant {
                Variant::Stack => stack::trace_stack(&mut s, t0, t1),
                Variant::Restart => restart::trace_restart(&mut s, t0, t1),
                Variant::PushDown => push_down::trace_push_down(&mut s, t0, t1),
                Variant::ShortStack => short_stack::trace_short_stack(&mut s, t0, t1, size, false),
                Variant::PushDownShortStack => short_stack::trace_short_stack(&mut s, t0, t1, size, true),
                Variant::Backtrack => backtrack::trace_backtrack(&mut s, links(), t0, t1),
                Variant::Ropes => ropes::trace_ropes(&mut s, links(), t0, t1),
            };
            best = s.best.hit;
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

/// What every variant carries: the scene, the ray, the closest hit (`Closest`,
/// passed `inout` in the GLSL) and the counters.
struct State<'s, 'a> {
    scene: &'s SceneRef<'a>,
    r: &'s TraceRay,
    best: Closest,
    c: &'s mut Counters,
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
