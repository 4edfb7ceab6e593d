//! `short-stack` and `push-down-short-stack`. Twin of
//! `glsl/traverse/short_stack.glsl`.

use super::decide::{decide_children, node_plane, restart_after_leaf, ExitPlane, Visit};
use super::leaf::starts_before;
use super::node::Counters;
use super::seek::{stack_successor, Successor};
use super::State;
use crate::consts::{MAX_SHORT_STACK, MAX_TRAVERSAL_STEPS};

/// Twin of `trace_short_stack` in glsl/traverse/short_stack.glsl: a ring buffer of
/// `size` entries; a push onto a full stack overwrites the oldest entry.
pub(super) fn trace_short_stack(s: &mut State, mut t0: f32, t1_scene: f32, size: usize, use_push_down: bool) -> bool {
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
        restart_after_leaf(t1_scene, s.reach(), &mut t0, &mut t1, &mut t0_restart, &mut exit_plane, &mut t1_plane);
        node = restart_node;
        push_down = use_push_down;
        s.c.restarts += 1;
    }
    false
}
