//! The exact restart's seek: the entry a full stack would pop after a leaf. Twin
//! of `glsl/traverse/seek.glsl`.

use super::decide::{decide_children, ExitPlane, Visit};
use super::leaf::starts_before;
use super::State;
use crate::consts::MAX_TRAVERSAL_STEPS;

/// What [`stack_successor`] found: the entry a full stack pops next, none (the
/// traversal is over), or the step limit.
pub(super) enum Successor {
    None,
    /// `above`: the entries still pending above the one found.
    Found {
        node: u32,
        t0: f32,
        t1: f32,
        above: u32,
    },
    Cut,
}

/// Twin of the seek of seek.glsl (`Seek`, `seek_step`), which the shaders run
/// inside their descent loop and this twin as a loop of its own (the same nodes in
/// the same order): the entry a full stack would pop after `leaf`, found by
/// descending again from `start` (segment `[s0, s1]`) along the path to the leaf
/// with the stack's decisions, stopping at the last of the `known` entries
/// pending on that path.
pub(super) fn stack_successor(
    s: &mut State,
    start: u32,
    s0: f32,
    s1: f32,
    leaf: u32,
    known: u32,
    done: bool,
) -> Successor {
    let (mut node, mut t0, mut t1) = (start, s0, s1);
    let mut pending = 0u32;
    let mut found = Successor::None;
    while node != leaf && pending < known {
        if s.c.steps >= MAX_TRAVERSAL_STEPS {
            return Successor::Cut;
        }
        let n = s.fetch(node);
        let (visit, near, far, ts) = decide_children(s.r, node, n, t0, t1, ExitPlane::None);
        let child = if leaf >= n.above_child() { n.above_child() } else { node + 1 };
        if matches!(visit, Visit::Both | Visit::BothSame) {
            let far_t0 = if visit == Visit::Both { ts } else { t0 };
            if child == near {
                if !done || starts_before(far_t0, s.reach()) {
                    found = Successor::Found { node: far, t0: far_t0, t1, above: pending };
                }
                pending += 1;
                if visit == Visit::Both {
                    t1 = ts;
                }
            } else {
                t0 = far_t0;
            }
        }
        node = child;
    }
    found
}
