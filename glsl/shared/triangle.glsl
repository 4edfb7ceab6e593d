// Watertight ray/triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)) with an
// f64 fallback near edges. The CPU twin is `WatertightRay` in src/geom.rs: same
// operations in the same order, so both give the same bits. `precise` forbids the
// compiler from fusing into FMAs.
//
// Near an edge the f32 edge function's sign is decided by rounding (translation,
// shear and products each lose ~2^-24 of the coordinates' magnitude), so a ray
// passing within a few ulps of an edge may hit the wrong one of two neighbours.
// Each edge function gets an error bound, EDGE_GAMMA times the magnitudes of its
// two vertices before cancellation (twice the worst case); when any edge function
// lies within its bound, the whole test is redone in f64 as triple products
// d . (P x Q) on the unrounded f32 inputs, whose sign is that of the exact edge
// function (times |d[kz]|) unless the ray passes within ~2^-50 of the edge.
// Watertightness is kept: a shared edge's f32 sign outside its bound is the exact
// sign, and both f32 and f64 forms negate exactly when the edge is reversed.
#ifndef TRIANGLE_GLSL
#define TRIANGLE_GLSL

struct WatertightRay {
    uint kx, ky, kz;
    float sx, sy, sz;
    vec3 origin;
    vec3 dir;
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
    r.dir = dir;
    return r;
}

// The error bound of an f32 edge function relative to its terms' magnitude
// (EDGE_GAMMA_LOG2 from src/consts.rs).
const float EDGE_GAMMA = 1.0 / float(1u << EDGE_GAMMA_LOG2);

// d . (p x q) in f64, in a fixed order (exact negation when p and q swap).
double triple(dvec3 d, dvec3 p, dvec3 q) {
    precise double x = p.y * q.z - p.z * q.y;
    precise double y = p.z * q.x - p.x * q.z;
    precise double z = p.x * q.y - p.y * q.x;
    precise double s = d.x * x + d.y * y + d.z * z;
    return s;
}

// The test in f64 on the f32 inputs, for rays near an edge (see the top).
bool intersect_triangle_f64(WatertightRay r, vec3 v0, vec3 v1, vec3 v2, float tmin, float tmax,
                            out float t_out, out float u_out, out float v_out) {
    dvec3 o = dvec3(r.origin);
    dvec3 d = dvec3(r.dir);
    precise dvec3 a = dvec3(v0) - o;
    precise dvec3 b = dvec3(v1) - o;
    precise dvec3 c = dvec3(v2) - o;
    // The edge functions times |d[kz]|: u for the edge v1-v2, v for v2-v0, w for v0-v1.
    double u = triple(d, c, b);
    double v = triple(d, a, c);
    double w = triple(d, b, a);
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
    precise double det = u + v + w;
    if (det == 0.0) return false;
    uint kz = r.kz;
    precise double t_scaled = u * a[kz] + v * b[kz] + w * c[kz];
    precise double t64 = t_scaled / (det * d[kz]);
    float t = float(t64);
    if (!(t >= tmin && t <= tmax)) return false;
    t_out = t;
    precise double bu = v / det;
    precise double bv = w / det;
    u_out = float(bu);
    v_out = float(bv);
    return true;
}

// Returns true and (t, u, v) when the ray hits the triangle at tmin <= t <= tmax.
// Edges and vertices are hits; a ray in the triangle's plane misses.
bool intersect_triangle(WatertightRay r, vec3 v0, vec3 v1, vec3 v2, float tmin, float tmax,
                        out float t_out, out float u_out, out float v_out) {
    precise vec3 a = v0 - r.origin;
    precise vec3 b = v1 - r.origin;
    precise vec3 c = v2 - r.origin;
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
    // Error bounds: |a[kx]| + |sx a[kz]| is the magnitude of ax before the shear cancels.
    precise float aex = abs(a[r.kx]) + abs(r.sx * a[r.kz]);
    precise float aey = abs(a[r.ky]) + abs(r.sy * a[r.kz]);
    precise float bex = abs(b[r.kx]) + abs(r.sx * b[r.kz]);
    precise float bey = abs(b[r.ky]) + abs(r.sy * b[r.kz]);
    precise float cex = abs(c[r.kx]) + abs(r.sx * c[r.kz]);
    precise float cey = abs(c[r.ky]) + abs(r.sy * c[r.kz]);
    precise float eu = EDGE_GAMMA * (cex * bey + cey * bex);
    precise float ev = EDGE_GAMMA * (aex * cey + aey * cex);
    precise float ew = EDGE_GAMMA * (bex * aey + bey * aex);
    // Certainly outside (one edge function surely negative, another surely positive)?
    bool negative = u < -eu || v < -ev || w < -ew;
    bool positive = u > eu || v > ev || w > ew;
    if (negative && positive) return false;
    // Any sign in doubt: decide in f64.
    if (!(abs(u) > eu && abs(v) > ev && abs(w) > ew)) {
        return intersect_triangle_f64(r, v0, v1, v2, tmin, tmax, t_out, u_out, v_out);
    }
    precise float det = u + v + w;
    if (det == 0.0) return false;
    precise float az = r.sz * a[r.kz];
    precise float bz = r.sz * b[r.kz];
    precise float cz = r.sz * c[r.kz];
    precise float t_scaled = u * az + v * bz + w * cz;
    precise float rcp_det = 1.0 / det;
    precise float t = t_scaled * rcp_det;
    if (!(t >= tmin && t <= tmax)) return false;
    t_out = t;
    precise float bu = v * rcp_det;
    precise float bv = w * rcp_det;
    u_out = bu;
    v_out = bv;
    return true;
}

#endif
