// Watertight ray/triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)) with an
// exact fallback near edges (float-float arithmetic on f32, ff.glsl: no kernel
// uses a 64-bit type). The CPU twin is `WatertightRay` in src/geom.rs: same
// operations in the same order, so both give the same bits. `precise` forbids the
// compiler from fusing into FMAs.
//
// Near an edge the f32 edge function's sign is decided by rounding (translation,
// shear and products each lose ~2^-24 of the coordinates' magnitude), so a ray
// passing within a few ulps of an edge may hit the wrong one of two neighbours.
// Each edge function gets an error bound (the sheared coordinates' errors,
// EDGE_GAMMA times their magnitudes before cancellation, carried through its two
// products, with a margin of about 6); when any edge function
// lies within its bound, the whole test is redone exactly on the f32 inputs
// (intersect_triangle_exact: each sheared coordinate an exact expansion rounded
// once to 48 bits), whose signs are those of the exact edge functions unless the
// ray passes within about 2^-46 of the edge; within 2^-40 the sign comes from an
// exact orientation (edge_sign_exact: det[v_i - o, v_j - o, d] as an exact
// expansion), exact unless the ray passes within 2^-100 of the edge. Watertightness
// is kept: a shared edge's f32 sign outside its bound is the exact sign, and
// every form negates exactly when the edge is reversed.
#ifndef TRIANGLE_GLSL
#define TRIANGLE_GLSL

#include "ff.glsl"

// The exact test works from `origin`, in the ray's own parameter. The f32 test
// works in the segment frame (TraceRay in traverse/segment.glsl): from the point
// seg_origin + seg_lo = origin + t_shift * dir (a far ray moved to the scene
// box), answering t - t_shift; seg_err bounds, per axis and divided by
// EDGE_GAMMA, how far that point may lie from the exact one. Unshifted:
// seg_origin = origin and the rest 0. CPU twin: WatertightRay in src/geom.rs.
struct WatertightRay {
    uint kx, ky, kz;
    float sx, sy, sz;
    vec3 origin;
    vec3 seg_origin;
    vec3 seg_lo;
    vec3 seg_err;
    float t_shift;
    vec3 dir;
    float ray_tmax;  // the ray's own tmax (the tmax argument of a test is the closest hit so far)
    float seg_tmax;  // ray_tmax - t_shift
};

WatertightRay watertight_ray(vec3 origin, vec3 dir) {
    vec3 a = abs(dir);
    uint kz = 0u;
    if (a.y > a[kz]) kz = 1u;
    if (a.z > a[kz]) kz = 2u;
    uint kx = (kz + 1u) % 3u;
    uint ky = (kx + 1u) % 3u;
    if (dir[kz] < 0.0) { uint tmp = kx; kx = ky; ky = tmp; }
    WatertightRay r;
    r.kx = kx; r.ky = ky; r.kz = kz;
    precise float sz = 1.0 / dir[kz];
    r.sz = sz;
    precise float sx = dir[kx] * sz;
    precise float sy = dir[ky] * sz;
    r.sx = sx; r.sy = sy;
    r.origin = origin;
    r.seg_origin = origin;
    r.seg_lo = vec3(0.0);
    r.seg_err = vec3(0.0);
    r.t_shift = 0.0;
    r.dir = dir;
    r.ray_tmax = uintBitsToFloat(0x7f800000u);
    r.seg_tmax = r.ray_tmax;
    return r;
}

// The smallest normal and the largest finite f32 (also for the traversal code
// of the kernels that include this file).
const float FLT_MIN_NORMAL = 1.17549435e-38;
const float FLT_MAX = 3.40282347e38;

// The error bound of an f32 edge function relative to its terms' magnitude
// (EDGE_GAMMA_LOG2 from src/consts.rs).
const float EDGE_GAMMA = 1.0 / float(1u << EDGE_GAMMA_LOG2);

// The exponent e of x = m 2^e, m in [1, 2) (0 for x = 0; x normal).
int exponent_of(float x) {
    return x == 0.0 ? 0 : int((floatBitsToUint(x) >> 23) & 0xffu) - 127;
}

