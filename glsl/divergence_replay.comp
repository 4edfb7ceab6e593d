#version 450
// The replay kernel of `kdtrace divergence` (src/divergence.rs): each lane runs
// the control flow its ray took in the `stack` traversal — the same number of
// outer rounds, and in each the same trip counts of the descent loop and of the
// leaf loop — from a compact record written by the CPU twin, with no node or
// triangle fetch and no intersection arithmetic: one integer multiply-add per
// loop step. Lanes of a subgroup run these loops under masks as they run the real
// kernel's, so the replay's time is what the per-lane control flow costs with the
// real divergence. With READ_ONLY the loops go and only the record words are read
// and summed: the records' own read cost.
//
// Record of ray i: words offsets[i] .. offsets[i + 1], one per leaf visit that
// tested triangles: descent steps (low 16 bits) | triangles (high 16 bits).

layout(constant_id = 0) const bool READ_ONLY = false;

layout(local_size_x = 64) in;

layout(std430, set = 0, binding = 0) readonly buffer Offsets { uint offsets[]; };
layout(std430, set = 0, binding = 1) readonly buffer Records { uint words[]; };
layout(std430, set = 0, binding = 2) writeonly buffer Sink { uint sink[]; };

layout(push_constant) uniform Push { uint count; };

void main() {
    uint i = gl_GlobalInvocationID.x;
    if (i >= count) return;
    uint first = offsets[i];
    uint end = offsets[i + 1u];
    uint acc = i;
    for (uint k = first; k < end; ++k) {
        uint w = words[k];
        if (READ_ONLY) {
            acc += w;
        } else {
            uint descent = w & 0xffffu;
            uint triangles = w >> 16;
            for (uint j = 0u; j < descent; ++j) acc = acc * 1664525u + 1013904223u;
            for (uint j = 0u; j < triangles; ++j) acc = acc * 22695477u + 1u;
        }
    }
    sink[i] = acc;
}
