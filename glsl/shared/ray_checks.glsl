// The checks every kernel makes on a ray before tracing it, as `Ray::traced_dir`
// and `Ray::is_valid` in src/geom.rs make them on the CPU.
#ifndef RAY_CHECKS_GLSL
#define RAY_CHECKS_GLSL

// A ray from its 32-byte record read as two uvec4 words (bits only).
Ray ray_from_words(uvec4 a, uvec4 b) {
    Ray ray;
    ray.origin = uintBitsToFloat(a.xyz);
    ray.tmin = uintBitsToFloat(a.w);
    ray.dir = uintBitsToFloat(b.xyz);
    ray.tmax = uintBitsToFloat(b.w);
    return ray;
}

// The two uvec4 words of a ray's 32-byte record (ray_from_words' inverse).
uvec4 ray_word0(Ray ray) { return uvec4(floatBitsToUint(ray.origin), floatBitsToUint(ray.tmin)); }
uvec4 ray_word1(Ray ray) { return uvec4(floatBitsToUint(ray.dir), floatBitsToUint(ray.tmax)); }

// The direction as traced: denormal components count as zeros of the same sign
// (as on GPUs that flush them; the CPU twins and the exact reference do the same).
vec3 traced_dir(vec3 dir) {
    vec3 signed_zero = uintBitsToFloat(floatBitsToUint(dir) & uvec3(0x80000000u));
    return mix(dir, signed_zero, lessThan(abs(dir), vec3(uintBitsToFloat(0x00800000u))));
}

// A valid ray has a finite origin, a direction without NaN that is not zero (after
// traced_dir), and bounds that are not NaN. Invalid rays get PRIM_INVALID.
bool ray_is_valid(Ray ray) {
    bool origin_ok = !any(isnan(ray.origin)) && !any(isinf(ray.origin));
    bool dir_ok = !any(isnan(ray.dir)) && any(notEqual(ray.dir, vec3(0.0)));
    return origin_ok && dir_ok && !isnan(ray.tmin) && !isnan(ray.tmax);
}

#endif
