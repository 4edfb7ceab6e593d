#version 450
// A coherent order for a batch of rays, on the device: a counting sort of the ray
// indices by a key of the direction's octant and the origin's cell in the scene
// box (a Morton code of ORDER_CELL_BITS bits per axis). The trace kernel then
// traces the rays in that order (TraceParams.ordered) and still writes each hit at
// its ray's index. Three steps, chosen by a specialization constant, with a
// barrier between each (src/trace.rs, `record_unchecked`):
//   ORDER_STEP_COUNT:   each ray adds one to its key's bucket;
//   ORDER_STEP_SCAN:    one workgroup turns the counts into start offsets;
//   ORDER_STEP_SCATTER: each ray takes the next place of its bucket.
// Invalid rays (NaN or zero direction, non-finite origin) take the last bucket.
// The order within a bucket is the order of the atomic additions: it may differ
// between runs, and no hit depends on it (each ray's trace is its own).

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "ray_checks.glsl"

layout(constant_id = ORDER_SPEC_STEP) const uint STEP = ORDER_STEP_COUNT;

layout(local_size_x = ORDER_WORKGROUP_SIZE) in;

// Rays as the trace kernel reads them (32-byte records, as two uvec4 words).
layout(std430, set = 0, binding = ORDER_BINDING_RAYS) readonly buffer Rays { uvec4 ray_words[]; };
// ORDER_BUCKETS counts, then start offsets, then next free places.
layout(std430, set = 0, binding = ORDER_BINDING_BUCKETS) buffer Buckets { uint buckets[]; };
// The ray indices in the coherent order.
layout(std430, set = 0, binding = ORDER_BINDING_LIST) writeonly buffer List { uint list[]; };
// A device-counted batch's arguments, when params.indirect (glsl/indirect_args.comp).
layout(std430, set = 0, binding = ORDER_BINDING_INDIRECT) readonly buffer Indirect { uint indirect_words[]; };

layout(push_constant) uniform Push { TraceParams params; };

#include "batch.glsl"

// The 3 low bits of x spread to every third bit (x < 2^ORDER_CELL_BITS).
uint spread3(uint x) {
    uint r = 0u;
    [[unroll]] for (uint b = 0u; b < ORDER_CELL_BITS; ++b) r |= ((x >> b) & 1u) << (3u * b);
    return r;
}

uint ray_key(uint index) {
    Ray ray = ray_from_words(ray_words[2u * index], ray_words[2u * index + 1u]);
    ray.dir = traced_dir(ray.dir);
    if (!ray_is_valid(ray)) return ORDER_BUCKETS - 1u;
    uvec3 neg = uvec3(lessThan(ray.dir, vec3(0.0)));
    uint octant = neg.x | (neg.y << 1u) | (neg.z << 2u);
    vec3 lo = params.scene_min.xyz;
    vec3 size = max(params.scene_max.xyz - lo, vec3(1e-30));
    float cells = float(1u << ORDER_CELL_BITS);
    // Origins outside the box clamp to its boundary cells.
    uvec3 cell = uvec3(clamp((ray.origin - lo) / size * cells, vec3(0.0), vec3(cells - 1.0)));
    uint morton = spread3(cell.x) | (spread3(cell.y) << 1u) | (spread3(cell.z) << 2u);
    return (octant << (3u * ORDER_CELL_BITS)) | morton;
}

// The scan: ORDER_WORKGROUP_SIZE invocations, each over a run of the buckets.
shared uint run_sums[ORDER_WORKGROUP_SIZE];

void main() {
    if (STEP == ORDER_STEP_SCAN) {
        const uint per = ORDER_BUCKETS / ORDER_WORKGROUP_SIZE;
        uint first = gl_LocalInvocationID.x * per;
        uint sum = 0u;
        for (uint i = 0u; i < per; ++i) sum += buckets[first + i];
        run_sums[gl_LocalInvocationID.x] = sum;
        barrier();
        uint start = 0u;
        for (uint j = 0u; j < gl_LocalInvocationID.x; ++j) start += run_sums[j];
        for (uint i = 0u; i < per; ++i) {
            uint n = buckets[first + i];
            buckets[first + i] = start;
            start += n;
        }
        return;
    }
    uint index = batch_slot(ORDER_WORKGROUP_SIZE);
    if (index >= batch_count()) return;
    uint key = ray_key(index);
    if (STEP == ORDER_STEP_COUNT) {
        atomicAdd(buckets[key], 1u);
    } else {
        list[atomicAdd(buckets[key], 1u)] = index;
    }
}
