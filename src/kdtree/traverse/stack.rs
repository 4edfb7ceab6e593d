//! `stack`: front-to-back traversal with a full stack. Twin of
//! `glsl/traverse/stack.glsl`.

use super::decide::{decide_children, ExitPlane, Visit};
use super::leaf::starts_before;
use super::State;
use crate::consts::{MAX_STACK, MAX_TRAVERSAL_STEPS};

/// Twin of `trace_stack` in glsl/traverse/stack.glsl.
pub(super) fn trace_stack(s: &mut State, mut t0: f32, mut t1: f32) -> bool {
    let mut stack = [(0u32, 0f32, 0f32); MAX_STACK as usize];
    let mut sp = 0usize;
    let mut node = 0u32;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = s.fetch(node);
        if !n.is_leaf() {
            let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
            match visit {
                Visit::Near => node = near,
                Visit::Far => node = far,
                Visit::BothSame => {
                    stack[sp] = (far, t0, t1);
                    sp += 1;
                    node = near;
                }
                Visit::Both => {
                    stack[sp] = (far, ts, t1);
                    sp += 1;
                    node = near;
                    t1 = ts;
                }
            }
            continue;
        }
        if s.leaf(n, t1) {
            if s.r.any_hit {
                return true;
            }
            // Only entries starting before the hit can hold a closer one (stack.glsl).
            while sp > 0 && !starts_before(stack[sp - 1].1, s.reach()) {
                sp -= 1;
            }
        }
        if sp == 0 {
            return true;
        }
        sp -= 1;
        (node, t0, t1) = stack[sp];
    }
    false
}
