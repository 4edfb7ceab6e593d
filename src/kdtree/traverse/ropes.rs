//! `ropes`: stackless traversal along leaf ropes. Twin of
//! `glsl/traverse/ropes.glsl`.

use super::boxes::{ambiguous_decision, box_exit, box_face_plane, near_t0};
use super::decide::{decide_children, ExitPlane, Visit};
use super::restart::trace_restart_exact;
use super::segment::{glsl_max, glsl_min};
use super::State;
use crate::consts::{MAX_TRAVERSAL_STEPS, PRIM_MISS};
use crate::kdtree::links::{TreeLinks, NO_ROPE};

/// Twin of `trace_ropes` in glsl/traverse/ropes.glsl.
pub(super) fn trace_ropes(s: &mut State, links: &TreeLinks, mut t0: f32, t1_scene: f32) -> bool {
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
        if s.leaf(n, leaf_t1) {
            return true;
        }
        if leaf_t1 >= t1_scene {
            // Robust, before the first hit, on a segment that ends at tmax (not at
            // the scene's box; then best.hit.t is tmax's bound): a segment that
            // ends within rounding of a face with a leaf across it may end exactly
            // on a triangle of that leaf lying in the face's plane.
            let ends_at_box = t1_scene < s.best.hit.t;
            let at_tmax = robust && s.best.hit.prim_id == PRIM_MISS && !ends_at_box;
            if at_tmax && near_t0(s.r, exit, t1_scene) && links.ropes[node as usize][face] != NO_ROPE {
                return trace_restart_exact(s, t_scene0, t1_scene, true, glsl_max(t0, leaf_t1));
            }
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
