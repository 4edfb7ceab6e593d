// The leaf: its triangle tests (intersect_leaf), the closest hit they keep
// (Closest), and the tests of whether a traversal is done. CPU twin:
// src/kdtree/traverse/leaf.rs.
//
// Expects from its includer: the triangle texel buffer `tri_texels`
// (R32G32B32A32_UINT, three texels per leaf reference; see trace.comp), the
// specialization constants ANY_HIT, ROBUST and PASS, and what segment.glsl and
// node.glsl expect.
#ifndef TRAVERSE_LEAF_GLSL
#define TRAVERSE_LEAF_GLSL

#include "ray.glsl"
#include "kdnode.glsl"
#include "triangle.glsl"
#include "segment.glsl"
#include "node.glsl"

// Loads the triangle of the leaf reference `index` (stored in prim_indices
// order, the prim id inline).
// A two-level kernel (GEOMETRY_BASES) reads the current geometry's references
// from `texel_base` on (in references; see load_node).
uint load_triangle(uint index, out vec3 v0, out vec3 v1, out vec3 v2) {
#ifdef GEOMETRY_BASES
    int base = int(texel_base + index) * 3;
#else
    int base = int(index) * 3;
#endif
    uvec4 a = imageLoad(tri_texels, base);
    v0 = uintBitsToFloat(a.xyz);
    v1 = uintBitsToFloat(imageLoad(tri_texels, base + 1).xyz);
    v2 = uintBitsToFloat(imageLoad(tri_texels, base + 2).xyz);
    return a.w;
}

// Robust single rays are traced in two passes (trace.comp, src/trace.rs): a fast
// pass whose leaves skip the exact pass below and only note that a pair needed it
// (and whose `backtrack` and `ropes` note where they would fall back to exact
// restarts), then, in a second dispatch over the rays so noted, a careful trace
// from scratch. Packets and the plain kernels trace once (careful_pass true).
// The split exists because lavapipe runs every branch and loop of a kernel under
// a mask whether or not a lane enters it, so code a kernel holds costs in every
// subgroup: the leaf's exact pass, needed in few leaves, and a careful copy of the
// traversal each cost every ray a large share of its instructions when held by
// the fast kernel (see docs/BENCH.md, "Where the instructions go"). The careful
// trace decides everything the fast one decided the same way, so hits and
// counters are those of a single careful trace (the CPU twins').
const bool careful_pass = PASS != PASS_FAST;

// No triangle reference.
#define NO_REF 0xffffffffu

// What a traversal keeps about the closest hit so far, passed `inout` through
// every variant (CPU twin: `Closest`). `hit` is in the segment frame (t = the
// segment frame's tmax and PRIM_MISS for none); `reference` is its triangle
// reference (an index of tri_texels; NO_REF for none) and `err` a bound on
// |hit.t - its exact t|: intersect_leaf orders hits within each other's bounds
// by float-float t. `needs_careful`: the fast pass met what it leaves to the careful pass
// (see careful_pass), so this trace's answer is not written. The member order
// matters to the compiler only (it orders the loops' phis): this one keeps the
// kernels' instruction counts closest to those of per-invocation globals, which
// the members replace (docs/BENCH.md).
struct Closest {
    bool needs_careful;
    uint reference;
    float err;
    Hit hit;
};

// No hit yet, up to `tmax` (segment frame).
Closest closest_none(float tmax) {
    Closest best;
    best.hit = Hit(tmax, PRIM_MISS, 0.0, 0.0);
    best.reference = NO_REF;
    best.err = 0.0;
    best.needs_careful = false;
    return best;
}

// The farthest t at which the closest hit's exact t may lie: cells and stack
// entries beyond it cannot hold a closer hit (hit.t without ROBUST, or no hit).
float best_reach(Closest best) {
    return ROBUST ? best.hit.t + best.err : best.hit.t;
}

