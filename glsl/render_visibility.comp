#version 450
// Render pass 2 with --primary raster: turns the visibility buffer into the
// hits of the camera rays, in place of tracing them. Each pixel's triangle is
// intersected with the pixel's camera ray by the tracer's own watertight test,
// so t, u and v are those a trace would give for that triangle. Where the
// rasterizer covered the pixel centre but the ray test misses the triangle (the
// ray passes along an edge, within rounding of it), the hit is taken on the
// triangle's plane with clamped barycentrics and counted in RC_RASTER_EDGE.
// See src/render/wavefront.rs.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "render.glsl"

layout(local_size_x = RENDER_WORKGROUP_SIZE) in;

layout(constant_id = VISIBILITY_SPEC_ROBUST) const bool ROBUST = true;
const bool SEGMENT_FRAME = false;  // camera rays are never moved (see trace.comp)

#include "triangle.glsl"

layout(std430, set = 0, binding = VISIBILITY_BINDING_PIXELS) readonly buffer Pixels { uint pixels[]; };
layout(std430, set = 0, binding = VISIBILITY_BINDING_VISIBILITY) readonly buffer Visibility { uint visibility[]; };
layout(std430, set = 0, binding = VISIBILITY_BINDING_SURFACES) readonly buffer Surfaces { Surface surfaces[]; };
layout(std430, set = 0, binding = VISIBILITY_BINDING_RAYS) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = VISIBILITY_BINDING_HITS) writeonly buffer Hits { Hit hits[]; };
layout(std430, set = 0, binding = VISIBILITY_BINDING_COUNTERS) buffer Counters { uint counters[]; };

layout(push_constant) uniform Params { RenderParams p; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= p.count) return;
    uint pixel = pixels[floatBitsToUint(p.eye.w) + i];
    uint id = visibility[pixel];
    Hit hit;
    hit.t = uintBitsToFloat(0x7f800000u);
    hit.prim_id = PRIM_MISS;
    hit.u = 0.0;
    hit.v = 0.0;
    if (id != 0u) {
        uint prim = id - 1u;
        Surface s = surfaces[prim];
        Ray ray = rays[i];
        WatertightRay wr = watertight_ray(ray.origin, ray.dir);
        wr.ray_tmax = ray.tmax;
        float t, u, v, e, err_x;
        vec2 t_ff;
        uint result = intersect_triangle_f32(wr, s.v0.xyz, s.v1.xyz, s.v2.xyz, ray.tmin, ray.tmax, t, u, v, e);
        bool found = (result == TRI_HIT && t <= ray.tmax)
            || (result == TRI_UNSURE && intersect_triangle_exact(wr, s.v0.xyz, s.v1.xyz, s.v2.xyz, ray.tmin, t, u, v, t_ff, err_x));
        if (!found) {
            // An edge tie: the plane hit, barycentrics clamped into the triangle.
            vec3 e1 = s.v1.xyz - s.v0.xyz;
            vec3 e2 = s.v2.xyz - s.v0.xyz;
            vec3 n = cross(e1, e2);
            float denom = dot(n, ray.dir);
            t = denom != 0.0 ? dot(n, s.v0.xyz - ray.origin) / denom : 0.0;
            vec3 x = ray.origin + t * ray.dir - s.v0.xyz;
            float d00 = dot(e1, e1), d01 = dot(e1, e2), d11 = dot(e2, e2);
            float d20 = dot(x, e1), d21 = dot(x, e2);
            float det = d00 * d11 - d01 * d01;
            u = det != 0.0 ? clamp((d11 * d20 - d01 * d21) / det, 0.0, 1.0) : 0.0;
            v = det != 0.0 ? clamp((d00 * d21 - d01 * d20) / det, 0.0, 1.0 - u) : 0.0;
            t = max(t, 0.0);
            atomicAdd(counters[RC_RASTER_EDGE], 1u);
        }
        hit.t = t;
        hit.prim_id = prim;
        hit.u = u;
        hit.v = v;
    }
    hits[i] = hit;
}
