#version 450
// Render pass 2: shades the closest hits of a ray queue. For each path it adds
// what it sees directly (emission, background, the headlight) to its pixel,
// appends its shadow rays (point lights, one area-light sample, ambient
// occlusion) with the radiance each would bring if unoccluded, and appends the
// path's next ray (mirror reflection or cosine-weighted diffuse bounce) to the
// next queue. Appending by atomic counter compacts the queues: finished paths
// take no slot. What the scene and options do not need is switched off by the
// specialization constants below, so the driver removes that code.
// See src/render/wavefront.rs.

#extension GL_GOOGLE_include_directive : require
#extension GL_EXT_control_flow_attributes : require

#include "ray.glsl"
#include "ray_checks.glsl"
#include "render.glsl"

layout(local_size_x = RENDER_WORKGROUP_SIZE) in;

layout(constant_id = SHADE_SPEC_HEADLIGHT) const bool HEADLIGHT = false;    // eye light, no shadow rays
layout(constant_id = SHADE_SPEC_POINT_LIGHTS) const bool POINT_LIGHTS = true;  // --light
layout(constant_id = SHADE_SPEC_AREA_LIGHTS) const bool AREA_LIGHTS = true;   // emissive triangles (Ke)
layout(constant_id = SHADE_SPEC_MIRRORS) const bool MIRRORS = true;       // illum 3 materials
layout(constant_id = SHADE_SPEC_GLOSSY) const bool GLOSSY = true;        // illum 2 highlights
layout(constant_id = SHADE_SPEC_AO) const bool AO = true;            // --ao N
layout(constant_id = SHADE_SPEC_BOUNCES) const bool BOUNCES = true;       // --bounces N
layout(constant_id = SHADE_SPEC_CONTINUE) const bool CONTINUE = true;      // a next queue exists
layout(constant_id = SHADE_SPEC_HEADLIGHT_SHADOWS) const bool HEADLIGHT_SHADOWS = false;  // trace the eye light's visibility (--no-skip)

// Surfaces and materials are read as texel buffers (three rgba32ui texels each):
// lavapipe gathers a struct from a storage buffer one word and one lane at a
// time, a texel 16 bytes at a time.
layout(set = 0, binding = SHADE_BINDING_SURFACES, rgba32ui) uniform readonly uimageBuffer surface_texels;
layout(set = 0, binding = SHADE_BINDING_MATERIALS, rgba32ui) uniform readonly uimageBuffer material_texels;
layout(std430, set = 0, binding = SHADE_BINDING_EMITTERS) readonly buffer Emitters { Emitter emitters[]; };
layout(std430, set = 0, binding = SHADE_BINDING_LIGHTS) readonly buffer Lights { PointLight lights[]; };
// Rays, paths and hits move as 16-byte words (a Ray or a Path is two, a Hit
// one), for the same reason: one vector load or store per lane and word.
layout(std430, set = 0, binding = SHADE_BINDING_RAYS_IN) readonly buffer RaysIn { uvec4 rays_in[]; };
layout(std430, set = 0, binding = SHADE_BINDING_PATHS_IN) readonly buffer PathsIn { uvec4 paths_in[]; };
layout(std430, set = 0, binding = SHADE_BINDING_HITS_IN) readonly buffer HitsIn { uvec4 hits_in[]; };
layout(std430, set = 0, binding = SHADE_BINDING_RAYS_NEXT) writeonly buffer RaysNext { uvec4 rays_next[]; };
layout(std430, set = 0, binding = SHADE_BINDING_PATHS_NEXT) writeonly buffer PathsNext { uvec4 paths_next[]; };
layout(std430, set = 0, binding = SHADE_BINDING_SHADOW_RAYS) writeonly buffer ShadowRays { uvec4 shadow_rays[]; };
layout(std430, set = 0, binding = SHADE_BINDING_SHADOW_WEIGHTS) writeonly buffer ShadowWeights { vec4 shadow_weights[]; };
layout(std430, set = 0, binding = SHADE_BINDING_SPANS) writeonly buffer Spans { uvec2 spans[]; };
layout(std430, set = 0, binding = SHADE_BINDING_COUNTERS) buffer Counters { uint counters[]; };
layout(std430, set = 0, binding = SHADE_BINDING_ACCUM) buffer Accum { vec4 accum[]; };

layout(push_constant) uniform Params { RenderParams p; };