// 2^k for k in [-126, 127] (clamped to it), from its bits.
float pow2(int k) {
    return uintBitsToFloat(uint(clamp(k, -126, 127) + 127) << 23);
}

// x 2^k for k in [-252, 254], in two exact steps (barring overflow and underflow).
vec2 ff_ldexp(vec2 x, int k) {
    int k1 = k / 2;
    precise vec2 y = (x * pow2(k1)) * pow2(k - k1);
    return y;
}
float ldexp2(float x, int k) {
    int k1 = k / 2;
    precise float y = (x * pow2(k1)) * pow2(k - k1);
    return y;
}

// Which side of the bound b 2^k the quotient num / den lies on (den.x != 0):
// negative below, 0 on it, positive above, from the sign of num - b 2^k den. The
// exact test has |num| < 2^8 and |den| >= 2^-149; a huge finite bound (tmax =
// 3e38 on a small scene) would overflow b 2^k, so both terms are scaled by a
// power of two that keeps them in range (the same answer as unscaled wherever
// that one is in range), and a bound beyond every possible quotient decides by
// its sign.
int quotient_side(vec2 num, vec2 den, vec2 b, int k) {
    int scale = 0;
    if (b.x != 0.0) {
        int s = k + exponent_of(b.x);
        if (s > 160) return b.x > 0.0 ? -1 : 1;
        scale = s > 100 ? 100 - s : (s < -100 ? min(-100 - s, 120) : 0);
    }
    vec2 diff = ff_sub(ff_ldexp(num, scale), ff_mul(den, ff_ldexp(b, k + scale)));
    int sign_ = diff.x > 0.0 ? 1 : (diff.x < 0.0 ? -1 : 0);
    return den.x > 0.0 ? sign_ : -sign_;
}

// The sheared coordinate (v - o) dz - s (v_z - o_z) of a vertex (one of its 2D
// coordinates in the watertight test, the direction scaled), from the offsets
// v - o and v_z - o_z scaled by 2^-eo, exactly up to one rounding to float-float.
vec2 sheared_exact(float v, float v_z, float o, float o_z, float dz, float s, int eo) {
    vec2 p = ff_ldexp(ff_diff(v, o), -eo);
    vec2 q = ff_ldexp(ff_diff(v_z, o_z), -eo);
    vec2 pa = ff_two_prod(p.x, dz);
    vec2 pb = ff_two_prod(p.y, dz);
    vec2 pc = ff_two_prod(q.x, -s);
    vec2 pd = ff_two_prod(q.y, -s);
    return ff_exact_sum8(float[8](pa.x, pa.y, pb.x, pb.y, pc.x, pc.y, pd.x, pd.y));
}

// 2^-40: 16x the float-float error of the exact test's 2D coordinates (one
// rounding each) carried through an edge function's two products.
const float ON_EDGE_GAMMA = 1.0 / 1099511627776.0;

// Whether the edge function e = p q - r s lies within ON_EDGE_GAMMA of its
// products' magnitude, where its float-float sign may be wrong (twin of in_band
// in WatertightRay::intersect_exact).
bool on_edge_band(vec2 e, vec2 p, vec2 q, vec2 r, vec2 s) {
    precise float m = abs(p.x * q.x) + abs(r.x * s.x);
    precise float bound = m * ON_EDGE_GAMMA;
    return abs(e.x) <= bound;
}

// The magnitude an in-band edge function takes when edge_sign_exact corrects
// its sign (ORIENT_ZERO, 2^-100: its barycentric weight is 0 to f32 precision).
const float ORIENT_TINY = ORIENT_ZERO;

// v - o exactly in float-float, scaled by the power of two that brings its
// largest component's high part to [1, 2): the inputs of ff_orient_sign.
// Twin: unit_offset in src/geom.rs.
void unit_offset(vec3 v, vec3 o, out vec2 x[3]) {
    for (uint i = 0u; i < 3u; ++i) x[i] = ff_diff(v[i], o[i]);
    int e = exponent_of(max(max(abs(x[0].x), abs(x[1].x)), abs(x[2].x)));
    for (uint i = 0u; i < 3u; ++i) x[i] = ff_ldexp(x[i], -e);
}

