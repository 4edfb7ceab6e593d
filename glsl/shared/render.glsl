// The renderer's wavefront data (std430), mirrored by src/render/abi.rs:
// per-path state, per-triangle surfaces, materials, lights, the push constants,
// and the helpers every render pass shares (sampling, robust ray offsets).
#ifndef RENDER_GLSL
#define RENDER_GLSL

// Path flags.
#define PATH_COUNT_EMISSION 1u   // a camera or mirror ray: emitters it hits count
#define PATH_AO_DONE 2u          // ambient occlusion was gathered at an earlier vertex
#define PATH_MIS 4u              // a diffuse bounce: emitters it hits count, MIS-weighted

// One path of a ray queue, beside its Ray (32 bytes).
struct Path {
    vec3 throughput;   // radiance weight of what this ray finds
    uint pixel;        // row-major pixel index
    uint flags;        // PATH_*
    uint depth;        // segments traced before this one (camera ray: 0)
    uint diffuse;      // diffuse bounces taken so far
    uint pad;          // PATH_MIS: the float bits of the bounce direction's pdf (solid angle)
};

// One triangle for shading: its vertices, material id in v0.w (48 bytes).
struct Surface {
    vec4 v0;
    vec4 v1;
    vec4 v2;
};

// Material flags (MAT_* in Material.ks.w): #defines from src/render/consts.rs.

struct Material {
    vec4 kd;   // xyz Kd, w Ns
    vec4 ks;   // xyz Ks, w: MAT_* flags as uint bits
    vec4 ke;   // xyz Ke
};

// An emissive triangle, for next-event estimation: chosen with probability
// `pick` (cumulative `cdf`), proportional to area × luminance of Ke.
struct Emitter {
    uint prim;
    float cdf;
    float pick;
    float area;
};

struct PointLight {
    vec4 position;    // xyz
    vec4 intensity;   // xyz: radiant intensity (W/sr per channel)
};

// Push constants of every render pass (128 bytes; RenderParams of src/render/abi.rs).
struct RenderParams {
    vec4 eye;          // camera: xyz eye
    vec4 forward;      // xyz forward (unit); w: total emitter weight (sum of area x luminance of Ke)
    vec4 right;        // xyz right * tan(fov/2) * aspect; w: this sample's jitter x (one per image)
    vec4 up;           // xyz up * tan(fov/2); w: this sample's jitter y (one per image)
    vec4 background;   // xyz radiance of rays that leave the scene; w ambient radiance (AO)
    uint width;
    uint height;
    uint count;        // paths (or pixels) in this dispatch
    uint sample_index; // which sample of each pixel
    uint seed;
    uint max_depth;    // ray segments per path at most
    uint bounces;      // diffuse bounces per path at most
    uint ao_samples;
    float ao_radius;
    uint light_count;
    uint emitter_count;
    uint shadow_capacity;   // shadow rays the queue holds
};

// The render counters buffer (uint each) is indexed by RC_*, the kernels'
// bindings are *_BINDING_*, their workgroup size RENDER_WORKGROUP_SIZE: all
// #defines from src/render/consts.rs (build.rs).

// --- Sampling ---------------------------------------------------------------

// A 32-bit integer hash (good avalanche, cheap).
uint hash_u32(uint x) {
    x ^= x >> 16;
    x *= 0x7feb352du;
    x ^= x >> 15;
    x *= 0x846ca68bu;
    x ^= x >> 16;
    return x;
}

// A hash-based permutation of 32-bit integers in which each bit depends only on
// itself and the bits below it (the Laine–Karras construction, with Burley's
// 2020 constants); between two bit reversals it is an Owen scramble.
uint lk_permute(uint x, uint seed) {
    x += seed;
    x ^= x * 0x6c50b47cu;
    x ^= x * 0xb82f1e52u;
    x ^= x * 0xc7afe638u;
    x ^= x * 0x8d22f6e6u;
    return x;
}

