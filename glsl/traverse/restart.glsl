// `restart`: kd-restart (Foley & Sugerman 2005), no stack. After a leaf without
// a hit inside it, the segment becomes [leaf exit, scene exit] and descent starts
// again at the root. Progress: after a restart the plane the last leaf was left
// through goes far on a tie, planes before t0 are passed, and the restart point
// always moves forward (restart_point in decide.glsl), so restarts end.
// That is the paper's algorithm, run when ROBUST is off. With ROBUST on, restarts
// are exact (trace_restart_exact below) and visit what `stack` visits.
// CPU twins: `trace_restart` and `trace_restart_exact` in src/kdtree/traverse/restart.rs.
#ifndef TRAVERSE_RESTART_GLSL
#define TRAVERSE_RESTART_GLSL

#include "node.glsl"
#include "decide.glsl"
#include "seek.glsl"
#include "leaf.glsl"

// Exact restarts for `restart` and (use_push_down) `push-down`: every restart
// seeks the entry a full stack would pop next (Seek in seek.glsl) by
// descending again from the restart node toward the leaf just left, so the
// leaves, their order and their segments are the stack's, and so are the
// answers. The push-down node is the
// deepest node above which no entry is pending, kept with its stack segment.
// `pending` counts the entries a full stack would hold, so the search is skipped
// when there are none, and after a hit inside the leaf unless the ray ever lay
// in a split plane (only such entries can start before the hit).
// `t_from`: leaves whose segment ends before it (less the widening) are known to
// be done (the fallback of robust backtrack, ropes and packets); -FLT_MAX for none.
// `step`: the loop steps already taken.
bool trace_restart_exact(TraceRay r, float t0, float t1, bool use_push_down, float t_from, uint step,
                         inout Closest best, inout TraceCounters c) {
    precise float t_from_lo_rel = t_from - T_EPS * abs(t_from);
    float t_from_lo = minus_err(r, t_from_lo_rel);
    uint node = 0u;
    uint restart_node = 0u;
    float restart_t0 = t0;
    float restart_t1 = t1;
    bool push_down = use_push_down;
    uint pending = 0u;
    bool in_plane = false;
    Seek k = seek_start(0u, false, 0u);
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        ++step;
        while (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, NO_PLANE, near, far, ts);
            if (k.seeking) {
                node = seek_step(k, node, n, visit, near, far, ts, t0, t1, best_reach(best));
                if (!k.seeking) {
                    if (!k.found) return true;  // nothing left
                    node = k.next;
                    t0 = k.next_t0;
                    t1 = k.next_t1;
                    pending = k.above;
                    push_down = use_push_down && pending == 0u;
                    c.restarts += 1u;
                }
            } else if (visit == VISIT_BOTH && ts < t_from_lo) {
                node = far;  // the near side ends before t_from: done already
                t0 = ts;
            } else {
                node = visit == VISIT_FAR ? far : near;
                if (visit == VISIT_BOTH) t1 = ts;
                if (visit == VISIT_BOTH || visit == VISIT_BOTH_SAME) {
                    pending += 1u;
                    push_down = false;
                }
                if (visit == VISIT_BOTH_SAME) in_plane = true;
            }
            if (push_down) {
                restart_node = node;
                restart_t0 = t0;
                restart_t1 = t1;
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        }
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE && ANY_HIT) return true;
        if (pending == 0u || (leaf == LEAF_DONE && !in_plane)) return true;
        k = seek_start(node, leaf == LEAF_DONE, pending);
        node = restart_node;
        t0 = restart_t0;
        t1 = restart_t1;
    }
    return false;
}

// The fallback of robust `backtrack` and `ropes`, which met a decision they
// cannot take in f32: finish with exact restarts, leaves before `t_from` done.
// The fast pass leaves that to the careful one (see careful_pass). Called once
// after each variant's loop, so the kernel holds one copy of this code.
bool trace_fallback_exact(TraceRay r, float t0_scene, float t1_scene, float t_from, uint step,
                          inout Closest best, inout TraceCounters c) {
    if (!careful_pass) {
        best.needs_careful = true;
        return true;
    }
    return trace_restart_exact(r, t0_scene, t1_scene, true, t_from, step, best, c);
}

bool trace_restart(TraceRay r, float t0, float t1_scene, inout Closest best, inout TraceCounters c) {
    if (ROBUST) return trace_restart_exact(r, t0, t1_scene, false, -3.40282347e38, 0u, best, c);
    uint node = 0u;
    float t1 = t1_scene;
    float t0_restart = t0;  // where the segment started at the last restart
    uvec2 exit_plane = NO_PLANE;  // the plane the last leaf was left through
    uvec2 t1_plane = NO_PLANE;    // the plane the current segment ends at
    // While-while form (see stack.glsl): descend to a leaf, then visit it.
    uint step = 0u;
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        ++step;
        while (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, exit_plane, near, far, ts);
            if (visit == VISIT_FAR) {
                node = far;
            } else if (visit == VISIT_BOTH) {
                node = near;
                t1 = ts;
                t1_plane = node_plane(n);
            } else {
                // VISIT_NEAR, or a ray inside the split plane (only one side can
                // be followed without a stack: the near one).
                node = near;
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        }
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE || t1 >= t1_scene) return true;
        // Restart from the root behind this leaf.
        restart_after_leaf(t1_scene, best_reach(best), t0, t1, t0_restart, exit_plane, t1_plane);
        node = 0u;
        c.restarts += 1u;
    }
    return false;
}

#endif