// The sign of the edge function of the edge p -> q for the ray from o along
// dir: of det[p - o, q - o, dir], exact unless within 2^-100 of the three
// vectors' magnitudes (then 0: on the edge). The pair is taken in a fixed
// (lexicographic) order and the sign negated when swapped, so the triangles
// sharing an edge see exactly opposite signs. Twin: edge_sign in src/geom.rs.
int edge_sign_exact(vec3 p, vec3 q, vec3 o, vec3 dir) {
    bool swap = p.x > q.x || (p.x == q.x && (p.y > q.y || (p.y == q.y && p.z > q.z)));
    vec3 f = swap ? q : p;
    vec3 g = swap ? p : q;
    vec2 x[3], y[3];
    unit_offset(f, o, x);
    unit_offset(g, o, y);
    int ed = exponent_of(max(max(abs(dir.x), abs(dir.y)), abs(dir.z)));
    vec2 d[3] = vec2[3](vec2(ldexp2(dir.x, -ed), 0.0), vec2(ldexp2(dir.y, -ed), 0.0), vec2(ldexp2(dir.z, -ed), 0.0));
    int s = ff_orient_sign(x, y, d);
    return swap ? -s : s;
}

// The side of the plane through v0, v1, v2 that o lies on: the sign of
// det[v0 - o, v1 - o, v2 - o], the numerator of the exact test's t (whose
// float-float value can miss the sign of an origin exactly on the plane: a ray
// leaving a surface from a vertex or edge of a slanted triangle), exact unless
// within 2^-100 of the vectors' magnitudes (then 0: on the plane). Twin:
// plane_side in src/geom.rs.
int plane_side_exact(vec3 v0, vec3 v1, vec3 v2, vec3 o) {
    vec3 vs[3] = vec3[3](v0, v1, v2);
    vec2 x[3][3];
    [[dont_unroll]] for (uint k = 0u; k < 3u; ++k) unit_offset(vs[k], o, x[k]);
    return ff_orient_sign(x[0], x[1], x[2]);
}

