//! `push-down`: kd-restart from the push-down node. Twin of
//! `glsl/traverse/push_down.glsl`.

use super::decide::{decide_children, node_plane, restart_after_leaf, ExitPlane, Visit};
use super::restart::trace_restart_exact;
use super::State;
use crate::consts::MAX_TRAVERSAL_STEPS;

/// Twin of `trace_push_down` in glsl/traverse/push_down.glsl.
pub(super) fn trace_push_down(s: &mut State, mut t0: f32, t1_scene: f32) -> bool {
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
        restart_after_leaf(t1_scene, s.reach(), &mut t0, &mut t1, &mut t0_restart, &mut exit_plane, &mut t1_plane);
        node = restart_node;
        push_down = true;
        s.c.restarts += 1;
    }
    false
}
