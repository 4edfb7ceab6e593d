#version 450
// The trace kernel: one ray per invocation, closest hit, traversal variant chosen
// by a specialization constant. Shared layouts live in glsl/shared/.
//
// A driver may end loops silently (Mesa lavapipe gives each subgroup one budget
// of loop passes for the whole run, see docs/BENCH.md). Every loop here checks
// that it ran to its end; a ray whose traversal was cut short (or hit the step
// cap) is written as PRIM_INCOMPLETE, which the host reports, never as a miss.

#extension GL_GOOGLE_include_directive : require
#extension GL_KHR_shader_subgroup_basic : require
#extension GL_KHR_shader_subgroup_ballot : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "ray_checks.glsl"
#include "kdnode.glsl"

layout(local_size_x = TRACE_WORKGROUP_SIZE) in;

// Specialization constants (src/trace.rs sets them; never edit the source to switch).
// build.rs compiles this kernel once per variant (TRACE_MODULE_VARIANT): a
// module holds one traversal, so the validation layer, which re-validates the
// module at every pipeline creation, reads a seventh of the code.
const uint VARIANT = TRACE_MODULE_VARIANT;
layout(constant_id = TRACE_SPEC_COUNTERS) const bool COUNTERS = false;
layout(constant_id = TRACE_SPEC_STACK_SIZE) const uint STACK_SIZE = 3u;   // short-stack entries, 1..MAX_SHORT_STACK
layout(constant_id = TRACE_SPEC_ANY_HIT) const bool ANY_HIT = false;   // stop at the first hit (shadow rays)
layout(constant_id = TRACE_SPEC_PACKET_WIDTH) const uint PACKET_WIDTH = 1u; // lanes per packet; 1 = single rays
layout(constant_id = TRACE_SPEC_ROBUST) const bool ROBUST = true;     // conservative decisions, exact fallback near edges
layout(constant_id = TRACE_SPEC_PASS) const uint PASS = PASS_ONE;   // PASS_FAST / PASS_CAREFUL: robust single rays (see main)

// Far rays move to the scene box (shift_to_scene below) in the kernels that
// trace carefully: the careful pass and packets. The fast pass lists them.
const bool SEGMENT_FRAME = ROBUST && PASS != PASS_FAST;

#include "triangle.glsl"

// Nodes and triangles are read-only storage texel buffers (imageLoad of an
// imageBuffer), not storage buffers: lavapipe loads a storage buffer one lane and
// one 32-bit component at a time, whereas an image load is a straight-line gather
// of whole texels, in a shorter call than a texel fetch through a texture
// (docs/BENCH.md, "Where the instructions go").
// Nodes: R32G32_UINT, one texel per node. Triangles: R32G32B32A32_UINT, three
// texels per leaf reference, in prim_indices order: (v0, prim), (v1, 0), (v2, 0).
layout(set = 0, binding = BINDING_NODES, rg32ui) uniform readonly uimageBuffer node_texels;
layout(std430, set = 0, binding = BINDING_PRIM_INDICES) readonly buffer PrimIndices { uint prim_indices[]; };
layout(set = 0, binding = BINDING_TRIANGLES, rgba32ui) uniform readonly uimageBuffer tri_texels;
// Rays are read as two uvec4 words (bits only; no 64-bit type in any kernel).
layout(std430, set = 0, binding = BINDING_RAYS) readonly buffer Rays { uvec4 ray_words[]; };
layout(std430, set = 0, binding = BINDING_HITS) writeonly buffer Hits { Hit hits[]; };
layout(std430, set = 0, binding = BINDING_COUNTERS) writeonly buffer Counters { uint counters[]; };
// Side buffers of backtrack and ropes (a 4-byte dummy is bound for the others).
layout(std430, set = 0, binding = BINDING_PARENTS) readonly buffer Parents { uint parents[]; };
layout(std430, set = 0, binding = BINDING_NODE_BOXES) readonly buffer NodeBoxes { float node_boxes[]; };
layout(std430, set = 0, binding = BINDING_ROPES) readonly buffer Ropes { uint ropes[]; };
// The rays the fast pass leaves to the careful pass: the indirect dispatch's
// arguments (x, y, z), their count, then their indices (src/consts.rs).
layout(std430, set = 0, binding = BINDING_CAREFUL) coherent buffer Careful { uint careful[]; };
// The coherent order of the batch, when params.ordered (glsl/order_rays.comp).
layout(std430, set = 0, binding = BINDING_ORDER) readonly buffer Order { uint order[]; };
// A device-counted batch's arguments, when params.indirect (glsl/indirect_args.comp).
layout(std430, set = 0, binding = BINDING_INDIRECT) readonly buffer Indirect { uint indirect_words[]; };

