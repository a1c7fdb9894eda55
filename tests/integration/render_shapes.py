#!/usr/bin/env python3
"""Shapes for test_render.sh as OBJ in DIR: icosphere (radius 1 at the
origin, an icosahedron subdivided 6 times: 81920 triangles, so that its
facets are far below the low-pass's smoothing length), torus (R 1, r 0.4,
axis z, 256 x 128 quads), ball_a / ball_b (radius 0.6 at x = -0.5 / +0.5,
overlapping: the `meshes` sum).

Usage: render_shapes.py DIR"""
import math
import os
import sys


def icosphere(level, r=1.0, c=(0.0, 0.0, 0.0)):
    t = (1 + 5 ** 0.5) / 2
    vs = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
          (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    vs = [tuple(x / math.sqrt(sum(y * y for y in v)) for x in v) for v in vs]
    fs = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
          (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
          (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(level):
        mid = {}

        def m(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                p = [(vs[a][i] + vs[b][i]) / 2 for i in range(3)]
                n = math.sqrt(sum(x * x for x in p))
                vs.append(tuple(x / n for x in p))
                mid[key] = len(vs) - 1
            return mid[key]

        nf = []
        for a, b, cc in fs:
            ab, bc, ca = m(a, b), m(b, cc), m(cc, a)
            nf += [(a, ab, ca), (b, bc, ab), (cc, ca, bc), (ab, bc, ca)]
        fs = nf
    return [tuple(c[i] + r * v[i] for i in range(3)) for v in vs], fs


def torus(R, r, nu=256, nv=128):
    vs, ts = [], []
    for i in range(nu):
        u = 2 * math.pi * i / nu
        for j in range(nv):
            v = 2 * math.pi * j / nv
            vs.append(((R + r * math.cos(v)) * math.cos(u), (R + r * math.cos(v)) * math.sin(u), r * math.sin(v)))
    idx = lambda i, j: (i % nu) * nv + (j % nv)
    for i in range(nu):
        for j in range(nv):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            ts += [(a, b, c), (a, c, d)]
    return vs, ts


def write(path, shape):
    vs, ts = shape
    with open(path, "w") as f:
        f.writelines("v %.9f %.9f %.9f\n" % v for v in vs)
        f.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in ts)


def main():
    d = sys.argv[1]
    write(os.path.join(d, "icosphere.obj"), icosphere(6))
    write(os.path.join(d, "torus.obj"), torus(1.0, 0.4))
    write(os.path.join(d, "ball_a.obj"), icosphere(3, 0.6, (-0.5, 0, 0)))
    write(os.path.join(d, "ball_b.obj"), icosphere(3, 0.6, (0.5, 0, 0)))


if __name__ == "__main__":
    main()
