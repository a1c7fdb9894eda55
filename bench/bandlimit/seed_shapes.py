#!/usr/bin/env python3
"""The seed 002 example shapes as closed OBJ meshes in DIR, all about 2
units across: hyperboloid (one sheet, x^2 + y^2 = 0.5^2 (1 + z^2 / 0.6^2)
for |z| <= 1, capped), sphere (radius 1, icosphere level 4) and cube
(edge 2, each face split 8 x 8).

Usage: seed_shapes.py DIR"""
import math
import os
import sys

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "..", "tests", "integration"))
from shapes import icosphere, write  # noqa: E402


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


d = sys.argv[1]
write(os.path.join(d, "hyperboloid.obj"), *hyperboloid())
write(os.path.join(d, "sphere.obj"), *icosphere(4))
write(os.path.join(d, "cube.obj"), *cube())