Surface load_surface(uint k) {
    int b = int(k) * 3;
    return Surface(uintBitsToFloat(imageLoad(surface_texels, b)), uintBitsToFloat(imageLoad(surface_texels, b + 1)),
                   uintBitsToFloat(imageLoad(surface_texels, b + 2)));
}

Material load_material(uint k) {
    int b = int(k) * 3;
    return Material(uintBitsToFloat(imageLoad(material_texels, b)), uintBitsToFloat(imageLoad(material_texels, b + 1)),
                    uintBitsToFloat(imageLoad(material_texels, b + 2)));
}

// The direction of the ray in slot i of the input queue.
vec3 ray_in_dir(uint i) { return ray_from_words(rays_in[2u * i], rays_in[2u * i + 1u]).dir; }

Path load_path(uint i) {
    uvec4 a = paths_in[2u * i];
    uvec4 b = paths_in[2u * i + 1u];
    return Path(uintBitsToFloat(a.xyz), a.w, b.x, b.y, b.z, b.w);
}

void store_path(uint i, Path q) {
    paths_next[2u * i] = uvec4(floatBitsToUint(q.throughput), q.pixel);
    paths_next[2u * i + 1u] = uvec4(q.flags, q.depth, q.diffuse, q.pad);
}

// The shadow ray from `origin` to `origin + dir` in slot k.
void store_shadow_ray(uint k, vec3 origin, vec3 dir) {
    Ray ray = Ray(origin, 0.0, dir, 1.0);
    shadow_rays[2u * k] = ray_word0(ray);
    shadow_rays[2u * k + 1u] = ray_word1(ray);
}

const float PI = 3.14159265358979;
#define INF uintBitsToFloat(0x7f800000u)

// The emitter whose cumulative probability first exceeds u (binary search).
uint pick_emitter(float u) {
    uint lo = 0u;
    uint hi = p.emitter_count - 1u;
    while (lo < hi) {
        uint mid = (lo + hi) / 2u;
        if (emitters[mid].cdf > u) hi = mid; else lo = mid + 1u;
    }
    return lo;
}

// The shading point of a hit and what every part of its shading reads.
struct Vertex {
    vec3 x;          // the hit point
    vec3 ng;         // unit geometric normal, as the triangle winds
    vec3 n;          // ng on the side the ray arrived from
    vec3 wo;         // unit direction back along the ray
    vec3 origin;     // x moved off the surface, for the rays that leave it
    vec3 thr;        // the path's throughput
    Material m;
    bool diffuse;
    bool glossy;
    bool mirror;
    uint base;       // this vertex's first dimension pair
};

// The BRDF at v toward the unit direction wi: the diffuse lobe and the
// normalized Phong lobe of glossy materials.
vec3 brdf(Vertex v, vec3 wi) {
    vec3 f = v.diffuse ? v.m.kd.xyz / PI : vec3(0.0);
    if (v.glossy) f += v.m.ks.xyz * ((v.m.kd.w + 2.0) / (2.0 * PI)) * pow(max(dot(reflect(-wi, v.n), v.wo), 0.0), v.m.kd.w);
    return f;
}

// What the path finds emitted at v (an emissive material): all of it for camera
// and mirror rays; for a diffuse bounce, which next-event estimation could also
// have sampled, the share the power heuristic (Veach 1997) gives the bounce.
// `ray_length`: the length of the ray's direction, so hit.t * ray_length is the distance.
vec3 emission(Vertex v, Path path, float t, float ray_length) {
    if ((path.flags & PATH_COUNT_EMISSION) != 0u) {
        return v.thr * v.m.ke.xyz;
    } else if (AREA_LIGHTS && (path.flags & PATH_MIS) != 0u) {
        float d = t * ray_length;
        float cos_y = max(abs(dot(v.ng, v.wo)), 1e-12);
        float p_light = max(luminance(v.m.ke.xyz), 1e-6) / p.forward.w * d * d / cos_y;
        float p_bsdf = uintBitsToFloat(path.pad);
        return v.thr * v.m.ke.xyz * (p_bsdf * p_bsdf / (p_bsdf * p_bsdf + p_light * p_light));
    }
    return vec3(0.0);
}

