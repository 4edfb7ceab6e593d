// Pieces every traversal variant shares: the per-ray state, clipping to the scene
// box, the child decision at an interior node and the leaf loop. Included by
// trace.comp after the buffers are declared. The CPU twins are in
// src/kdtree/traverse.rs; both must change together.
#ifndef TRAVERSE_COMMON_GLSL
#define TRAVERSE_COMMON_GLSL

// Traversal runs in the ray's *segment frame*: t values measured from
// wr.seg_origin + wr.seg_lo = origin + wr.t_shift * dir, where t_shift is 0
// except for robust rays whose origin lies far outside the scene box (see
// shift_to_scene in trace.comp). There the origin is moved to the box entry
// (two f32, from f64), so that split decisions carry an error bound in scene
// space (t_err) instead of one relative to a huge t, and hits (best.t and its
// bound, the f32 triangle test) are in the same frame; tmin and tmax stay the
// ray's own, and trace.comp converts the hit back when it writes it. The frame
// is defined once, in `wr` (WatertightRay, triangle.glsl).
struct TraceRay {
    WatertightRay wr;
    vec3 dir;
    vec3 inv_dir;
    float tmin;   // the ray's own bounds: a hit must lie in [tmin, tmax]
    float tmax;
    float t_err;    // absolute error bound of a segment-frame plane distance
    // Axes along which a shifted ray moves so little that t_err would span a good
    // part of the scene (bit per axis): their planes are decided by position
    // instead, against the band of coordinates the ray may occupy (see
    // flat_side), and never bound a segment.
    uint flat_axes;
    vec3 band;
};

bool is_flat(TraceRay r, uint axis) {
    return SEGMENT_FRAME && ((r.flat_axes >> axis) & 1u) != 0u;
}

// On a flat axis: -1 when the ray stays below `plane` (its whole band of
// coordinates), +1 when above, 0 when the band reaches the plane.
int flat_side(TraceRay r, uint axis, float plane) {
    precise float gap = (plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis];
    return gap > r.band[axis] ? -1 : (gap < -r.band[axis] ? 1 : 0);
}

// Distance (segment frame) along the ray to the plane `axis` = `plane`. With
// seg_lo = 0 both forms give the same bits; kernels without SEGMENT_FRAME skip
// the subtraction (lavapipe would run it).
float plane_t(TraceRay r, uint axis, float plane) {
    precise float shifted = (plane - r.wr.seg_origin[axis]) - r.wr.seg_lo[axis];
    precise float t = (SEGMENT_FRAME ? shifted : plane - r.wr.seg_origin[axis]) * r.inv_dir[axis];
    return t;
}

// x widened down / up by t_err (0 when not shifted) in the kernels with
// SEGMENT_FRAME (see trace.comp); x itself in the others, at no cost.
float minus_err(TraceRay r, float x) {
    precise float y = x - r.t_err;
    return SEGMENT_FRAME ? y : x;
}
float plus_err(TraceRay r, float x) {
    precise float y = x + r.t_err;
    return SEGMENT_FRAME ? y : x;
}

// A stack entry's segment [t0, t1] as one 64-bit word (the bits of both floats,
// no float64 arithmetic): lavapipe stores and loads a private array lane by lane,
// so one 64-bit array costs half of two 32-bit ones.
double seg_pack(float t0, float t1) {
    return packDouble2x32(uvec2(floatBitsToUint(t0), floatBitsToUint(t1)));
}
void seg_unpack(double seg, out float t0, out float t1) {
    uvec2 w = unpackDouble2x32(seg);
    t0 = uintBitsToFloat(w.x);
    t1 = uintBitsToFloat(w.y);
}
float seg_t0(double seg) {
    return uintBitsToFloat(unpackDouble2x32(seg).x);
}
// The empty segment [inf, -inf].
#define EMPTY_SEG packDouble2x32(uvec2(0x7f800000u, 0xff800000u))

// Per-ray counters (kept even when COUNTERS is off; the compiler drops dead stores).
struct TraceCounters {
    uint nodes;
    uint leaves;
    uint triangles;
    uint restarts;
    uint steps;
    uint drops;
};

