//! Packets: decisions by ballot over the packet's lanes, each lane with its own
//! interval and hit. Twins of `glsl/traverse/packet.glsl` (`lane_split`),
//! `packet_stack.glsl` (`stack`) and `packet_short_stack.glsl` (`restart`,
//! `push-down` and the short stacks), for `kdtrace divergence`: hits and
//! per-lane counters equal the GPU's bit for bit (`tests/packets.rs`), so the
//! logs are the kernels' loop trip counts.

use super::decide::{decide_children, restart_point, ExitPlane, Visit};
use super::leaf::{intersect_leaf, Closest};
use super::node::Counters;
use super::restart::trace_restart_exact;
use super::segment::{glsl_min, TraceRay};
use super::{FlowLog, SceneRef, State};
use crate::consts::{MAX_TRAVERSAL_STEPS, PRIM_MISS};

/// One lane of a packet: its ray, segment, closest hit, counters and log.
pub(super) struct Lane<'l> {
    pub(super) r: TraceRay,
    /// The ray is valid and meets the scene box (a dead lane still runs the
    /// packet's loop: decisions are ballots).
    pub(super) alive: bool,
    pub(super) t0: f32,
    pub(super) t1: f32,
    pub(super) best: Closest,
    pub(super) c: Counters,
    pub(super) log: Option<&'l mut FlowLog>,
}

/// Twin of `LaneSplit` in packet.glsl: the children one lane needs, with their intervals.
struct LaneSplit {
    below: bool,
    above: bool,
    below_first: bool,
    splits: bool,
    same: bool,
    below_t: (f32, f32),
    above_t: (f32, f32),
}

/// Twin of `lane_split` in packet.glsl.
fn lane_split(lane_on: bool, l: &Lane, node: u32, n: crate::kdtree::KdNode, exit_plane: ExitPlane) -> LaneSplit {
    let (t0, t1) = (l.t0, l.t1);
    let mut s = LaneSplit {
        below: false,
        above: false,
        below_first: true,
        splits: false,
        same: false,
        below_t: (t0, t1),
        above_t: (t0, t1),
    };
    if !lane_on {
        return s;
    }
    let (visit, near, _far, ts) = decide_children(&l.r, node, n, t0, t1, exit_plane);
    s.below_first = near == node + 1;
    let (need_near, need_far) = (visit != Visit::Far, visit != Visit::Near);
    s.splits = need_near && need_far;
    s.same = visit == Visit::BothSame;
    let near_t1 = if visit == Visit::Both { ts } else { t1 };
    let far_t0 = if visit == Visit::Both { ts } else { t0 };
    if s.below_first {
        (s.below, s.below_t.1, s.above, s.above_t.0) = (need_near, near_t1, need_far, far_t0);
    } else {
        (s.above, s.above_t.1, s.below, s.below_t.0) = (need_near, near_t1, need_far, far_t0);
    }
    s
}

/// Twin of `lane_wants` in packet_stack.glsl.
fn lane_wants(alive: bool, t0: f32, t1: f32, best: &Closest, any_hit: bool) -> bool {
    // `!(t0 <= t1)`: false for NaN too, as in the shader.
    if !alive || !matches!(t0.partial_cmp(&t1), Some(std::cmp::Ordering::Less | std::cmp::Ordering::Equal)) {
        return false;
    }
    if any_hit {
        return best.hit.prim_id == PRIM_MISS;
    }
    let reach = best.reach();
    t0 < reach || (best.hit.prim_id == PRIM_MISS && t0 <= reach)
}

