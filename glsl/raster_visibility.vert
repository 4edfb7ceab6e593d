#version 450
// Rasterized first hits (--primary raster), vertex stage: projects the scene's
// triangles (3 vertices each, not indexed) with the pinhole model of the camera
// rays, so that the pixel centre the rasterizer samples is the point a camera
// ray of this sample passes through. See src/gpu/raster.rs.
//
// Clip space: x = q·right, y = -q·up (Vulkan's y points down), w = q·forward
// for q = p - eye, with right and up divided by their squared lengths; then a
// pixel-centre sample at NDC (sx, -sy) is the ray forward + sx·right + sy·up.
// z = near for every vertex gives the depth near / w: 1 at the near plane and
// falling toward 0 at infinity (reversed, infinite far plane; compare GREATER).

#extension GL_GOOGLE_include_directive : require

#include "raster.glsl"

layout(location = RASTER_LOCATION_POSITION) in vec3 position;
layout(location = RASTER_LOCATION_PRIM) flat out uint prim;

layout(push_constant) uniform Push { RasterView view; };

void main() {
    vec3 q = position - view.eye.xyz;
    float w = dot(q, view.forward.xyz);
    float x = dot(q, view.right.xyz);
    float y = -dot(q, view.up.xyz);
    gl_Position = vec4(x - view.params.y * w, y - view.params.z * w, view.params.x, w);
    prim = uint(gl_VertexIndex) / 3u;
}
