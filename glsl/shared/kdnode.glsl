// The 8-byte kd-tree node (pbrt-v3; Hapala & Havran) as a uvec2; these
// accessors are the GPU side of `KdNode`'s in src/kdtree/node.rs (the layout
// probe checks each).
//   interior: x = split position (float bits); y = axis (0..2) | above child << NODE_TAG_BITS.
//             The below child is the next node (depth-first order).
//   leaf:     y = NODE_LEAF | primitive count << NODE_TAG_BITS; x = offset into prim_indices.
#ifndef KDNODE_GLSL
#define KDNODE_GLSL

// NODE_LEAF and NODE_TAG_BITS: #defines from src/consts.rs.
#define NODE_TAG_MASK ((1u << NODE_TAG_BITS) - 1u)

bool node_is_leaf(uvec2 n) { return (n.y & NODE_TAG_MASK) == NODE_LEAF; }
uint node_axis(uvec2 n) { return n.y & NODE_TAG_MASK; }
float node_split(uvec2 n) { return uintBitsToFloat(n.x); }
uint node_above_child(uvec2 n) { return n.y >> NODE_TAG_BITS; }
uint node_prim_count(uvec2 n) { return n.y >> NODE_TAG_BITS; }
uint node_prim_offset(uvec2 n) { return n.x; }

#endif
