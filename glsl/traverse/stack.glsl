// `stack`: front-to-back traversal with a full per-ray stack of (node, t0, t1)
// (pbrt-v3's KdTreeAccel::Intersect). The baseline every variant is compared to.
// Beyond pbrt and the paper, and unlike the other variants, it neither pushes nor
// fetches a child that its parent flags as an empty leaf (NODE_BELOW_EMPTY,
// NODE_ABOVE_EMPTY), and it skips every entry that starts behind the closest hit
// at each pop (not only after the leaf of the hit).
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
        // Descend to a leaf. A child that the parent's flags mark as an empty leaf
        // is neither pushed nor fetched: the lane pops the next entry and keeps
        // descending instead of waiting for the others' triangle tests. So the only
        // empty leaf ever fetched is a root that is one (an empty scene).
        if (!node_is_leaf(n)) do {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, NO_PLANE, near, far, ts);
            bool below_near = near == node + 1u;
            bool near_empty = below_near ? node_below_empty(n) : node_above_empty(n);
            bool far_empty = below_near ? node_above_empty(n) : node_below_empty(n);
            bool both = visit >= VISIT_BOTH;
            // VISIT_BOTH: near gets [t0, ts], far [ts, t1]; VISIT_BOTH_SAME: both [t0, t1].
            float near_t1 = visit == VISIT_BOTH ? ts : t1;
            float far_t0 = visit == VISIT_BOTH ? ts : t0;
            bool pop = false;
            if (both && !near_empty && !far_empty) {
                stack_node[sp] = far;
                stack_t0[sp] = far_t0;
                stack_t1[sp] = t1;
                ++sp;
                node = near;
                t1 = near_t1;
            } else if (visit == VISIT_NEAR || (both && far_empty)) {
                node = near;
                t1 = near_t1;
                pop = near_empty;
            } else {
                // VISIT_FAR, or both with the near child an empty leaf (then the
                // far segment may start behind the closest hit: nothing closer there).
                node = far;
                t0 = far_t0;
                pop = far_empty || (both && !(far_t0 < best_reach(best)));
            }
            if (pop) {
                // The next entry that starts before the closest hit's reach: only
                // such an entry can hold a closer hit. (Not the top one alone: an
                // entry of a split plane the ray lies in starts where its sibling does.)
                do {
                    if (sp == 0u) return true;
                    --sp;
                    t0 = stack_t0[sp];
                } while (!(t0 < best_reach(best)));
                node = stack_node[sp];
                t1 = stack_t1[sp];
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        } while (!node_is_leaf(n));
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (ANY_HIT && leaf == LEAF_DONE) return true;
        // A second pop site, on purpose: leaving visited leaves through the
        // descent's pop (one site) costs more instructions on SIMD drivers, as every
        // lane then enters the descent at a pop (see docs/BENCH.md).
        do {
            if (sp == 0u) return true;
            --sp;
            t0 = stack_t0[sp];
        } while (!(t0 < best_reach(best)));
        node = stack_node[sp];
        t1 = stack_t1[sp];
    }
    return false;
}

#endif