// The test in float-float (ff.glsl) on the f32 inputs, for rays near an edge, a
// vertex or the ray's bounds (see the top). Its 2D coordinates come from the
// ray's own origin (exact expansions for a shifted ray, sheared_exact); its t
// from the segment frame's origin seg_origin + seg_lo, with the
// vertices' offsets and the direction scaled by powers of two to about 1 (no
// overflow, no flushed error terms). The vertices are sheared as in the f32 test
// but scaled by |d[kz]| instead of divided by d[kz]: each vertex's 2D coordinates
// are the same for every triangle sharing it, and the 2D edge functions are
// antisymmetric with signs exact unless the ray passes within about 2^-44 of the
// edge (relative to the coordinates), so the triangles around an edge or vertex
// tile the plane: a ray through a vertex hits one of them, never none. Within
// 2^-40 an edge function takes the sign of the exact orientation
// (edge_sign_exact), 0 within 2^-100: a ray through an edge where two triangles
// fold hits them rather than slipping between, and a ray 2^-60 beside a spoke
// of a fan hits the one triangle it passes through, not both.
//
// The hit's t lies in [tmin, r.ray_tmax] (in float-float, in the ray's own
// parameter: t - t_shift + t_shift). Answers in the segment frame: t_out and
// tff_out are t - t_shift (tff_out in float-float, by which callers order hits
// whose f32 t lie within rounding of each other, see intersect_leaf in
// traverse/leaf.glsl); for a shifted ray err_out bounds tff_out's error (the
// shifted origin's error and the arithmetic's; 0 unshifted, where callers use
// EDGE_GAMMA |t|).
bool intersect_triangle_exact(WatertightRay r, vec3 v0, vec3 v1, vec3 v2, float tmin,
                              out float t_out, out float u_out, out float v_out, out vec2 tff_out,
                              out float err_out) {
    uint kx = r.kx, ky = r.ky, kz = r.kz;
    // The offsets v - origin in float-float, exactly up to the rounding of seg_lo.
    vec2 a[3], b[3], c[3];
    for (uint i = 0u; i < 3u; ++i) {
        vec2 o = vec2(r.seg_origin[i], r.seg_lo[i]);
        a[i] = ff_sub(ff_from(v0[i]), o);
        b[i] = ff_sub(ff_from(v1[i]), o);
        c[i] = ff_sub(ff_from(v2[i]), o);
    }
    // Scale: the offsets by 2^-es (largest about 1), the direction by 2^-eq.
    float m = 0.0;
    for (uint i = 0u; i < 3u; ++i) m = max(m, max(abs(a[i].x), max(abs(b[i].x), abs(c[i].x))));
    int es = exponent_of(m);
    int eq = exponent_of(abs(r.dir[kz]));
    precise vec3 d = vec3(ldexp2(r.dir.x, -eq), ldexp2(r.dir.y, -eq), ldexp2(r.dir.z, -eq));
    for (uint i = 0u; i < 3u; ++i) {
        a[i] = ff_ldexp(a[i], -es);
        b[i] = ff_ldexp(b[i], -es);
        c[i] = ff_ldexp(c[i], -es);
    }
    float dz = abs(d[kz]);
    float sx = d[kz] < 0.0 ? -d[kx] : d[kx];
    float sy = d[kz] < 0.0 ? -d[ky] : d[ky];
    // The 2D coordinates from the ray's own origin, exactly up to one rounding
    // each (sheared_exact; the shear is the same from every point of the ray, and
    // a shifted origin is off the ray by its error bound, which at a vertex or an
    // edge decides the answer).
    vec2 ax, ay, bx, by, cx, cy;
    {
        vec3 o = r.origin;
        vec3 vm = max(max(abs(v0), abs(v1)), abs(v2));
        float om = max(max(max(abs(o.x), abs(o.y)), abs(o.z)), max(max(vm.x, vm.y), vm.z));
        int eo = max(exponent_of(om) - 99, 0);
        ax = sheared_exact(v0[kx], v0[kz], o[kx], o[kz], dz, sx, eo);
        ay = sheared_exact(v0[ky], v0[kz], o[ky], o[kz], dz, sy, eo);
        bx = sheared_exact(v1[kx], v1[kz], o[kx], o[kz], dz, sx, eo);
        by = sheared_exact(v1[ky], v1[kz], o[ky], o[kz], dz, sy, eo);
        cx = sheared_exact(v2[kx], v2[kz], o[kx], o[kz], dz, sx, eo);
        cy = sheared_exact(v2[ky], v2[kz], o[ky], o[kz], dz, sy, eo);
        // One power of two for all six, the largest about 1 (signs unchanged).
        float sm = max(max(max(abs(ax.x), abs(ay.x)), max(abs(bx.x), abs(by.x))), max(abs(cx.x), abs(cy.x)));
        int e2 = exponent_of(sm);
        ax = ff_ldexp(ax, -e2);
        ay = ff_ldexp(ay, -e2);
        bx = ff_ldexp(bx, -e2);
        by = ff_ldexp(by, -e2);
        cx = ff_ldexp(cx, -e2);
        cy = ff_ldexp(cy, -e2);
    }
    // The edge functions times d[kz]^2: u for the edge v1-v2, v for v2-v0, w for v0-v1.
    vec2 u = ff_sub(ff_mul(cx, by), ff_mul(cy, bx));
    vec2 v = ff_sub(ff_mul(ax, cy), ff_mul(ay, cx));
    vec2 w = ff_sub(ff_mul(bx, ay), ff_mul(by, ax));
    // An edge function within the coordinates' rounding of 0 takes the exact
    // sign (edge_sign_exact), 0 for a ray through the edge: a hit. (Where two
    // triangles fold, at a box corner or a mesh's border, their projections lie
    // on one side of the edge, and a rounded sign could put the ray outside
    // both, or inside both where they tile.) Edge k runs from vertex k+2 to
    // vertex k+1 (u: v2 -> v1, v: v0 -> v2, w: v1 -> v0); one call site.
    bool band[3] = bool[3](on_edge_band(u, cx, by, cy, bx), on_edge_band(v, ax, cy, ay, cx),
                           on_edge_band(w, bx, ay, by, ax));
    if (band[0] || band[1] || band[2]) {
        vec3 vs[3] = vec3[3](v0, v1, v2);
        vec2 uvw[3] = vec2[3](u, v, w);
        [[dont_unroll]] for (uint k = 0u; k < 3u; ++k) {
            if (!band[k]) continue;
            int s = edge_sign_exact(vs[(k + 2u) % 3u], vs[(k + 1u) % 3u], r.origin, r.dir);
            vec2 e = uvw[k];
            bool agrees = (s > 0 && e.x > 0.0) || (s < 0 && e.x < 0.0);
            uvw[k] = agrees ? e : vec2(float(s) * ORIENT_TINY, 0.0);
        }
        u = uvw[0];
        v = uvw[1];
        w = uvw[2];
    }
    if ((u.x < 0.0 || v.x < 0.0 || w.x < 0.0) && (u.x > 0.0 || v.x > 0.0 || w.x > 0.0)) return false;
    vec2 det = ff_add(ff_add(u, v), w);
    if (det.x == 0.0) return false;
    // t from the plane: ((v0 - o) . n) / (d . n) with n from the edges (exact
    // differences of the vertices, scaled like the offsets): for a triangle in an
    // axis plane n has two exact zeros, so an origin on that plane gives t = 0
    // exactly.
    vec2 e1[3], e2[3];
    for (uint i = 0u; i < 3u; ++i) {
        e1[i] = ff_ldexp(ff_diff(v1[i], v0[i]), -es);
        e2[i] = ff_ldexp(ff_diff(v2[i], v0[i]), -es);
    }
    vec2 n[3];
    n[0] = ff_sub(ff_mul(e1[1], e2[2]), ff_mul(e1[2], e2[1]));
    n[1] = ff_sub(ff_mul(e1[2], e2[0]), ff_mul(e1[0], e2[2]));
    n[2] = ff_sub(ff_mul(e1[0], e2[1]), ff_mul(e1[1], e2[0]));
    vec2 num = ff_add(ff_add(ff_mul(a[0], n[0]), ff_mul(a[1], n[1])), ff_mul(a[2], n[2]));
    vec2 den = ff_add(ff_add(ff_mul_f(n[0], d.x), ff_mul_f(n[1], d.y)), ff_mul_f(n[2], d.z));
    if (den.x == 0.0) return false;
    // The ray's own bounds: tmin <= t <= ray_tmax, with t = (num / den) 2^(es - eq),
    // decided on the signs of num - b den (no rounded quotient: a hit exactly at a
    // bound, a ray leaving a surface, stays decided exactly). A shifted ray's
    // frame origin is off its own point by its error bound, so it decides its
    // bounds from its own origin: num from the exact offset v0 - origin (a
    // segment ending exactly on an axis-aligned triangle far away stays exact).
    vec2 bound_num = num;
    int bound_k = eq - es;
    if (r.t_shift != 0.0) {
        vec2 own[3];
        for (uint i = 0u; i < 3u; ++i) own[i] = ff_diff(v0[i], r.origin[i]);
        int eo_own = exponent_of(max(max(abs(own[0].x), abs(own[1].x)), abs(own[2].x)));
        for (uint i = 0u; i < 3u; ++i) own[i] = ff_ldexp(own[i], -eo_own);
        bound_num = ff_add(ff_add(ff_mul(own[0], n[0]), ff_mul(own[1], n[1])), ff_mul(own[2], n[2]));
        bound_k = eq - eo_own;
    }
    bool above_min = isinf(tmin) ? tmin < 0.0 : quotient_side(bound_num, den, ff_from(tmin), bound_k) >= 0;
    // A ray from a point of the triangle's plane (tmin = 0: a ray leaving a
    // surface from its exact point): when num lies within its float-float
    // rounding of 0 (2^-40 of its terms' magnitudes), its sign is the plane
    // side's, exactly (plane_side_exact), and t is 0 on the plane or within
    // rounding of it.
    bool gated = false;
    bool at_origin = false;
    if (tmin == 0.0 && r.t_shift == 0.0) {
        precise float mag = 0.0;
        for (uint i = 0u; i < 3u; ++i) {
            uint j = (i + 1u) % 3u;
            uint k = (i + 2u) % 3u;
            precise float cross_mag = abs(e1[j].x * e2[k].x) + abs(e1[k].x * e2[j].x);
            mag = mag + abs(a[i].x) * cross_mag;
        }
        precise float limit = mag * (1.0 / 1099511627776.0);  // 2^-40
        if (abs(num.x) <= limit) {
            int s = plane_side_exact(v0, v1, v2, r.origin);
            above_min = s == 0 || (s > 0) == (den.x > 0.0);
            gated = true;
            at_origin = s == 0;
        }
    }
    bool below_max = isinf(r.ray_tmax) ? r.ray_tmax > 0.0
                                       : quotient_side(bound_num, den, ff_from(r.ray_tmax), bound_k) <= 0;
    if (!(above_min && below_max)) return false;
    // t along the unscaled direction: t' 2^(es - eq) (0 for an origin on the
    // plane, or within rounding of it on the side away from the ray).
    vec2 t_scaled = ff_div(num, den);
    if (gated && (at_origin || t_scaled.x < 0.0)) t_scaled = vec2(0.0);
    vec2 t = ff_ldexp(t_scaled, es - eq);
    err_out = 0.0;
    if (SEGMENT_FRAME && r.t_shift != 0.0) {
        // The shifted origin's error (EDGE_GAMMA seg_err per axis, scaled by s)
        // moves t by at most |delta . n| / |den|; the float-float arithmetic adds
        // about 2^-44 of the terms' magnitudes (bounded by 2^-40).
        precise float origin_err = ldexp2(EDGE_GAMMA * (r.seg_err.x * abs(n[0].x) + r.seg_err.y * abs(n[1].x) +
                                                        r.seg_err.z * abs(n[2].x)), -es);
        precise float num_mag = abs(a[0].x * n[0].x) + abs(a[1].x * n[1].x) + abs(a[2].x * n[2].x);
        precise float den_mag = abs(d.x * n[0].x) + abs(d.y * n[1].x) + abs(d.z * n[2].x);
        precise float bound = (origin_err + (num_mag + abs(t_scaled.x) * den_mag) * (1.0 / 1099511627776.0)) *
                                  (1.0 / abs(den.x)) + abs(t_scaled.x) * (1.0 / 1099511627776.0);  // 2^-40
        precise float err = ldexp2(bound, es - eq) * 1.0001;
        err_out = err;
    }
    t_out = t.x;
    tff_out = t;
    precise float rcp_det = 1.0 / det.x;
    precise float bu = v.x * rcp_det;
    precise float bv = w.x * rcp_det;
    u_out = bu;
    v_out = bv;
    return true;
}

