#version 450
// Rasterized first hits, fragment stage: the visibility buffer holds the
// nearest triangle's number + 1 per pixel (0: nothing covers the pixel centre).

layout(location = RASTER_LOCATION_PRIM) flat in uint prim;
layout(location = RASTER_LOCATION_VISIBILITY) out uint visibility;

void main() {
    visibility = prim + 1u;
}
