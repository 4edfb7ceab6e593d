#version 450
// Render pass 1: one camera ray per pixel for sample `sample_index`, jittered
// inside the pixel by a scrambled Sobol sequence (dimensions 2-3, the partner of the
// first light sample's pair: see ld2_partner; the pixel centre when there is one sample
// per pixel), in the order of `pixels` (Morton order, so packets hold neighbours).
// See src/render/wavefront.rs.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "render.glsl"

layout(local_size_x = RENDER_WORKGROUP_SIZE) in;

// JITTER_NONE: pixel centres; JITTER_PER_PIXEL: a jitter per pixel and sample;
// JITTER_PER_SAMPLE: one jitter per sample for the whole image (what a rasterized
// first hit can follow). Values from src/render/consts.rs.
layout(constant_id = RAYGEN_SPEC_JITTER) const uint JITTER = JITTER_PER_PIXEL;

layout(std430, set = 0, binding = RAYGEN_BINDING_PIXELS) readonly buffer Pixels { uint pixels[]; };
layout(std430, set = 0, binding = RAYGEN_BINDING_RAYS) writeonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = RAYGEN_BINDING_PATHS) writeonly buffer Paths { Path paths[]; };

layout(push_constant) uniform Params { RenderParams p; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= p.count) return;
    uint pixel = pixels[floatBitsToUint(p.eye.w) + i];   // eye.w: this chunk's first pixel
    uint x = pixel % p.width;
    uint y = pixel / p.width;
    // Mode 2 takes the jitter the host computed for the rasterizer's projection
    // (right.w, up.w), so both use one value.
    vec2 jitter = JITTER == JITTER_NONE ? vec2(0.5)
                : JITTER == JITTER_PER_PIXEL ? ld2_partner(pixel, p.sample_index, 0u, p.seed)
                               : vec2(p.right.w, p.up.w);
    float sx = 2.0 * (float(x) + jitter.x) / float(p.width) - 1.0;
    float sy = 1.0 - 2.0 * (float(y) + jitter.y) / float(p.height);
    Ray ray;
    ray.origin = p.eye.xyz;
    ray.tmin = 0.0;
    ray.dir = normalize(p.forward.xyz + sx * p.right.xyz + sy * p.up.xyz);
    ray.tmax = uintBitsToFloat(0x7f800000u);
    rays[i] = ray;
    Path path;
    path.throughput = vec3(1.0);
    path.pixel = pixel;
    path.flags = PATH_COUNT_EMISSION;
    path.depth = 0u;
    path.diffuse = 0u;
    path.pad = 0u;
    paths[i] = path;
}
