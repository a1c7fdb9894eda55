#!/usr/bin/env python3
"""Analytic test shapes as OBJ for test_voxelize.sh, each with its exact
mesh volume (divergence theorem over the triangles) in DIR/volumes.json.
The builders (sphere, icosphere, torus, merge, write) are shared with
render_shapes.py and bench/bandlimit/seed_shapes.py.

Usage: shapes.py DIR
Shapes (outward-facing unless said): sphere (r 1), torus (R 1, r 0.4),
hollow (sphere r 1 around an inward-facing sphere r 0.5: a ball with a
void), nested (hollow plus a sphere r 0.3 inside the void), two (spheres
r 0.75 at x = 0 and x = 1, overlapping), open (the sphere without the
triangles of its cap around +z: not closed). volumes.json also has
two_union / two_xor (what nonzero / parity should give for `two`) and
open_closed (the closed sphere `open` was cut from)."""
import json
import math
import os
import sys


def sphere(c, r, nu=48, nv=24, inward=False, skip_cap=None):
    """UV sphere: (vertices, triangles). skip_cap: drop triangles whose
    vertices all have z > skip_cap * r (relative to the centre)."""
    vs = [(c[0], c[1], c[2] + r)]
    for i in range(1, nv):
        th = math.pi * i / nv
        for j in range(nu):
            ph = 2 * math.pi * j / nu
            vs.append((c[0] + r * math.sin(th) * math.cos(ph), c[1] + r * math.sin(th) * math.sin(ph),
                       c[2] + r * math.cos(th)))
    vs.append((c[0], c[1], c[2] - r))
    last = len(vs) - 1
    ring = lambda i, j: 1 + (i - 1) * nu + (j % nu)
    ts = []
    for j in range(nu):
        ts.append((0, ring(1, j), ring(1, j + 1)))
        ts.append((last, ring(nv - 1, j + 1), ring(nv - 1, j)))
    for i in range(1, nv - 1):
        for j in range(nu):
            a, b, cc, d = ring(i, j), ring(i + 1, j), ring(i + 1, j + 1), ring(i, j + 1)
            ts.append((a, b, cc))
            ts.append((a, cc, d))
    if skip_cap is not None:
        ts = [t for t in ts if not all(vs[k][2] - c[2] > skip_cap * r for k in t)]
    if inward:
        ts = [(t[0], t[2], t[1]) for t in ts]
    return vs, ts


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


def torus(R, r, nu=64, nv=32):
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
            ts.append((a, b, c))
            ts.append((a, c, d))
    return vs, ts


def merge(*parts):
    vs, ts = [], []
    for pv, pt in parts:
        o = len(vs)
        vs += pv
        ts += [(a + o, b + o, c + o) for a, b, c in pt]
    return vs, ts


def volume(vs, ts):
    v = 0.0
    for a, b, c in ts:
        (x1, y1, z1), (x2, y2, z2), (x3, y3, z3) = vs[a], vs[b], vs[c]
        v += (x1 * (y2 * z3 - y3 * z2) - x2 * (y1 * z3 - y3 * z1) + x3 * (y1 * z2 - y2 * z1)) / 6
    return v


def write(path, vs, ts):
    with open(path, "w") as f:
        for x, y, z in vs:
            f.write("v %.17g %.17g %.17g\n" % (x, y, z))
        for a, b, c in ts:
            f.write("f %d %d %d\n" % (a + 1, b + 1, c + 1))


def main():
    out = sys.argv[1]
    s = sphere((0, 0, 0), 1)
    shapes = {
        "sphere": s,
        "torus": torus(1, 0.4),
        "hollow": merge(s, sphere((0, 0, 0), 0.5, inward=True)),
        "nested": merge(s, sphere((0, 0, 0), 0.5, inward=True), sphere((0, 0, 0), 0.3)),
        "two": merge(sphere((0, 0, 0), 0.75), sphere((1, 0, 0), 0.75)),
        "open": sphere((0, 0, 0), 1, skip_cap=0.97),
    }
    vols = {}
    for name, (vs, ts) in shapes.items():
        write(os.path.join(out, name + ".obj"), vs, ts)
        vols[name] = volume(vs, ts)
    # Two spheres of radius r at distance d: the lens they share, from the
    # tessellated volumes' ratio to the analytic ones (tessellation shrinks
    # every part alike, to first order).
    r, d = 0.75, 1.0
    ball = 4 / 3 * math.pi * r ** 3
    lens = math.pi * (4 * r + d) * (2 * r - d) ** 2 / 12
    k = volume(*sphere((0, 0, 0), r)) / ball
    vols["two_union"] = k * (2 * ball - lens)
    vols["two_xor"] = k * (2 * ball - 2 * lens)
    vols["open_closed"] = vols["sphere"]
    with open(os.path.join(out, "volumes.json"), "w") as f:
        json.dump(vols, f)


if __name__ == "__main__":
    main()
