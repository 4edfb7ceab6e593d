// Which ray of a batch an invocation traces, and how many rays the batch holds:
// `ray_count` rays dispatched in one row of workgroups, or, for a device-counted
// trace (`indirect` of TraceParams or TwoLevelParams, record_binding_indirect), the count that
// glsl/indirect_args.comp wrote into the binding's arguments, dispatched
// indirectly in rows of CAREFUL_MAX_GROUPS workgroups. Used by trace.comp,
// trace_twolevel.comp, trace_ray_query.comp and order_rays.comp.
//
// Expects from its includer: `params` (with `ray_count` and `indirect`) and `indirect_words[]`.
#ifndef SHARED_BATCH_GLSL
#define SHARED_BATCH_GLSL

// The invocation's place in its dispatch of workgroups of `group_size`.
uint batch_slot(uint group_size) {
    if (params.indirect == 0u) return gl_GlobalInvocationID.x;
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * group_size + gl_LocalInvocationID.x;
}

// The rays of the batch: invocations at or past it return.
uint batch_count() {
    return params.indirect != 0u ? indirect_words[INDIRECT_COUNT] : params.ray_count;
}

#endif
