#version 450
// Layout test kernel: reads every struct that crosses the host/GPU boundary and
// writes its fields back as raw words in declaration order, so a test can prove
// the Rust mirrors (src/geom.rs, src/kdtree/node.rs, src/trace.rs) agree with
// glsl/shared/*.glsl field by field. Element 1 is read so the stride counts too.

#extension GL_GOOGLE_include_directive : require

#include "ray.glsl"
#include "kdnode.glsl"

layout(local_size_x = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = 1) readonly buffer Hits { Hit hits[]; };
layout(std430, set = 0, binding = 2) readonly buffer Nodes { uvec2 nodes[]; };
layout(std430, set = 0, binding = 3) writeonly buffer Words { uint words[]; };

layout(push_constant) uniform Push { TraceParams params; };

void main() {
    uint k = 0u;
    Ray r = rays[1];
    words[k++] = floatBitsToUint(r.origin.x);
    words[k++] = floatBitsToUint(r.origin.y);
    words[k++] = floatBitsToUint(r.origin.z);
    words[k++] = floatBitsToUint(r.tmin);
    words[k++] = floatBitsToUint(r.dir.x);
    words[k++] = floatBitsToUint(r.dir.y);
    words[k++] = floatBitsToUint(r.dir.z);
    words[k++] = floatBitsToUint(r.tmax);
    Hit h = hits[1];
    words[k++] = floatBitsToUint(h.t);
    words[k++] = h.prim_id;
    words[k++] = floatBitsToUint(h.u);
    words[k++] = floatBitsToUint(h.v);
    uvec2 interior = nodes[1];
    words[k++] = node_is_leaf(interior) ? 1u : 0u;
    words[k++] = node_axis(interior);
    words[k++] = floatBitsToUint(node_split(interior));
    words[k++] = node_above_child(interior);
    uvec2 leaf = nodes[2];
    words[k++] = node_is_leaf(leaf) ? 1u : 0u;
    words[k++] = node_prim_count(leaf);
    words[k++] = node_prim_offset(leaf);
    words[k++] = floatBitsToUint(params.scene_min.x);
    words[k++] = floatBitsToUint(params.scene_min.w);
    words[k++] = floatBitsToUint(params.scene_max.y);
    words[k++] = params.ray_count;
    words[k++] = params.pad0;
    words[k++] = params.pad2;
}
