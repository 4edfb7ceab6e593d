// Packets as subgroups (Horn et al. 2007 traversed 4-ray packets with a mask):
// a packet is an aligned group of PACKET_WIDTH lanes inside a subgroup. Decisions
// come from ballots restricted to the group's bits; each lane keeps its own
// t-interval and hit; lanes that do not need a subtree are masked out.
// Expects from its includer: the specialization constant PACKET_WIDTH, the
// subgroup extensions, and what decide.glsl expects.
#ifndef TRAVERSE_PACKET_GLSL
#define TRAVERSE_PACKET_GLSL

#include "segment.glsl"
#include "decide.glsl"

// The ballot bits of this lane's packet.
uvec4 packet_mask() {
    uint base = (gl_SubgroupInvocationID / PACKET_WIDTH) * PACKET_WIDTH;
    uvec4 mask = uvec4(0u);
    for (uint word = 0u; word < 4u; ++word) {
        uint lo = max(base, word * 32u);
        uint hi = min(base + PACKET_WIDTH, word * 32u + 32u);
        if (lo < hi) {
            uint n = hi - lo;
            uint bits = n == 32u ? 0xFFFFFFFFu : ((1u << n) - 1u);
            mask[word] = bits << (lo - word * 32u);
        }
    }
    return mask;
}

bool packet_any(bool c, uvec4 mask) {
    return any(notEqual(subgroupBallot(c) & mask, uvec4(0u)));
}

uint packet_count(bool c, uvec4 mask) {
    return subgroupBallotBitCount(subgroupBallot(c) & mask);
}

// One lane's view of an interior node: which children it needs, with which
// intervals, and which child comes first for it (front to back).
struct LaneSplit {
    bool below;          // needs the below child
    bool above;          // needs the above child
    bool below_first;    // below is its near child
    bool splits;         // needs both children
    bool same;           // lies in the split plane: both children with the same interval
    float below_t0, below_t1, above_t0, above_t1;
};

LaneSplit lane_split(bool lane_on, TraceRay r, uint node, uvec2 n, float t0, float t1, uvec2 exit_plane) {
    LaneSplit s;
    s.below = false;
    s.above = false;
    s.below_first = true;
    s.splits = false;
    s.same = false;
    s.below_t0 = t0; s.below_t1 = t1; s.above_t0 = t0; s.above_t1 = t1;
    if (!lane_on) return s;
    uint near, far;
    float ts;
    uint visit = decide_children(r, node, n, t0, t1, exit_plane, near, far, ts);
    s.below_first = near == node + 1u;
    bool need_near = visit != VISIT_FAR;
    bool need_far = visit != VISIT_NEAR;
    s.splits = need_near && need_far;
    s.same = visit == VISIT_BOTH_SAME;
    float near_t1 = visit == VISIT_BOTH ? ts : t1;
    float far_t0 = visit == VISIT_BOTH ? ts : t0;
    if (s.below_first) {
        s.below = need_near; s.below_t1 = near_t1;
        s.above = need_far; s.above_t0 = far_t0;
    } else {
        s.above = need_near; s.above_t1 = near_t1;
        s.below = need_far; s.below_t0 = far_t0;
    }
    return s;
}

#endif
