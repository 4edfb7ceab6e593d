// The child decision at an interior node (decide_children), the planes a
// segment may end at, and the restart point and state of the t-value restarts.
// CPU twin: src/kdtree/traverse/decide.rs.
//
// Expects from its includer: the specialization constant ROBUST and what
// segment.glsl expects.
#ifndef TRAVERSE_DECIDE_GLSL
#define TRAVERSE_DECIDE_GLSL

#include "kdnode.glsl"
#include "segment.glsl"

// Relative widening of the split decisions and early exits (src/consts.rs).
const float T_EPS = 1.0 / float(1u << TRAVERSAL_EPS_LOG2);

// The start of the segment after a restart: the exit of the last leaf or, when
// rounding put that exit at or before the previous restart point (a cell the ray
// only grazes), the next float after that point. The restart point always moves
// forward, so restarts end even though near-ties at t0 are followed (below).
float restart_point(float t_exit, float t_prev) {
    if (t_exit > t_prev) return t_exit;
    if (t_prev == 0.0) return uintBitsToFloat(0x00800000u);
    uint bits = floatBitsToUint(t_prev);
    return uintBitsToFloat(t_prev > 0.0 ? bits + 1u : bits - 1u);
}

// The plane a segment ended at, for the tie rule below: (axis, split bits) of a
// split plane, or NO_PLANE (no tie rule: the first descent, the stacks), or
// ANY_PLANE (every tie at t0 goes far: restarts whose plane is unknown, and the
// packet restarts, which keep none).
const uvec2 NO_PLANE = uvec2(3u, 0u);
const uvec2 ANY_PLANE = uvec2(4u, 0u);
// EXACT_PLANE: the first descent of `backtrack` and `ropes`, whose climbs and
// rope hops need the leaf to hold the point at t0: no near child behind t0.
const uvec2 EXACT_PLANE = uvec2(5u, 0u);

uvec2 node_plane(uvec2 n) {
    return uvec2(node_axis(n), n.x);
}

// Restart behind the leaf just left (`restart`, `push-down`, the short stacks):
// the segment becomes [restart point, the nearer of the scene exit and `reach`],
// and ties at its start follow the plane the leaf was left through (any plane
// when that one is not known). The restart state is each variant's own three
// variables, not a struct, which lavapipe runs much slower (docs/BENCH.md):
// `t0_restart` (where the segment started at the last restart), `exit_plane`
// (the tie rule's) and `t1_plane` (where the current segment ends).
// The caller sets the node to descend from and counts the restart.
void restart_after_leaf(float t1_scene, float reach, inout float t0, inout float t1, inout float t0_restart,
                        inout uvec2 exit_plane, inout uvec2 t1_plane) {
    t0 = restart_point(t1, t0_restart);
    t0_restart = t0;
    t1 = min(t1_scene, reach);
    exit_plane = t1_plane.x == NO_PLANE.x ? ANY_PLANE : t1_plane;
    t1_plane = NO_PLANE;
}

// Which children of an interior node the segment [t0, t1] needs.
// `near` is the child the ray is in for t < t_split (chosen by the direction's
// sign bit, so -0.0 and origins on the plane are handled without ties).
#define VISIT_NEAR 0u
#define VISIT_FAR 1u
#define VISIT_BOTH 2u
#define VISIT_BOTH_SAME 3u   // ray lies in the split plane: both children, same interval

uint decide_children(TraceRay r, uint node, uvec2 n, float t0, float t1, uvec2 exit_plane,
                     out uint near, out uint far, out float t_split) {
    uint axis = node_axis(n);
    float split = node_split(n);
    float o = r.wr.seg_origin[axis];
    float d = r.dir[axis];
    bool below_first = (floatBitsToUint(d) >> 31u) == 0u;
    uint below = node + 1u;
    uint above = node_above_child(n);
    near = below_first ? below : above;
    far = below_first ? above : below;
    // Clamped finite, so that the widening below never computes inf - inf.
    precise float ts = clamp(plane_t(r, axis, split), -3.40282347e38, 3.40282347e38);
    t_split = ts;
    if (d == 0.0 && o == split) return VISIT_BOTH_SAME;
    if (is_flat(r, axis)) {
        // By position: one child when the ray's band lies on one side, else both
        // with the same segment (no t from this axis enters a segment).
        int side = flat_side(r, axis, split);
        if (side == 0) return VISIT_BOTH_SAME;
        bool wants_near = (side < 0) == below_first;
        t_split = wants_near ? 3.40282347e38 : -3.40282347e38;
        return wants_near ? VISIT_NEAR : VISIT_FAR;
    }
    // Conservative: one child only when the plane lies beyond the segment by more
    // than rounding (Ize 2013 in spirit). After a restart (t0 = a leaf exit) the
    // near side of a plane is skipped when the plane lies before t0, or at t0 and
    // it is the plane the last leaf was left through.
    // The bound is relative to |t| plus, in a shifted segment frame, t_err.
    float eps = ROBUST ? T_EPS : 0.0;
    precise float ts_lo_rel = ts - eps * abs(ts);
    precise float ts_hi_rel = ts + eps * abs(ts);
    precise float t1_hi_rel = t1 + eps * abs(t1);
    precise float t0_lo_rel = t0 - eps * abs(t0);
    float ts_lo = minus_err(r, ts_lo_rel);
    float ts_hi = plus_err(r, ts_hi_rel);
    float t1_hi = plus_err(r, t1_hi_rel);
    float t0_lo = minus_err(r, t0_lo_rel);
    if (ts_lo > t1_hi) return VISIT_NEAR;
    bool far_only;
    if (exit_plane.x == NO_PLANE.x) {
        far_only = ts_hi < t0_lo;
    } else if (exit_plane.x == ANY_PLANE.x) {
        far_only = ts <= t0;
    } else if (exit_plane.x == EXACT_PLANE.x) {
        far_only = ts < t0;
    } else {
        // A plane behind t0 is taken as passed (restarts must progress); a tie at
        // t0 with another plane is followed into the near child with an empty
        // segment there, and the next restart steps past it.
        far_only = ts < t0 || (ts == t0 && exit_plane.x == axis && exit_plane.y == n.x);
    }
    if (far_only) return VISIT_FAR;
    // Both: near gets [t0, ts], far [ts, t1], with ts kept inside the segment (a
    // plane just outside it by rounding gives one child an empty segment there).
    t_split = min(max(ts, t0), t1);
    return VISIT_BOTH;
}

#endif
