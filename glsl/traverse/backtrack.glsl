// `backtrack`: kd-backtrack (Foley & Sugerman 2005). No stack: after a leaf
// without a hit inside it, climb the parent links (side buffer) to the first
// ancestor whose box (side buffer) the ray leaves after the leaf's exit, and
// descend from there with [leaf exit, ancestor exit].
// With ROBUST on, a leaf left near an edge or corner of its box, a climb or
// descent that meets a plane within rounding of the leaf exit (other than the
// plane just crossed), or a ray inside a split plane finishes with exact
// restarts from there (see near_t0 in boxes.glsl).
// CPU twin: `trace_backtrack` in src/kdtree/traverse/backtrack.rs.
#ifndef TRAVERSE_BACKTRACK_GLSL
#define TRAVERSE_BACKTRACK_GLSL

#include "node.glsl"
#include "decide.glsl"
#include "leaf.glsl"
#include "boxes.glsl"
#include "restart.glsl"

bool trace_backtrack(TraceRay r, float t0, float t1_scene, inout Closest best, inout TraceCounters c) {
    float t_scene0 = t0;
    uint node = 0u;
    float t1 = t1_scene;
    // No near child behind t0 on the first descent; after a hop, ties at t0 go far.
    uvec2 exit_plane = EXACT_PLANE;
    uvec2 t1_plane = NO_PLANE;  // ROBUST: the plane the segment ends at, when known
    uvec2 crossed = NO_PLANE;   // ROBUST: the plane the last leaf was left through
    bool fallback = false;  // ROBUST: finish with exact restarts from t0 (after the loop)
    // While-while form (see stack.glsl): descend to a leaf, then visit it.
    uint step = 0u;
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
                // A split clamped into the segment names no plane the segment ends at.
                t1_plane = ts == t0 || ts == t1 ? NO_PLANE : node_plane(n);
                t1 = ts;
            } else {
                node = near;
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        }
        if (fallback) break;
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE) return true;
        if (t1 >= t1_scene) {
            // Robust, before the first hit, on a segment that ends at tmax (not
            // at the scene's box; then best.hit.t is tmax's bound): a segment that
            // ends within rounding of a face of the leaf's box with a leaf across
            // it may end exactly on a triangle of that leaf in the face's plane.
            if (!ROBUST || best.hit.prim_id != PRIM_MISS || t1_scene < best.hit.t) return true;
            uint face;
            float t_next;
            float leaf_exit = box_exit(r, node, face, t_next);
            if (!near_t0(r, leaf_exit, t1_scene) || all(equal(box_face_plane(node, face), box_face_plane(0u, face)))) {
                return true;
            }
            t0 = t1;
            fallback = true;
            break;
        }
        if (ROBUST) {
            // Left near an edge or corner of the leaf's box: a second face within rounding.
            uint leaf_face;
            float t_next;
            float leaf_exit = box_exit(r, node, leaf_face, t_next);
            if (near_t0(r, t_next, leaf_exit)) {
                t0 = t1;
                fallback = true;
                break;
            }
        }
        // Climb to the first ancestor the ray leaves after t1.
        t0 = t1;
        crossed = t1_plane;
        float exit_t = t0;
        uint face = 0u;
        uint depth = 0u;
        bool ambiguous = false;
        for (; exit_t <= t0 && node != 0u && depth < MAX_STACK; ++depth) {
            node = parents[node];
            c.nodes += 1u;
            float t_next;
            exit_t = box_exit(r, node, face, t_next);
            if (ROBUST && near_t0(r, exit_t, t0) && any(notEqual(box_face_plane(node, face), crossed))) ambiguous = true;
        }
        if (exit_t <= t0 && node != 0u && depth < MAX_STACK) return false;  // climb cut short
        if (ambiguous) {
            fallback = true;
            break;
        }
        if (exit_t <= t0) return true;  // the root's box ends here: nothing left
        t1 = min(min(exit_t, t1_scene), best_reach(best));
        t1_plane = t1 == exit_t ? box_face_plane(node, face) : NO_PLANE;
        exit_plane = ANY_PLANE;
        c.restarts += 1u;
    }
    if (fallback) return trace_fallback_exact(r, t_scene0, t1_scene, t0, step, best, c);
    return false;
}

#endif
