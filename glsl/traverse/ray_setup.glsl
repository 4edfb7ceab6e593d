// The per-ray setup and finish of the trace kernels: a ray clipped to a box
// (the scene's, or a geometry's in object space), far rays moved next to it, the closed segment, and the hit
// written back in the ray's own parameter. trace_twolevel.comp calls setup_ray
// and final_hit; trace.comp writes their steps out (fewer instructions there)
// and shares the far-ray functions.
//
// Expects from its includer: the specialization constants ROBUST and PASS,
// SEGMENT_FRAME, FLT_MIN_NORMAL and FLT_MAX (triangle.glsl), and what leaf.glsl expects.
#ifndef TRAVERSE_RAY_SETUP_GLSL
#define TRAVERSE_RAY_SETUP_GLSL

#include "ray.glsl"
#include "ray_checks.glsl"
#include "ff.glsl"
#include "segment.glsl"
#include "leaf.glsl"

// Robust rays from far away (more than SHIFT_DIAGONALS scene diagonals before
// the box) move the segment frame's origin to a point p of the ray next to the
// box, so that decisions carry errors in scene space rather than relative to a
// huge t. p is the ray's point at t_shift, the f32 parameter where it crosses a
// plane c just before the box's near face on its dominant axis k (p lies within
// about sqrt(3) diagonals before the box entry): o + t_shift d summed exactly
// and rounded once to float-float, within about 2^-47 |p| of the ray at any
// distance (inputs scaled by powers of two so that no product overflows). The frame's t_shift is that point's parameter
// (c - o[k]) / d[k], rounded to f32.
// The f32 triangle test and the plane distances then work from hi + lo (see
// WatertightRay in triangle.glsl and plane_t in segment.glsl), with a per axis
// (a bound on |hi + lo - p| plus 2^-45 |hi| for the f32 subtraction of lo) in
// seg_err = |lo| + 2^20 a and t_err = max a / |d| over the axes the ray moves
// on; axes along which a / |d| would span a good part of the segment are flat
// (decided by position, within band). CPU twin: shift_to_scene in
// src/kdtree/traverse/mod.rs.
// Only the kernels that trace carefully hold this code (SEGMENT_FRAME): the fast
// pass lists far rays for the careful one, so near rays do not pay for it.
// Returns false when the ray misses the box after all.
bool shift_to_scene(inout TraceRay r, inout float t0, inout float t1, vec3 bmin, vec3 bmax) {
    uint k = r.wr.kz;
    vec3 o = r.wr.origin;
    vec3 d = r.dir;
    // A plane a little before the near face (1/128 of the box's extent, or of
    // |face| for a flat box), so that the new frame's origin never lies on the
    // box's boundary: the walk from there enters the box as a near ray does.
    precise float margin = (bmax[k] - bmin[k]) * (1.0 / 128.0) + abs(bmin[k]) * (1.0 / 1048576.0) +
                           abs(bmax[k]) * (1.0 / 1048576.0) + FLT_MIN_NORMAL;
    precise float c_below = bmin[k] - margin;
    precise float c_above = bmax[k] + margin;
    float c = d[k] > 0.0 ? c_below : c_above;
    // Scaled inputs: d[k] in [1, 2), the origin and c below 2^100 (Veltkamp's
    // split overflows above 2^113).
    int eq = exponent_of(abs(d[k]));
    float om = max(max(abs(o.x), abs(o.y)), max(abs(o.z), abs(c)));
    int eo = max(exponent_of(om) - 99, 0);
    precise vec3 ds = vec3(ldexp2(d.x, -eq), ldexp2(d.y, -eq), ldexp2(d.z, -eq));
    precise vec3 os = vec3(ldexp2(o.x, -eo), ldexp2(o.y, -eo), ldexp2(o.z, -eo));
    float cs = ldexp2(c, -eo);
    // The frame's origin is the ray's point at t_shift, the f32 nearest to
    // (c - o[k]) / d[k]: p = o + t_shift d, summed exactly per axis (an exact
    // expansion: the far origin's huge terms cancel without loss) and rounded once
    // to float-float, so p lies on the ray within about 2^-47 |p| per axis, at
    // exactly the parameter t_shift (which the f32 tests subtract from tmin and
    // tmax). Scaled: o by 2^-eo and d by 2^-eq, so t_shift by 2^(eq - eo).
    vec2 t_scaled = ff_div(ff_diff(cs, os[k]), vec2(ds[k], 0.0));
    float t_shift = ldexp2(t_scaled.x, eo - eq);
    float ts = ldexp2(t_shift, eq - eo);
    vec3 hi, lo, a;
    [[unroll]] for (uint j = 0u; j < 3u; ++j) {
        vec2 step = ff_two_prod(ts, ds[j]);
        vec2 p = ff_ldexp(ff_exact_sum8(float[8](os[j], step.x, step.y, 0.0, 0.0, 0.0, 0.0, 0.0)), eo);
        hi[j] = p.x;
        lo[j] = p.y;
        // 2^-45 |p| (the rounding to float-float, with margin) and the error terms
        // a flushing device drops.
        precise float aj = abs(p.x) * (1.0 / 35184372088832.0) + ldexp2(1.0, eo - 120);  // 2^-45
        a[j] = aj;
    }
    // Flat axes: where a / |d| would exceed T_EPS s_max, s_max a bound on |t| over
    // the segment in the new frame (from p to the clip's t1, plus rounding).
    // There the ray's coordinate stays within band = a + |d| s_max of hi + lo.
    precise float s_max = (t1 - t_shift) + abs(t1) * (1.0 / 1048576.0);  // 2^-20
    float e = 0.0;
    r.flat_axes = 0u;
    r.band = vec3(0.0);
    [[unroll]] for (uint axis = 0u; axis < 3u; ++axis) {
        if (r.dir[axis] == 0.0) continue;
        precise float limit = T_EPS * s_max * abs(d[axis]);
        if (a[axis] > limit) {
            r.flat_axes |= 1u << axis;
            precise float band = (a[axis] + abs(d[axis]) * s_max) * 1.000001;
            r.band[axis] = band;
        } else {
            precise float ea = a[axis] * (1.0 / abs(d[axis]));
            e = max(e, ea);
        }
    }
    precise float t_err = e * 1.000001;
    r.t_err = max(t_err, FLT_MIN_NORMAL);
    r.wr.seg_origin = hi;
    r.wr.seg_lo = lo;
    precise vec3 seg_err = abs(lo) + a * 1048576.0;  // 2^20
    r.wr.seg_err = seg_err;
    r.wr.t_shift = t_shift;
    precise float seg_tmax = r.tmax - t_shift;
    r.wr.seg_tmax = seg_tmax;
    return clip_to_box(r, bmin, bmax, t0, t1);
}

