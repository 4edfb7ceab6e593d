// `stack`: front-to-back traversal with a full per-ray stack of (node, t0, t1)
// (pbrt-v3's KdTreeAccel::Intersect). The baseline every variant is compared to.
// CPU twin: `trace_stack` in src/kdtree/traverse.rs.
#ifndef TRAVERSE_STACK_GLSL
#define TRAVERSE_STACK_GLSL

// Returns true when traversal finished; false when it was cut short.
bool trace_stack(TraceRay r, float t0, float t1, inout Hit best, inout TraceCounters c) {
    uint stack_node[MAX_STACK];
    float stack_t0[MAX_STACK];
    float stack_t1[MAX_STACK];
    uint sp = 0u;
    uint node = 0u;
    for (uint step = 0u; step < MAX_TRAVERSAL_STEPS; ++step) {
        uvec2 n = fetch_node(node, c);
        if (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, false, near, far, ts);
            if (visit == VISIT_NEAR) {
                node = near;
            } else if (visit == VISIT_FAR) {
                node = far;
            } else if (visit == VISIT_BOTH_SAME) {
                stack_node[sp] = far; stack_t0[sp] = t0; stack_t1[sp] = t1; ++sp;
                node = near;
            } else {
                stack_node[sp] = far; stack_t0[sp] = ts; stack_t1[sp] = t1; ++sp;
                node = near;
                t1 = ts;
            }
            continue;
        }
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE || sp == 0u) return true;
        --sp;
        node = stack_node[sp];
        t0 = stack_t0[sp];
        t1 = stack_t1[sp];
    }
    return false;
}

#endif