// One next-event-estimation sample of the emitters from v: `weight`, the
// radiance it brings if unoccluded (0 when none), MIS-weighted against the
// diffuse bounce taken with probability bounce_share; `target`, the sampled
// point moved off its emitter.
void sample_area_light(Vertex v, Path path, float bounce_share, out vec3 weight, out vec3 target) {
    weight = vec3(0.0);
    target = vec3(0.0);
    // One stratified 2D point picks the emitter and the point on it: w.x picks
    // by the emitters' cdf, then its place inside the picked emitter's interval
    // is the point's first coordinate, so every triangle of a lamp receives a
    // stratified point set (a pick from one pair and the point from another gave
    // each triangle random points: plain Monte Carlo convergence).
    // The path's first light sample (at the camera hit, or behind mirrors) takes
    // pair 0, whose 4D partner (ld2_partner) is the camera jitter: one 4D Sobol
    // point per sample; later ones take their vertex's own pair.
    vec2 w = (path.flags & PATH_LIGHT_SAMPLED) == 0u ? ld2(path.pixel, p.sample_index, 0u, p.seed)
                                                     : ld2(path.pixel, p.sample_index, v.base + 1u, p.seed);
    uint k = pick_emitter(w.x);
    Emitter e = emitters[k];
    float lo = k == 0u ? 0.0 : emitters[k - 1u].cdf;
    float wx = clamp((w.x - lo) / max(e.cdf - lo, 1e-30), 0.0, uintBitsToFloat(0x3f7fffffu));
    Surface es = load_surface(e.prim & EMITTER_PRIM_MASK);
    vec3 y;
    if ((e.prim & EMITTER_PARALLELOGRAM) != 0u) {
        // A quad lamp: the square maps affinely onto the parallelogram spanned
        // from the corner vertex by its two edges.
        uint corner = (e.prim >> EMITTER_CORNER_SHIFT) & 3u;
        vec3 c = corner == 0u ? es.v0.xyz : corner == 1u ? es.v1.xyz : es.v2.xyz;
        vec3 s1 = corner == 0u ? es.v1.xyz : corner == 1u ? es.v2.xyz : es.v0.xyz;
        vec3 s2 = corner == 0u ? es.v2.xyz : corner == 1u ? es.v0.xyz : es.v1.xyz;
        y = c + wx * (s1 - c) + w.y * (s2 - c);
    } else {
        float su = sqrt(wx);
        float c0 = 1.0 - su;
        float c1 = w.y * su;
        y = c0 * es.v0.xyz + c1 * es.v1.xyz + (1.0 - c0 - c1) * es.v2.xyz;
    }
    vec3 ny = normalize(cross(es.v1.xyz - es.v0.xyz, es.v2.xyz - es.v0.xyz));
    vec3 d = y - v.x;
    float dist2 = dot(d, d);
    vec3 wi = d * inversesqrt(dist2);
    float cos_x = dot(v.n, wi);
    float cos_y = abs(dot(ny, wi));
    if (dist2 > 0.0 && cos_x > 0.0 && cos_y > 0.0 && e.pick > 0.0) {
        vec3 f = brdf(v, wi);
        vec3 ke = uintBitsToFloat(imageLoad(material_texels, int(floatBitsToUint(es.v0.w)) * 3 + 2).xyz);
        // The power heuristic against the diffuse bounce's cosine sampling,
        // when this vertex bounces (else the light sample takes it all).
        float p_light = e.pick / e.area * dist2 / cos_y;
        float p_bsdf = bounce_share * cos_x / PI;
        float mis = p_light * p_light / (p_light * p_light + p_bsdf * p_bsdf);
        weight = v.thr * f * ke * (cos_x * cos_y / dist2) * (e.area / e.pick) * mis;
        vec3 escale = triangle_scale(es.v0.xyz, es.v1.xyz, es.v2.xyz);
        target = offset_origin(y, dot(ny, wi) > 0.0 ? -ny : ny, escale);
    }
}

