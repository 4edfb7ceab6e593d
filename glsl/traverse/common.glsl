// Pieces every traversal variant shares: the per-ray state, clipping to the scene
// box, the child decision at an interior node and the leaf loop. Included by
// trace.comp after the buffers are declared. The CPU twins are in
// src/kdtree/traverse.rs; both must change together.
#ifndef TRAVERSE_COMMON_GLSL
#define TRAVERSE_COMMON_GLSL

struct TraceRay {
    WatertightRay wr;
    vec3 origin;
    vec3 dir;
    vec3 inv_dir;
    float tmin;   // the ray's own bounds: a hit must lie in [tmin, tmax]
    float tmax;
};

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
    return texelFetch(node_texels, int(node)).xy;
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
bool clip_to_box(TraceRay r, vec3 bmin, vec3 bmax, out float t0, out float t1) {
    t0 = r.tmin;
    t1 = r.tmax;
    for (uint axis = 0u; axis < 3u; ++axis) {
        float o = r.origin[axis];
        if (r.dir[axis] == 0.0) {
            if (o < bmin[axis] || o > bmax[axis]) return false;
            continue;
        }
        precise float ta = (bmin[axis] - o) * r.inv_dir[axis];
        precise float tb = (bmax[axis] - o) * r.inv_dir[axis];
        float tnear = min(ta, tb);
        precise float tfar = max(ta, tb) * 1.0000003576278687;
        t0 = max(t0, tnear);
        t1 = min(t1, tfar);
    }
    return t0 <= t1;
}

// Which children of an interior node the segment [t0, t1] needs.
// `near` is the child the ray is in for t < t_split (chosen by the direction's
// sign bit, so -0.0 and origins on the plane are handled without ties).
#define VISIT_NEAR 0u
#define VISIT_FAR 1u
#define VISIT_BOTH 2u
#define VISIT_BOTH_SAME 3u   // ray lies in the split plane: both children, same interval

uint decide_children(TraceRay r, uint node, uvec2 n, float t0, float t1, bool ties_go_far,
                     out uint near, out uint far, out float t_split) {
    uint axis = node_axis(n);
    float split = node_split(n);
    float o = r.origin[axis];
    float d = r.dir[axis];
    bool below_first = (floatBitsToUint(d) >> 31u) == 0u;
    uint below = node + 1u;
    uint above = node_above_child(n);
    near = below_first ? below : above;
    far = below_first ? above : below;
    precise float ts = (split - o) * r.inv_dir[axis];
    t_split = ts;
    if (d == 0.0 && o == split) return VISIT_BOTH_SAME;
    if (ts > t1) return VISIT_NEAR;
    if (ts < t0 || (ties_go_far && ts == t0)) return VISIT_FAR;
    return VISIT_BOTH;
}

// Tests the leaf's triangles, keeping the closest hit in `best` (t <= best.t);
// any-hit mode stops at the first hit. Returns false when the driver cut the
// loop short (see trace.comp).
bool intersect_leaf(TraceRay r, uvec2 n, inout Hit best, inout TraceCounters c) {
    uint count = node_prim_count(n);
    uint offset = node_prim_offset(n);
    uint i = 0u;
    bool stopped = false;
    for (; i < count; ++i) {
        // The leaf's references are stored in prim_indices order, the prim id inline.
        int base = int(offset + i) * 3;
        uvec4 a = texelFetch(tri_texels, base);
        vec3 v0 = uintBitsToFloat(a.xyz);
        vec3 v1 = uintBitsToFloat(texelFetch(tri_texels, base + 1).xyz);
        vec3 v2 = uintBitsToFloat(texelFetch(tri_texels, base + 2).xyz);
        uint prim = a.w;
        float t, u, v;
        if (intersect_triangle(r.wr, v0, v1, v2, r.tmin, best.t, t, u, v)) {
            best.t = t;
            best.prim_id = prim;
            best.u = u;
            best.v = v;
            if (ANY_HIT) {
                stopped = true;
                break;
            }
        }
    }
    c.triangles += stopped ? i + 1u : count;
    return stopped || i == count;
}

// Visits a leaf whose segment ends at t1.
#define LEAF_GO_ON 0u   // no hit that ends traversal: go on behind the leaf
#define LEAF_DONE 1u    // any-hit found one, or the closest hit lies inside the leaf
#define LEAF_CUT 2u     // the driver cut the leaf loop short
uint visit_leaf(TraceRay r, uvec2 n, float t1, inout Hit best, inout TraceCounters c) {
    c.leaves += 1u;
    if (!intersect_leaf(r, n, best, c)) return LEAF_CUT;
    bool done = ANY_HIT ? best.prim_id != PRIM_MISS : best.t <= t1;
    return done ? LEAF_DONE : LEAF_GO_ON;
}

// Distance at which the ray leaves a node box (side buffer node_boxes): the
// nearest far plane; `face` is 2*axis (+1 for the max face). Axes with a zero
// direction component never end the segment.
float box_exit(TraceRay r, uint node, out uint face) {
    float t_exit = uintBitsToFloat(0x7f800000u);
    face = 0u;
    for (uint axis = 0u; axis < 3u; ++axis) {
        float d = r.dir[axis];
        if (d == 0.0) continue;
        bool positive = d > 0.0;
        float plane = node_boxes[node * 6u + axis + (positive ? 3u : 0u)];
        precise float t = (plane - r.origin[axis]) * r.inv_dir[axis];
        if (t < t_exit) {
            t_exit = t;
            face = 2u * axis + (positive ? 1u : 0u);
        }
    }
    return t_exit;
}

#endif
