// The exact restart's seek: the entry a full stack would pop after a leaf,
// found inside a variant's own descent loop. CPU twin:
// src/kdtree/traverse/seek.rs (`stack_successor`).
//
// Expects from its includer: what decide.glsl expects.
#ifndef TRAVERSE_SEEK_GLSL
#define TRAVERSE_SEEK_GLSL

#include "kdnode.glsl"
#include "decide.glsl"

// Exact restarts (ROBUST; `restart`, `push-down` and a short stack run empty):
// instead of starting again at a t value - at a vertex or edge of cells several
// leaves end within one float of each other, and a t cannot order them - find the
// entry a full stack would pop after the leaf just left. The traversal seeks it in
// its own descent loop (one loop, so SIMD lanes that seek and lanes that descend
// share it): from the restart node (an ancestor of the leaf with no pending entry
// above it, whose stack segment it knows) along the path to the leaf, with the
// stack's own decisions; the entry is the far child of the deepest node where the
// path took the near side of a split that needed both children. `done`: the leaf
// held the closest hit, and only entries that start before it count (the stack's
// drop rule). `known`: how many entries are pending on that path; the seek ends at
// the last of them (the deepest), so it descends no deeper than a kd-restart to
// the same entry.
struct Seek {
    bool seeking;
    uint target;  // the leaf just left
    bool done;
    uint known;
    uint seen;    // pending entries met so far
    bool found;
    uint next;    // the entry: node, stack segment, entries pending above it
    float next_t0;
    float next_t1;
    uint above;
};

// A seek for the entry after leaf `target`; none (not seeking) when known is 0.
Seek seek_start(uint target, bool done, uint known) {
    Seek k;
    k.seeking = known > 0u;
    k.target = target;
    k.done = done;
    k.known = known;
    k.seen = 0u;
    k.found = false;
    k.next = 0u;
    k.next_t0 = 0.0;
    k.next_t1 = 0.0;
    k.above = 0u;
    return k;
}

// One node of the seek: notes the entry a decision leaves (if any), keeps the
// stack's segment in t0, t1, and returns the child on the path. Ends the seek
// (k.seeking = false) at the last known entry or at the leaf.
uint seek_step(inout Seek k, uint node, uvec2 n, uint visit, uint near, uint far, float ts, inout float t0,
               inout float t1, float best_t) {
    uint child = k.target >= node_above_child(n) ? node_above_child(n) : node + 1u;
    if (visit == VISIT_BOTH || visit == VISIT_BOTH_SAME) {
        float far_t0 = visit == VISIT_BOTH ? ts : t0;
        if (child == near) {
            if (!k.done || far_t0 < best_t) {
                k.found = true;
                k.next = far;
                k.next_t0 = far_t0;
                k.next_t1 = t1;
                k.above = k.seen;
            }
            k.seen += 1u;
            if (visit == VISIT_BOTH) t1 = ts;
        } else {
            t0 = far_t0;
        }
    }
    if (k.seen == k.known || child == k.target) k.seeking = false;
    return child;
}

#endif