// The next float above x (FLT_MIN above a zero; infinities and NaN unchanged).
// CPU twin: next_up in src/kdtree/traverse/mod.rs.
float next_up(float x) {
    if (isinf(x) || isnan(x)) return x;
    if (x == 0.0) return FLT_MIN_NORMAL;
    uint bits = floatBitsToUint(x);
    return uintBitsToFloat(x > 0.0 ? bits + 1u : bits - 1u);
}

// True when the box entry t0 lies more than SHIFT_DIAGONALS scene diagonals
// along the ray (squared lengths: no sqrt, whose rounding GPUs do not fix).
// Lengths are scaled by the power of two that brings the box's largest extent
// to [1, 2), exactly: the squares of a scene's extents above about 1e19
// overflowed f32 (no ray was far, so none was shifted, and far rays' hits
// tied in t) and those below about 1e-19 underflowed.
bool is_far(TraceRay r, float t0, vec3 bmin, vec3 bmax) {
    precise vec3 ext = bmax - bmin;
    int s = exponent_of(max(ext.x, max(ext.y, ext.z)));
    precise vec3 e = vec3(ldexp2(ext.x, -s), ldexp2(ext.y, -s), ldexp2(ext.z, -s));
    precise float diag2 = e.x * e.x + e.y * e.y + e.z * e.z;
    vec3 ad = abs(r.dir);
    precise float dist = ldexp2(t0 * max(ad.x, max(ad.y, ad.z)), -s);
    precise float far2 = float(SHIFT_DIAGONALS * SHIFT_DIAGONALS) * diag2;
    return t0 > 0.0 && dist * dist > far2;
}

