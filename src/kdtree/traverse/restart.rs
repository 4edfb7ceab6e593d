//! `restart` (kd-restart) and the exact restarts of the robust variants. Twin of
//! `glsl/traverse/restart.glsl`.

use super::decide::{decide_children, node_plane, restart_after_leaf, ExitPlane, Visit, T_EPS};
use super::seek::{stack_successor, Successor};
use super::State;
use crate::consts::MAX_TRAVERSAL_STEPS;

/// Twin of `trace_restart_exact` in glsl/traverse/restart.glsl: `restart` and
/// `push-down` with exact restarts (robust mode), visiting what `trace_stack` visits.
/// `t_from`: leaves whose segment ends before it (less the widening) are done
/// already (the fallback of robust backtrack and ropes); `-f32::MAX` for none.
pub(super) fn trace_restart_exact(s: &mut State, mut t0: f32, mut t1: f32, use_push_down: bool, t_from: f32) -> bool {
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
pub(super) fn trace_restart(s: &mut State, mut t0: f32, t1_scene: f32) -> bool {
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
        restart_after_leaf(t1_scene, s.reach(), &mut t0, &mut t1, &mut t0_restart, &mut exit_plane, &mut t1_plane);
        node = 0;
        s.c.restarts += 1;
    }
    false
}
