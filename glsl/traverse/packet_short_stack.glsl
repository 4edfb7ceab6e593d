// `restart`, `push-down`, `short-stack` and `push-down-short-stack` for packets
// (Horn et al. 2007): one shared ring buffer of `size` entries (0 = kd-restart)
// and one shared restart node. Every lane walks its own segment strictly front
// to back: it takes part in an entry only if the entry starts exactly where its
// last leaf ended; any part it could not take (the packet went the other way, an
// entry was dropped) is picked up by the next restart, which starts each lane at
// the exit of its last leaf. That is the paper's scheme, run when ROBUST is off.
// With ROBUST on there is no restart at a t value (which cannot order the cells
// around an edge or vertex the ray passes within rounding of): where the packet
// would restart, each unfinished lane finishes alone with exact restarts
// (trace_restart_exact) over the part of its segment behind its last leaf and
// behind the earliest entry it had to leave (t_gap), or over all of it when the
// lane lay in a split plane (whose other side it may have skipped). A lane that
// finishes earlier does the same when it left an entry starting before its hit.
// CPU twin: src/kdtree/traverse/packet.rs (the same hits and per-lane counters,
// tests/packets.rs); packets must also give the single-ray twins' hits.
#ifndef TRAVERSE_PACKET_SHORT_STACK_GLSL
#define TRAVERSE_PACKET_SHORT_STACK_GLSL

#include "node.glsl"
#include "stack_entry.glsl"
#include "decide.glsl"
#include "leaf.glsl"
#include "packet.glsl"
#include "restart.glsl"

