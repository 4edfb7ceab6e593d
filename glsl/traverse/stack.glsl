// `stack`: front-to-back traversal with a full per-ray stack of (node, t0, t1)
// (pbrt-v3's KdTreeAccel::Intersect). The baseline every variant is compared to.
// CPU twin: `trace_stack` in src/kdtree/traverse/stack.rs.
#ifndef TRAVERSE_STACK_GLSL
#define TRAVERSE_STACK_GLSL

#include "node.glsl"
#include "stack_entry.glsl"
#include "decide.glsl"
#include "leaf.glsl"

// Returns true when traversal finished; false when it was cut short.
//
// While-while form (Aila & Laine 2009): an inner loop descends to a leaf, then the
// leaf is visited. Same nodes in the same order and the same step count as a
// one-loop form, but on SIMD drivers (lavapipe runs a block for all 8 lanes of a
// subgroup, under a mask, whenever one lane needs it) the leaf block - the triangle test - no longer
// runs once per interior step, and lanes reach their leaves together. The single
// push site matters for the same reason: each private-array store is a per-lane
// scatter whether or not any lane pushes.
bool trace_stack(TraceRay r, float t0, float t1, inout Closest best, inout TraceCounters c) {
    uint stack_node[MAX_STACK];
    float stack_t0[MAX_STACK];  // entries' segments [t0, t1] (see stack_entry.glsl)
    float stack_t1[MAX_STACK];
    uint sp = 0u;
    uint node = 0u;
    uint step = 0u;
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        ++step;
        // Descend to a leaf with triangles. An empty leaf that does not end the
        // traversal is left here, popping the next entry: the lane keeps descending
        // instead of waiting for the others' triangle tests.
        if (descends(n, t1, best)) do {
            if (node_is_leaf(n)) {
                c.leaves += 1u;
                if (sp == 0u) return true;
                --sp;
                node = stack_node[sp];
                t0 = stack_t0[sp];
                t1 = stack_t1[sp];
            } else {
                uint near, far;
                float ts;
                uint visit = decide_children(r, node, n, t0, t1, NO_PLANE, near, far, ts);
                if (visit == VISIT_NEAR) {
                    node = near;
                } else if (visit == VISIT_FAR) {
                    node = far;
                } else {
                    // VISIT_BOTH: far gets [ts, t1]; VISIT_BOTH_SAME: far gets [t0, t1].
                    stack_node[sp] = far;
                    stack_t0[sp] = visit == VISIT_BOTH ? ts : t0;
                    stack_t1[sp] = t1;
                    ++sp;
                    node = near;
                    if (visit == VISIT_BOTH) t1 = ts;
                }
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        } while (descends(n, t1, best));
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE) {
            if (ANY_HIT) return true;
            // A closer hit can only lie in an entry that starts before this one: the
            // other side of a split plane the ray lies in (VISIT_BOTH_SAME) has the
            // same segment as the leaf just done. Drop the entries behind the hit.
            if (sp > 0u && !(stack_t0[sp - 1u] < best_reach(best))) do {
                --sp;
            } while (sp > 0u && !(stack_t0[sp - 1u] < best_reach(best)));
        }
        // A second pop site, on purpose: leaving visited leaves through the
        // descent's pop (one site) costs more instructions on SIMD drivers, as every
        // lane then enters the descent at a pop (see docs/BENCH.md).
        if (sp == 0u) return true;
        --sp;
        node = stack_node[sp];
        t0 = stack_t0[sp];
                t1 = stack_t1[sp];
    }
    return false;
}

#endif
