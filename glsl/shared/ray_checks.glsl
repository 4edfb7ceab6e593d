// The checks every kernel makes on a ray before tracing it, as `Ray::traced_dir`
// and `Ray::is_valid` in src/geom.rs make them on the CPU.
#ifndef RAY_CHECKS_GLSL
#define RAY_CHECKS_GLSL

// A ray from its 32-byte record read as four 64-bit words (bits only: lavapipe
// loads storage buffers per lane and per component, so 4 loads beat 8).
Ray ray_from_words(double a, double b, double c, double d) {
    uvec2 w0 = unpackDouble2x32(a);
    uvec2 w1 = unpackDouble2x32(b);
    uvec2 w2 = unpackDouble2x32(c);
    uvec2 w3 = unpackDouble2x32(d);
    Ray ray;
    ray.origin = uintBitsToFloat(uvec3(w0, w1.x));
    ray.tmin = uintBitsToFloat(w1.y);
    ray.dir = uintBitsToFloat(uvec3(w2, w3.x));
    ray.tmax = uintBitsToFloat(w3.y);
    return ray;
}

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