// True when a stack entry or a leaf that starts at `t0` cannot hold the closest
// hit: t0 lies at or behind its reach (NaN too). With ROBUST only once there is
// a hit: without one the reach is the segment's end, where a split plane
// through a hit exactly at tmax may round to, and the entry beyond it is clamped
// to start there (decide_children) and still holds that hit. (Without ROBUST as
// before: its instructions and hits unchanged.) CPU twin: State::starts_behind.
bool starts_behind(float t0, Closest best) {
    bool has_hit = !ROBUST || best.hit.prim_id != PRIM_MISS;
    return has_hit && !(t0 < best_reach(best));
}

// Tests the leaf's triangles, keeping the closest hit in `best` (t <= best.hit.t);
// any-hit mode stops at the first hit. Returns false when the driver cut a loop
// short (see trace.comp).
//
// The f32 tests come first. Two kinds of pairs they cannot decide go to a
// second pass exactly, in a loop of its own, which only the careful pass holds
// (lavapipe runs even a loop no lane enters under a mask, so in the fast pass
// the leaf only notes that the ray needs the careful pass):
// - unsure pairs (an edge function or a ray bound within rounding);
// - with ROBUST, depth ties: a hit whose f32 t lies within rounding of the
//   closest one's (far from the origin, surfaces a few ulps of t apart).
// The second pass orders its contenders by float-float t (a later one wins an exact
// tie, as in the f32 pass): the closest hit on entry (when its interval meets
// the closest one's after the f32 pass), that closest one, and the leaf's
// unsure pairs and, after a tie, its hits within the closest one's interval.
// It tests each again (same bits), so only references stay live across the
// f32 pass.
bool intersect_leaf(TraceRay r, uvec2 n, inout Closest best, inout TraceCounters c) {
    uint count = node_prim_count(n);
    uint offset = node_prim_offset(n);
    uint i = 0u;
    bool stopped = false;
    uint unsure = 0u;          // pairs left to the exact test
    uint first_unsure = count;
    bool tie = false;          // a hit within rounding of the closest one
    uint in_ref = best.reference;
    // Any-hit mode ends the loop by its condition, not by a `break`: on lavapipe a
    // divergent break here makes robust any-hit traversal much slower than closest
    // hit for the same work (see docs/BENCH.md).
    // A guarded do-while, not a for: lavapipe runs a loop's body once more under an
    // empty mask to find that every lane has left it, unless the test is at its end.
    if (count > 0u) do {
        vec3 v0, v1, v2;
        uint prim = load_triangle(offset + i, v0, v1, v2);
        float t, u, v, e;
        uint result = intersect_triangle_f32(r.wr, v0, v1, v2, seg_tmin(r), best_reach(best), t, u, v, e);
        if (result == TRI_HIT) {
            // [t - e, t + e] meets the closest hit's interval: order them by float-float t (unless
            // it is the same triangle, met again in another leaf: the same bits).
            // (has_best is a plain bool so that the && chain stays branch-free up to it.)
            bool has_best = best.reference != NO_REF;
            if (ROBUST && !ANY_HIT && has_best && prim != best.hit.prim_id && t + e >= best.hit.t - best.err) {
                tie = true;
            }
            if (t <= best.hit.t) {
                best.hit = Hit(t, prim, u, v);
                best.reference = offset + i;
                best.err = e;
                if (ANY_HIT) stopped = true;
            }
        } else if (result == TRI_UNSURE) {
            first_unsure = min(first_unsure, i);
            unsure += 1u;
        }
        ++i;
    } while (i < count && !(ANY_HIT && stopped));
    // A stop at triangle k leaves i = k + 1: the triangles tested.
    c.triangles += stopped ? i : count;
    bool complete = stopped || i == count;
    if (stopped) unsure = 0u;
    // Without ROBUST the f32 test is never unsure (and the pass below is dead code).
    // In the fast trace a leaf that needs the pass marks the ray to be traced
    // again (see careful_pass).
    if (!ROBUST || (unsure == 0u && !tie)) return complete;
    if (!careful_pass) {
        best.needs_careful = true;
        return complete;
    }

    // The second pass: j = -2 is the closest hit on entry, j = -1 the closest
    // after the f32 pass, j >= 0 the leaf's triangles.
    float window = best_reach(best);  // contenders start at or before it
    uint w_ref = best.reference;
    bool w_contends = !ANY_HIT && w_ref != NO_REF;
    int first = tie ? 0 : int(first_unsure);
    int j = (tie && in_ref != NO_REF && in_ref != w_ref) ? -2 : (w_contends ? -1 : first);
    vec2 bar = vec2(uintBitsToFloat(0x7f800000u), 0.0);  // float-float t of the closest contender
    for (; j < int(count) && (j < 0 || tie || unsure > 0u);
         j = j == -2 ? -1 : (j == -1 ? first : j + 1)) {
        uint ref = j == -2 ? in_ref : (j == -1 ? w_ref : offset + uint(j));
        vec3 v0, v1, v2;
        uint prim = load_triangle(ref, v0, v1, v2);
        float t, u, v, e;
        uint result = intersect_triangle_f32(r.wr, v0, v1, v2, seg_tmin(r), window, t, u, v, e);
        bool unsure_pair = result == TRI_UNSURE;
        if (unsure_pair && j >= 0) unsure -= 1u;
        if (!(unsure_pair || (result == TRI_HIT && (j < 0 || (tie && ref != w_ref))))) continue;
        float t_x, u_x, v_x, err_x;
        vec2 t_ff;
        if (!intersect_triangle_exact(r.wr, v0, v1, v2, r.tmin, t_x, u_x, v_x, t_ff, err_x)) {
            if (unsure_pair) continue;
            t_ff = vec2(t, 0.0);  // a certain f32 hit the exact test rejects: keep its f32 t
        }
        // An unsure pair takes the exact answer; a certain f32 hit keeps its f32 values.
        if (unsure_pair) {
            t = t_x;
            u = u_x;
            v = v_x;
            e = EDGE_GAMMA * abs(t_x) + err_x;
        }
        if (ff_le(t_ff, bar)) {
            bar = t_ff;
            best.hit = Hit(t, prim, u, v);
            best.reference = ref;
            best.err = e;
            if (ANY_HIT) unsure = 0u;
        }
    }
    return complete && unsure == 0u;
}

