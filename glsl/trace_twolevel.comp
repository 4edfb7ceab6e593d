#version 450
// The two-level kernel: one world ray per invocation through a top-level BVH
// over instance boxes, then, in each instance it enters, the geometry's own
// kd-tree in object space with a single-ray variant of trace.comp (`stack`,
// `restart`, `push-down` and the short stacks; robust or plain; closest or any
// hit). CPU twin, bit for bit: `TwoLevelScene::trace` in src/twolevel.rs, whose
// module docs give the contract (the object ray, ties, front face, masks).
//
// Every geometry's nodes and triangle references share one texel buffer each;
// `node_base` and `texel_base` (GEOMETRY_BASES in node.glsl and leaf.glsl) say
// where the instance being traced starts. Robust rays trace as in trace.comp: a
// fast pass (PASS_FAST) lists the rays it cannot decide in f32 (a ray is listed
// whole: the careful pass traces every instance again), and a careful pass
// (PASS_CAREFUL, dispatched indirectly) traces them.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#define GEOMETRY_BASES

#include "ray.glsl"
#include "twolevel.glsl"
#include "ray_checks.glsl"
#include "kdnode.glsl"

layout(local_size_x = TRACE_WORKGROUP_SIZE) in;

// One module per variant (build.rs sets TRACE_MODULE_VARIANT), as trace.comp.
const uint VARIANT = TRACE_MODULE_VARIANT;
// The trace kernel's specialization constants, same ids (src/twolevel/pipelines.rs sets them).
layout(constant_id = TRACE_SPEC_COUNTERS) const bool COUNTERS = false;         // unused here
layout(constant_id = TRACE_SPEC_STACK_SIZE) const uint STACK_SIZE = 3u;
layout(constant_id = TRACE_SPEC_ANY_HIT) const bool ANY_HIT = false;
layout(constant_id = TRACE_SPEC_PACKET_WIDTH) const uint PACKET_WIDTH = 1u;   // single rays only
layout(constant_id = TRACE_SPEC_ROBUST) const bool ROBUST = true;
layout(constant_id = TRACE_SPEC_PASS) const uint PASS = PASS_ONE;
// The scene has one instance: no top-level loop (src/twolevel/gpu.rs picks this
// pipeline then), and for robust rays PASS_FAST / PASS_CAREFUL.
layout(constant_id = TL_SPEC_ONE_INSTANCE) const bool ONE_INSTANCE = false;

const bool SEGMENT_FRAME = ROBUST && PASS != PASS_FAST;

#include "triangle.glsl"

layout(set = 0, binding = TL_BINDING_NODES, rg32ui) uniform readonly uimageBuffer node_texels;
layout(set = 0, binding = TL_BINDING_TRIANGLES, rgba32ui) uniform readonly uimageBuffer tri_texels;
layout(std430, set = 0, binding = TL_BINDING_RAYS) readonly buffer Rays { uvec4 ray_words[]; };
// Hits are written as two uvec4 words (a GpuInstanceHit each).
layout(std430, set = 0, binding = TL_BINDING_HITS) writeonly buffer Hits { uvec4 hit_words[]; };

void write_hit(uint index, GpuInstanceHit h) {
    hit_words[2u * index] = uvec4(floatBitsToUint(h.t), h.prim_index, floatBitsToUint(h.u), floatBitsToUint(h.v));
    hit_words[2u * index + 1u] = uvec4(h.instance_id, h.geometry_id, h.front_face, h.instance_index);
}
// The geometries (3 texels each), instances (4), top-level nodes (3) and the
// leaves' instance order (1) are texel buffers too: lavapipe loads a storage
// buffer's struct one lane and one word at a time, which cost one identity
// instance about 2,000 instructions per subgroup (tools/shader-instructions).
layout(set = 0, binding = TL_BINDING_GEOMETRIES, rgba32ui) uniform readonly uimageBuffer geometry_texels;
layout(set = 0, binding = TL_BINDING_INSTANCES, rgba32ui) uniform readonly uimageBuffer instance_texels;
layout(set = 0, binding = TL_BINDING_TOP, rgba32ui) uniform readonly uimageBuffer top_texels;
layout(set = 0, binding = TL_BINDING_ORDER, r32ui) uniform readonly uimageBuffer order_texels;

