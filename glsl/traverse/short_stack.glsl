// `short-stack` and `push-down-short-stack` (Horn et al. 2007): a ring buffer of
// STACK_SIZE entries; a push onto a full stack overwrites (drops) the oldest
// entry; when the stack runs empty before the segment ends, restart behind the
// last leaf — at the root, or at the push-down node when `use_push_down`.
// With ROBUST on, that restart is exact (Seek in seek.glsl): the
// leaves and answers are the full stack's.
// CPU twin: `trace_short_stack` in src/kdtree/traverse/short_stack.rs.
#ifndef TRAVERSE_SHORT_STACK_GLSL
#define TRAVERSE_SHORT_STACK_GLSL

#include "node.glsl"
#include "stack_entry.glsl"
#include "decide.glsl"
#include "seek.glsl"
#include "leaf.glsl"

bool trace_short_stack(TraceRay r, float t0, float t1_scene, bool use_push_down, inout Closest best,
                       inout TraceCounters c) {
    uint stack_node[STACK_SIZE];
    float stack_t0[STACK_SIZE];  // entries' segments [t0, t1] (see stack_entry.glsl)
    float stack_t1[STACK_SIZE];
    uvec2 stack_plane[STACK_SIZE];  // the plane each entry's segment ends at
    uint head = 0u;   // next slot to write
    uint count = 0u;
    uint node = 0u;
    float t1 = t1_scene;
    float t0_restart = t0;  // where the segment started at the last restart
    uvec2 exit_plane = NO_PLANE;  // the plane the last leaf was left through
    uvec2 t1_plane = NO_PLANE;    // the plane the current segment ends at
    uint restart_node = 0u;
    float restart_t0 = t0;  // the restart node's stack segment (exact restarts)
    float restart_t1 = t1_scene;
    bool push_down = use_push_down;
    uint dropped = 0u;      // exact restarts: entries pending below the short stack
    bool in_plane = false;  // a ray in a split plane pushed an entry (see restart.glsl)
    Seek k = seek_start(0u, false, 0u);  // exact restarts seek in this loop (seek.glsl)
    // While-while form (see stack.glsl): descend to a leaf, then visit it.
    uint step = 0u;
    while (step < MAX_TRAVERSAL_STEPS) {
        uvec2 n = fetch_node(node, c);
        ++step;
        // An empty leaf that does not end the traversal, with an entry to pop, is
        // left inside the descent (as in stack.glsl, which says why the pop below is
        // written twice); restarts go through the leaf visit below.
        if (descends(n, t1, best) && (!node_is_leaf(n) || (count > 0u && !k.seeking))) do {
            uint near, far;
            float ts;
            uint visit = node_is_leaf(n) ? VISIT_NEAR : decide_children(r, node, n, t0, t1, exit_plane, near, far, ts);
            if (node_is_leaf(n)) {
                // The pop after a leaf (below). push_down is false here: an entry
                // to pop means a push since the last restart.
                c.leaves += 1u;
                head = (head + STACK_SIZE - 1u) % STACK_SIZE;
                count -= 1u;
                node = stack_node[head];
                t0 = stack_t0[head];
                t1 = stack_t1[head];
                t1_plane = stack_plane[head];
            } else if (ROBUST && k.seeking) {
                node = seek_step(k, node, n, visit, near, far, ts, t0, t1, best_reach(best));
                if (!k.seeking) {
                    if (!k.found) return true;  // nothing left
                    node = k.next;
                    t0 = k.next_t0;
                    t1 = k.next_t1;
                    dropped = k.above;
                    push_down = use_push_down && dropped == 0u;
                    c.restarts += 1u;
                }
            } else if (visit == VISIT_FAR) {
                node = far;
            } else if (visit == VISIT_NEAR) {
                node = near;
            } else {
                // Push the far child; a full stack loses its oldest entry.
                if (count == STACK_SIZE) {
                    c.drops += 1u;
                    dropped += 1u;
                } else {
                    count += 1u;
                }
                stack_node[head] = far;
                stack_t0[head] = visit == VISIT_BOTH ? ts : t0;
                stack_t1[head] = t1;
                stack_plane[head] = t1_plane;
                head = (head + 1u) % STACK_SIZE;
                if (visit == VISIT_BOTH_SAME) in_plane = true;
                if (visit == VISIT_BOTH) {
                    t1 = ts;
                    t1_plane = node_plane(n);
                }
                node = near;
                push_down = false;
            }
            if (push_down) {
                restart_node = node;
                restart_t0 = t0;
                restart_t1 = t1;
            }
            if (step >= MAX_TRAVERSAL_STEPS) return false;
            n = fetch_node(node, c);
            ++step;
        } while (descends(n, t1, best) && (!node_is_leaf(n) || (count > 0u && !k.seeking)));
        uint leaf = visit_leaf(r, n, t1, best, c);
        if (leaf == LEAF_CUT) return false;
        if (leaf == LEAF_DONE) {
            if (ANY_HIT) return true;
            // As in stack.glsl: only entries starting before the hit can hold a
            // closer one (the other side of a split plane the ray lies in).
            while (count > 0u && !(stack_t0[(head + STACK_SIZE - 1u) % STACK_SIZE] < best_reach(best))) {
                head = (head + STACK_SIZE - 1u) % STACK_SIZE;
                count -= 1u;
            }
            if (count == 0u && (!ROBUST || dropped == 0u || !in_plane)) return true;
        }
        if (count > 0u) {
            head = (head + STACK_SIZE - 1u) % STACK_SIZE;
            count -= 1u;
            node = stack_node[head];
            t0 = stack_t0[head];
            t1 = stack_t1[head];
            t1_plane = stack_plane[head];
            continue;
        }
        if (ROBUST) {
            if (dropped == 0u) return true;
            k = seek_start(node, leaf == LEAF_DONE, dropped);
            node = restart_node;
            t0 = restart_t0;
            t1 = restart_t1;
            continue;
        }
        if (t1 >= t1_scene) return true;
        restart_after_leaf(t1_scene, best_reach(best), t0, t1, t0_restart, exit_plane, t1_plane);
        node = restart_node;
        push_down = use_push_down;
        c.restarts += 1u;
    }
    return false;
}

#endif
