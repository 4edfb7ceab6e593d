#version 450
// Rasterized first hits, fragment stage: the visibility buffer holds the
// nearest triangle's number + 1 per pixel (0: nothing covers the pixel centre).

layout(location = 0) flat in uint prim;
layout(location = 0) out uint visibility;

void main() {
    visibility = prim + 1u;
}
