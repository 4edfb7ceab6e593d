// A stack entry's segment [t0, t1] as one 64-bit word: the bits of both floats
// (packDouble2x32; no float64 arithmetic). lavapipe keeps private arrays in memory
// and stores or loads them lane by lane, so one 64-bit array beside the node array
// costs one scatter and one gather less per push and pop than two 32-bit ones
// (docs/BENCH.md, "A stack entry's segment in one 64-bit word").
// Used by the stack kernels (stack, short_stack, packet_stack, packet_short_stack);
// no CPU twin of its own: the twins' stacks hold (node, t0, t1) tuples.
#ifndef TRAVERSE_STACK_ENTRY_GLSL
#define TRAVERSE_STACK_ENTRY_GLSL

double seg_pack(float t0, float t1) {
    return packDouble2x32(uvec2(floatBitsToUint(t0), floatBitsToUint(t1)));
}

void seg_unpack(double seg, out float t0, out float t1) {
    uvec2 w = unpackDouble2x32(seg);
    t0 = uintBitsToFloat(w.x);
    t1 = uintBitsToFloat(w.y);
}

float seg_t0(double seg) {
    return uintBitsToFloat(unpackDouble2x32(seg).x);
}

// The empty segment [inf, -inf].
#define EMPTY_SEG packDouble2x32(uvec2(0x7f800000u, 0xff800000u))

#endif