// Loads a node (see trace.comp for the texel layout).
uvec2 load_node(uint node) {
    return imageLoad(node_texels, int(node)).xy;
}

// Fetches a node, counting the visit and the loop step.
uvec2 fetch_node(uint node, inout TraceCounters c) {
    c.steps += 1u;
    c.nodes += 1u;
    return load_node(node);
}

// Clip [ray.tmin, ray.tmax] to the scene box (slab test). A zero direction
// component constrains nothing unless the origin lies outside that slab.
// The far bound is widened by 1 + 2*gamma(3) (Ize 2013) so rounding never
// clips away a hit on the box boundary.
// In the segment frame, the bounds widen by t_err too (0 unless shifted).
bool clip_to_box(TraceRay r, vec3 bmin, vec3 bmax, out float t0, out float t1) {
    precise float tmin_seg = r.tmin - r.wr.t_shift;
    precise float tmax_seg = r.tmax - r.wr.t_shift;
    t0 = SEGMENT_FRAME ? tmin_seg : r.tmin;
    t1 = SEGMENT_FRAME ? tmax_seg : r.tmax;
    // Unrolled: lavapipe runs a loop's exit pass, and indexes vectors by a variable
    // with selects.
    [[unroll]] for (uint axis = 0u; axis < 3u; ++axis) {
        float o = r.wr.seg_origin[axis];
        if (r.dir[axis] == 0.0) {
            if (o < bmin[axis] || o > bmax[axis]) return false;
            continue;
        }
        if (is_flat(r, axis)) {
            if (flat_side(r, axis, bmin[axis]) < 0 || flat_side(r, axis, bmax[axis]) > 0) return false;
            continue;
        }
        float ta = plane_t(r, axis, bmin[axis]);
        float tb = plane_t(r, axis, bmax[axis]);
        float tnear = minus_err(r, min(ta, tb));
        precise float tfar_rel = max(ta, tb) * 1.0000003576278687;
        float tfar = plus_err(r, tfar_rel);
        t0 = max(t0, tnear);
        t1 = min(t1, tfar);
    }
    return t0 <= t1;
}

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

// Exact restarts (ROBUST; `restart`, `push-down` and a short stack run empty):
// instead of starting again at a t value - at a vertex or edge of cells several
// leaves end within one float of each other, and a t cannot order them - find the
// entry a full stack would pop after the leaf just left. The traversal seeks it in
// its own descent loop (one loop, so SIMD lanes that seek and lanes that descend
// share it): from the restart node (an ancestor of the leaf with no pending entry
// above it, whose stack segment it knows) along the path to the leaf, with the
// stack's own decisions; the entry is the far child of the deepest node where the
// path took the near side of a split that needed both children. `done`: the leaf
// held the closest hit, and only entries that start before it count (the stack's
// drop rule). `known`: how many entries are pending on that path; the seek ends at
// the last of them (the deepest), so it descends no deeper than a kd-restart to
// the same entry. CPU twin: `stack_successor` in src/kdtree/traverse.rs.
struct Seek {
    bool seeking;
    uint target;  // the leaf just left
    bool done;
    uint known;
    uint seen;    // pending entries met so far
    bool found;
    uint next;    // the entry: node, stack segment, entries pending above it
    float next_t0;
    float next_t1;
    uint above;
};

// A seek for the entry after leaf `target`; none (not seeking) when known is 0.
Seek seek_start(uint target, bool done, uint known) {
    Seek k;
    k.seeking = known > 0u;
    k.target = target;
    k.done = done;
    k.known = known;
    k.seen = 0u;
    k.found = false;
    k.next = 0u;
    k.next_t0 = 0.0;
    k.next_t1 = 0.0;
    k.above = 0u;
    return k;
}

