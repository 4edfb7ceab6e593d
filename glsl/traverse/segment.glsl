// The ray as traversal sees it (TraceRay), in its segment frame, and the clip of
// its [tmin, tmax] to a box. CPU twin: src/kdtree/traverse/segment.rs.
//
// Expects from its includer: the specialization constant ROBUST (for
// triangle.glsl) and the constant SEGMENT_FRAME (true in the kernels that may
// shift a ray, see trace.comp).
#ifndef TRAVERSE_SEGMENT_GLSL
#define TRAVERSE_SEGMENT_GLSL

#include "triangle.glsl"

// Traversal runs in the ray's *segment frame*: t values measured from
// wr.seg_origin + wr.seg_lo = origin + wr.t_shift * dir, where t_shift is 0
// except for robust rays whose origin lies far outside the scene box (see
// shift_to_scene in trace.comp). There the origin is moved to a point just before the box
// (two f32, from an exact expansion), so that split decisions carry an error bound in scene
// space (t_err) instead of one relative to a huge t, and hits (best.hit.t and its
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

// The near bound widened down by |t| 3 2^-23, as the far one is widened up:
// compared with the ray's own tmax, a rounded entry could pass it and clip away
// a hit on the box's face (twin of widen_near in segment.rs; also the
// two-level kernel's instance boxes).
float widen_near(float t) {
    precise float y = t - abs(t) * 3.5762786865234375e-7;
    return y;
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

// The ray's tmin in the segment frame (the f32 triangle test's).
float seg_tmin(TraceRay r) {
    precise float t = r.tmin - r.wr.t_shift;
    return SEGMENT_FRAME ? t : r.tmin;
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
        float tnear = minus_err(r, widen_near(min(ta, tb)));
        precise float tfar_rel = max(ta, tb) * 1.0000003576278687;
        float tfar = plus_err(r, tfar_rel);
        t0 = max(t0, tnear);
        t1 = min(t1, tfar);
    }
    return t0 <= t1;
}

#endif
