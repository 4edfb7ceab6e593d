// Float-float ("double-f32") arithmetic: a value held as hi + lo in two f32,
// |lo| <= ulp(hi) / 2, about 48 significant bits. The kernels need no 64-bit
// type (shaderFloat64 / shaderInt64): the careful paths that once ran in f64
// (the watertight test's exact fallback, a far ray's move to the scene box)
// run on these instead.
//
// Every operation is an error-free transformation (Knuth's two-sum; Dekker's
// product with Veltkamp's split, which needs no fused fma: Vulkan promises
// correctly rounded f32 add, sub and mul, not a fused fma) followed by one
// rounding of the small parts. `precise` keeps the compiler from fusing or
// reassociating. Sums and products are commutative and negate exactly
// (ff_add(-x, -y) == -ff_add(x, y)), which keeps the exact edge tests
// antisymmetric: two triangles sharing an edge see opposite signs.
//
// Exactness assumes no overflow and no flushed denormal: Veltkamp's split
// overflows above about 8e34, and a GPU that flushes denormals (lavapipe keeps
// them; many GPUs flush) drops an error term below 2^-126. Callers scale their
// inputs by powers of two where that matters, and their error bounds allow for
// the flushed terms. CPU twin: src/ff.rs (same operations, same order, IEEE
// denormals as lavapipe computes them).
#ifndef FF_GLSL
#define FF_GLSL

// a + b = s + e exactly (Knuth): any magnitudes.
vec2 ff_two_sum(float a, float b) {
    precise float s = a + b;
    precise float bb = s - a;
    precise float e = (a - (s - bb)) + (b - bb);
    return vec2(s, e);
}

// Veltkamp's split of a into two 12-bit halves: a = hi + lo exactly.
vec2 ff_split(float a) {
    precise float c = 4097.0 * a;
    precise float hi = c - (c - a);
    precise float lo = a - hi;
    return vec2(hi, lo);
}

// a * b = p + e exactly (Dekker 1971).
vec2 ff_two_prod(float a, float b) {
    vec2 x = ff_split(a);
    vec2 y = ff_split(b);
    precise float p = a * b;
    precise float e = ((x.x * y.x - p) + x.x * y.y + x.y * y.x) + x.y * y.y;
    return vec2(p, e);
}

vec2 ff_from(float a) {
    return vec2(a, 0.0);
}

// a - b of two f32, exactly.
vec2 ff_diff(float a, float b) {
    return ff_two_sum(a, -b);
}

vec2 ff_add(vec2 x, vec2 y) {
    vec2 s = ff_two_sum(x.x, y.x);
    vec2 t = ff_two_sum(x.y, y.y);
    precise float e = s.y + t.x;
    vec2 u = ff_two_sum(s.x, e);
    precise float f = u.y + t.y;
    return ff_two_sum(u.x, f);
}

vec2 ff_sub(vec2 x, vec2 y) {
    return ff_add(x, -y);
}

vec2 ff_add_f(vec2 x, float b) {
    vec2 s = ff_two_sum(x.x, b);
    precise float e = s.y + x.y;
    return ff_two_sum(s.x, e);
}

vec2 ff_mul(vec2 x, vec2 y) {
    vec2 p = ff_two_prod(x.x, y.x);
    precise float cross = x.x * y.y + x.y * y.x;
    precise float e = p.y + cross;
    return ff_two_sum(p.x, e);
}

vec2 ff_mul_f(vec2 x, float b) {
    vec2 p = ff_two_prod(x.x, b);
    precise float e = p.y + x.y * b;
    return ff_two_sum(p.x, e);
}

// x / y (y.x != 0): about 2^-44 relative. The quotients are products with the
// reciprocal (as Mesa lowers a division anyway), so that the CPU twin can
// reproduce them; the remainder step makes up for their rounding.
vec2 ff_div(vec2 x, vec2 y) {
    precise float rcp = 1.0 / y.x;
    precise float q1 = x.x * rcp;
    vec2 r = ff_sub(x, ff_mul_f(y, q1));
    precise float q2 = r.x * rcp;
    return ff_two_sum(q1, q2);
}

