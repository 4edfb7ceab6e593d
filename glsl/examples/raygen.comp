#version 450
// examples/embed.rs, pass 1: the engine's own ray generation. One pinhole-camera
// ray per pixel, written as kdtrace `Ray`s into a range of the engine's buffer.
// Compiled against kdtrace.glsl alone (shaders::HEADER), as a user's shader is,
// with the engine's own ENGINE_* #defines and structs (engine.glsl, generated
// from glsl/examples/abi.rs).

#extension GL_GOOGLE_include_directive : require

#include "kdtrace.glsl"
#include "engine.glsl"

layout(local_size_x = ENGINE_WORKGROUP) in;

layout(std430, set = 0, binding = ENGINE_RAYGEN_BINDING_RAYS) writeonly buffer Rays { Ray rays[]; };

layout(push_constant) uniform Push { CameraParams cam; };

void main() {
    uint index = gl_GlobalInvocationID.x;
    if (index >= cam.width * cam.height) return;
    uint x = index % cam.width;
    uint y = index / cam.width;
    float sx = 2.0 * (float(x) + 0.5) / float(cam.width) - 1.0;
    float sy = 1.0 - 2.0 * (float(y) + 0.5) / float(cam.height);
    Ray ray;
    ray.origin = cam.eye.xyz;
    ray.tmin = 0.0;
    ray.dir = normalize(cam.forward.xyz + sx * cam.right.xyz + sy * cam.up.xyz);
    ray.tmax = uintBitsToFloat(0x7f800000u);  // +inf
    rays[index] = ray;
}
