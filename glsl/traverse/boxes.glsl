// Node boxes for the stackless walks (`backtrack`, `ropes`): where the ray leaves
// a box, the plane of a face, and the checks that send a robust walk to its
// exact fallback. CPU twin: src/kdtree/traverse/boxes.rs.
//
// Expects from its includer: the side buffer `node_boxes` (six floats per node:
// min xyz, max xyz; see trace.comp) and what decide.glsl expects.
#ifndef TRAVERSE_BOXES_GLSL
#define TRAVERSE_BOXES_GLSL

#include "kdnode.glsl"
#include "segment.glsl"
#include "decide.glsl"

// Distance at which the ray leaves a node box (side buffer node_boxes): the
// nearest far plane; `face` is 2*axis (+1 for the max face), `t_next` the next
// far plane (+inf when none). Axes with a zero direction component never end
// the segment.
// A flat axis never ends the segment either, but a face of it within the ray's
// band makes t_next equal t_exit, which sends the callers to their exact fallback.
float box_exit(TraceRay r, uint node, out uint face, out float t_next) {
    float t_exit = uintBitsToFloat(0x7f800000u);
    t_next = t_exit;
    face = 0u;
    bool flat_face = false;
    for (uint axis = 0u; axis < 3u; ++axis) {
        float d = r.dir[axis];
        if (d == 0.0) continue;
        if (is_flat(r, axis)) {
            flat_face = flat_face || flat_side(r, axis, node_boxes[node * 6u + axis]) == 0 ||
                        flat_side(r, axis, node_boxes[node * 6u + axis + 3u]) == 0;
            continue;
        }
        bool positive = d > 0.0;
        float plane = node_boxes[node * 6u + axis + (positive ? 3u : 0u)];
        float t = plane_t(r, axis, plane);
        if (t < t_exit) {
            t_next = t_exit;
            t_exit = t;
            face = 2u * axis + (positive ? 1u : 0u);
        } else if (t < t_next) {
            t_next = t;
        }
    }
    if (flat_face) t_next = t_exit;
    return t_exit;
}

// The plane of face `face` of a node's box, as node_plane names split planes.
uvec2 box_face_plane(uint node, uint face) {
    uint axis = face >> 1u;
    return uvec2(axis, floatBitsToUint(node_boxes[node * 6u + axis + ((face & 1u) != 0u ? 3u : 0u)]));
}

// Robust `backtrack` and `ropes` walk cells by t values, which cannot order the
// cells around a vertex or edge that the ray passes within rounding of. They
// check for that (a plane other than the one just crossed, or a second exit
// face, within the widening of t0) and then finish with exact restarts from
// there (trace_restart_exact with t_from, and push-down), which are watertight.
bool near_t0(TraceRay r, float ts, float t0) {
    precise float d = abs(ts - t0);
    precise float bound_rel = T_EPS * min(max(abs(ts), abs(t0)), 3.40282347e38);
    float bound = plus_err(r, bound_rel);
    return d <= bound;
}

// True when a decision at node `n` needs the exact fallback: a ray inside the
// split plane, or a plane within rounding of t0 that is not `crossed`.
bool ambiguous_decision(TraceRay r, uint visit, uvec2 n, float ts, float t0, uvec2 crossed) {
    if (visit == VISIT_BOTH_SAME) return true;
    if (visit == VISIT_NEAR) return false;
    return near_t0(r, ts, t0) && any(notEqual(node_plane(n), crossed));
}

#endif