bool trace_packet_short_stack(bool alive, TraceRay r, float t_start, float t1_scene, uint size, bool use_push_down,
                              inout Closest best, inout TraceCounters c) {
    uvec4 mask = packet_mask();
    uint stack_node[STACK_SIZE];
    float stack_t0[STACK_SIZE];  // entries' segments [t0, t1] (see stack_entry.glsl)
    float stack_t1[STACK_SIZE];
    uint head = 0u;   // next slot to write
    uint count = 0u;
    uint node = 0u;
    uint restart_node = 0u;
    bool push_down = use_push_down;
    float t0 = t_start;
    float t1 = t1_scene;
    float t_done = t_start;    // exit of the last leaf this lane finished
    float t0_restart = t_start;  // where this lane's segment started at the last restart
    uvec2 exit_plane = NO_PLANE;
    bool lane_on = alive;
    bool complete = true;
    bool in_plane = false;  // ROBUST: this lane lay in a split plane
    bool fallback = false;  // ROBUST: this lane finishes alone with exact restarts from t_from
    float t_from = t_start;
    float t_gap = uintBitsToFloat(0x7f800000u);  // ROBUST: earliest start of an entry this lane left
    bool ended = false;
    if (!packet_any(lane_on, mask)) return true;
    uint step = 0u;
    for (; step < MAX_TRAVERSAL_STEPS; ++step) {
        c.steps += 1u;
        uvec2 n = load_node(node);
        if (lane_on) c.nodes += 1u;
        if (!node_is_leaf(n)) {
            LaneSplit s = lane_split(lane_on, r, node, n, t0, t1, exit_plane);
            if (s.same) in_plane = true;
            // A lane's first child is its near one when it needs it, else the only one.
            bool wants_below = s.below && (s.below_first || !s.above);
            bool wants_above = s.above && !wants_below;
            bool any_below = packet_any(wants_below, mask);
            bool any_above = packet_any(wants_above, mask);
            uint below = node + 1u;
            uint above = node_above_child(n);
            bool go_below = any_below && (!any_above || packet_count(wants_below, mask) >= packet_count(wants_above, mask));
            uint first = go_below ? below : above;
            uint second = go_below ? above : below;
            // Lanes that go on, and the part of the other child each lane still needs.
            bool goes_on = go_below ? wants_below : wants_above;
            bool needs_second = go_below ? s.above : s.below;
            float second_t0 = go_below ? s.above_t0 : s.below_t0;
            float second_t1 = go_below ? s.above_t1 : s.below_t1;
            // ROBUST: a lane that needs the first child but waits for its near one
            // (the second) has lost the first.
            bool needs_first = go_below ? s.below : s.above;
            if (needs_first && !goes_on) t_gap = min(t_gap, go_below ? s.below_t0 : s.above_t0);
            if (packet_any(needs_second, mask)) {
                push_down = false;
                // ROBUST: without a stack (kd-restart) the second child is lost to its lanes.
                if (size == 0u && needs_second) t_gap = min(t_gap, second_t0);
                if (size > 0u) {
                    if (count == size) {
                        // ROBUST: the overwritten entry is lost to its lanes.
                        float lost_t0 = stack_t0[head], lost_t1 = stack_t1[head];
                        if (alive && lost_t0 <= lost_t1) t_gap = min(t_gap, lost_t0);
                        // The oldest entry is overwritten: its lanes will restart.
                        if (alive) c.drops += 1u;
                    } else {
                        count += 1u;
                    }
                    stack_node[head] = second;
                    // A lane that does not need the second child gets the empty [inf, -inf].
                    stack_t0[head] = needs_second ? second_t0 : EMPTY_T0;
                    stack_t1[head] = needs_second ? second_t1 : EMPTY_T1;
                    head = (head + 1u) % size;
                }
            }
            if (packet_any(s.splits, mask)) push_down = false;
            node = first;
            lane_on = goes_on;
            t0 = go_below ? s.below_t0 : s.above_t0;
            t1 = go_below ? s.below_t1 : s.above_t1;
            if (push_down) restart_node = node;
            continue;
        }
        if (lane_on) {
            c.leaves += 1u;
            if (!intersect_leaf(r, n, best, c)) complete = false;
            bool done = leaf_done(best, t1);
            t_done = t1;
            if (done || t1 >= t1_scene) {
                alive = false;
                if (ROBUST) {
                    // Entries still on the stack for this lane are lost to it too.
                    for (uint k = 0u; k < count; ++k) {
                        uint slot = (head + size - 1u - k) % size;
                        float lost_t0 = stack_t0[slot], lost_t1 = stack_t1[slot];
                        if (lost_t0 <= lost_t1) t_gap = min(t_gap, lost_t0);
                    }
                    // Before the first hit, on a segment that ends at tmax (not at
                    // the scene's box; then best.hit.t is tmax's bound), an entry
                    // clamped to start at the segment's end may still hold a hit
                    // exactly at tmax.
                    bool at_tmax = best.hit.prim_id == PRIM_MISS && !(t1_scene < best.hit.t);
                    bool lost = t_gap < best_reach(best) || (at_tmax && t_gap <= best_reach(best));
                    if (!(ANY_HIT && done) && (in_plane || lost)) {
                        fallback = true;
                        t_from = in_plane ? -3.40282347e38 : t_gap;
                    }
                }
            }
        }
        // Pop until an entry that continues some lane's segment.
        lane_on = false;
        while (count > 0u) {
            head = (head + size - 1u) % size;
            count -= 1u;
            node = stack_node[head];
            t0 = stack_t0[head];
            t1 = stack_t1[head];
            lane_on = alive && t0 <= t1 && t0 == t_done;
            if (alive && t0 <= t1 && t0 != t_done) t_gap = min(t_gap, t0);
            if (packet_any(lane_on, mask)) break;
        }
        if (packet_any(lane_on, mask)) continue;
        if (!packet_any(alive, mask)) {
            ended = true;
            break;
        }
        if (ROBUST) {
            if (alive) {
                fallback = true;
                t_from = in_plane ? -3.40282347e38 : min(t_done, t_gap);
                alive = false;
            }
            ended = true;
            break;
        }
        // Restart every unfinished lane behind its last leaf.
        count = 0u;
        node = restart_node;
        push_down = use_push_down;
        lane_on = alive;
        t0 = restart_point(t_done, t0_restart);
        if (alive) t0_restart = t0;
        t_done = t0;
        t1 = min(t1_scene, best_reach(best));
        if (alive) {
            exit_plane = ANY_PLANE;
            c.restarts += 1u;
        }
    }
    if (ROBUST && fallback) {
        return trace_restart_exact(r, t_start, t1_scene, true, t_from, step, best, c) && complete;
    }
    return ended && complete;
}

#endif
