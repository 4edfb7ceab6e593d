// Node fetches and the per-ray counters they feed. CPU twin:
// src/kdtree/traverse/node.rs.
//
// Expects from its includer: the node texel buffer `node_texels` (a read-only
// storage texel buffer, R32G32_UINT, one texel per node; see trace.comp).
#ifndef TRAVERSE_NODE_GLSL
#define TRAVERSE_NODE_GLSL

#include "kdnode.glsl"

// Per-ray counters (kept even when COUNTERS is off; the compiler drops dead stores).
struct TraceCounters {
    uint nodes;
    uint leaves;
    uint triangles;
    uint restarts;
    uint steps;
    uint drops;
};

// Loads a node. A two-level kernel (GEOMETRY_BASES) keeps every geometry's
// nodes in one buffer and reads the current geometry's from `node_base` on.
uvec2 load_node(uint node) {
#ifdef GEOMETRY_BASES
    return imageLoad(node_texels, int(node_base + node)).xy;
#else
    return imageLoad(node_texels, int(node)).xy;
#endif
}

// Fetches a node, counting the visit and the loop step.
uvec2 fetch_node(uint node, inout TraceCounters c) {
    c.steps += 1u;
    c.nodes += 1u;
    return load_node(node);
}

#endif