/// Twin of `trace_packet_stack`: false when the packet reached the step cap.
pub(super) fn trace_packet_stack(scene: &SceneRef, lanes: &mut [Lane]) -> bool {
    let mut stack: Vec<(u32, Vec<(f32, f32)>)> = Vec::new();
    let mut node = 0u32;
    let mut on: Vec<bool> = lanes.iter().map(|l| l.alive).collect();
    if !on.iter().any(|&b| b) {
        return true;
    }
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = scene.nodes[node as usize];
        fetch(lanes, &on, node);
        if !n.is_leaf() {
            let splits: Vec<LaneSplit> =
                lanes.iter().zip(&on).map(|(l, &lane_on)| lane_split(lane_on, l, node, n, ExitPlane::None)).collect();
            let any_below = splits.iter().any(|s| s.below);
            let any_above = splits.iter().any(|s| s.above);
            let (below, above) = (node + 1, n.above_child());
            let below_goes_first = if any_below && any_above {
                let first = on.iter().zip(&splits).filter(|(&o, s)| o && s.below_first).count();
                let second = on.iter().zip(&splits).filter(|(&o, s)| o && !s.below_first).count();
                let bgf = first >= second;
                // A lane that does not need the second child gets the empty [inf, -inf].
                let entry = splits
                    .iter()
                    .map(|s| match (bgf, if bgf { s.above } else { s.below }) {
                        (_, false) => (f32::INFINITY, f32::NEG_INFINITY),
                        (true, true) => s.above_t,
                        (false, true) => s.below_t,
                    })
                    .collect();
                stack.push((if bgf { above } else { below }, entry));
                bgf
            } else {
                any_below
            };
            node = if below_goes_first { below } else { above };
            for ((lane, lane_on), s) in lanes.iter_mut().zip(on.iter_mut()).zip(&splits) {
                (*lane_on, (lane.t0, lane.t1)) =
                    if below_goes_first { (s.below, s.below_t) } else { (s.above, s.above_t) };
            }
            continue;
        }
        test_leaf(scene, lanes, &on, n);
        // Pop until an entry some lane still needs.
        on.iter_mut().for_each(|o| *o = false);
        while let Some((entry_node, entry)) = stack.pop() {
            node = entry_node;
            for ((lane, lane_on), &(t0, t1)) in lanes.iter_mut().zip(on.iter_mut()).zip(&entry) {
                (lane.t0, lane.t1) = (t0, t1);
                *lane_on = lane_wants(lane.alive, t0, t1, &lane.best, lane.r.any_hit);
            }
            if on.iter().any(|&b| b) {
                break;
            }
        }
        if !on.iter().any(|&b| b) {
            return true;
        }
    }
    false
}

/// Every lane of the packet steps (the load is the packet's); the lanes on it count a node.
fn fetch(lanes: &mut [Lane], on: &[bool], node: u32) {
    for (lane, &lane_on) in lanes.iter_mut().zip(on) {
        lane.c.steps += 1;
        lane.c.nodes += u32::from(lane_on);
        if let Some(log) = lane.log.as_mut() {
            log.fetched(node);
        }
    }
}

/// The lanes on a leaf test its triangles; the logs close a round when any lane tested one.
fn test_leaf(scene: &SceneRef, lanes: &mut [Lane], on: &[bool], n: crate::kdtree::KdNode) {
    let mut tris = vec![0u32; lanes.len()];
    for ((lane, &lane_on), t) in lanes.iter_mut().zip(on).zip(tris.iter_mut()) {
        if lane_on {
            lane.c.leaves += 1;
            let before = lane.c.triangles;
            intersect_leaf(scene, &lane.r, n, &mut lane.best, &mut lane.c);
            *t = lane.c.triangles - before;
        }
    }
    if tris.iter().any(|&t| t > 0) {
        for (lane, &t) in lanes.iter_mut().zip(&tris) {
            if let Some(log) = lane.log.as_mut() {
                log.packet_round(t);
            }
        }
    }
}

/// A lane's own state in `trace_packet_short_stack` (the shader's per-lane locals).
#[derive(Clone, Copy)]
struct RestartLane {
    t_done: f32,
    t0_restart: f32,
    exit_plane: ExitPlane,
    in_plane: bool,
    fallback: bool,
    t_from: f32,
    t_gap: f32,
}