uint owen_scramble(uint x, uint seed) {
    return bitfieldReverse(lk_permute(bitfieldReverse(x), seed));
}

// The second dimension of the Sobol sequence (its first is the bit reversal).
uint sobol_second(uint index) {
    uint result = 0u;
    uint v = 1u << 31;
    for (uint i = index; i != 0u; i >>= 1) {
        if ((i & 1u) != 0u) result ^= v;
        v ^= v >> 1;
    }
    return result;
}

// Point `sample_index` of a 2D low-discrepancy set for (pixel, dimension pair):
// the first two Sobol dimensions, Owen-scrambled, with the sample order
// shuffled (also by an Owen scramble of the index) per pixel and pair, so that
// pairs are not correlated with each other. Any prefix of 2^k samples is
// stratified. In [0, 1)^2.
vec2 ld2(uint pixel, uint sample_index, uint pair, uint seed) {
    uint h = hash_u32(pixel * 0x9e3779b9u ^ hash_u32(pair * 0x85ebca6bu ^ hash_u32(seed)));
    uint i = owen_scramble(sample_index, h);
    uint x = owen_scramble(bitfieldReverse(i), hash_u32(h ^ 0x68bc21ebu));
    uint y = owen_scramble(sobol_second(i), hash_u32(h ^ 0x02e5be93u));
    return vec2(x >> 8, y >> 8) * (1.0 / 16777216.0);
}

// An orthonormal basis around the unit vector n (Duff et al. 2017).
void basis(vec3 n, out vec3 t, out vec3 b) {
    float s = n.z >= 0.0 ? 1.0 : -1.0;
    float a = -1.0 / (s + n.z);
    float c = n.x * n.y * a;
    t = vec3(1.0 + s * n.x * n.x * a, s * c, -s * n.x);
    b = vec3(c, s + n.y * n.y * a, -n.y);
}

// A cosine-weighted direction around n (pdf cos/pi).
vec3 cosine_direction(vec3 n, vec2 u) {
    vec3 t, b;
    basis(n, t, b);
    float r = sqrt(u.x);
    float phi = 6.283185307 * u.y;
    return normalize(r * cos(phi) * t + r * sin(phi) * b + sqrt(max(0.0, 1.0 - u.x)) * n);
}

// --- Robust secondary-ray origins -------------------------------------------

// How far rounding may have moved a point computed from a triangle's vertices
// by barycentric weights, per axis: a few units in the last place of the
// largest vertex coordinate on that axis. Floored at 2^-8 of the largest
// coordinate, so that an axis on which all vertices are 0 still gets an offset.
vec3 triangle_scale(vec3 v0, vec3 v1, vec3 v2) {
    vec3 s = max(max(abs(v0), abs(v1)), abs(v2));
    return max(s, vec3(max(max(s.x, s.y), s.z) * (1.0 / 256.0)));
}

// Moves p, a point on a triangle computed from its vertices (triangle_scale
// gives `scale`), off the surface toward the unit normal n, far enough that
// rounding cannot have left it on the wrong side, so a ray from it does not
// hit its own surface (after Wächter & Binder 2019, who offset by a number of
// units in the last place proportional to n). Per axis: 64 * n ulps of p where
// |p| is at least a quarter of the axis's scale; where it is smaller (the
// vertices' coordinates cancelled, so p's error exceeds its ulp) a fixed
// n * scale * 2^-18 instead (32 ulps of the scale).
vec3 offset_origin(vec3 p, vec3 n, vec3 scale) {
    ivec3 ulps = ivec3(64.0 * n);
    vec3 by_ulps = intBitsToFloat(floatBitsToInt(p) + mix(ulps, -ulps, lessThan(p, vec3(0.0))));
    vec3 by_scale = p + n * scale * (1.0 / 262144.0);
    return mix(by_ulps, by_scale, lessThanEqual(abs(p), 0.25 * scale));
}

float luminance(vec3 c) {
    return dot(c, vec3(0.2126, 0.7152, 0.0722));
}

#endif
