// Rays, hits and the trace kernel's push constants, as they cross the host/GPU
// boundary (std430). Mirrored by `Ray`, `Hit` in src/geom.rs and `TraceParams` in
// src/trace.rs; layout tests prove sizes and offsets agree.
#ifndef RAY_GLSL
#define RAY_GLSL

// The segment origin + t * dir, tmin <= t <= tmax (32 bytes).
struct Ray {
    vec3 origin;
    float tmin;
    vec3 dir;
    float tmax;
};

// prim_id is PRIM_MISS, PRIM_INVALID or PRIM_INCOMPLETE when there is no hit;
// the hit point is (1-u-v)*v0 + u*v1 + v*v2 (16 bytes).
struct Hit {
    float t;
    uint prim_id;
    float u;
    float v;
};

// Push constants of trace.comp (48 bytes).
struct TraceParams {
    vec4 scene_min;   // xyz: scene box
    vec4 scene_max;
    uint ray_count;   // rays in this dispatch
    uint pad0;        // 0 (trace.comp uses it as a zero the compiler cannot fold)
    uint pad1;
    uint pad2;
};

#endif
