// `ropes` (Popov, Günther, Seidel & Slusallek 2007), single rays: each leaf links
// each of its six faces to the subtree across it (side buffer `ropes`, leaf boxes
// in `node_boxes`). After a leaf without a hit inside it, the ray leaves through
// the face where its box ends, follows that rope and descends the subtree to the
// leaf that holds the segment just behind. No stack, no restart from the root.
// With ROBUST on, a leaf left within rounding of an edge or corner of its box, a
// descent that meets a plane within rounding of t0 (other than the face just
// crossed), or a ray inside a split plane finishes with exact restarts from
// there (see near_t0 in boxes.glsl).
// CPU twin: `trace_ropes` in src/kdtree/traverse/ropes.rs.
#ifndef TRAVERSE_ROPES_GLSL
#define TRAVERSE_ROPES_GLSL

#include "node.glsl"
#include "decide.glsl"
#include "leaf.glsl"
#include "boxes.glsl"
#include "restart.glsl"

bool trace_ropes(TraceRay r, float t0, float t1_scene, inout Closest best, inout TraceCounters c) {
    float t_scene0 = t0;
    uint node = 0u;
    float t1 = t1_scene;
    // No near child behind t0 on the first descent; after a hop, ties at t0 go far.
    uvec2 exit_plane = EXACT_PLANE;
    uvec2 crossed = NO_PLANE;  // ROBUST: the face the last leaf was left through
    bool fallback = false;  // ROBUST: finish with exact restarts from t0 (after the loop)
    uint step = 0u;
    // While-while form, as in stack.glsl: descend to a leaf, then visit it.
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        ++step;
        while (!node_is_leaf(n)) {
            uint near, far;
            float ts;
            uint visit = decide_children(r, node, n, t0, t1, exit_plane, near, far, ts);
            if (ROBUST && ambiguous_decision(r, visit, n, ts, t0, crossed)) {
                fallback = true;
                break;
            }
            if (visit == VISIT_FAR) {
                node = far;
            } else if (visit == VISIT_BOTH) {
                node = near;
                t1 = ts;
            } else {
                node = near;
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        }
        if (fallback) break;
        // The leaf's own exit, from its box: ropes leave the ancestors' planes behind.
        uint face;
        float t_next;
        float exit_t = box_exit(r, node, face, t_next);
        float leaf_t1 = min(min(exit_t, t1_scene), t1);
        uint leaf = visit_leaf(r, n, leaf_t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE) return true;
        if (leaf_t1 >= t1_scene) {
            // ROBUST, before the first hit, on a segment that ends at tmax (not
            // at the scene's box; then best.hit.t is tmax's bound): a segment that
            // ends within rounding of a face with a leaf across it may end exactly
            // on a triangle of that leaf lying in the face's plane.
            bool at_tmax = ROBUST && best.hit.prim_id == PRIM_MISS && !(t1_scene < best.hit.t);
            if (!(at_tmax && near_t0(r, exit_t, t1_scene) && ropes[node * 6u + face] != NO_ROPE)) {
                return true;
            }
            t0 = max(t0, leaf_t1);
            fallback = true;
            break;
        }
        if (ROBUST && (leaf_t1 != exit_t || near_t0(r, t_next, exit_t) || near_t0(r, exit_t, t0))) {
            // Left near an edge or corner of the leaf (or a sliver of it).
            t0 = max(t0, leaf_t1);
            fallback = true;
            break;
        }
        uint next = ropes[node * 6u + face];
        if (next == NO_ROPE) return true;
        crossed = box_face_plane(node, face);
        // Never step backwards: keep t0 when rounding puts the exit behind it.
        t0 = max(t0, leaf_t1);
        t1 = min(t1_scene, best_reach(best));
        node = next;
        exit_plane = ANY_PLANE;
        c.restarts += 1u;
    }
    if (fallback) return trace_fallback_exact(r, t_scene0, t1_scene, t0, step, best, c);
    return false;
}

#endif
