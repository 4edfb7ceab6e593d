#version 450
// The replay and memory-only kernels of `kdtrace divergence` (src/divergence.rs),
// one lane per ray, from records written by the traversal's CPU twin.
//
// MODE_REPLAY: each lane runs the control flow its ray took — the same number of
// rounds, and in each the same trip counts of the descent loop and of the leaf
// loop — with no node or triangle fetch and no intersection arithmetic: one
// integer multiply-add per loop step. Lanes of a subgroup run these loops under
// masks as they run the real kernel's, so the replay's time is what the
// per-lane control flow costs with the real divergence.
// Record of ray i: words offsets[i] .. offsets[i + 1], one per leaf visit that
// tested triangles: loop steps (low 16 bits) | triangles (high 16 bits).
//
// MODE_MEMORY: each lane makes its ray's node fetches in order, and the triangle
// fetches of each leaf whose triangles it tested (all of the leaf's), from the
// same texel buffers as the trace kernel, and only sums the bits: the memory
// traffic without the decisions. Record of ray i: one word per node fetch, the
// node index with bit 31 set on a tested leaf.
//
// MODE_READ_ROUNDS / MODE_READ_FETCHES: the same records read and summed, no
// loops and no fetches: the records' own read cost.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "kdnode.glsl"

#define MODE_REPLAY 0u
#define MODE_READ_ROUNDS 1u
#define MODE_MEMORY 2u
#define MODE_READ_FETCHES 3u
layout(constant_id = 0) const uint MODE = MODE_REPLAY;

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Records { uint words[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Sink { uint sink[]; };
layout(set = 0, binding = 3, rg32ui) uniform readonly uimageBuffer node_texels;
layout(set = 0, binding = 4, rgba32ui) uniform readonly uimageBuffer tri_texels;

layout(push_constant) uniform Push { uint count; };

const uint TESTED = 0x80000000u;

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint first = offsets[i];
    uint end = offsets[i + 1u];
    uint acc = i;
    for (uint k = first; k < end; ++k) {
        uint w = words[k];
        if (MODE == MODE_READ_ROUNDS || MODE == MODE_READ_FETCHES) {
            acc += w;
        } else if (MODE == MODE_REPLAY) {
            uint descent = w & 0xffffu;
            uint triangles = w >> 16;
            for (uint j = 0u; j < descent; ++j) acc = acc * 1664525u + 1013904223u;
            for (uint j = 0u; j < triangles; ++j) acc = acc * 22695477u + 1u;
        } else {
            uvec2 n = imageLoad(node_texels, int(w & ~TESTED)).xy;
            acc += n.x ^ n.y;
            if ((w & TESTED) != 0u) {
                uint base = 3u * node_prim_offset(n);
                uint tris = node_prim_count(n);
                for (uint j = 0u; j < tris; ++j) {
                    uvec4 a = imageLoad(tri_texels, int(base + 3u * j));
                    uvec4 b = imageLoad(tri_texels, int(base + 3u * j + 1u));
                    uvec4 c = imageLoad(tri_texels, int(base + 3u * j + 2u));
                    acc += (a.x ^ b.y ^ c.z) + (a.y ^ b.z ^ c.x) + (a.z ^ b.x ^ c.y) + a.w;
                }
            }
        }
    }
    sink[i] = acc;
}
