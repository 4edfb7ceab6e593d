#version 460
// The ray-query kernel: one ray per invocation through the driver's own
// acceleration structure (VK_KHR_ray_query), reading the same rays and writing
// the same hits as trace.comp. src/ray_query.rs builds the scene: the triangles
// that can be hit, sorted by the Morton code of their centroids (the driver's
// BVH quality depends on the order), with prim_ids mapping the driver's
// primitive index back to the scene's triangle index.
//
// A ray query takes only 0 <= tmin <= tmax, finite origins and directions and
// no NaN (otherwise its behaviour is undefined), so every ray is checked first:
// invalid rays are written PRIM_INVALID as trace.comp writes them, empty
// segments as misses, and a segment starting behind its origin (tmin < 0) is
// traced from where it enters the scene box instead.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require
#extension GL_EXT_ray_query : require

#include "ray.glsl"
#include "ray_checks.glsl"
#include "ff.glsl"

layout(local_size_x = TRACE_WORKGROUP_SIZE) in;

// Specialization constants (src/ray_query.rs sets them).
layout(constant_id = RQ_SPEC_ANY_HIT) const bool ANY_HIT = false;  // stop at the first hit (shadow rays)

layout(set = 0, binding = RQ_BINDING_SCENE) uniform accelerationStructureEXT scene;
layout(std430, set = 0, binding = RQ_BINDING_PRIM_IDS) readonly buffer PrimIds { uint prim_ids[]; };
layout(std430, set = 0, binding = RQ_BINDING_RAYS) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = RQ_BINDING_HITS) writeonly buffer Hits { Hit hits[]; };
// A device-counted batch's arguments, when params.indirect (glsl/indirect_args.comp).
layout(std430, set = 0, binding = RQ_BINDING_INDIRECT) readonly buffer Indirect { uint indirect_words[]; };

layout(push_constant) uniform Push { TraceParams params; };

#include "batch.glsl"

#define INF uintBitsToFloat(0x7f800000u)
#define NAN uintBitsToFloat(0x7fc00000u)

// The part [t0, t1] of the line o + t d inside the scene box, in float-float
// (ff.glsl; false: it misses the box).
bool line_in_box(vec3 o, vec3 d, out vec2 t0, out vec2 t1) {
    t0 = vec2(-INF, 0.0);
    t1 = vec2(INF, 0.0);
    for (uint axis = 0u; axis < 3u; ++axis) {
        float lo = params.scene_min[axis];
        float hi = params.scene_max[axis];
        if (d[axis] == 0.0) {
            if (o[axis] < lo || o[axis] > hi) return false;
            continue;
        }
        vec2 a = ff_div(ff_diff(lo, o[axis]), ff_from(d[axis]));
        vec2 b = ff_div(ff_diff(hi, o[axis]), ff_from(d[axis]));
        vec2 near = ff_le(a, b) ? a : b;
        vec2 far = ff_le(a, b) ? b : a;
        if (ff_le(t0, near)) t0 = near;
        if (ff_le(far, t1)) t1 = far;
    }
    return ff_le(t0, t1);
}

// The closest (or, ANY_HIT, the first found) hit of a valid ray with a finite
// direction, t in the ray's own parameter.
Hit trace_query(Ray ray) {
    Hit miss = Hit(INF, PRIM_MISS, 0.0, 0.0);
    vec3 origin = ray.origin;
    float tmin = ray.tmin;
    float tmax = ray.tmax;
    if (!(tmin <= tmax) || tmin == INF) return miss;
    // Where the segment starts behind the origin, trace from a point just before
    // the line enters the scene box (or from tmin, whichever is later): the
    // query wants tmin >= 0, and the box entry keeps far starts (tmin = -1e30)
    // near the scene. t goes back to the ray's parameter below.
    float shift = 0.0;
    if (tmin < 0.0) {
        vec2 t0, t1;
        if (!line_in_box(ray.origin, ray.dir, t0, t1)) return miss;
        if (t0.x >= 0.0) {
            tmin = 0.0;  // no part of the box lies behind the origin
        } else {
            vec2 margin = ff_mul_f(ff_sub(t1, t0), 1.0 / 65536.0);
            vec2 start = ff_sub(t0, margin);
            shift = ff_ge_f(start, tmin) ? start.x : tmin;
            // The start point, rounded once from float-float.
            for (uint axis = 0u; axis < 3u; ++axis) {
                origin[axis] = ff_add_f(ff_two_prod(shift, ray.dir[axis]), ray.origin[axis]).x;
            }
            // f32 differences and sums of two f32 are correctly rounded.
            precise float tmin_shifted = tmin - shift;
            precise float tmax_shifted = tmax - shift;
            tmin = max(tmin_shifted, 0.0);
            tmax = tmax_shifted;
        }
        if (!(tmin <= tmax)) return miss;
    }
    tmin = max(tmin, 0.0);  // -0.0 as +0.0

    uint flags = gl_RayFlagsOpaqueEXT | (ANY_HIT ? gl_RayFlagsTerminateOnFirstHitEXT : 0u);
    rayQueryEXT query;
    rayQueryInitializeEXT(query, scene, flags, 0xFFu, origin, tmin, ray.dir, tmax);
    // Every triangle is opaque, so the driver commits them itself; a candidate
    // would only come from non-opaque geometry, which this scene has none of.
    while (rayQueryProceedEXT(query)) {
        if (rayQueryGetIntersectionTypeEXT(query, false) == gl_RayQueryCandidateIntersectionTriangleEXT) {
            rayQueryConfirmIntersectionEXT(query);
        }
    }
    if (rayQueryGetIntersectionTypeEXT(query, true) != gl_RayQueryCommittedIntersectionTriangleEXT) return miss;
    float t = rayQueryGetIntersectionTEXT(query, true);
    vec2 uv = rayQueryGetIntersectionBarycentricsEXT(query, true);  // the weights of v1 and v2
    uint prim = prim_ids[rayQueryGetIntersectionPrimitiveIndexEXT(query, true)];
    precise float t_own = t + shift;
    if (shift != 0.0) t = t_own;
    return Hit(t, prim, uv.x, uv.y);
}

void main() {
    uint index = batch_slot(TRACE_WORKGROUP_SIZE);
    if (index >= batch_count()) return;
    Ray ray = rays[index];
    ray.dir = traced_dir(ray.dir);
    Hit hit;
    if (!ray_is_valid(ray)) {
        hit = Hit(NAN, PRIM_INVALID, 0.0, 0.0);
    } else if (any(isinf(ray.dir))) {
        // A query takes finite directions only: such a ray cannot be traced here.
        hit = Hit(NAN, PRIM_INCOMPLETE, 0.0, 0.0);
    } else {
        hit = trace_query(ray);
    }
    hits[index] = hit;
}
