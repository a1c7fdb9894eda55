#!/usr/bin/env python3
"""Topology and normal checks of a gregory job's OBJ output (pure Python).

gregory_check.py FILE.obj [--g1 [--crease DEG] [--input MESH.obj]]
Prints one JSON object:
  edges_over_2   edges used by more than two triangles
  edges_once     edges used by one triangle (boundary)
  dup_tris       triangles whose vertex set another triangle also has
  back_facing    triangles whose geometric normal turns against the mean of
                 their three vertex normals (dot < 0; zero-area ones skipped)
  g1_max_deg     (--g1, unwelded output with one `g patch` group per patch)
                 the largest angle between the normals two patches give at
                 one point (points on patch boundaries matched within 1e-7
                 of the bounding box diagonal)
  g1_points      how many such shared points were compared
  g1_creases     (--crease DEG) points where the normals differ by more
                 than DEG: surfaces that only touch there (the teapot's
                 handle and spout on its body), left out of g1_max_deg
  g1_excluded    (--input MESH.obj, the job's input) points left out of
                 g1_max_deg: where the input holds two vertices at one
                 position, and the corners of its zero-area triangles
  back_facing_transition  (--g1) back-facing triangles in transition
                 patches (a group that is not a regular (N+1)^2 grid)
"""
import json
import math
import sys


def read(path):
    v, n, faces, group, groups = [], [], [], -1, []
    with open(path) as f:
        for line in f:
            if not line or line[0] not in "vfg":
                continue
            t = line.split()
            if t[0] == "v":
                v.append((float(t[1]), float(t[2]), float(t[3])))
            elif t[0] == "vn":
                n.append((float(t[1]), float(t[2]), float(t[3])))
            elif t[0] == "g":
                group += 1
            elif t[0] == "f":
                ids = [x.split("/") for x in t[1:]]
                vi = [int(x[0]) - 1 for x in ids]
                ni = [int(x[-1]) - 1 if len(x) > 1 and x[-1] else vi[k] for k, x in enumerate(ids)]
                for k in range(1, len(vi) - 1):
                    faces.append(((vi[0], vi[k], vi[k + 1]), (ni[0], ni[k], ni[k + 1])))
                    groups.append(group)
    return v, n, faces, groups


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]


def angle(a, b):
    c = dot(a, b) / math.sqrt(dot(a, a) * dot(b, b))
    return math.degrees(math.acos(max(-1.0, min(1.0, c))))


def input_exclusions(path):
    """Points of the input OBJ where patches need not agree: positions two
    or more of its vertices hold (the patches meet there without sharing
    topology; ogre has 9) and the corners of its zero-area triangles (no
    normal to agree on; ogre has 2, each three collinear points)."""
    verts, count, out = [], {}, set()
    with open(path) as f:
        for line in f:
            w = line.split()
            if not w:
                continue
            if w[0] == "v":
                p = tuple(float(x) for x in w[1:4])
                verts.append(p)
                count[p] = count.get(p, 0) + 1
            elif w[0] == "f":
                idx = [int(x.split("/")[0]) for x in w[1:]]
                c = [verts[i - 1 if i > 0 else len(verts) + i] for i in idx]
                for k in range(1, len(c) - 1):
                    a, b = sub(c[k], c[0]), sub(c[k + 1], c[0])
                    e = max(dot(a, a), dot(b, b))
                    g = cross(a, b)
                    if dot(g, g) <= (1e-9 * e) ** 2:
                        out.update(c)
    out.update(p for p, k in count.items() if k > 1)
    return sorted(out)