// True when the closest hit ends traversal at a segment ending at t1: any-hit
// found one, or the closest hit lies within the segment. Without a hit never (a
// leaf's rounded exit may pass tmax although a hit at tmax lies beyond it):
// traversal ends as for tmax = inf, on segments clipped to tmax (twin of
// Closest::done in leaf.rs).
bool leaf_done(Closest best, float t1) {
    return ANY_HIT ? best.hit.prim_id != PRIM_MISS : (best.hit.prim_id != PRIM_MISS && best_reach(best) <= t1);
}

// Visits a leaf whose segment ends at t1.
#define LEAF_GO_ON 0u   // no hit that ends traversal: go on behind the leaf
#define LEAF_DONE 1u    // any-hit found one, or the closest hit lies inside the leaf
#define LEAF_CUT 2u     // the driver cut the leaf loop short
uint visit_leaf(TraceRay r, uvec2 n, float t1, inout Closest best, inout TraceCounters c) {
    c.leaves += 1u;
    if (!intersect_leaf(r, n, best, c)) return LEAF_CUT;
    return leaf_done(best, t1) ? LEAF_DONE : LEAF_GO_ON;
}

// True while a descent goes on at node `n` (segment end t1): an interior node, or
// an empty leaf after which traversal goes on (visit_leaf would answer LEAF_GO_ON:
// no triangle to test, so the descent may pop the next entry itself).
bool descends(uvec2 n, float t1, Closest best) {
    if (!node_is_leaf(n)) return true;
    bool done = leaf_done(best, t1);  // before the &&, which would branch around a call
    return node_prim_count(n) == 0u && !done;
}

#endif
