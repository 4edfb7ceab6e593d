// `restart`: kd-restart (Foley & Sugerman 2005), no stack. After a leaf without
// a hit inside it, the segment becomes [leaf exit, scene exit] and descent starts
// again at the root. Progress: after the first restart, ties at t0 go to the far
// child, so every leaf reached ends strictly after t0.
// CPU twin: `trace_restart` in src/kdtree/traverse.rs.
#ifndef TRAVERSE_RESTART_GLSL
#define TRAVERSE_RESTART_GLSL

bool trace_restart(TraceRay r, float t0, float t1_scene, inout Hit best, inout TraceCounters c) {
    uint node = 0u;
    float t1 = t1_scene;
    bool ties_go_far = false;
    for (uint step = 0u; step < MAX_TRAVERSAL_STEPS; ++step) {
        uvec2 n = fetch_node(node, c);
        if (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, ties_go_far, near, far, ts);
            if (visit == VISIT_FAR) {
                node = far;
            } else if (visit == VISIT_BOTH) {
                node = near;
                t1 = ts;
            } else {
                // VISIT_NEAR, or a ray inside the split plane (only one side can
                // be followed without a stack: the near one).
                node = near;
            }
            continue;
        }
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE || t1 >= t1_scene) return true;
        // Restart from the root behind this leaf.
        t0 = t1;
        t1 = min(t1_scene, best.t);
        node = 0u;
        ties_go_far = true;
        c.restarts += 1u;
    }
    return false;
}

#endif