layout(push_constant) uniform Push { TraceParams params; };

#include "batch.glsl"

// The traversal pieces (segment, node, decide, seek, leaf, boxes) come with the
// variants that include them; each names the buffers and constants above it reads.
#include "stack.glsl"
#include "restart.glsl"
#include "push_down.glsl"
#include "short_stack.glsl"
#include "backtrack.glsl"
#include "ropes.glsl"
#include "packet.glsl"
#include "packet_stack.glsl"
#include "packet_short_stack.glsl"
#include "ray_setup.glsl"
#include "careful_list.glsl"

// Runs the variant on one ray (every lane enters for packets: their decisions
// are ballots). False when the driver cut a loop short.
bool run_traversal(bool alive, TraceRay r, float t0, float t1, inout Closest best, inout TraceCounters c) {
    bool finished = true;
    bool packet_variant = VARIANT == VARIANT_STACK || VARIANT == VARIANT_RESTART || VARIANT == VARIANT_PUSH_DOWN ||
                          VARIANT == VARIANT_SHORT_STACK || VARIANT == VARIANT_PUSH_DOWN_SHORT_STACK;
    if (PACKET_WIDTH > 1u && packet_variant) {
        // Every lane of a packet enters, finished or not: decisions are ballots.
        if (VARIANT == VARIANT_STACK) {
            finished = trace_packet_stack(alive, r, t0, t1, best, c);
        } else {
            uint size = (VARIANT == VARIANT_SHORT_STACK || VARIANT == VARIANT_PUSH_DOWN_SHORT_STACK) ? STACK_SIZE : 0u;
            bool use_push_down = VARIANT == VARIANT_PUSH_DOWN || VARIANT == VARIANT_PUSH_DOWN_SHORT_STACK;
            finished = trace_packet_short_stack(alive, r, t0, t1, size, use_push_down, best, c);
        }
    } else if (alive) {
        if (VARIANT == VARIANT_RESTART) {
            finished = trace_restart(r, t0, t1, best, c);
        } else if (VARIANT == VARIANT_PUSH_DOWN) {
            finished = trace_push_down(r, t0, t1, best, c);
        } else if (VARIANT == VARIANT_SHORT_STACK) {
            finished = trace_short_stack(r, t0, t1, false, best, c);
        } else if (VARIANT == VARIANT_PUSH_DOWN_SHORT_STACK) {
            finished = trace_short_stack(r, t0, t1, true, best, c);
        } else if (VARIANT == VARIANT_BACKTRACK) {
            finished = trace_backtrack(r, t0, t1, best, c);
        } else if (VARIANT == VARIANT_ROPES) {
            finished = trace_ropes(r, t0, t1, best, c);
        } else {
            finished = trace_stack(r, t0, t1, best, c);
        }
    }
    return finished;
}

