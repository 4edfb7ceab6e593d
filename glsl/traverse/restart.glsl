// `restart`: kd-restart (Foley & Sugerman 2005), no stack. After a leaf without
// a hit inside it, the segment becomes [leaf exit, scene exit] and descent starts
// again at the root. Progress: after the first descent, ties at t0 go to the far
// child, so every leaf reached ends strictly after t0.
// CPU twin: `trace_restart` in src/kdtree/traverse.rs.
#ifndef TRAVERSE_RESTART_GLSL
#define TRAVERSE_RESTART_GLSL

bool trace_restart(TraceRay r, float t0, float t1_scene, inout Hit best, inout TraceCounters c) {
    uint node = 0u;
    float t1 = t1_scene;
    bool first_descent = true;
    for (uint step = 0u; step < MAX_TRAVERSAL_STEPS; ++step) {
        c.steps += 1u;
        c.nodes += 1u;
        uvec2 n = nodes[node];
        if (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, !first_descent, near, far, ts);
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
        c.leaves += 1u;
        if (!intersect_leaf(r, n, best, c)) return false;
        if (best.t <= t1 || t1 >= t1_scene) return true;
        // Restart from the root behind this leaf.
        t0 = t1;
        t1 = min(t1_scene, best.t);
        node = 0u;
        first_descent = false;
        c.restarts += 1u;
    }
    return false;
}

#endif
