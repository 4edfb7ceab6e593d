// Watertight ray/triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)) with an
// f64 fallback near edges. The CPU twin is `WatertightRay` in src/geom.rs: same
// operations in the same order, so both give the same bits. `precise` forbids the
// compiler from fusing into FMAs.
//
// Near an edge the f32 edge function's sign is decided by rounding (translation,
// shear and products each lose ~2^-24 of the coordinates' magnitude), so a ray
// passing within a few ulps of an edge may hit the wrong one of two neighbours.
// Each edge function gets an error bound (the sheared coordinates' errors,
// EDGE_GAMMA times their magnitudes before cancellation, carried through its two
// products, with a margin of about 6); when any edge function
// lies within its bound, the whole test is redone in f64 on the f32 inputs, whose
// signs are those of the exact edge functions unless the ray passes within about
// 2^-50 of the edge. Watertightness is kept: a shared edge's f32 sign outside its
// bound is the exact sign, both forms negate exactly when the edge is reversed,
// and the f64 form is an exact 2D orientation test of shared 2D vertices.
#ifndef TRIANGLE_GLSL
#define TRIANGLE_GLSL

// The f64 test works from `origin`, in the ray's own parameter. The f32 test
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

// The error bound of an f32 edge function relative to its terms' magnitude
// (EDGE_GAMMA_LOG2 from src/consts.rs).
const float EDGE_GAMMA = 1.0 / float(1u << EDGE_GAMMA_LOG2);

// The f64 product a*b as p + e exactly (Dekker 1971: Veltkamp's split into
// 26-bit halves, no FMA, so every IEEE device gives the same bits; lavapipe does
// not fuse fma).
void two_product(double a, double b, out double p, out double e) {
    precise double ca = 134217729.0 * a;
    precise double a_hi = ca - (ca - a);
    precise double a_lo = a - a_hi;
    precise double cb = 134217729.0 * b;
    precise double b_hi = cb - (cb - b);
    precise double b_lo = b - b_hi;
    precise double prod = a * b;
    precise double err = ((a_hi * b_hi - prod) + a_hi * b_lo + a_lo * b_hi) + a_lo * b_lo;
    p = prod;
    e = err;
}

// a*b - c*d in f64 from exact products: 0 exactly when a*b == c*d, and of the
// exact sign unless the products' rounding errors cancel their difference.
double diff_of_products(double a, double b, double c, double d) {
    double p1, e1, p2, e2;
    two_product(a, b, p1, e1);
    two_product(c, d, p2, e2);
    precise double r = (p1 - p2) + (e1 - e2);
    return r;
}

// The test in f64 on the f32 inputs, for rays near an edge, a vertex or the
// ray's bounds (see the top). The vertices are sheared as in the f32 test but
// scaled by |d[kz]| instead of divided by d[kz]: each vertex's 2D coordinates are
// the same for every triangle sharing it, and the 2D edge functions have exact
// signs, so the triangles around an edge or vertex tile the plane exactly: a ray
// through a vertex hits one of them, never none.
//
// The hit's t lies in [tmin, r.ray_tmax] (exactly, in f64); `t64_out` is its f64
// value, by which callers order hits whose f32 t lie within rounding of each
// other (see intersect_leaf in traverse/leaf.glsl).
//
// Answers in the segment frame: t_out and t64_out are t - t_shift, and for a
// shifted ray err_out bounds t64_out's error (num, den and the subtraction;
// 0 unshifted, where callers use EDGE_GAMMA |t|).
bool intersect_triangle_f64(WatertightRay r, vec3 v0, vec3 v1, vec3 v2, float tmin,
                            out float t_out, out float u_out, out float v_out, out double t64_out,
                            out float err_out) {
    dvec3 o = dvec3(r.origin);
    dvec3 d = dvec3(r.dir);
    precise dvec3 a = dvec3(v0) - o;
    precise dvec3 b = dvec3(v1) - o;
    precise dvec3 c = dvec3(v2) - o;
    uint kx = r.kx, ky = r.ky, kz = r.kz;
    double dz = abs(d[kz]);
    double sign = d[kz] < 0.0 ? -1.0 : 1.0;
    double sx = d[kx] * sign;
    double sy = d[ky] * sign;
    precise double ax = a[kx] * dz - sx * a[kz];
    precise double ay = a[ky] * dz - sy * a[kz];
    precise double bx = b[kx] * dz - sx * b[kz];
    precise double by = b[ky] * dz - sy * b[kz];
    precise double cx = c[kx] * dz - sx * c[kz];
    precise double cy = c[ky] * dz - sy * c[kz];
    // The edge functions times d[kz]^2: u for the edge v1-v2, v for v2-v0, w for v0-v1.
    double u = diff_of_products(cx, by, cy, bx);
    double v = diff_of_products(ax, cy, ay, cx);
    double w = diff_of_products(bx, ay, by, ax);
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
    precise double det = u + v + w;
    if (det == 0.0) return false;
    // t from the plane: ((v0 - o) . n) / (d . n) with n from the edges, which are
    // exact f32 differences: for a triangle in an axis plane n has two exact
    // zeros, so an origin on that plane gives t = 0 exactly.
    precise dvec3 e1 = dvec3(v1) - dvec3(v0);
    precise dvec3 e2 = dvec3(v2) - dvec3(v0);
    precise double nx = e1.y * e2.z - e1.z * e2.y;
    precise double ny = e1.z * e2.x - e1.x * e2.z;
    precise double nz = e1.x * e2.y - e1.y * e2.x;
    precise double num = a.x * nx + a.y * ny + a.z * nz;
    precise double den = d.x * nx + d.y * ny + d.z * nz;
    if (den == 0.0) return false;
    precise double t64 = num / den;
    // Exact against the ray's bounds.
    if (!(t64 >= double(tmin) && t64 <= double(r.ray_tmax))) return false;
    precise double t_seg = SEGMENT_FRAME ? t64 - double(r.t_shift) : t64;
    err_out = 0.0;
    if (SEGMENT_FRAME && r.t_shift != 0.0) {
        precise double num_mag = abs(a.x * nx) + abs(a.y * ny) + abs(a.z * nz);
        precise double den_mag = abs(d.x * nx) + abs(d.y * ny) + abs(d.z * nz);
        precise double bound = (num_mag + abs(t64) * den_mag) / abs(den) * double(1.0 / 562949953421312.0)  // 2^-49
                               + abs(t64) * double(1.0 / 1125899906842624.0);                         // 2^-50
        err_out = float(bound * 1.0000010000000000LF);
    }
    t_out = float(t_seg);
    t64_out = t_seg;
    precise double bu = v / det;
    precise double bv = w / det;
    u_out = float(bu);
    v_out = float(bv);
    return true;
}