// The sum of eight f32, exactly as a nonoverlapping expansion (Shewchuk 1997,
// Grow-Expansion: h[7] is the largest part, within an ulp of the sum), then
// rounded to float-float: within about 2^-47 of the sum however much the terms
// cancel (the far-away origin's huge products, for a point next to the scene).
vec2 ff_exact_sum8(float terms[8]) {
    float h[8];
    for (uint m = 0u; m < 8u; ++m) {
        float q = terms[m];
        for (uint i = 0u; i < m; ++i) {
            vec2 s = ff_two_sum(q, h[i]);
            q = s.x;
            h[i] = s.y;
        }
        h[m] = q;
    }
    // The smaller parts in f32 (off by at most about 2^-24 of the second largest);
    // written out, not as a loop over a float-float accumulator, which Mesa
    // compiled without the low word (measured: its GPU result lost it).
    precise float rest = (((((h[0] + h[1]) + h[2]) + h[3]) + h[4]) + h[5]) + h[6];
    return ff_two_sum(h[7], rest);
}

// The sign of det[x, y, z] = z . (x × y) for float-float vectors x, y, z,
// each scaled by a power of two so that its largest component lies in [1, 2):
// -1, 0 or 1, exact unless the determinant lies within 2^-100 of 0 (then 0;
// far below every rounding the kernels make, above the error of terms a GPU
// flushes to 0). The products of the parts (96 when z's low parts are all 0, a
// direction; else 192) are exact (Dekker); repeated error-free passes (Ogita,
// Rump & Oishi's VecSum) carry the sum to the last term until it outweighs the
// rest. Rarely run: the exact triangle test calls it only for a ray within
// 2^-40 of an edge or an origin within rounding of the triangle's plane, and
// its loops stay rolled ([[dont_unroll]]; includers enable
// GL_EXT_control_flow_attributes). Twin: orient_sign in src/ff.rs.
// 2^-ORIENT_ZERO_LOG2 (src/consts.rs): a determinant of unit-scaled vectors
// within it of 0 counts as 0.
const float ORIENT_ZERO = exp2(-float(ORIENT_ZERO_LOG2));

int ff_orient_sign(vec2 x[3], vec2 y[3], vec2 z[3]) {
    float t[192];
    uint n = 0u;
    uint parts = (z[0].y != 0.0 || z[1].y != 0.0 || z[2].y != 0.0) ? 2u : 1u;
    [[dont_unroll]] for (uint c = 0u; c < 3u; ++c) {
        // (x × y)_c = x_a y_b - x_b y_a.
        uint a = (c + 1u) % 3u;
        uint b = (c + 2u) % 3u;
        [[dont_unroll]] for (uint i = 0u; i < 2u; ++i) {
            [[dont_unroll]] for (uint j = 0u; j < 2u; ++j) {
                vec2 p = ff_two_prod(x[a][i], y[b][j]);
                vec2 q = ff_two_prod(x[b][i], y[a][j]);
                vec4 f = vec4(p.x, p.y, -q.x, -q.y);
                [[dont_unroll]] for (uint k = 0u; k < 4u; ++k) {
                    [[dont_unroll]] for (uint m = 0u; m < parts; ++m) {
                        vec2 e = ff_two_prod(f[k], z[c][m]);
                        t[n] = e.x;
                        t[n + 1u] = e.y;
                        n += 2u;
                    }
                }
            }
        }
    }
    [[dont_unroll]] for (uint pass = 0u; pass < 16u; ++pass) {
        // One VecSum pass: the running sum moves to the last slot, each step's
        // rounding error stays behind; the terms' sum is unchanged.
        float s = t[0];
        [[dont_unroll]] for (uint i = 1u; i < n; ++i) {
            vec2 e = ff_two_sum(s, t[i]);
            t[i - 1u] = e.y;
            s = e.x;
        }
        t[n - 1u] = s;
        precise float rest = 0.0;
        [[dont_unroll]] for (uint i = 0u; i + 1u < n; ++i) rest = rest + abs(t[i]);
        // rest is within 191 roundings (2^-16.4) of the exact sum of magnitudes.
        precise float margin = rest * 1.0000152587890625;
        if (abs(s) > margin) return s > 0.0 ? 1 : -1;
        precise float total = abs(s) + rest;
        if (total <= ORIENT_ZERO) return 0;
    }
    return 0;
}

// x >= b against an f32 (exact for normalized pairs).
bool ff_ge_f(vec2 x, float b) {
    return x.x > b || (x.x == b && x.y >= 0.0);
}
// x <= y (exact for normalized pairs).
bool ff_le(vec2 x, vec2 y) {
    return x.x < y.x || (x.x == y.x && x.y <= y.y);
}

#endif
