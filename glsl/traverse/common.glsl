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
};

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

// Tests the leaf's triangles, keeping the closest hit in `best` (t <= best.t).
// Returns false when the driver cut the loop short (see trace.comp).
bool intersect_leaf(TraceRay r, uvec2 n, inout Hit best, inout TraceCounters c) {
    uint count = node_prim_count(n);
    uint offset = node_prim_offset(n);
    uint i = 0u;
    for (; i < count; ++i) {
        uint prim = prim_indices[offset + i];
        uint base = prim * 9u;
        vec3 v0 = vec3(tri_verts[base + 0u], tri_verts[base + 1u], tri_verts[base + 2u]);
        vec3 v1 = vec3(tri_verts[base + 3u], tri_verts[base + 4u], tri_verts[base + 5u]);
        vec3 v2 = vec3(tri_verts[base + 6u], tri_verts[base + 7u], tri_verts[base + 8u]);
        float t, u, v;
        if (intersect_triangle(r.wr, v0, v1, v2, r.tmin, best.t, t, u, v)) {
            best.t = t;
            best.prim_id = prim;
            best.u = u;
            best.v = v;
        }
    }
    c.triangles += count;
    return i == count;
}

#endif
