// `push-down`: kd-restart that restarts not at the root but at the push-down
// node (Horn et al. 2007): the deepest node reached before the first decision
// that needed both children. Its region holds the whole rest of the segment, so
// the levels above it are never visited again.
// With ROBUST on, restarts are exact (trace_restart_exact in restart.glsl).
// CPU twin: `trace_push_down` in src/kdtree/traverse/push_down.rs.
#ifndef TRAVERSE_PUSH_DOWN_GLSL
#define TRAVERSE_PUSH_DOWN_GLSL

#include "node.glsl"
#include "decide.glsl"
#include "leaf.glsl"
#include "restart.glsl"

bool trace_push_down(TraceRay r, float t0, float t1_scene, inout Closest best, inout TraceCounters c) {
    if (ROBUST) return trace_restart_exact(r, t0, t1_scene, true, -3.40282347e38, 0u, best, c);
    uint node = 0u;
    float t1 = t1_scene;
    float t0_restart = t0;  // where the segment started at the last restart
    uvec2 exit_plane = NO_PLANE;  // the plane the last leaf was left through
    uvec2 t1_plane = NO_PLANE;    // the plane the current segment ends at
    uint restart_node = 0u;
    bool push_down = true;
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
            } else if (visit == VISIT_NEAR) {
                node = near;
            } else if (visit == VISIT_BOTH) {
                node = near;
                t1 = ts;
                t1_plane = node_plane(n);
                push_down = false;
            } else {
                node = near;
                push_down = false;
            }
            if (push_down) restart_node = node;
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        }
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE || t1 >= t1_scene) return true;
        restart_after_leaf(t1_scene, best_reach(best), t0, t1, t0_restart, exit_plane, t1_plane);
        node = restart_node;
        push_down = true;
        c.restarts += 1u;
    }
    return false;
}

#endif
