// A stack entry's segment [t0, t1]: two float arrays beside the node array, in
// the stack kernels (stack, short_stack, packet_stack, packet_short_stack).
// Measured on lavapipe (Mesa 25, bunny camera rays, docs/BENCH.md): one 64-bit
// word per entry (packDouble2x32) was as fast, a uvec2 array 0.68x as fast (its
// vector elements cost far more than two scalar arrays); 64-bit words need
// shaderFloat64 or shaderInt64, which kernels do not use. No CPU twin of its
// own: the twins' stacks hold (node, t0, t1) tuples.
#ifndef TRAVERSE_STACK_ENTRY_GLSL
#define TRAVERSE_STACK_ENTRY_GLSL

// The empty segment [inf, -inf] (a packet lane that does not need an entry).
#define EMPTY_T0 uintBitsToFloat(0x7f800000u)
#define EMPTY_T1 uintBitsToFloat(0xff800000u)

#endif
