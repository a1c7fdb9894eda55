#!/usr/bin/env python3
"""Shapes for test_render.sh as OBJ in DIR: icosphere (radius 1 at the
origin, an icosahedron subdivided 6 times: 81920 triangles, so that its
facets are far below the low-pass's smoothing length), torus (R 1, r 0.4,
axis z, 256 x 128 quads), ball_a / ball_b (radius 0.6 at x = -0.5 / +0.5,
overlapping: the `meshes` sum).

Usage: render_shapes.py DIR"""
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from shapes import icosphere, torus, write  # noqa: E402


def main():
    d = sys.argv[1]
    write(os.path.join(d, "icosphere.obj"), *icosphere(6))
    write(os.path.join(d, "torus.obj"), *torus(1.0, 0.4, 256, 128))
    write(os.path.join(d, "ball_a.obj"), *icosphere(3, 0.6, (-0.5, 0, 0)))
    write(os.path.join(d, "ball_b.obj"), *icosphere(3, 0.6, (0.5, 0, 0)))


if __name__ == "__main__":
    main()