// The includer declares the specialization constant ROBUST (trace.comp): false
// gives the plain test, with the f64 recompute only at an edge function of 0.
//
// The f32 test: TRI_HIT with (t, u, v) when the ray hits the triangle at
// tmin <= t <= tmax, TRI_MISS, or TRI_UNSURE when rounding could decide it (an
// edge function or the distance to the ray's bounds within its error bound):
// then intersect_triangle_f64 decides. Whether a pair is unsure does not depend
// on tmax (the closest hit so far), so callers may defer the f64 tests.
// `tmin` must be the ray's own; the decision near the ray's end uses `r.ray_tmax`.
// Edges and vertices are hits; a ray in the triangle's plane misses.
//
// With ROBUST, `e_out` bounds |t - exact t| (the edge functions' errors carried
// through t = sum(u_i z_i) / sum(u_i), plus t's own rounding), and a hit whose
// interval [t - e, t] reaches tmax counts (t <= ray_tmax still holds): far from
// the origin two surfaces a few ulps of t apart cannot be ordered in f32, and
// the caller orders such pairs in f64. Without ROBUST, `e_out` is 0.
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
        // Plain Woop, Benthin & Wald: recompute in f64 only at an edge function of 0.
        if (u == 0.0 || v == 0.0 || w == 0.0) {
            precise double du = double(cx) * double(by) - double(cy) * double(bx);
            precise double dv = double(ax) * double(cy) - double(ay) * double(cx);
            precise double dw = double(bx) * double(ay) - double(by) * double(ax);
            u = float(du);
            v = float(dv);
            w = float(dw);
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
        // Any sign in doubt: decide in f64.
        if (!(abs(u) > eu && abs(v) > ev && abs(w) > ew)) return TRI_UNSURE;
    }
    precise float det = u + v + w;
    if (det == 0.0) return TRI_MISS;
    precise float az = r.sz * a[r.kz];
    precise float bz = r.sz * b[r.kz];
    precise float cz = r.sz * c[r.kz];
    precise float t_scaled = u * az + v * bz + w * cz;
    precise float rcp_det = 1.0 / det;
    precise float t = t_scaled * rcp_det;
    precise float e = 0.0;
    if (ROBUST) {
        // A bound on |t - exact t|: the edge functions' errors du_i move t_scaled -
        // t det by sum du_i (z_i - t), and |z_i - t| is at most the spread of the z_i
        // (t is their weighted mean); then the roundings of t_scaled, det and t.
        precise float ez = SEGMENT_FRAME ? (abs(u) + abs(v) + abs(w)) * abs(r.sz * r.seg_err[r.kz]) : 0.0;
        precise float t_err = EDGE_GAMMA * ((abs(u * az) + abs(v * bz) + abs(w * cz)) + ez);
        precise float weights_err = eu + ev + ew;
        precise float spread = max(max(az, bz), cz) - min(min(az, bz), cz);
        e = (t_err + weights_err * spread + EDGE_GAMMA * abs(t_scaled)) / abs(det) + EDGE_GAMMA * abs(t);
        // A hit within that bound of tmin or of the ray's own tmax (a ray leaving a
        // surface, a shadow ray ending on a vertex): decide in f64 which side of the
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
    precise float bu = v * rcp_det;
    precise float bv = w * rcp_det;
    u_out = bu;
    v_out = bv;
    return TRI_HIT;
}

#endif
