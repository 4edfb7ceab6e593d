// `stack` for packets: the packet descends together with one shared stack of
// nodes; each lane stores its own interval for every entry (empty when it does
// not need that child). The packet visits children in the order most of its
// lanes see as front to back; a lane whose own order differs still gets every
// part of its segment, and the closest hit wins because a popped entry is
// visited only by lanes whose interval starts before their best hit.
// CPU twin: src/kdtree/traverse/packet.rs (the same hits and per-lane counters,
// tests/packets.rs); packets must also give the single-ray twins' hits.
#ifndef TRAVERSE_PACKET_STACK_GLSL
#define TRAVERSE_PACKET_STACK_GLSL

#include "node.glsl"
#include "stack_entry.glsl"
#include "leaf.glsl"
#include "packet.glsl"

// True while the lane may still find something in an entry starting at t0.
bool lane_wants(bool alive, float t0, float t1, Closest best) {
    if (!alive || !(t0 <= t1)) return false;
    if (ANY_HIT) return best.hit.prim_id == PRIM_MISS;
    float reach = best_reach(best);
    return t0 < reach || (best.hit.prim_id == PRIM_MISS && t0 <= reach);
}

// Returns false when this lane's traversal was cut short.
bool trace_packet_stack(bool alive, TraceRay r, float t0, float t1, inout Closest best, inout TraceCounters c) {
    uvec4 mask = packet_mask();
    uint stack_node[MAX_STACK];
    float stack_t0[MAX_STACK];  // entries' segments [t0, t1] (see stack_entry.glsl)
    float stack_t1[MAX_STACK];
    uint sp = 0u;
    uint node = 0u;
    bool lane_on = alive;
    bool complete = true;
    if (!packet_any(lane_on, mask)) return true;
    for (uint step = 0u; step < MAX_TRAVERSAL_STEPS; ++step) {
        c.steps += 1u;
        uvec2 n = load_node(node);
        if (lane_on) c.nodes += 1u;
        if (!node_is_leaf(n)) {
            LaneSplit s = lane_split(lane_on, r, node, n, t0, t1, NO_PLANE);
            bool any_below = packet_any(s.below, mask);
            bool any_above = packet_any(s.above, mask);
            uint below = node + 1u;
            uint above = node_above_child(n);
            if (any_below && any_above) {
                bool below_goes_first = packet_count(lane_on && s.below_first, mask) >=
                                        packet_count(lane_on && !s.below_first, mask);
                stack_node[sp] = below_goes_first ? above : below;
                bool second = below_goes_first ? s.above : s.below;
                // A lane that does not need the second child gets the empty [inf, -inf].
                stack_t0[sp] = !second ? EMPTY_T0 : (below_goes_first ? s.above_t0 : s.below_t0);
                stack_t1[sp] = !second ? EMPTY_T1 : (below_goes_first ? s.above_t1 : s.below_t1);
                ++sp;
                node = below_goes_first ? below : above;
                lane_on = below_goes_first ? s.below : s.above;
                t0 = below_goes_first ? s.below_t0 : s.above_t0;
                t1 = below_goes_first ? s.below_t1 : s.above_t1;
            } else if (any_below) {
                node = below;
                lane_on = s.below;
                t0 = s.below_t0;
                t1 = s.below_t1;
            } else {
                node = above;
                lane_on = s.above;
                t0 = s.above_t0;
                t1 = s.above_t1;
            }
            continue;
        }
        if (lane_on) {
            c.leaves += 1u;
            if (!intersect_leaf(r, n, best, c)) complete = false;
        }
        // Pop until an entry some lane still needs.
        lane_on = false;
        while (sp > 0u) {
            --sp;
            node = stack_node[sp];
            t0 = stack_t0[sp];
            t1 = stack_t1[sp];
            lane_on = lane_wants(alive, t0, t1, best);
            if (packet_any(lane_on, mask)) break;
        }
        if (!packet_any(lane_on, mask)) return complete && sp == 0u;
    }
    return false;
}

#endif
