// Watertight ray/triangle test (Woop, Benthin & Wald 2013, JCGT 2(1)). The CPU
// twin is `WatertightRay` in src/geom.rs: same operations in the same order, so
// both give the same bits. `precise` forbids the compiler from fusing into FMAs.
#ifndef TRIANGLE_GLSL
#define TRIANGLE_GLSL

struct WatertightRay {
    uint kx, ky, kz;
    float sx, sy, sz;
    vec3 origin;
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
    return r;
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
    // On an edge, recompute in double precision so the sign is exact.
    if (u == 0.0 || v == 0.0 || w == 0.0) {
        precise double dax = double(ax), day = double(ay), dbx = double(bx);
        precise double dby = double(by), dcx = double(cx), dcy = double(cy);
        precise double du = dcx * dby - dcy * dbx;
        precise double dv = dax * dcy - day * dcx;
        precise double dw = dbx * day - dby * dax;
        u = float(du);
        v = float(dv);
        w = float(dw);
    }
    if ((u < 0.0 || v < 0.0 || w < 0.0) && (u > 0.0 || v > 0.0 || w > 0.0)) return false;
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
