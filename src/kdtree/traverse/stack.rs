//! `stack`: front-to-back traversal with a full stack. Twin of
//! `glsl/traverse/stack.glsl`.

use super::decide::{decide_children, ExitPlane, Visit};
use super::State;
use crate::consts::{MAX_STACK, MAX_TRAVERSAL_STEPS};

/// Twin of `trace_stack` in glsl/traverse/stack.glsl: children that the parent's
/// flags mark as empty leaves are neither pushed nor fetched, and the first entry
/// or leaf that starts at or behind the closest hit's reach ends the ray (robust:
/// once there is a hit: `State::starts_behind`; entries
/// lie front to back), unless the ray lies in a split plane: then only that entry
/// or leaf is skipped, its node still fetched (as the kernel's careful pass does;
/// its fast pass lists such rays).
pub(super) fn trace_stack(s: &mut State, mut t0: f32, mut t1: f32) -> bool {
    let mut stack = [(0u32, 0f32, 0f32); MAX_STACK as usize];
    let mut sp = 0usize;
    let mut node = 0u32;
    let mut in_plane = false;
    let mut dropped = false;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if dropped {
            // DROPPED_ENTRY in stack.glsl: fetched, then popped at once.
        } else if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
            let (near_empty, far_empty) =
                if near == node + 1 { (n.below_empty(), n.above_empty()) } else { (n.above_empty(), n.below_empty()) };
            let (near_t1, far_t0) = if visit == Visit::Both { (ts, ts) } else { (t1, t0) };
            let both = matches!(visit, Visit::Both | Visit::BothSame);
            let pop = if both && !near_empty && !far_empty {
                stack[sp] = (far, far_t0, t1);
                sp += 1;
                in_plane |= visit == Visit::BothSame;
                node = near;
                t1 = near_t1;
                false
            } else if visit == Visit::Near || (both && far_empty) {
                node = near;
                t1 = near_t1;
                near_empty
            } else {
                node = far;
                t0 = far_t0;
                far_empty
            };
            if !pop {
                continue;
            }
        } else {
            let behind = s.starts_behind(t0);
            if behind && !in_plane {
                return true;
            }
            if !behind && s.leaf(n, t1) && s.r.any_hit {
                return true;
            }
        }
        if sp == 0 {
            return true;
        }
        sp -= 1;
        (node, t0, t1) = stack[sp];
        dropped = s.starts_behind(t0);
        if dropped && !in_plane {
            return true;
        }
    }
    false
}