// Sets up the traversal of `ray` through the box [bmin, bmax]: the ray's
// TraceRay, its segment [t0, t1] in the box and, for a far robust ray in the
// kernels that trace carefully, the segment frame next to the box (best's bound
// moves with it). `valid`: the ray passed ray_is_valid (the caller marks an
// invalid one); `far`: it starts more than SHIFT_DIAGONALS diagonals before the
// box. Returns whether it enters the box.
bool setup_ray(Ray ray, vec3 bmin, vec3 bmax, out TraceRay r, out float t0, out float t1, out bool valid,
               out bool far, inout Closest best) {
    ray.dir = traced_dir(ray.dir);
    valid = ray_is_valid(ray);
    r.dir = ray.dir;
    // Clamped so that a plane through the origin gives t = 0, never 0 * inf = NaN.
    r.inv_dir = clamp(1.0 / ray.dir, vec3(-FLT_MAX), vec3(FLT_MAX));
    r.tmin = ray.tmin;
    r.tmax = ray.tmax;
    r.t_err = 0.0;
    r.flat_axes = 0u;
    r.band = vec3(0.0);
    r.wr = watertight_ray(ray.origin, ray.dir);
    r.wr.ray_tmax = ray.tmax;
    r.wr.seg_tmax = ray.tmax;
    t0 = 0.0;
    t1 = 0.0;
    bool alive = valid && clip_to_box(r, bmin, bmax, t0, t1);
    far = ROBUST && alive && is_far(r, t0, bmin, bmax);
    if (SEGMENT_FRAME && far) {
        alive = shift_to_scene(r, t0, t1, bmin, bmax);
        precise float best_seg = ray.tmax - r.wr.t_shift;
        best.hit.t = best_seg;  // the segment frame, like every hit below
    }
    // A closed segment: the robust mode keeps a cell that starts exactly where the
    // segment ends (a triangle lying in the plane through which the ray reaches
    // tmax or leaves the box): the segment and the no-hit bound end one float
    // later, and the triangle tests still check the ray's own tmax exactly.
    if (ROBUST && alive) {
        t1 = next_up(t1);
        best.hit.t = next_up(best.hit.t);
    }
    return alive;
}

// The hit a traversal leaves in `best`, as written: PRIM_INCOMPLETE when it did
// not finish, `t` back in the ray's own parameter, and the special prim_ids'
// t (inf for a miss, NaN otherwise), u and v.
Hit final_hit(Closest best, TraceRay r, bool finished) {
    Hit hit = best.hit;
    if (!finished && hit.prim_id != PRIM_INVALID) hit.prim_id = PRIM_INCOMPLETE;
    // Back to the ray's own parameter (one rounding: an f32 sum is correctly rounded).
    precise float t_own = hit.t + r.wr.t_shift;
    if (SEGMENT_FRAME && r.wr.t_shift != 0.0) hit.t = t_own;
    if (hit.prim_id >= PRIM_INCOMPLETE) {
        hit.t = hit.prim_id == PRIM_MISS ? uintBitsToFloat(0x7f800000u) : uintBitsToFloat(0x7fc00000u);
        hit.u = 0.0;
        hit.v = 0.0;
    }
    return hit;
}

#endif
