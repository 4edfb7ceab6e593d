//! `backtrack`: kd-backtrack. Twin of `glsl/traverse/backtrack.glsl`.

use super::boxes::{ambiguous_decision, box_exit, box_face_plane, near_t0};
use super::decide::{decide_children, node_plane, ExitPlane, Visit};
use super::restart::trace_restart_exact;
use super::segment::glsl_min;
use super::State;
use crate::consts::{MAX_STACK, MAX_TRAVERSAL_STEPS, PRIM_MISS};
use crate::kdtree::links::TreeLinks;

/// Twin of `trace_backtrack` in glsl/traverse/backtrack.glsl.
pub(super) fn trace_backtrack(s: &mut State, links: &TreeLinks, mut t0: f32, t1_scene: f32) -> bool {
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
        if s.leaf(n, t1) {
            return true;
        }
        if t1 >= t1_scene {
            // Robust, before the first hit, on a segment that ends at tmax (not at
            // the scene's box; then best.hit.t is tmax's bound): a segment that
            // ends within rounding of a face of the leaf's box with a leaf across it
            // may end exactly on a triangle of that leaf in the face's plane.
            if !robust || s.best.hit.prim_id != PRIM_MISS || t1_scene < s.best.hit.t {
                return true;
            }
            let (leaf_exit, face, _) = box_exit(s.r, &links.boxes[node as usize]);
            let inner = box_face_plane(&links.boxes[node as usize], face) != box_face_plane(&links.boxes[0], face);
            if near_t0(s.r, leaf_exit, t1_scene) && inner {
                return trace_restart_exact(s, t_scene0, t1_scene, true, t1);
            }
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
