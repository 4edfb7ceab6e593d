#version 450
// examples/engine.rs: the engine's shading of kdtrace's two-level hits on a
// scene of instances. Each hit names the instance id, the geometry id and the
// triangle within the mesh (GpuInstanceHit); the engine's
// own index and interleaved vertex buffers then give the triangle's vertex
// normals, interpolated with the hit's (u, v) and carried to world space by the
// instance's normal matrix. A light at the eye on the instance's colour; sRGB
// RGBA8 out. Compiled against kdtrace.glsl alone, with the engine's defines and
// structs (engine.glsl, from glsl/examples/abi.rs).

#extension GL_GOOGLE_include_directive : require

#include "kdtrace.glsl"
#include "engine.glsl"

layout(local_size_x = ENGINE_WORKGROUP) in;

layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_RAYS) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_HITS) readonly buffer Hits { GpuInstanceHit hits[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_INSTANCES) readonly buffer Instances { EngineInstance instances[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_MESHES) readonly buffer Meshes { EngineMesh meshes[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_VERTICES) readonly buffer Vertices { float vertices[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_INDICES) readonly buffer Indices { uint index_words[]; };
layout(std430, set = 0, binding = ENGINE_SCENE_BINDING_PIXELS) writeonly buffer Pixels { uint pixels[]; };

layout(push_constant) uniform Push { EngineShadeParams params; };

float srgb(float c) {
    c = clamp(c, 0.0, 1.0);
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

// Index k (0, 1, 2) of triangle t of mesh m.
uint mesh_index(EngineMesh m, uint t, uint k) {
    uint i = 3u * t + k;
    if (m.index_bits == 16u) {
        uint word = index_words[m.first_word + i / 2u];
        return (i % 2u == 0u) ? (word & 0xffffu) : (word >> 16);
    }
    return index_words[m.first_word + i];
}

vec3 vertex_normal(EngineMesh m, uint index) {
    uint base = 6u * (m.first_vertex + index) + 3u;
    return vec3(vertices[base], vertices[base + 1u], vertices[base + 2u]);
}

void main() {
    uint index = gl_GlobalInvocationID.x;
    if (index >= params.count) return;
    GpuInstanceHit hit = hits[index];
    vec3 color;
    if (hit.prim_index == PRIM_INCOMPLETE) {
        color = vec3(1.0, 0.0, 1.0);  // traversal cut short: never passes as a miss
    } else if (hit.prim_index == PRIM_MISS || hit.prim_index == PRIM_INVALID) {
        color = vec3(0.05);
    } else {
        uint triangle = hit.prim_index;
        EngineMesh mesh = meshes[hit.geometry_id];
        EngineInstance inst = instances[hit.instance_id];
        vec3 n0 = vertex_normal(mesh, mesh_index(mesh, triangle, 0u));
        vec3 n1 = vertex_normal(mesh, mesh_index(mesh, triangle, 1u));
        vec3 n2 = vertex_normal(mesh, mesh_index(mesh, triangle, 2u));
        vec3 n = (1.0 - hit.u - hit.v) * n0 + hit.u * n1 + hit.v * n2;
        vec3 world = vec3(dot(inst.normal_x.xyz, n), dot(inst.normal_y.xyz, n), dot(inst.normal_z.xyz, n));
        vec3 dir = normalize(rays[index].dir);
        float cos_theta = abs(dot(normalize(world), dir));
        color = inst.color.rgb * (0.15 + 0.85 * cos_theta);
    }
    uvec3 rgb = uvec3(vec3(srgb(color.r), srgb(color.g), srgb(color.b)) * 255.0 + 0.5);
    pixels[index] = rgb.r | (rgb.g << 8) | (rgb.b << 16) | (255u << 24);
}
