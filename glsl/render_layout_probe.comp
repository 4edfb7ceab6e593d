#version 450
// Layout test kernel of the renderer: reads element 1 of each std430 struct of
// glsl/shared/render.glsl (Surface, Material, Emitter, PointLight, Path) and the
// RenderParams push constants, and writes their fields back as raw words in
// declaration order, so tests/layout.rs can prove the Rust mirrors
// (src/render/abi.rs) agree with the shaders' view field by field.

#extension GL_GOOGLE_include_directive : require

#include "ray.glsl"
#include "render.glsl"

layout(local_size_x = 1) in;

layout(std430, set = 0, binding = 0) readonly buffer Surfaces { Surface surfaces[]; };
layout(std430, set = 0, binding = 1) readonly buffer Materials { Material materials[]; };
layout(std430, set = 0, binding = 2) readonly buffer Emitters { Emitter emitters[]; };
layout(std430, set = 0, binding = 3) readonly buffer Lights { PointLight lights[]; };
layout(std430, set = 0, binding = 4) readonly buffer Paths { Path paths[]; };
layout(std430, set = 0, binding = 5) writeonly buffer Words { uint words[]; };

layout(push_constant) uniform Params { RenderParams p; };

uint k = 0u;

void put(vec4 v) {
    words[k++] = floatBitsToUint(v.x);
    words[k++] = floatBitsToUint(v.y);
    words[k++] = floatBitsToUint(v.z);
    words[k++] = floatBitsToUint(v.w);
}

void main() {
    put(p.eye);
    put(p.forward);
    put(p.right);
    put(p.up);
    put(p.background);
    words[k++] = p.width;
    words[k++] = p.height;
    words[k++] = p.count;
    words[k++] = p.sample_index;
    words[k++] = p.seed;
    words[k++] = p.max_depth;
    words[k++] = p.bounces;
    words[k++] = p.ao_samples;
    words[k++] = floatBitsToUint(p.ao_radius);
    words[k++] = p.light_count;
    words[k++] = p.emitter_count;
    words[k++] = p.shadow_capacity;
    Surface s = surfaces[1];
    put(s.v0);
    put(s.v1);
    put(s.v2);
    Material m = materials[1];
    put(m.kd);
    put(m.ks);
    put(m.ke);
    Emitter e = emitters[1];
    words[k++] = e.prim;
    words[k++] = floatBitsToUint(e.cdf);
    words[k++] = floatBitsToUint(e.pick);
    words[k++] = floatBitsToUint(e.area);
    PointLight l = lights[1];
    put(l.position);
    put(l.intensity);
    Path q = paths[1];
    words[k++] = floatBitsToUint(q.throughput.x);
    words[k++] = floatBitsToUint(q.throughput.y);
    words[k++] = floatBitsToUint(q.throughput.z);
    words[k++] = q.pixel;
    words[k++] = q.flags;
    words[k++] = q.depth;
    words[k++] = q.diffuse;
    words[k++] = q.pad;
}