GpuGeometry load_geometry(uint g) {
    int base = int(g) * 3;
    uvec4 a = imageLoad(geometry_texels, base);
    uvec4 b = imageLoad(geometry_texels, base + 1);
    uvec4 c = imageLoad(geometry_texels, base + 2);
    return GpuGeometry(uintBitsToFloat(a), uintBitsToFloat(b), c.x, c.y, c.z, c.w);
}

// An instance's geometry, instance id, mask and identity flag (its matrix
// rows are read by object_ray only where needed).
uvec4 load_instance_ids(uint i) { return imageLoad(instance_texels, int(i) * 4 + 3); }

TopNode load_top(uint n) {
    int base = int(n) * 3;
    uvec4 a = imageLoad(top_texels, base);
    uvec4 b = imageLoad(top_texels, base + 1);
    uvec4 c = imageLoad(top_texels, base + 2);
    return TopNode(uintBitsToFloat(a), uintBitsToFloat(b), c.x, c.y, c.z, c.w);
}

uint load_order(uint k) { return imageLoad(order_texels, int(k)).x; }

// The rays the fast pass leaves to the careful pass (careful_list.glsl).
layout(std430, set = 0, binding = TL_BINDING_CAREFUL) coherent buffer Careful { uint careful[]; };

layout(push_constant) uniform Push { TwoLevelParams params; };

// A device-counted batch's arguments, when params.indirect (glsl/indirect_args.comp).
layout(std430, set = 0, binding = TL_BINDING_INDIRECT) readonly buffer Indirect { uint indirect_words[]; };

#include "batch.glsl"

// Where the geometry of the instance being traced starts in the shared buffers.
uint node_base = 0u;
uint texel_base = 0u;

#include "stack.glsl"
#include "restart.glsl"
#include "push_down.glsl"
#include "short_stack.glsl"
#include "ray_setup.glsl"
#include "careful_list.glsl"

// The entry of the world ray into the box [lo - widen, hi + widen] within
// [tmin, tmax], conservatively (the far bound times 1 + 3 * 2^-23). CPU twin:
// `slab` in src/twolevel.rs.
bool enters_box(vec3 lo, vec3 hi, float far_scale, float condition, vec3 o, vec3 d, vec3 inv, float tmin, float tmax,
                out float entry) {
    precise float widen = far_scale * condition;
    float t0 = tmin;
    float t1 = tmax;
    [[unroll]] for (uint a = 0u; a < 3u; ++a) {
        precise float l = lo[a] - widen;
        precise float h = hi[a] + widen;
        if (d[a] == 0.0) {
            if (o[a] < l || o[a] > h) return false;
            continue;
        }
        precise float ta = (l - o[a]) * inv[a];
        precise float tb = (h - o[a]) * inv[a];
        t0 = max(t0, widen_near(min(ta, tb)));  // segment.glsl
        precise float far_bound = max(ta, tb) * uintBitsToFloat(0x3f800003u);  // 1 + 3 * 2^-23
        t1 = min(t1, far_bound);
    }
    entry = t0;
    return t0 <= t1;
}

// The object ray of instance `i` (CPU twin: `TwoLevelScene::object_ray`): each
// component summed left to right, no fused multiply-add; the world ray itself
// where the matrix is exactly the identity.
Ray object_ray(uint i, bool identity, Ray ray) {
    Ray o = ray;
    if (identity) return o;
    [[unroll]] for (uint k = 0u; k < 3u; ++k) {
        vec4 m = uintBitsToFloat(imageLoad(instance_texels, int(i) * 4 + int(k)));
        precise float p = ((m.x * ray.origin.x + m.y * ray.origin.y) + m.z * ray.origin.z) + m.w;
        precise float q = (m.x * ray.dir.x + m.y * ray.dir.y) + m.z * ray.dir.z;
        o.origin[k] = p;
        o.dir[k] = q;
    }
    return o;
}