// Appends the path's next ray from v to the next queue: a mirror reflection
// with probability p_mirror, else a diffuse bounce (probability bounce_share)
// when can_bounce; `gather_ao`: v gathered ambient occlusion; `light_sampled`:
// v took an area-light sample.
void continue_path(Vertex v, Path path, float p_mirror, float bounce_share, bool can_bounce, bool gather_ao,
                   bool light_sampled) {
    vec2 u = ld2(path.pixel, p.sample_index, v.base, p.seed);
    uint sampled = (path.flags & PATH_LIGHT_SAMPLED) | (light_sampled ? PATH_LIGHT_SAMPLED : 0u);
    Path next = path;
    next.depth = path.depth + 1u;
    vec3 dir = vec3(0.0);
    bool go = false;
    if (v.mirror && u.y < p_mirror) {
        dir = reflect(-v.wo, v.n);
        next.throughput = v.thr * v.m.ks.xyz / p_mirror;
        next.flags = PATH_COUNT_EMISSION | (path.flags & PATH_AO_DONE) | (gather_ao ? PATH_AO_DONE : 0u) | sampled;
        go = true;
    } else if (can_bounce) {
        dir = cosine_direction(v.n, ld2(path.pixel, p.sample_index, v.base + 2u, p.seed));
        next.throughput = v.thr * v.m.kd.xyz / bounce_share;
        next.flags = PATH_AO_DONE | (AREA_LIGHTS ? PATH_MIS : 0u) | sampled;
        next.pad = floatBitsToUint(bounce_share * max(dot(v.n, dir), 0.0) / PI);
        next.diffuse = path.diffuse + 1u;
        go = true;
    }
    if (go && luminance(next.throughput) > 0.0) {
        uint block = wave_block(p.count);
        uint slot = atomicAdd(counters[block + RC_NEXT], 1u);
        // Grow the next wave's indirect dispatch by a workgroup when one begins.
        if (slot % RENDER_WORKGROUP_SIZE == 0u) atomicAdd(counters[block + RC_ARGS], 1u);
        Ray ray = Ray(v.origin, 0.0, dir, INF);
        rays_next[2u * slot] = ray_word0(ray);
        rays_next[2u * slot + 1u] = ray_word1(ray);
        store_path(slot, next);
    }
}

// The shading point of `hit` on its triangle for a path whose ray has direction `dir`.
Vertex vertex_at(Hit hit, Path path, vec3 dir) {
    Surface s = load_surface(hit.prim_id);
    Vertex v;
    v.m = load_material(floatBitsToUint(s.v0.w));
    uint mat = floatBitsToUint(v.m.ks.w);
    v.wo = -normalize(dir);
    v.ng = normalize(cross(s.v1.xyz - s.v0.xyz, s.v2.xyz - s.v0.xyz));
    v.n = dot(v.ng, v.wo) < 0.0 ? -v.ng : v.ng;
    float b0 = 1.0 - hit.u - hit.v;
    v.x = b0 * s.v0.xyz + hit.u * s.v1.xyz + hit.v * s.v2.xyz;
    vec3 scale = triangle_scale(s.v0.xyz, s.v1.xyz, s.v2.xyz);
    v.origin = offset_origin(v.x, v.n, scale);
    v.thr = path.throughput;
    v.diffuse = (mat & MAT_DIFFUSE) != 0u;
    v.glossy = GLOSSY && (mat & MAT_GLOSSY) != 0u;
    v.mirror = MIRRORS && (mat & MAT_MIRROR) != 0u;
    v.base = 1u + 4u * path.depth;
    return v;
}

// Writes the shadow rays of v and their weights from slot `first` on, in the
// order main counted them: the area-light sample, the point lights facing v,
// the eye light's visibility ray, the ambient-occlusion rays.
void write_shadow_rays(uint first, Vertex v, Path path, vec3 area_weight, vec3 area_target, bool lit, bool head_ray,
                       vec3 head, bool gather_ao) {
    uint k = first;
    if (luminance(area_weight) > 0.0) {
        store_shadow_ray(k, v.origin, area_target - v.origin);
        shadow_weights[k] = vec4(area_weight, 0.0);
        k++;
    }
    if (POINT_LIGHTS && lit) {
        for (uint l = 0u; l < p.light_count; l++) {
            vec3 d = lights[l].position.xyz - v.x;
            if (dot(v.n, d) <= 0.0) continue;
            float dist2 = dot(d, d);
            vec3 wi = d * inversesqrt(dist2);
            vec3 f = brdf(v, wi);
            store_shadow_ray(k, v.origin, lights[l].position.xyz - v.origin);
            shadow_weights[k] = vec4(v.thr * f * lights[l].intensity.xyz * (dot(v.n, wi) / dist2), 0.0);
            k++;
        }
    }
    if (head_ray) {
        store_shadow_ray(k, v.origin, p.eye.xyz - v.origin);
        shadow_weights[k] = vec4(head, 0.0);
        k++;
    }
    if (gather_ao) {
        vec3 weight = v.thr * v.m.kd.xyz * (p.background.w / float(p.ao_samples));
        for (uint a = 0u; a < p.ao_samples; a++) {
            vec2 u = ld2(path.pixel, p.sample_index * p.ao_samples + a, v.base + 3u, p.seed);
            store_shadow_ray(k, v.origin, cosine_direction(v.n, u) * p.ao_radius);
            shadow_weights[k] = vec4(weight, 0.0);
            k++;
        }
    }
}

