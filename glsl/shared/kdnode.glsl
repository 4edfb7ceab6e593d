// The 8-byte kd-tree node (pbrt-v3; Hapala & Havran) as a uvec2; these
// accessors are the GPU side of `KdNode`'s in src/kdtree/node.rs (the layout
// probe checks each).
//   interior: x = split position (float bits); y = axis (0..2) | NODE_BELOW_EMPTY
//             (below child is an empty leaf) | NODE_ABOVE_EMPTY (above child is)
//             | above child << NODE_CHILD_SHIFT. The below child is the next node
//             (depth-first order).
//   leaf:     y = NODE_LEAF | primitive count << NODE_TAG_BITS; x = offset into prim_indices.
#ifndef KDNODE_GLSL
#define KDNODE_GLSL

// NODE_LEAF, NODE_TAG_BITS, NODE_BELOW_EMPTY, NODE_ABOVE_EMPTY and
// NODE_CHILD_SHIFT: #defines from src/consts.rs.
#define NODE_TAG_MASK ((1u << NODE_TAG_BITS) - 1u)

bool node_is_leaf(uvec2 n) { return (n.y & NODE_TAG_MASK) == NODE_LEAF; }
uint node_axis(uvec2 n) { return n.y & NODE_TAG_MASK; }
float node_split(uvec2 n) { return uintBitsToFloat(n.x); }
uint node_above_child(uvec2 n) { return n.y >> NODE_CHILD_SHIFT; }
bool node_below_empty(uvec2 n) { return (n.y & NODE_BELOW_EMPTY) != 0u; }
bool node_above_empty(uvec2 n) { return (n.y & NODE_ABOVE_EMPTY) != 0u; }
uint node_prim_count(uvec2 n) { return n.y >> NODE_TAG_BITS; }
uint node_prim_offset(uvec2 n) { return n.x; }

#endif
