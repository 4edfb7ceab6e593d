#version 450
// examples/embed.rs, pass 3: the engine's own shading of kdtrace's hits. A light
// at the eye on each triangle's diffuse colour (as `kdtrace render` shades),
// written as sRGB RGBA8 pixels. Compiled against kdtrace.glsl alone, with the
// engine's own ENGINE_* #defines and structs (engine.glsl, generated from
// glsl/examples/abi.rs).

#extension GL_GOOGLE_include_directive : require

#include "kdtrace.glsl"
#include "engine.glsl"

layout(local_size_x = ENGINE_WORKGROUP) in;

layout(std430, set = 0, binding = ENGINE_SHADE_BINDING_RAYS) readonly buffer Rays { Ray rays[]; };
layout(std430, set = 0, binding = ENGINE_SHADE_BINDING_HITS) readonly buffer Hits { Hit hits[]; };
layout(std430, set = 0, binding = ENGINE_SHADE_BINDING_SURFACES) readonly buffer Surfaces { Surface surfaces[]; };
layout(std430, set = 0, binding = ENGINE_SHADE_BINDING_PIXELS) writeonly buffer Pixels { uint pixels[]; };

layout(push_constant) uniform Push { ShadeParams params; };

float srgb(float c) {
    c = clamp(c, 0.0, 1.0);
    return c <= 0.0031308 ? 12.92 * c : 1.055 * pow(c, 1.0 / 2.4) - 0.055;
}

void main() {
    uint index = gl_GlobalInvocationID.x;
    if (index >= params.count) return;
    Hit hit = hits[index];
    vec3 color;
    if (hit.prim_id == PRIM_INCOMPLETE) {
        color = vec3(1.0, 0.0, 1.0);  // traversal cut short: never passes as a miss
    } else if (hit.prim_id == PRIM_MISS || hit.prim_id == PRIM_INVALID) {
        color = vec3(0.05);
    } else {
        Surface s = surfaces[hit.prim_id];
        vec3 dir = normalize(rays[index].dir);
        float cos_theta = abs(dot(s.normal.xyz, dir));
        color = s.albedo.rgb * (0.1 + 0.9 * cos_theta) + s.emission.rgb;
    }
    uvec3 rgb = uvec3(vec3(srgb(color.r), srgb(color.g), srgb(color.b)) * 255.0 + 0.5);
    pixels[index] = rgb.r | (rgb.g << 8) | (rgb.b << 16) | (255u << 24);
}
