#!/usr/bin/env python3
"""Writes a test scene of flat triangle fans whose vertices come from cos and sin
(so coordinates such as cos(pi/2) = 6.1e-17 sit next to 1.0), plus a seeded soup
of small triangles: a scene none of the shared ones resembles, for
`kdtrace verify` (docs/ACCURACY.md, Known limits).

Usage: tools/fan-scene.py OUT.obj [FANS] [SEGMENTS] [SOUP] [SEED]
"""
import math
import random
import sys


def main():
    if len(sys.argv) < 2:
        print(__doc__.strip(), file=sys.stderr)
        sys.exit(2)
    out = sys.argv[1]
    fans, segments, soup, seed = (int(a) for a in (sys.argv[2:] + ["5", "64", "300", "5"][len(sys.argv) - 2:])[:4])
    rng = random.Random(seed)
    vertices, faces = [], []
    for k in range(fans):
        z = 0.5 * k
        centre = len(vertices)
        vertices.append((0.0, 0.0, z))
        for i in range(segments):
            a = 2.0 * math.pi * i / segments
            vertices.append((math.cos(a), math.sin(a), z))
        for i in range(segments):
            faces.append((centre, centre + 1 + i, centre + 1 + (i + 1) % segments))
    for _ in range(soup):
        c = (rng.uniform(-1, 1), rng.uniform(-1, 1), rng.uniform(0, 2))
        first = len(vertices)
        for _ in range(3):
            vertices.append(tuple(c[q] + rng.uniform(-0.2, 0.2) for q in range(3)))
        faces.append((first, first + 1, first + 2))
    with open(out, "w") as f:
        f.write(f"# tools/fan-scene.py: {fans} fans of {segments} triangles, {soup} soup triangles, seed {seed}\n")
        for v in vertices:
            f.write("v %.9g %.9g %.9g\n" % v)
        for a, b, c in faces:
            f.write(f"f {a + 1} {b + 1} {c + 1}\n")
    print(f"{out}: {len(faces)} triangles")


if __name__ == "__main__":
    main()