// One node of the seek: notes the entry a decision leaves (if any), keeps the
// stack's segment in t0, t1, and returns the child on the path. Ends the seek
// (k.seeking = false) at the last known entry or at the leaf.
uint seek_step(inout Seek k, uint node, uvec2 n, uint visit, uint near, uint far, float ts, inout float t0,
               inout float t1, float best_t) {
    uint child = k.target >= node_above_child(n) ? node_above_child(n) : node + 1u;
    if (visit == VISIT_BOTH || visit == VISIT_BOTH_SAME) {
        float far_t0 = visit == VISIT_BOTH ? ts : t0;
        if (child == near) {
            if (!k.done || far_t0 < best_t) {
                k.found = true;
                k.next = far;
                k.next_t0 = far_t0;
                k.next_t1 = t1;
                k.above = k.seen;
            }
            k.seen += 1u;
            if (visit == VISIT_BOTH) t1 = ts;
        } else {
            t0 = far_t0;
        }
    }
    if (k.seen == k.known || child == k.target) k.seeking = false;
    return child;
}

// Loads the triangle of the leaf reference `index` (stored in prim_indices
// order, the prim id inline).
uint load_triangle(uint index, out vec3 v0, out vec3 v1, out vec3 v2) {
    int base = int(index) * 3;
    uvec4 a = imageLoad(tri_texels, base);
    v0 = uintBitsToFloat(a.xyz);
    v1 = uintBitsToFloat(imageLoad(tri_texels, base + 1).xyz);
    v2 = uintBitsToFloat(imageLoad(tri_texels, base + 2).xyz);
    return a.w;
}

// Robust single rays are traced in two passes (trace.comp, src/trace.rs): a fast
// pass whose leaves skip the f64 pass below and only note that a pair needed it
// (and whose `backtrack` and `ropes` note where they would fall back to exact
// restarts), then, in a second dispatch over the rays so noted, a careful trace
// from scratch. Packets and the plain kernels trace once (careful_pass true).
// lavapipe runs every branch and loop of a kernel under a mask whether or not a
// lane enters it, so code a kernel holds costs in every subgroup: the leaf's f64
// pass, needed in about 1 leaf in 4000, cost 44 % of robust `stack`'s
// instructions in every leaf (bunny, random rays), and a careful copy in the same
// kernel as the fast one 14 % (bunny, camera rays). The careful
// trace decides everything the fast one decided the same way, so hits and
// counters are those of a single careful trace (the CPU twins').
const bool careful_pass = PASS != PASS_FAST;
bool needs_careful = false;

// The closest hit's triangle reference (an index of tri_texels; NO_REF for none)
// and a bound on |best.t - its exact t|, per invocation like `best` itself:
// intersect_leaf orders hits within each other's bounds in f64.
#define NO_REF 0xffffffffu
uint best_ref = NO_REF;
float best_err = 0.0;

// The farthest t at which the closest hit's exact t may lie: cells and stack
// entries beyond it cannot hold a closer hit (best.t without ROBUST, or no hit).
float best_reach(Hit best) {
    return ROBUST ? best.t + best_err : best.t;
}

// The ray's tmin in the segment frame (the f32 triangle test's).
float seg_tmin(TraceRay r) {
    precise float t = r.tmin - r.wr.t_shift;
    return SEGMENT_FRAME ? t : r.tmin;
}

