#!/usr/bin/env python3
"""Prints the direction numbers of Sobol dimensions 3 and 4 (primitive
polynomials x^2+x+1 and x^3+x+1; initial m = 1,3 and 1,3,1) as GLSL
uint arrays, for SOBOL_THIRD/SOBOL_FOURTH in glsl/shared/render.glsl, and checks
that dimension 2 of the same recurrence is render.glsl's sobol_second."""


def directions(degree, coeffs, m):
    v = [0] * 33
    for k in range(1, 33):
        if k <= degree:
            v[k] = (m[k - 1] << (32 - k)) & 0xFFFFFFFF
        else:
            x = v[k - degree] ^ (v[k - degree] >> degree)
            for j in range(1, degree):
                if (coeffs >> (degree - 1 - j)) & 1:
                    x ^= v[k - j]
            v[k] = x & 0xFFFFFFFF
    return v[1:]


def point(v, i):
    r, k = 0, 0
    while i:
        if i & 1:
            r ^= v[k]
        i >>= 1
        k += 1
    return r


def sobol_second(i):
    r, v = 0, 1 << 31
    while i:
        if i & 1:
            r ^= v
        v ^= v >> 1
        i >>= 1
    return r


assert all(point(directions(1, 0, [1]), i) == sobol_second(i) for i in range(4096))
for name, d in (("SOBOL_THIRD", directions(2, 1, [1, 3])), ("SOBOL_FOURTH", directions(3, 1, [1, 3, 1]))):
    rows = [", ".join("0x%08xu" % x for x in d[r:r + 8]) for r in range(0, 32, 8)]
    print("const uint %s[32] = uint[32](\n    %s);" % (name, ",\n    ".join(rows)))
