//! Node boxes for the stackless walks (`backtrack`, `ropes`): where the ray leaves
//! a box, the plane of a face, and the checks that send a robust walk to its
//! exact fallback. Twin of `glsl/traverse/boxes.glsl`.

use super::decide::{node_plane, ExitPlane, Visit, T_EPS};
use super::segment::{flat_side, glsl_max, glsl_min, is_flat, plane_t, TraceRay};
use crate::kdtree::KdNode;

/// Exit distance of the ray from a node box: the nearest far plane, its face
/// (2·axis + 1 for the max face) and the next far plane (+inf when none). Axes
/// with a zero direction component never end the segment. Twin of `box_exit` in
/// boxes.glsl.
pub(super) fn box_exit(r: &TraceRay, b: &[f32; 6]) -> (f32, usize, f32) {
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
/// (twin of `box_face_plane` in boxes.glsl).
pub(super) fn box_face_plane(b: &[f32; 6], face: usize) -> ExitPlane {
    let axis = face / 2;
    ExitPlane::Plane(axis, b[axis + if face % 2 == 1 { 3 } else { 0 }].to_bits())
}

/// Twin of `near_t0` in boxes.glsl: `ts` within the widening of `t0`.
pub(super) fn near_t0(r: &TraceRay, ts: f32, t0: f32) -> bool {
    (ts - t0).abs() <= T_EPS * glsl_min(glsl_max(ts.abs(), t0.abs()), f32::MAX) + r.t_err
}

/// Twin of `ambiguous_decision` in boxes.glsl: a ray inside the split plane, or
/// a plane within rounding of t0 that is not `crossed`.
pub(super) fn ambiguous_decision(r: &TraceRay, visit: &Visit, n: KdNode, ts: f32, t0: f32, crossed: ExitPlane) -> bool {
    match visit {
        Visit::BothSame => true,
        Visit::Near => false,
        _ => near_t0(r, ts, t0) && node_plane(n) != crossed,
    }
}