// Traces ray `index` and writes its hit (and counters). In the fast pass, a ray
// that met a pair the f32 tests could not decide is listed for the careful pass
// instead, and nothing is written for it.
void trace_ray(uint index) {
    Ray ray = ray_from_words(ray_words[2u * index], ray_words[2u * index + 1u]);

    Closest best = closest_none(ray.tmax);
    TraceCounters c = TraceCounters(0u, 0u, 0u, 0u, 0u, 0u);

    // The steps of setup_ray (ray_setup.glsl) written out: as calls (setup_ray,
    // final_hit) they cost this kernel 0.3-0.8 % more lavapipe instructions
    // (tools/shader-instructions, bunny camera and random rays).
    ray.dir = traced_dir(ray.dir);
    bool valid = ray_is_valid(ray);
    TraceRay r;
    r.dir = ray.dir;
    // Clamped so that a plane through the origin gives t = 0, never 0 * inf = NaN.
    r.inv_dir = clamp(1.0 / ray.dir, vec3(-FLT_MAX), vec3(FLT_MAX));
    r.tmin = ray.tmin;
    r.tmax = ray.tmax;
    r.t_err = 0.0;
    r.flat_axes = 0u;
    r.band = vec3(0.0);
    r.wr = watertight_ray(ray.origin, ray.dir);
    r.wr.ray_tmax = ray.tmax;
    r.wr.seg_tmax = ray.tmax;
    float t0 = 0.0, t1 = 0.0;
    bool alive = valid && clip_to_box(r, params.scene_min.xyz, params.scene_max.xyz, t0, t1);
    bool far = ROBUST && alive && is_far(r, t0, params.scene_min.xyz, params.scene_max.xyz);
    if (SEGMENT_FRAME && far) {
        alive = shift_to_scene(r, t0, t1, params.scene_min.xyz, params.scene_max.xyz);
        precise float best_seg = ray.tmax - r.wr.t_shift;
        best.hit.t = best_seg;  // the segment frame, like every hit below
    }
    // The closed segment (see setup_ray).
    if (ROBUST && alive) {
        t1 = next_up(t1);
        best.hit.t = next_up(best.hit.t);
    }
    // The fast pass leaves far rays to the careful one (without tracing them).
    bool skip = PASS == PASS_FAST && far;
    if (skip) best.needs_careful = true;
    if (!valid) best.hit.prim_id = PRIM_INVALID;
    // Robust single rays trace fast first, then carefully in a second dispatch when
    // the fast trace met what it could not decide in f32 (see careful_pass in
    // leaf.glsl). Packets trace once, carefully: their kernels are large and
    // slower than single rays on lavapipe anyway.
    bool finished = run_traversal(alive && !skip, r, t0, t1, best, c);
    bool needs_careful = best.needs_careful;  // a plain bool: the && below stays branch-free
    if (PASS == PASS_FAST && alive && needs_careful) {
        list_for_careful_pass(index);
        return;
    }
    // final_hit (ray_setup.glsl) written out.
    Hit hit = best.hit;
    if (!finished && hit.prim_id != PRIM_INVALID) hit.prim_id = PRIM_INCOMPLETE;
    precise float t_own = hit.t + r.wr.t_shift;
    if (SEGMENT_FRAME && r.wr.t_shift != 0.0) hit.t = t_own;
    if (hit.prim_id >= PRIM_INCOMPLETE) {
        hit.t = hit.prim_id == PRIM_MISS ? uintBitsToFloat(0x7f800000u) : uintBitsToFloat(0x7fc00000u);
        hit.u = 0.0;
        hit.v = 0.0;
    }
    hits[index] = hit;
    if (COUNTERS) {
        uint base = index * COUNTERS_PER_RAY;
        counters[base + COUNTER_NODES] = c.nodes;
        counters[base + COUNTER_LEAVES] = c.leaves;
        counters[base + COUNTER_TRIANGLES] = c.triangles;
        counters[base + COUNTER_RESTARTS] = c.restarts;
        counters[base + COUNTER_STEPS] = c.steps;
        counters[base + COUNTER_DROPS] = c.drops;
    }
}

void main() {
    // One call site, so the kernel holds one inlined copy of the traversal (and no
    // loop around it: lavapipe runs a loop's body under the loop's mask, which made
    // every ray dearer). The careful pass takes the listed rays, in rows of
    // CAREFUL_MAX_GROUPS workgroups.
    bool listed = PASS == PASS_CAREFUL;
    uint id = listed ? careful_slot() : batch_slot(TRACE_WORKGROUP_SIZE);
    uint count = listed ? careful[CAREFUL_COUNT] : batch_count();
    if (id >= count) return;
    // The careful pass lists ray indices; an ordered batch traces ray order[id].
    trace_ray(listed ? careful[CAREFUL_HEADER_WORDS + id] : (params.ordered != 0u ? order[id] : id));
}
