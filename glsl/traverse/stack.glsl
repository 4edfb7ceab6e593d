// `stack`: front-to-back traversal with a full per-ray stack of (node, t0, t1)
// (pbrt-v3's KdTreeAccel::Intersect). The baseline every variant is compared to.
// Beyond pbrt and the paper, and unlike the other variants, it neither pushes nor
// fetches a child that its parent flags as an empty leaf (NODE_BELOW_EMPTY,
// NODE_ABOVE_EMPTY), and it skips every entry and leaf that starts behind the
// closest hit's reach (not only after the leaf of the hit; robust: once there
// is a hit, see starts_behind in leaf.glsl).
//
// Entries lie front to back on the stack (each one's t0 at or before those below
// it), so the first entry or leaf found behind the reach ends the ray - except
// for a ray that lies in a split plane (VISIT_BOTH_SAME), whose far entry starts
// where its sibling does, before entries pushed later. Such a ray drops only that
// entry and pops on (DROPPED_ENTRY below); the robust fast pass lists it for the
// careful pass instead, which keeps the fast kernel free of that case. A loop
// that drops entries until one starts before the reach gives the same hits and
// costs more instructions on lavapipe (docs/BENCH.md).
// CPU twin: `trace_stack` in src/kdtree/traverse/stack.rs.
#ifndef TRAVERSE_STACK_GLSL
#define TRAVERSE_STACK_GLSL

#include "node.glsl"
#include "stack_entry.glsl"
#include "decide.glsl"
#include "leaf.glsl"

// Stands in for the node of a popped entry that starts behind the closest hit
// (rays in a split plane only): an interior node whose children are both flagged
// empty, so the descent pops again at once.
const uvec2 DROPPED_ENTRY = uvec2(0u, NODE_BELOW_EMPTY | NODE_ABOVE_EMPTY);

// The robust fast pass lists rays that lie in a split plane for the careful pass.
const bool LIST_PLANE_RAYS = ROBUST && PASS == PASS_FAST;

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
    bool in_plane = false;  // an entry of a split plane the ray lies in was pushed
    bool dropped = false;   // the entry just popped starts behind the closest hit
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        if (!LIST_PLANE_RAYS && dropped) n = DROPPED_ENTRY;
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
                if (LIST_PLANE_RAYS) {
                    if (visit == VISIT_BOTH_SAME) best.needs_careful = true;
                } else {
                    in_plane = in_plane || visit == VISIT_BOTH_SAME;
                }
                node = near;
                t1 = near_t1;
            } else if (visit == VISIT_NEAR || (both && far_empty)) {
                node = near;
                t1 = near_t1;
                pop = near_empty;
            } else {
                // VISIT_FAR, or both with the near child an empty leaf (then the
                // far segment may start behind the closest hit: its leaf is
                // skipped below, not here, which costs fewer instructions).
                node = far;
                t0 = far_t0;
                pop = far_empty;
            }
            dropped = false;
            if (pop) {
                if (sp == 0u) return true;
                --sp;
                t0 = stack_t0[sp];
                dropped = starts_behind(t0, best);
                if (dropped && (LIST_PLANE_RAYS || !in_plane)) return true;
                node = stack_node[sp];
                t1 = stack_t1[sp];
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            if (!LIST_PLANE_RAYS && dropped) n = DROPPED_ENTRY;
            ++step;
        } while (!node_is_leaf(n));
        // A leaf starts behind the closest hit's reach only below a near child
        // skipped as empty: nothing closer there or in any entry, unless one of
        // a split plane the ray lies in is left (then only this leaf is skipped).
        bool behind = starts_behind(t0, best);
        if (behind && (LIST_PLANE_RAYS || !in_plane)) return true;
        uint leaf = (!LIST_PLANE_RAYS && behind) ? LEAF_GO_ON : visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (ANY_HIT && leaf == LEAF_DONE) return true;
        // A second pop site, on purpose: leaving visited leaves through the
        // descent's pop (one site) costs more instructions on SIMD drivers, as every
        // lane then enters the descent at a pop (see docs/BENCH.md).
        if (sp == 0u) return true;
        --sp;
        t0 = stack_t0[sp];
        dropped = starts_behind(t0, best);
        if (dropped && (LIST_PLANE_RAYS || !in_plane)) return true;
        node = stack_node[sp];
        t1 = stack_t1[sp];
    }
    return false;
}

#endif
