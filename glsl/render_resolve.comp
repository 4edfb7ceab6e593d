#version 450
// Render pass 4: after the shadow rays of a queue were traced (any hit), adds
// to each path's pixel the contributions of its unoccluded shadow rays. One
// invocation per path: a queue holds each pixel at most once, so no two
// invocations write the same pixel. See src/render/wavefront.rs.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "render.glsl"

layout(local_size_x = RENDER_WORKGROUP_SIZE) in;

layout(std430, set = 0, binding = RESOLVE_BINDING_PATHS) readonly buffer Paths { Path paths[]; };
layout(std430, set = 0, binding = RESOLVE_BINDING_SPANS) readonly buffer Spans { uvec2 spans[]; };
layout(std430, set = 0, binding = RESOLVE_BINDING_SHADOW_HITS) readonly buffer ShadowHits { Hit shadow_hits[]; };
layout(std430, set = 0, binding = RESOLVE_BINDING_SHADOW_WEIGHTS) readonly buffer ShadowWeights { vec4 shadow_weights[]; };
layout(std430, set = 0, binding = RESOLVE_BINDING_ACCUM) buffer Accum { vec4 accum[]; };
layout(std430, set = 0, binding = RESOLVE_BINDING_COUNTERS) buffer Counters { uint counters[]; };

layout(push_constant) uniform Params { RenderParams p; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint block = wave_block(p.count);
    if (i >= WAVE_PATHS(p.count, block)) return;
    uvec2 span = spans[i];
    if (span.y == 0u) return;
    vec3 sum = vec3(0.0);
    uint incomplete = 0u;
    for (uint k = span.x; k < span.x + span.y; k++) {
        uint prim = shadow_hits[k].prim_id;
        if (prim == PRIM_MISS) {
            sum += shadow_weights[k].xyz;
        } else if (prim == PRIM_INCOMPLETE || prim == PRIM_INVALID) {
            incomplete++;
        }
    }
    if (incomplete > 0u) atomicAdd(counters[block + RC_BAD_RAYS], incomplete);
    uint pixel = paths[i].pixel;
    accum[pixel] += vec4(sum, float(incomplete));  // w counts the pixel's bad rays
}
