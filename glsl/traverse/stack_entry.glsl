// A stack entry's segment [t0, t1] as one uvec2: the bits of both floats. The
// stack kernels once kept it in one 64-bit word (packDouble2x32), one private-
// array scatter and gather less per push and pop on lavapipe; kernels now use no
// 64-bit type (shaderFloat64 is optional in Vulkan), see docs/BENCH.md for the cost.
// Used by the stack kernels (stack, short_stack, packet_stack, packet_short_stack);
// no CPU twin of its own: the twins' stacks hold (node, t0, t1) tuples.
#ifndef TRAVERSE_STACK_ENTRY_GLSL
#define TRAVERSE_STACK_ENTRY_GLSL

uvec2 seg_pack(float t0, float t1) {
    return uvec2(floatBitsToUint(t0), floatBitsToUint(t1));
}

void seg_unpack(uvec2 seg, out float t0, out float t1) {
    t0 = uintBitsToFloat(seg.x);
    t1 = uintBitsToFloat(seg.y);
}

float seg_t0(uvec2 seg) {
    return uintBitsToFloat(seg.x);
}

// The empty segment [inf, -inf].
#define EMPTY_SEG uvec2(0x7f800000u, 0xff800000u)

#endif
