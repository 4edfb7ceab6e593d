//! The child decision at an interior node ([`decide_children`]), the planes a
//! segment may end at, and the restart point and state of the t-value restarts.
//! Twin of `glsl/traverse/decide.glsl`.

use super::segment::{flat_side, glsl_max, glsl_min, is_flat, plane_t, TraceRay};
use crate::kdtree::KdNode;

/// Relative widening of the split decisions (`T_EPS` in decide.glsl).
pub(super) const T_EPS: f32 = 1.0 / (1u32 << crate::consts::TRAVERSAL_EPS_LOG2) as f32;

/// Twin of `restart_point` in decide.glsl: the start of the segment after a
/// restart, the last leaf's exit or, when rounding put it at or before the
/// previous restart point, the next float after that point (progress).
pub(super) fn restart_point(t_exit: f32, t_prev: f32) -> f32 {
    if t_exit > t_prev {
        return t_exit;
    }
    if t_prev == 0.0 {
        return f32::MIN_POSITIVE;
    }
    let bits = t_prev.to_bits();
    f32::from_bits(if t_prev > 0.0 { bits + 1 } else { bits - 1 })
}

#[derive(PartialEq, Eq)]
pub(super) enum Visit {
    Near,
    Far,
    Both,
    /// The ray lies in the split plane: both children with the same interval.
    BothSame,
}

/// The plane a segment ended at, for the tie rule of [`decide_children`] (the
/// `uvec2` planes of decide.glsl): none (first descent, stacks: widened rule
/// only), any (after a restart whose plane is unknown, and the packet kernels:
/// every tie at t0 goes far), exact (the first descent of backtrack and ropes:
/// no near child behind t0), or (axis, split bits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum ExitPlane {
    None,
    Any,
    Exact,
    Plane(usize, u32),
}

/// The split plane of an interior node.
pub(super) fn node_plane(n: KdNode) -> ExitPlane {
    ExitPlane::Plane(n.axis(), n.split().to_bits())
}

/// Twin of `restart_after_leaf` in decide.glsl: restart behind the leaf just left
/// (`restart`, `push-down`, the short stacks). The segment [`t0`, `t1`] becomes
/// [restart point, the nearer of the scene exit and `reach`], and ties at its
/// start follow the plane the leaf was left through (any plane when that one is
/// not known). The restart state is each variant's own three variables:
/// `t0_restart` (where the segment started at the last restart), `exit_plane`
/// (the tie rule's) and `t1_plane` (where the current segment ends). The caller
/// sets the node to descend from and counts the restart.
pub(super) fn restart_after_leaf(
    t1_scene: f32,
    reach: f32,
    t0: &mut f32,
    t1: &mut f32,
    t0_restart: &mut f32,
    exit_plane: &mut ExitPlane,
    t1_plane: &mut ExitPlane,
) {
    *t0 = restart_point(*t1, *t0_restart);
    *t0_restart = *t0;
    *t1 = glsl_min(t1_scene, reach);
    *exit_plane = if *t1_plane == ExitPlane::None { ExitPlane::Any } else { *t1_plane };
    *t1_plane = ExitPlane::None;
}

/// Twin of `decide_children` in decide.glsl: (visit, near, far, t_split).
pub(super) fn decide_children(
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
    // Conservative (see decide.glsl): one child only beyond rounding; after a
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
        // A flat axis: by position (see decide.glsl).
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
        // Both, with ts kept inside the segment (see decide.glsl).
        (Visit::Both, glsl_min(glsl_max(ts, t0), t1))
    };
    (visit, near, far, ts)
}