/// Twin of `trace_packet_short_stack` in packet_short_stack.glsl: `size` ring
/// entries (0 = kd-restart), push-down when asked; per lane, false when cut short.
pub(super) fn trace_packet_short_stack(
    scene: &SceneRef,
    lanes: &mut [Lane],
    size: usize,
    use_push_down: bool,
    robust: bool,
) -> Vec<bool> {
    let t_start: Vec<f32> = lanes.iter().map(|l| l.t0).collect();
    let t1_scene: Vec<f32> = lanes.iter().map(|l| l.t1).collect();
    let mut stack: Vec<(u32, Vec<(f32, f32)>)> = vec![(0, Vec::new()); size];
    let (mut head, mut count) = (0usize, 0usize);
    let (mut node, mut restart_node) = (0u32, 0u32);
    let mut push_down = use_push_down;
    let mut st: Vec<RestartLane> = lanes
        .iter()
        .map(|l| RestartLane {
            t_done: l.t0,
            t0_restart: l.t0,
            exit_plane: ExitPlane::None,
            in_plane: false,
            fallback: false,
            t_from: l.t0,
            t_gap: f32::INFINITY,
        })
        .collect();
    let mut on: Vec<bool> = lanes.iter().map(|l| l.alive).collect();
    if !on.iter().any(|&b| b) {
        return vec![true; lanes.len()];
    }
    let mut ended = false;
    for _ in 0..MAX_TRAVERSAL_STEPS {
        let n = scene.nodes[node as usize];
        fetch(lanes, &on, node);
        if !n.is_leaf() {
            let splits: Vec<LaneSplit> = lanes
                .iter()
                .zip(&on)
                .zip(&st)
                .map(|((l, &lane_on), s)| lane_split(lane_on, l, node, n, s.exit_plane))
                .collect();
            // A lane's first child is its near one when it needs it, else the only one.
            let wants_below: Vec<bool> = splits.iter().map(|s| s.below && (s.below_first || !s.above)).collect();
            let wants_above: Vec<bool> = splits.iter().zip(&wants_below).map(|(s, &b)| s.above && !b).collect();
            let n_below = wants_below.iter().filter(|&&b| b).count();
            let n_above = wants_above.iter().filter(|&&b| b).count();
            let (below, above) = (node + 1, n.above_child());
            let go_below = n_below > 0 && (n_above == 0 || n_below >= n_above);
            let (first, second) = if go_below { (below, above) } else { (above, below) };
            let mut entry = Vec::with_capacity(lanes.len());
            for ((s, l), &wb) in splits.iter().zip(st.iter_mut()).zip(&wants_below) {
                let goes_on = if go_below { wb } else { s.above && !wb };
                let (first_t, second_t) = if go_below { (s.below_t, s.above_t) } else { (s.above_t, s.below_t) };
                let (needs_first, needs_second) = if go_below { (s.below, s.above) } else { (s.above, s.below) };
                l.in_plane |= s.same;
                if needs_first && !goes_on {
                    l.t_gap = glsl_min(l.t_gap, first_t.0);
                }
                entry.push((needs_second, second_t));
            }
            if entry.iter().any(|(needs, _)| *needs) {
                push_down = false;
                if size == 0 {
                    for (l, (needs, t)) in st.iter_mut().zip(&entry) {
                        if *needs {
                            l.t_gap = glsl_min(l.t_gap, t.0);
                        }
                    }
                } else {
                    if count == size {
                        // The oldest entry is overwritten: lost to its lanes, which will restart.
                        for ((l, lane), &(lost_t0, lost_t1)) in st.iter_mut().zip(lanes.iter_mut()).zip(&stack[head].1)
                        {
                            if lane.alive && lost_t0 <= lost_t1 {
                                l.t_gap = glsl_min(l.t_gap, lost_t0);
                            }
                            lane.c.drops += u32::from(lane.alive);
                        }
                    } else {
                        count += 1;
                    }
                    let ts = entry
                        .iter()
                        .map(|&(needs, t)| if needs { t } else { (f32::INFINITY, f32::NEG_INFINITY) })
                        .collect();
                    stack[head] = (second, ts);
                    head = (head + 1) % size;
                }
            }
            if splits.iter().any(|s| s.splits) {
                push_down = false;
            }
            node = first;
            for (((lane, lane_on), s), &wb) in lanes.iter_mut().zip(on.iter_mut()).zip(&splits).zip(&wants_below) {
                *lane_on = if go_below { wb } else { s.above && !wb };
                (lane.t0, lane.t1) = if go_below { s.below_t } else { s.above_t };
            }
            if push_down {
                restart_node = node;
            }
            continue;
        }
        let done: Vec<bool> = {
            let before: Vec<u32> = lanes.iter().map(|l| l.c.leaves).collect();
            test_leaf(scene, lanes, &on, n);
            lanes.iter().zip(&before).map(|(l, &b)| l.c.leaves > b && l.best.done(l.r.any_hit, l.t1)).collect()
        };
        for (i, (lane, l)) in lanes.iter_mut().zip(st.iter_mut()).enumerate() {
            if !on[i] {
                continue;
            }
            l.t_done = lane.t1;
            if done[i] || lane.t1 >= t1_scene[i] {
                lane.alive = false;
                if robust {
                    // Entries still on the stack for this lane are lost to it too.
                    for k in 0..count {
                        let slot = (head + size - 1 - k) % size;
                        let (lost_t0, lost_t1) = stack[slot].1[i];
                        if lost_t0 <= lost_t1 {
                            l.t_gap = glsl_min(l.t_gap, lost_t0);
                        }
                    }
                    // Before the first hit, on a segment that ends at tmax (not at
                    // the scene's box; then best.hit.t is tmax's bound), an entry
                    // clamped to start at the segment's end may still hold a hit
                    // exactly at tmax.
                    let reach = lane.best.reach();
                    let ends_at_box = t1_scene[i] < lane.best.hit.t;
                    let at_tmax = lane.best.hit.prim_id == PRIM_MISS && !ends_at_box;
                    let lost = l.t_gap < reach || (at_tmax && l.t_gap <= reach);
                    if !(lane.r.any_hit && done[i]) && (l.in_plane || lost) {
                        l.fallback = true;
                        l.t_from = if l.in_plane { -f32::MAX } else { l.t_gap };
                    }
                }
            }
        }
        // Pop until an entry that continues some lane's segment.
        on.iter_mut().for_each(|o| *o = false);
        while count > 0 {
            head = (head + size - 1) % size;
            count -= 1;
            node = stack[head].0;
            for (((lane, lane_on), l), &(t0, t1)) in
                lanes.iter_mut().zip(on.iter_mut()).zip(st.iter_mut()).zip(&stack[head].1)
            {
                (lane.t0, lane.t1) = (t0, t1);
                *lane_on = lane.alive && t0 <= t1 && t0 == l.t_done;
                if lane.alive && t0 <= t1 && t0 != l.t_done {
                    l.t_gap = glsl_min(l.t_gap, t0);
                }
            }
            if on.iter().any(|&b| b) {
                break;
            }
        }
        if on.iter().any(|&b| b) {
            continue;
        }
        if !lanes.iter().any(|l| l.alive) {
            ended = true;
            break;
        }
        if robust {
            for (lane, l) in lanes.iter_mut().zip(st.iter_mut()) {
                if lane.alive {
                    l.fallback = true;
                    l.t_from = if l.in_plane { -f32::MAX } else { glsl_min(l.t_done, l.t_gap) };
                    lane.alive = false;
                }
            }
            ended = true;
            break;
        }
        // Restart every unfinished lane behind its last leaf.
        count = 0;
        node = restart_node;
        push_down = use_push_down;
        for (i, ((lane, lane_on), l)) in lanes.iter_mut().zip(on.iter_mut()).zip(st.iter_mut()).enumerate() {
            *lane_on = lane.alive;
            lane.t0 = restart_point(l.t_done, l.t0_restart);
            if lane.alive {
                l.t0_restart = lane.t0;
            }
            l.t_done = lane.t0;
            lane.t1 = glsl_min(t1_scene[i], lane.best.reach());
            if lane.alive {
                l.exit_plane = ExitPlane::Any;
                lane.c.restarts += 1;
            }
        }
    }
    lanes
        .iter_mut()
        .zip(&st)
        .enumerate()
        .map(|(i, (lane, l))| {
            if robust && l.fallback {
                let mut s = State { scene, r: &lane.r, best: lane.best, c: &mut lane.c, log: lane.log.as_deref_mut() };
                let finished = trace_restart_exact(&mut s, t_start[i], t1_scene[i], true, l.t_from);
                lane.best = s.best;
                finished
            } else {
                ended
            }
        })
        .collect()
}