// Tests the leaf's triangles, keeping the closest hit in `best` (t <= best.t);
// any-hit mode stops at the first hit. Returns false when the driver cut a loop
// short (see trace.comp).
//
// The f32 tests come first. Two kinds of pairs they cannot decide go to a
// second pass in f64, in a loop of its own, which only the careful pass holds
// (lavapipe runs even a loop no lane enters under a mask, so in the fast pass
// the leaf only notes that the ray needs the careful pass):
// - unsure pairs (an edge function or a ray bound within rounding);
// - with ROBUST, depth ties: a hit whose f32 t lies within rounding of the
//   closest one's (far from the origin, surfaces a few ulps of t apart).
// The second pass orders its contenders by f64 t (a later one wins an exact
// tie, as in the f32 pass): the closest hit on entry (when its interval meets
// the closest one's after the f32 pass), that closest one, and the leaf's
// unsure pairs and, after a tie, its hits within the closest one's interval.
// It tests each again (same bits), so only references stay live across the
// f32 pass.
bool intersect_leaf(TraceRay r, uvec2 n, inout Hit best, inout TraceCounters c) {
    uint count = node_prim_count(n);
    uint offset = node_prim_offset(n);
    uint i = 0u;
    bool stopped = false;
    uint unsure = 0u;          // pairs left to f64
    uint first_unsure = count;
    bool tie = false;          // a hit within rounding of the closest one
    uint in_ref = best_ref;
    // Any-hit mode ends the loop by its condition, not by a `break`: on lavapipe a
    // divergent break here made robust any-hit traversal 1.6x slower than closest
    // hit for the same work (measured on Cornell box shadow rays).
    // A guarded do-while, not a for: lavapipe runs a loop's body once more under an
    // empty mask to find that every lane has left it, unless the test is at its end.
    if (count > 0u) do {
        vec3 v0, v1, v2;
        uint prim = load_triangle(offset + i, v0, v1, v2);
        float t, u, v, e;
        uint result = intersect_triangle_f32(r.wr, v0, v1, v2, seg_tmin(r), best_reach(best), t, u, v, e);
        if (result == TRI_HIT) {
            // [t - e, t + e] meets the closest hit's interval: order them in f64 (unless
            // it is the same triangle, met again in another leaf: the same bits).
            if (ROBUST && !ANY_HIT && best_ref != NO_REF && prim != best.prim_id && t + e >= best.t - best_err) {
                tie = true;
            }
            if (t <= best.t) {
                best = Hit(t, prim, u, v);
                best_ref = offset + i;
                best_err = e;
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
        needs_careful = true;
        return complete;
    }

    // The second pass: j = -2 is the closest hit on entry, j = -1 the closest
    // after the f32 pass, j >= 0 the leaf's triangles.
    float window = best_reach(best);  // contenders start at or before it
    uint w_ref = best_ref;
    bool w_contends = !ANY_HIT && w_ref != NO_REF;
    int first = tie ? 0 : int(first_unsure);
    int j = (tie && in_ref != NO_REF && in_ref != w_ref) ? -2 : (w_contends ? -1 : first);
    double bar = double(uintBitsToFloat(0x7f800000u));  // f64 t of the closest contender
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
        float t_f64, u_f64, v_f64, err64;
        double t64;
        if (!intersect_triangle_f64(r.wr, v0, v1, v2, r.tmin, t_f64, u_f64, v_f64, t64, err64)) {
            if (unsure_pair) continue;
            t64 = double(t);  // a certain f32 hit the f64 test rejects: keep its f32 t
        }
        // An unsure pair takes the f64 answer; a certain f32 hit keeps its f32 values.
        if (unsure_pair) {
            t = t_f64;
            u = u_f64;
            v = v_f64;
            e = EDGE_GAMMA * abs(t_f64) + err64;
        }
        if (t64 <= bar) {
            bar = t64;
            best = Hit(t, prim, u, v);
            best_ref = ref;
            best_err = e;
            if (ANY_HIT) unsure = 0u;
        }
    }
    return complete && unsure == 0u;
}

// Visits a leaf whose segment ends at t1.
#define LEAF_GO_ON 0u   // no hit that ends traversal: go on behind the leaf
#define LEAF_DONE 1u    // any-hit found one, or the closest hit lies inside the leaf
#define LEAF_CUT 2u     // the driver cut the leaf loop short
uint visit_leaf(TraceRay r, uvec2 n, float t1, inout Hit best, inout TraceCounters c) {
    c.leaves += 1u;
    if (!intersect_leaf(r, n, best, c)) return LEAF_CUT;
    bool done = ANY_HIT ? best.prim_id != PRIM_MISS : best_reach(best) <= t1;
    return done ? LEAF_DONE : LEAF_GO_ON;
}

// True while a descent goes on at node `n` (segment end t1): an interior node, or
// an empty leaf after which traversal goes on (visit_leaf would answer LEAF_GO_ON:
// no triangle to test, so the descent may pop the next entry itself).
bool descends(uvec2 n, float t1, Hit best) {
    if (!node_is_leaf(n)) return true;
    bool done = ANY_HIT ? best.prim_id != PRIM_MISS : best_reach(best) <= t1;
    return node_prim_count(n) == 0u && !done;
}

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