// Whether triangle `reference` of the current geometry faces the object ray
// direction `d`: the exact sign of dot(n, d) < 0, n the f32 cross product of
// its edges (CPU twin: `faces` in src/twolevel.rs).
bool front_facing(uint reference, vec3 d) {
    vec3 v0, v1, v2;
    load_triangle(reference, v0, v1, v2);
    precise vec3 e1 = v1 - v0;
    precise vec3 e2 = v2 - v0;
    precise float nx = e1.y * e2.z - e2.y * e1.z;
    precise float ny = e1.z * e2.x - e2.z * e1.x;
    precise float nz = e1.x * e2.y - e2.x * e1.y;
    // The f32 dot product decides where its rounding (below 3 * 2^-24 of the
    // products' magnitudes) cannot reach zero; else the exact sum.
    precise float dot_f32 = (nx * d.x + ny * d.y) + nz * d.z;
    precise float magnitude = (abs(nx * d.x) + abs(ny * d.y)) + abs(nz * d.z);
    if (abs(dot_f32) > magnitude * (1.0 / 2097152.0) && magnitude > ORIENT_ZERO) {  // 2^-21
        return dot_f32 < 0.0;
    }
    vec2 px = ff_two_prod(nx, d.x);
    vec2 py = ff_two_prod(ny, d.y);
    vec2 pz = ff_two_prod(nz, d.z);
    return ff_exact_sum8(float[8](px.x, px.y, py.x, py.y, pz.x, pz.y, 0.0, 0.0)).x < 0.0;
}

// Traces the object ray of one instance through its geometry (trace.comp's
// trace_ray). `reference`: the hit's triangle reference. `needs_careful`: the
// fast pass met what it leaves to the careful pass (the hit is not the answer).
Hit trace_instance(Ray ray, GpuGeometry g, out uint reference, out bool needs_careful) {
    node_base = g.node_base;
    texel_base = g.texel_base;
    Closest best = closest_none(ray.tmax);
    TraceCounters c = TraceCounters(0u, 0u, 0u, 0u, 0u, 0u);
    TraceRay r;
    float t0, t1;
    bool valid, far;
    bool alive = setup_ray(ray, g.bounds_min.xyz, g.bounds_max.xyz, r, t0, t1, valid, far, best);
    if (!valid) best.hit.prim_id = PRIM_INVALID;
    // The fast pass leaves far rays to the careful one (without tracing them).
    bool skip = PASS == PASS_FAST && far;
    if (skip) best.needs_careful = true;
    bool finished = true;
    if (alive && !skip) {
        if (VARIANT == VARIANT_RESTART) {
            finished = trace_restart(r, t0, t1, best, c);
        } else if (VARIANT == VARIANT_PUSH_DOWN) {
            finished = trace_push_down(r, t0, t1, best, c);
        } else if (VARIANT == VARIANT_SHORT_STACK) {
            finished = trace_short_stack(r, t0, t1, false, best, c);
        } else if (VARIANT == VARIANT_PUSH_DOWN_SHORT_STACK) {
            finished = trace_short_stack(r, t0, t1, true, best, c);
        } else {
            finished = trace_stack(r, t0, t1, best, c);
        }
    }
    reference = best.reference;
    needs_careful = PASS == PASS_FAST && alive && best.needs_careful;
    return final_hit(best, r, finished);
}

// Traces instance `i` if the dispatch's mask sees it, keeping the closest hit in
// `best` (CPU twin: the instance loop of `TwoLevelScene::trace`); `incomplete`
// notes an instance cut short, `listed` one the fast pass leaves to the careful
// pass. True when an any-hit trace is done.
bool visit_instance(uint i, Ray ray, inout GpuInstanceHit best, inout bool incomplete, inout bool listed) {
    uvec4 inst = load_instance_ids(i);  // geometry, instance id, mask, identity
    if ((inst.z & params.mask) == 0u) return false;
    GpuGeometry g = load_geometry(inst.x);
    Ray object = object_ray(i, inst.w != 0u, ray);
    object.tmax = min(best.t, ray.tmax);
    uint reference;
    bool needs_careful;
    Hit hit = trace_instance(object, g, reference, needs_careful);
    if (needs_careful) {
        listed = true;
        return true;
    }
    if (hit.prim_id >= PRIM_INCOMPLETE) {
        // Cut short (or an object ray the transform made invalid).
        if (hit.prim_id != PRIM_MISS) incomplete = true;
        return false;
    }
    if (hit.t <= best.t || best.prim_index >= PRIM_INCOMPLETE) {
        best = GpuInstanceHit(hit.t, hit.prim_id, hit.u, hit.v, inst.y, g.id,
                              front_facing(reference, traced_dir(object.dir)) ? 1u : 0u, i);
        return ANY_HIT;
    }
    return false;
}

