// The list a robust fast pass leaves to the careful pass: the indirect
// dispatch's arguments (x, y, z), the count, then the ray indices
// (CAREFUL_HEADER_WORDS, src/consts.rs). Used by trace.comp and
// trace_twolevel.comp.
//
// Expects from its includer: `careful[]`, a coherent uint buffer.
#ifndef TRAVERSE_CAREFUL_LIST_GLSL
#define TRAVERSE_CAREFUL_LIST_GLSL

// Lists ray `index` for the careful pass and grows its indirect dispatch by one
// workgroup at every TRACE_WORKGROUP_SIZE-th ray: the first CAREFUL_MAX_GROUPS
// in x, then one more row in y per as many.
void list_for_careful_pass(uint index) {
    uint slot = atomicAdd(careful[CAREFUL_COUNT], 1u);
    careful[CAREFUL_HEADER_WORDS + slot] = index;
    if (slot % TRACE_WORKGROUP_SIZE == 0u) {
        uint group = slot / TRACE_WORKGROUP_SIZE;
        if (group < CAREFUL_MAX_GROUPS) {
            atomicAdd(careful[0], 1u);
        } else if (group % CAREFUL_MAX_GROUPS == 0u) {
            atomicAdd(careful[1], 1u);
        }
    }
}

// The ray the careful pass's invocation traces: its place in the list
// (workgroups in rows of CAREFUL_MAX_GROUPS), or a value at or past the count.
uint careful_slot() {
    return (gl_WorkGroupID.y * gl_NumWorkGroups.x + gl_WorkGroupID.x) * TRACE_WORKGROUP_SIZE + gl_LocalInvocationID.x;
}

#endif
