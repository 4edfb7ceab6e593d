#version 450
// Device-counted traces (Tracer::record_binding_indirect): one invocation turns
// the caller's ray count (word `word` of its buffer, written by an earlier pass
// on the device) into a binding's arguments (INDIRECT_WORDS words, src/consts.rs):
// the trace kernel's dispatch, the count clamped to the binding's capacity, and
// the ordering kernel's dispatch. Dispatches lay their workgroups out in rows of
// CAREFUL_MAX_GROUPS (x), more rows in y (glsl/shared/batch.glsl).

layout(local_size_x = 1) in;

layout(std430, set = 0, binding = ARGS_BINDING_SOURCE) readonly buffer Source { uint source[]; };
layout(std430, set = 0, binding = ARGS_BINDING_ARGS) writeonly buffer Args { uint args[]; };

layout(push_constant) uniform Push {
    uint word;      // the count's word in the source
    uint capacity;  // the binding's capacity: counts above it are clamped
} push;

// Workgroups of `group_size` for `count` invocations, in rows.
uvec3 rows(uint count, uint group_size) {
    uint groups = count / group_size + uint(count % group_size != 0u);
    if (groups == 0u) return uvec3(0u, 1u, 1u);
    uint x = min(groups, CAREFUL_MAX_GROUPS);
    return uvec3(x, (groups + x - 1u) / x, 1u);
}

void main() {
    uint count = min(source[push.word], push.capacity);
    uvec3 trace = rows(count, TRACE_WORKGROUP_SIZE);
    uvec3 order = rows(count, ORDER_WORKGROUP_SIZE);
    args[0] = trace.x;
    args[1] = trace.y;
    args[2] = trace.z;
    args[INDIRECT_COUNT] = count;
    args[INDIRECT_ORDER_ARGS] = order.x;
    args[INDIRECT_ORDER_ARGS + 1u] = order.y;
    args[INDIRECT_ORDER_ARGS + 2u] = order.z;
    args[INDIRECT_ORDER_ARGS + 3u] = 0u;
}
