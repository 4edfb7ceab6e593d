// The 8-byte kd-tree node (pbrt-v3; Hapala & Havran). Mirrored by `KdNode` in
// src/kdtree/node.rs.
//   interior: x = split position (float bits); y = axis (0..2, low 2 bits) | above child << 2.
//             The below child is the next node (depth-first order).
//   leaf:     y = 3 | primitive count << 2; x = offset into prim_indices.
#ifndef KDNODE_GLSL
#define KDNODE_GLSL

bool node_is_leaf(uvec2 n) { return (n.y & 3u) == 3u; }
uint node_axis(uvec2 n) { return n.y & 3u; }
float node_split(uvec2 n) { return uintBitsToFloat(n.x); }
uint node_above_child(uvec2 n) { return n.y >> 2u; }
uint node_prim_count(uvec2 n) { return n.y >> 2u; }
uint node_prim_offset(uvec2 n) { return n.x; }

#endif
