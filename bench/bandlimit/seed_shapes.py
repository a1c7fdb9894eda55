#!/usr/bin/env python3
"""The seed 002 example shapes as closed OBJ meshes in DIR, all about 2
units across: hyperboloid (one sheet, x^2 + y^2 = 0.5^2 (1 + z^2 / 0.6^2)
for |z| <= 1, capped), sphere (radius 1, icosphere level 4) and cube
(edge 2, each face split 8 x 8).

Usage: seed_shapes.py DIR"""
import math
import os
import sys


def hyperboloid(a=0.5, c=0.6, h=1.0, nu=96, nv=48):
    vs, fs = [], []
    for j in range(nv + 1):
        z = -h + 2 * h * j / nv
        r = a * math.sqrt(1 + (z / c) ** 2)
        for i in range(nu):
            u = 2 * math.pi * i / nu
            vs.append((r * math.cos(u), r * math.sin(u), z))
    idx = lambda i, j: j * nu + (i % nu)
    for j in range(nv):
        for i in range(nu):
            a0, b0, c0, d0 = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            fs += [(a0, b0, c0), (a0, c0, d0)]
    bot, top = len(vs), len(vs) + 1
    vs += [(0, 0, -h), (0, 0, h)]
    for i in range(nu):
        fs.append((bot, idx(i + 1, 0), idx(i, 0)))
        fs.append((top, idx(i, nv), idx(i + 1, nv)))
    return vs, fs


def icosphere(level, r=1.0):
    t = (1 + 5 ** 0.5) / 2
    vs = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
          (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    vs = [tuple(x / math.sqrt(sum(y * y for y in v)) for x in v) for v in vs]
    fs = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
          (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
          (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(level):
        mid, nf = {}, []

        def m(p, q):
            key = (min(p, q), max(p, q))
            if key not in mid:
                x = [(vs[p][i] + vs[q][i]) / 2 for i in range(3)]
                n = math.sqrt(sum(y * y for y in x))
                vs.append(tuple(y / n for y in x))
                mid[key] = len(vs) - 1
            return mid[key]

        for p, q, s in fs:
            pq, qs, sp = m(p, q), m(q, s), m(s, p)
            nf += [(p, pq, sp), (q, qs, pq), (s, sp, qs), (pq, qs, sp)]
        fs = nf
    return [tuple(r * x for x in v) for v in vs], fs


def cube(n=8):
    vs, fs, index = [], [], {}

    def vid(p):
        if p not in index:
            index[p] = len(vs)
            vs.append(tuple(-1 + 2 * x / n for x in p))
        return index[p]

    for ax in range(3):
        for side in (0, n):
            for i in range(n):
                for j in range(n):
                    def pt(a, b):
                        p = [0, 0, 0]
                        p[ax], p[(ax + 1) % 3], p[(ax + 2) % 3] = side, a, b
                        return vid(tuple(p))
                    q = [pt(i, j), pt(i + 1, j), pt(i + 1, j + 1), pt(i, j + 1)]
                    if side == 0:
                        q.reverse()
                    fs += [(q[0], q[1], q[2]), (q[0], q[2], q[3])]
    return vs, fs


def write(path, shape):
    vs, fs = shape
    with open(path, "w") as f:
        f.writelines("v %.9f %.9f %.9f\n" % v for v in vs)
        f.writelines("f %d %d %d\n" % (a + 1, b + 1, c + 1) for a, b, c in fs)


d = sys.argv[1]
write(os.path.join(d, "hyperboloid.obj"), hyperboloid())
write(os.path.join(d, "sphere.obj"), icosphere(4))
write(os.path.join(d, "cube.obj"), cube())