void main() {
    uint i = gl_GlobalInvocationID.x;
    uint block = wave_block(p.count);
    if (i >= WAVE_PATHS(p.count, block)) return;
    Path path = load_path(i);
    uvec4 h = hits_in[i];
    Hit hit = Hit(uintBitsToFloat(h.x), h.y, uintBitsToFloat(h.z), uintBitsToFloat(h.w));
    spans[i] = uvec2(0u);

    if (hit.prim_id >= PRIM_INCOMPLETE) {
        if (hit.prim_id == PRIM_MISS) {
            accum[path.pixel] += vec4(path.throughput * p.background.xyz, 0.0);
        } else {
            atomicAdd(counters[block + RC_BAD_RAYS], 1u);
            accum[path.pixel] += vec4(0.0, 0.0, 0.0, 1.0);  // w counts the pixel's bad rays
        }
        return;
    }

    Vertex v = vertex_at(hit, path, ray_in_dir(i));
    uint mat = floatBitsToUint(v.m.ks.w);

    // How the path goes on from here: a mirror reflection with probability
    // p_mirror, else a diffuse bounce when allowed (probability bounce_share).
    bool continues = CONTINUE && path.depth + 1u < p.max_depth;
    bool can_bounce = continues && BOUNCES && !HEADLIGHT && v.diffuse && path.diffuse < p.bounces;
    float p_mirror = 0.0;
    if (v.mirror && continues) {
        float lm = luminance(v.m.ks.xyz);
        float ld = can_bounce ? luminance(v.m.kd.xyz) : 0.0;
        p_mirror = lm + ld > 0.0 ? lm / (lm + ld) : 0.0;
    }
    float bounce_share = can_bounce ? 1.0 - p_mirror : 0.0;

    vec3 L = vec3(0.0);
    if ((mat & MAT_EMISSIVE) != 0u) L += emission(v, path, hit.t, length(ray_in_dir(i)));
    // The eye light shades without shadows. At a camera hit the camera ray
    // proves the eye sees v.x; HEADLIGHT_SHADOWS traces that visibility anyway
    // (--no-skip), to measure what skipping it saves.
    vec3 head = (HEADLIGHT && v.diffuse) ? v.thr * v.m.kd.xyz * (0.1 + 0.9 * max(dot(v.n, v.wo), 0.0)) : vec3(0.0);
    bool head_ray = HEADLIGHT && HEADLIGHT_SHADOWS && path.depth == 0u && luminance(head) > 0.0;
    if (HEADLIGHT && !head_ray) L += head;

    // Shadow rays: count them, reserve a contiguous span, then write them.
    uint shadow_count = 0u;
    bool lit = !HEADLIGHT && (v.diffuse || v.glossy);
    vec3 area_weight = vec3(0.0);
    vec3 area_target = vec3(0.0);
    bool light_sampled = AREA_LIGHTS && lit && p.emitter_count > 0u;
    if (light_sampled) {
        sample_area_light(v, path, bounce_share, area_weight, area_target);
        if (luminance(area_weight) > 0.0) shadow_count++;
    }
    if (POINT_LIGHTS && lit) {
        for (uint l = 0u; l < p.light_count; l++) {
            if (dot(v.n, lights[l].position.xyz - v.x) > 0.0) shadow_count++;
        }
    }
    bool gather_ao = AO && v.diffuse && !HEADLIGHT && (path.flags & PATH_AO_DONE) == 0u;
    if (gather_ao) shadow_count += p.ao_samples;
    if (head_ray) shadow_count++;

    if (shadow_count > 0u) {
        uint first = atomicAdd(counters[block + RC_SHADOW], shadow_count);
        if (first + shadow_count > p.shadow_capacity) {
            atomicAdd(counters[block + RC_OVERFLOW], shadow_count);
        } else {
            spans[i] = uvec2(first, shadow_count);
            write_shadow_rays(first, v, path, area_weight, area_target, lit, head_ray, head, gather_ao);
        }
    }

    // The path's next ray: a mirror reflection or a diffuse bounce.
    if (continues) continue_path(v, path, p_mirror, bounce_share, can_bounce, gather_ao, light_sampled);

    accum[path.pixel] += vec4(L, 0.0);
}