def g1(v, n, faces, groups, diag, crease, seams=()):
    """Largest normal angle between patches at their shared boundary points
    (points within 1e-7 of the diagonal of one of seams are left out)."""
    own = {}  # (group, a, b) edge count within a patch
    for (t, tn), g in zip(faces, groups):
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            key = (g, min(a, b), max(a, b))
            own[key] = own.get(key, 0) + 1
    bnd = {}  # vertex -> (group, normal index)
    for (t, tn), g in zip(faces, groups):
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            if own[(g, min(a, b), max(a, b))] == 1:
                bnd[a] = (g, tn[k])
                bnd[b] = (g, tn[(k + 1) % 3])
    h = 1e-7 * diag
    cells = {}
    for vi, (g, ni) in bnd.items():
        p = v[vi]
        cells.setdefault((math.floor(p[0] / h), math.floor(p[1] / h), math.floor(p[2] / h)), []).append(vi)
    skip = set()
    for p in seams:
        c = tuple(math.floor(p[i] / h) for i in range(3))
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    skip.add((c[0] + dx, c[1] + dy, c[2] + dz))
    worst, count, creases = 0.0, 0, 0
    for (cx, cy, cz), here in cells.items():
        if (cx, cy, cz) in skip:
            continue
        near = []
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    near += cells.get((cx + dx, cy + dy, cz + dz), [])
        for a in here:
            for b in near:
                if b <= a or bnd[a][0] == bnd[b][0]:
                    continue
                if dot(sub(v[a], v[b]), sub(v[a], v[b])) > h * h:
                    continue
                d = angle(n[bnd[a][1]], n[bnd[b][1]])
                if d > crease:
                    creases += 1
                    continue
                count += 1
                worst = max(worst, d)
    return worst, count, creases


def transition_back(v, n, faces, groups, diag):
    """Back-facing triangles of the patches that are not a regular grid."""
    verts, tris = {}, {}
    for (t, tn), g in zip(faces, groups):
        verts.setdefault(g, set()).update(t)
        tris[g] = tris.get(g, 0) + 1
    bad = 0
    for (t, tn), g in zip(faces, groups):
        r = int(round(math.sqrt(len(verts[g])))) - 1
        if (r + 1) ** 2 == len(verts[g]) and tris[g] == 2 * r * r:
            continue
        gn = cross(sub(v[t[1]], v[t[0]]), sub(v[t[2]], v[t[0]]))
        m = [n[tn[0]][i] + n[tn[1]][i] + n[tn[2]][i] for i in range(3)]
        if dot(gn, gn) > (1e-12 * diag * diag) ** 2 and dot(gn, m) < 0:
            bad += 1
    return bad


def main():
    path = sys.argv[1]
    v, n, faces, groups = read(path)
    lo = [min(p[i] for p in v) for i in range(3)]
    hi = [max(p[i] for p in v) for i in range(3)]
    diag = math.sqrt(sum((b - a) ** 2 for a, b in zip(lo, hi)))
    use, seen, dup, back = {}, set(), 0, 0
    for t, tn in faces:
        for k in range(3):
            a, b = t[k], t[(k + 1) % 3]
            e = (a, b) if a < b else (b, a)
            use[e] = use.get(e, 0) + 1
        s = tuple(sorted(t))
        if s in seen:
            dup += 1
        seen.add(s)
        g = cross(sub(v[t[1]], v[t[0]]), sub(v[t[2]], v[t[0]]))
        m = [n[tn[0]][i] + n[tn[1]][i] + n[tn[2]][i] for i in range(3)]
        if dot(g, g) > (1e-12 * diag * diag) ** 2 and dot(g, m) < 0:
            back += 1
    out = {
        "triangles": len(faces),
        "edges_over_2": sum(1 for c in use.values() if c > 2),
        "edges_once": sum(1 for c in use.values() if c == 1),
        "dup_tris": dup,
        "back_facing": back,
    }
    if "--g1" in sys.argv[2:]:
        args = sys.argv[2:]
        crease = float(args[args.index("--crease") + 1]) if "--crease" in args else 180.0
        seams = input_exclusions(args[args.index("--input") + 1]) if "--input" in args else []
        out["g1_excluded"] = len(seams)
        out["g1_max_deg"], out["g1_points"], out["g1_creases"] = g1(v, n, faces, groups, diag, crease, seams)
        out["back_facing_transition"] = transition_back(v, n, faces, groups, diag)
    print(json.dumps(out))


if __name__ == "__main__":
    main()
