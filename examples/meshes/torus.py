#!/usr/bin/env python3
"""Writes a closed quad torus as OBJ (examples/meshes/torus.obj is its output):
    python3 examples/meshes/torus.py [MAJOR_SEGMENTS MINOR_SEGMENTS] > torus.obj
"""
import math
import sys

n = int(sys.argv[1]) if len(sys.argv) > 1 else 32
m = int(sys.argv[2]) if len(sys.argv) > 2 else 16
R, r = 1.0, 0.35
print("# torus R=%g r=%g, %d x %d quads (examples/meshes/torus.py)" % (R, r, n, m))
for i in range(n):
    u = 2 * math.pi * i / n
    for j in range(m):
        v = 2 * math.pi * j / m
        print("v %.6f %.6f %.6f" % ((R + r * math.cos(v)) * math.cos(u),
                                    (R + r * math.cos(v)) * math.sin(u), r * math.sin(v)))
for i in range(n):
    for j in range(m):
        a = i * m + j + 1
        b = ((i + 1) % n) * m + j + 1
        c = ((i + 1) % n) * m + (j + 1) % m + 1
        d = i * m + (j + 1) % m + 1
        print("f %d %d %d %d" % (a, b, c, d))