void trace_world(uint index) {
    Ray ray = ray_from_words(ray_words[2u * index], ray_words[2u * index + 1u]);
    GpuInstanceHit best = GpuInstanceHit(uintBitsToFloat(0x7f800000u), PRIM_MISS, 0.0, 0.0, 0xffffffffu, 0xffffffffu,
                                         0u, 0xffffffffu);
    Ray checked = ray;
    checked.dir = traced_dir(ray.dir);
    bool valid = ray_is_valid(checked);
    if (!valid) best.prim_index = PRIM_INVALID;
    if (!valid || (params.mask & 0xffu) == 0u || params.top_nodes == 0u) {
        if (!valid) best.t = uintBitsToFloat(0x7fc00000u);
        write_hit(index, best);
        return;
    }
    vec3 o = ray.origin;
    vec3 d = checked.dir;
    vec3 inv = clamp(1.0 / d, vec3(-FLT_MAX), vec3(FLT_MAX));
    // The object rays' rounding grows with the origin's magnitude (see `Placed`
    // in src/twolevel.rs): boxes widen by it times each subtree's condition number.
    precise float far_scale = max(abs(o.x), max(abs(o.y), abs(o.z))) * (1.0 / 1048576.0);
    bool incomplete = false;
    bool listed = false;
    bool done = false;
    uint stack[MAX_TOP_STACK];
    stack[0] = 0u;
    uint sp = 1u;
    if (ONE_INSTANCE) {
        // The top level is one leaf holding one instance: the instance, with no
        // loop around the object-space traversal (lavapipe runs a loop's body
        // under the loop's mask; see docs/EMBEDDING.md) and no test of its world
        // box (the object ray's clip to the geometry's box decides as much; the
        // CPU twin skips it too).
        done = visit_instance(load_order(0u), ray, best, incomplete, listed);
        sp = 0u;
    } else while (sp > 0u && !done) {
        // Every pass pops one node, each pushed at most once: the loop ends, and
        // one the driver ends early leaves entries, caught below.
        --sp;
        uint n = stack[sp];
        TopNode node = load_top(n);
        float reach = min(best.t, ray.tmax);
        float entry;
        if (!enters_box(node.bounds_min.xyz, node.bounds_max.xyz, far_scale, node.bounds_min.w, o, d, inv, ray.tmin, reach, entry)) continue;
        if (node.count == 0u) {
            uint a = n + 1u;
            uint b = node.index;
            TopNode na = load_top(a);
            TopNode nb = load_top(b);
            float ta, tb;
            if (!enters_box(na.bounds_min.xyz, na.bounds_max.xyz, far_scale, na.bounds_min.w, o, d, inv, ray.tmin, reach, ta)) {
                ta = uintBitsToFloat(0x7f800000u);
            }
            if (!enters_box(nb.bounds_min.xyz, nb.bounds_max.xyz, far_scale, nb.bounds_min.w, o, d, inv, ray.tmin, reach, tb)) {
                tb = uintBitsToFloat(0x7f800000u);
            }
            // The nearer child is popped first.
            bool a_first = ta <= tb;
            stack[sp] = a_first ? b : a;
            stack[sp + 1u] = a_first ? a : b;
            sp += 2u;
            continue;
        }
        for (uint k = node.index; k < node.index + node.count; ++k) {
            if (visit_instance(load_order(k), ray, best, incomplete, listed)) {
                done = true;
                break;
            }
        }
    }
    if (PASS == PASS_FAST && listed) {
        list_for_careful_pass(index);
        return;
    }
    // A loop the driver ended early leaves entries on the stack: not a miss.
    if (sp > 0u && !done) incomplete = true;
    if (incomplete && !done) {
        best = GpuInstanceHit(uintBitsToFloat(0x7fc00000u), PRIM_INCOMPLETE, 0.0, 0.0, 0xffffffffu, 0xffffffffu, 0u,
                              0xffffffffu);
    }
    write_hit(index, best);
}

void main() {
    // The careful pass traces the rays the fast pass listed.
    bool from_list = PASS == PASS_CAREFUL;
    uint id = from_list ? careful_slot() : batch_slot(TRACE_WORKGROUP_SIZE);
    uint count = from_list ? careful[CAREFUL_COUNT] : batch_count();
    if (id >= count) return;
    trace_world(from_list ? careful[CAREFUL_HEADER_WORDS + id] : id);
}