// The includer declares the specialization constant ROBUST (trace.comp): false
// gives the plain test, with the exact recompute only at an edge function of 0.
//
// The f32 test: TRI_HIT with (t, u, v) when the ray hits the triangle at
// tmin <= t <= tmax, TRI_MISS, or TRI_UNSURE when rounding could decide it (an
// edge function or the distance to the ray's bounds within its error bound):
// then intersect_triangle_exact decides. Whether a pair is unsure does not depend
// on tmax (the closest hit so far), so callers may defer the exact tests.
// `tmin` must be the ray's own; the decision near the ray's end uses `r.ray_tmax`.
// Edges and vertices are hits; a ray in the triangle's plane misses.
//
// With ROBUST, `e_out` bounds |t - exact t| (the edge functions' errors carried
// through t = sum(u_i z_i) / sum(u_i), plus t's own rounding), and a hit whose
// interval [t - e, t] reaches tmax counts (t <= ray_tmax still holds): far from
// the origin two surfaces a few ulps of t apart cannot be ordered in f32, and
// the caller orders such pairs by their float-float t. Without ROBUST, `e_out` is 0.
#define TRI_MISS 0u
#define TRI_HIT 1u
#define TRI_UNSURE 2u
uint intersect_triangle_f32(WatertightRay r, vec3 v0, vec3 v1, vec3 v2, float tmin, float tmax,
                            out float t_out, out float u_out, out float v_out, out float e_out) {
    // The segment frame's terms exist only in kernels that shift (SEGMENT_FRAME,
    // declared by the includer); elsewhere seg_origin is origin and the rest 0.
    precise vec3 a = SEGMENT_FRAME ? (v0 - r.seg_origin) - r.seg_lo : v0 - r.origin;
    precise vec3 b = SEGMENT_FRAME ? (v1 - r.seg_origin) - r.seg_lo : v1 - r.origin;
    precise vec3 c = SEGMENT_FRAME ? (v2 - r.seg_origin) - r.seg_lo : v2 - r.origin;
    // Shear and scale the vertices into ray space.
    precise float ax = a[r.kx] - r.sx * a[r.kz];
    precise float ay = a[r.ky] - r.sy * a[r.kz];
    precise float bx = b[r.kx] - r.sx * b[r.kz];
    precise float by = b[r.ky] - r.sy * b[r.kz];
    precise float cx = c[r.kx] - r.sx * c[r.kz];
    precise float cy = c[r.ky] - r.sy * c[r.kz];
    // Scaled barycentric coordinates (edge functions).
    precise float u = cx * by - cy * bx;
    precise float v = ax * cy - ay * cx;
    precise float w = bx * ay - by * ax;
    precise float eu = 0.0, ev = 0.0, ew = 0.0;  // the edge functions' error bounds (ROBUST)
    if (!ROBUST) {
        // Plain Woop, Benthin & Wald: recompute exactly only at an edge function of 0.
        if (u == 0.0 || v == 0.0 || w == 0.0) {
            u = ff_sub(ff_two_prod(cx, by), ff_two_prod(cy, bx)).x;
            v = ff_sub(ff_two_prod(ax, cy), ff_two_prod(ay, cx)).x;
            w = ff_sub(ff_two_prod(bx, ay), ff_two_prod(by, ax)).x;
        }
        if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return TRI_MISS;
    } else {
        // Error bounds: |a[kx]| + |sx a[kz]| is the magnitude of ax before the shear cancels.
        // A shifted origin adds its own error (seg_err, 0 unless shifted).
        precise float aex = abs(a[r.kx]) + abs(r.sx * a[r.kz]);
        precise float aey = abs(a[r.ky]) + abs(r.sy * a[r.kz]);
        precise float bex = abs(b[r.kx]) + abs(r.sx * b[r.kz]);
        precise float bey = abs(b[r.ky]) + abs(r.sy * b[r.kz]);
        precise float cex = abs(c[r.kx]) + abs(r.sx * c[r.kz]);
        precise float cey = abs(c[r.ky]) + abs(r.sy * c[r.kz]);
        if (SEGMENT_FRAME) {
            precise float ex = r.seg_err[r.kx] + abs(r.sx * r.seg_err[r.kz]);
            precise float ey = r.seg_err[r.ky] + abs(r.sy * r.seg_err[r.kz]);
            aex = aex + ex;
            aey = aey + ey;
            bex = bex + ex;
            bey = bey + ey;
            cex = cex + ex;
            cey = cey + ey;
        }
        // Each sheared coordinate lies within EDGE_GAMMA * m of its exact value (about
        // 5 roundings of 2^-24; EDGE_GAMMA is 32), m the largest magnitude before the
        // shear cancelled. With l the largest |coordinate|, an edge function p q - r s
        // is then off by at most ep|q| + |p|eq + ep eq + (the same for r s) plus two
        // roundings of 2^-24 l^2: below EDGE_GAMMA m (4.2 l + 2 EDGE_GAMMA m). First
        // order in the errors: a triangle near the ray but far from its origin (the
        // usual case) gets a bound of its size times its distance, not its distance
        // squared.
        precise float m = max(max(max(aex, aey), max(bex, bey)), max(cex, cey));
        precise float l = max(max(max(abs(ax), abs(ay)), max(abs(bx), abs(by))), max(abs(cx), abs(cy)));
        precise float bound = EDGE_GAMMA * m * (5.0 * l + 2.0 * EDGE_GAMMA * m);
        eu = bound;
        ev = bound;
        ew = bound;
        // Certainly outside (one edge function surely negative, another surely positive)?
        bool negative = u < -eu || v < -ev || w < -ew;
        bool positive = u > eu || v > ev || w > ew;
        if (negative && positive) return TRI_MISS;
        // Any sign in doubt, or a bound below the smallest normal f32 (coordinates
        // under about 1e-16 of the ray's scale: the bound lost its meaning, and a GPU
        // flushes it to 0): decide exactly.
        if (!(abs(u) > eu && abs(v) > ev && abs(w) > ew) || bound < FLT_MIN_NORMAL) return TRI_UNSURE;
    }
    precise float det = u + v + w;
    if (det == 0.0) return TRI_MISS;
    // The edge functions overflowed (coordinates above about 1e19 of the ray's
    // scale): the exact test scales them.
    if (ROBUST && !(abs(det) <= FLT_MAX)) return TRI_UNSURE;
    precise float az = r.sz * a[r.kz];
    precise float bz = r.sz * b[r.kz];
    precise float cz = r.sz * c[r.kz];
    // t = sum(u_i z_i) / sum(u_i) as the barycentric weights' sum of the z_i: no
    // product of three coordinates, which under- or overflows f32 for scenes
    // whose coordinates are below about 1e-13 or above 1e12.
    precise float rcp_det = 1.0 / det;
    precise float b0 = u * rcp_det;
    precise float b1 = v * rcp_det;
    precise float b2 = w * rcp_det;
    precise float t = (b0 * az + b1 * bz) + b2 * cz;
    precise float e = 0.0;
    if (ROBUST) {
        // A bound on |t - exact t|: the edge functions' errors du_i move t by
        // sum du_i (z_i - t) / det, and |z_i - t| is at most the spread of the z_i
        // (t is their weighted mean); then the roundings of the weights (det's
        // included) and of the sum.
        precise float ez = SEGMENT_FRAME ? (abs(b0) + abs(b1) + abs(b2)) * abs(r.sz * r.seg_err[r.kz]) : 0.0;
        precise float terms = abs(b0 * az) + abs(b1 * bz) + abs(b2 * cz);
        precise float weights_err = (eu + ev + ew) * abs(rcp_det);
        precise float spread = max(max(az, bz), cz) - min(min(az, bz), cz);
        e = EDGE_GAMMA * ((2.0 * terms + ez) + abs(t)) + weights_err * spread;
        // A hit within that bound of tmin or of the ray's own tmax (a ray leaving a
        // surface, a shadow ray ending on a vertex): decide exactly which side of the
        // bound it lies on. |t - b| is exact near b (Sterbenz) and far from it it
        // exceeds e by far, so the f32 difference decides soundly.
        bool near_tmin = !isinf(tmin) && abs(t - tmin) <= e;
        float seg_tmax = SEGMENT_FRAME ? r.seg_tmax : r.ray_tmax;
        bool near_tmax = !isinf(seg_tmax) && abs(t - seg_tmax) <= e;
        if (near_tmin || near_tmax) return TRI_UNSURE;
    }
    bool below = t <= tmax || (ROBUST && t - e <= tmax && t <= (SEGMENT_FRAME ? r.seg_tmax : r.ray_tmax));
    if (!(t >= tmin && below)) return TRI_MISS;
    t_out = t;
    e_out = e;
    u_out = b1;
    v_out = b2;
    return TRI_HIT;
}

#endif
