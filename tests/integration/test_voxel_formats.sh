#!/usr/bin/env bash
# voxelize's outputs in the field's tools, through the API: every vdb_grid
# class read by OpenVDB's own vdb_print, the scalar ones rendered by
# vdb_render and turned into a mesh by vdb_tool (-iso2ls, -ls2mesh) whose
# bounds are the sphere's, the level set's band checked voxel by voxel
# (vdbcheck, with OpenVDB's checkLevelSet); vox, nrrd and npy read back by independent
# readers (a MagicaVoxel chunk reader written here, an NRRD header parser,
# NumPy) and compared voxel for voxel with the raw8 output of the same job.
# Skips (77) only when the OpenVDB tools or NumPy are missing
# (scripts/install-deps.sh installs libopenvdb-tools and python3-numpy).
source "$(dirname "$0")/lib.sh"
for t in vdb_print vdb_render vdb_tool; do
    command -v $t >/dev/null || { echo "SKIP: $t missing (libopenvdb-tools)"; exit 77; }
done
# NumPy: Debian's python3-numpy lives with /usr/bin/python3 (a pyenv
# python3 first on PATH may lack it).
PY=
for p in python3 /usr/bin/python3; do
    if "$p" -c 'import numpy' 2>/dev/null; then PY=$p; break; fi
done
[[ -n "$PY" ]] || { echo "SKIP: python3-numpy missing"; exit 77; }
start_daemon || exit 1

python3 "$(dirname "$0")/shapes.py" "$TMP" || exit 1
upload "$TMP/sphere.obj"
expect_status "upload sphere" 201
M=$MESH_ID

vox() {
    run_job voxelize "$M" "$2"
    VJ=$JOB
    job_ok "$1"
}
fetch() {
    api GET "/v1/jobs/$VJ/result"
    check "result of $VJ: 200" test "$STATUS" = 200
    cp "$BODY" "$1"
}

# --- vdb: each grid class in OpenVDB's tools ---
vox "default vdb" '{"resolution":32}'
check "default vdb_grid is fog" jq -e '.params.vdb_grid == "fog" and .params.format == "vdb"' "$TMP/job.json"
fetch "$TMP/fog.vdb"
for c in level_set bool; do
    vox "vdb $c" "{\"resolution\":32,\"vdb_grid\":\"$c\"}"
    fetch "$TMP/$c.vdb"
done
N_IN=$(st voxels_inside)
H=$(st voxel_size)
# the level set's band, voxel by voxel, against the same job's raw8 voxels
vox "raw8 sphere" '{"resolution":32,"format":"raw8"}'
fetch "$TMP/sphere.raw8"
read -r NX NY NZ < <(jq -r '.stats.dims | map(tostring) | join(" ")' "$TMP/job.json")
check "level_set: the exact band of the raw8 voxels (vdbcheck)" \
    "$VX_TOOLS/vdbcheck" "$TMP/level_set.vdb" "$TMP/sphere.raw8" "$NX" "$NY" "$NZ"
# A voxel size whose 3 voxels round down as a float (0.03 ->
# 0.0299999993): the background is rounded up, or checkLevelSet says it is
# under 3 voxels (vdbcheck wants the float nearest 3 h from above).
G='{"origin":[0.9,-0.1,-0.1],"voxel_size":0.01,"dims":[20,20,20]}'
vox "level_set at h 0.01" "{\"grid\":$G,\"vdb_grid\":\"level_set\"}"
fetch "$TMP/ls01.vdb"
vox "raw8 at h 0.01" "{\"grid\":$G,\"format\":\"raw8\"}"
fetch "$TMP/ls01.raw8"
check "level_set at h 0.01: the exact band, a background of 3 voxels (vdbcheck)" \
    "$VX_TOOLS/vdbcheck" "$TMP/ls01.vdb" "$TMP/ls01.raw8" 20 20 20
"$VX_TOOLS/vdbinfo" "$TMP/level_set.vdb" >"$TMP/ls.json"
check "level_set: FloatGrid surface" jq -e '.grids | length == 1 and .[0].name == "surface" and .[0].type == "float"' "$TMP/ls.json"
"$VX_TOOLS/vdbinfo" "$TMP/fog.vdb" >"$TMP/fog.json"
check "fog: FloatGrid density, active = value sum = voxels_inside" jq -e --argjson n "$N_IN" \
    '.grids[0] | .name == "density" and .type == "float" and .active_voxels == $n and .value_sum == $n' "$TMP/fog.json"
for c in level_set fog bool; do
    vdb_print -l "$TMP/$c.vdb" >"$TMP/$c.print" 2>&1
    check "vdb_print reads $c" test $? = 0
done
check "vdb_print: level set class" grep -qi "level.set" "$TMP/level_set.print"
check "vdb_print: fog volume class" grep -qi "fog" "$TMP/fog.print"
check "vdb_print: bool grid" grep -qi "bool" "$TMP/bool.print"
for c in level_set fog; do
    # (relative names: vdb_render takes the image type from the first dot of
    # the path, and $TMP has one)
    (cd "$TMP" && vdb_render "$c.vdb" "$c.ppm" -res 48x48 -translate 0,0,4 -lookat 0,0,0 -cpus 1) \
        >"$TMP/$c.render" 2>&1
    rc=$?
    check "vdb_render renders $c ($(tail -c 200 "$TMP/$c.render"))" test $rc = 0
    # the sphere fills the middle of the image: its centre pixel differs from a corner
    check "vdb_render $c: the sphere is in the image" python3 - "$TMP/$c.ppm" <<'PY'
import sys
d = open(sys.argv[1], "rb").read()
parts = d.split(maxsplit=4)
assert parts[0] == b"P6", parts[0]
w, h = int(parts[1]), int(parts[2])
px = parts[4][-w * h * 3:]
at = lambda x, y: px[3 * (y * w + x):3 * (y * w + x) + 3]
sys.exit(at(w // 2, h // 2) == at(0, 0))
PY
done
(cd "$TMP" && vdb_render bool.vdb bool.ppm -res 16x16) >/dev/null 2>&1
check "vdb_render refuses bool (topology only, documented)" test $? != 0
# vdb_tool: the scalar grid -> a level set -> a mesh with the sphere's bounds
for c in level_set:0 fog:0.5; do
    g=${c%%:*} iso=${c#*:}
    vdb_tool -read "$TMP/$g.vdb" -iso2ls iso=$iso -ls2mesh -write "$TMP/$g.obj" >"$TMP/$g.tool" 2>&1
    check "vdb_tool -iso2ls -ls2mesh on $g ($(tail -c 200 "$TMP/$g.tool"))" test -s "$TMP/$g.obj"
    # the unit sphere's voxel hull: within about one voxel of [-1, 1]^3
    check "vdb_tool mesh of $g spans the sphere" python3 - "$TMP/$g.obj" "$H" <<'PY'
import sys
h = float(sys.argv[2])
v = [list(map(float, l.split()[1:4])) for l in open(sys.argv[1]) if l.startswith("v ")]
assert len(v) > 100, len(v)
ok = all(abs(min(p[a] for p in v) + 1) < 1.5 * h and abs(max(p[a] for p in v) - 1) < 1.5 * h for a in range(3))
sys.exit(not ok)
PY
done

# --- vox, nrrd, npy against raw8 on a grid of 2 x 2 x 2 vox bricks (the
# upper ones partial): the unit sphere reaches the first and the three next
# to it along x, y and z (the other four are empty: no model) ---
G='"grid":{"origin":[-1.1,-1.05,-1.1],"voxel_size":0.0075,"dims":[300,280,270]}'
vox "raw8 slab" "{$G,\"format\":\"raw8\"}"
fetch "$TMP/slab.raw8"
SLAB_IN=$(st voxels_inside)
check "the slab has voxels" test "$SLAB_IN" -gt 100000
for f in vox nrrd npy; do
    vox "$f slab" "{$G,\"format\":\"$f\"}"
    fetch "$TMP/slab.$f"
    check "$f disposition" bash -c "grep -qi 'filename=\"$VJ-voxels.$f\"' '$HDRS'"
    check "$f: voxels_inside as raw8" test "$(st voxels_inside)" = "$SLAB_IN"
done
check "vox: models <= 256, placed by the scene graph, = raw8" "$PY" - "$TMP/slab.vox" "$TMP/slab.raw8" 300 280 270 <<'PY'
import struct, sys
import numpy as np
d = open(sys.argv[1], "rb").read()
nx, ny, nz = map(int, sys.argv[3:6])
assert d[:4] == b"VOX " and struct.unpack_from("<i", d, 4)[0] == 150
assert d[8:12] == b"MAIN"
content, children = struct.unpack_from("<ii", d, 12)
assert 20 + content + children == len(d), (content, children, len(d))
p = 20 + content
sizes, models, nodes = [], [], {}
def dict_at(q):
    n = struct.unpack_from("<i", d, q)[0]; q += 4; out = {}
    for _ in range(n):
        kl = struct.unpack_from("<i", d, q)[0]; k = d[q + 4:q + 4 + kl].decode(); q += 4 + kl
        vl = struct.unpack_from("<i", d, q)[0]; v = d[q + 4:q + 4 + vl].decode(); q += 4 + vl
        out[k] = v
    return out, q
while p < len(d):
    cid = d[p:p + 4]; n, m = struct.unpack_from("<ii", d, p + 4); c = p + 12
    if cid == b"SIZE":
        sizes.append(struct.unpack_from("<iii", d, c))
    elif cid == b"XYZI":
        cnt = struct.unpack_from("<i", d, c)[0]
        models.append(np.frombuffer(d, np.uint8, 4 * cnt, c + 4).reshape(-1, 4))
    elif cid == b"nTRN":
        nid = struct.unpack_from("<i", d, c)[0]; _, q = dict_at(c + 4)
        child, res, layer, nf = struct.unpack_from("<iiii", d, q)
        fr, _ = dict_at(q + 16)
        nodes[nid] = ("T", child, fr.get("_t", "0 0 0"))
    elif cid == b"nGRP":
        nid = struct.unpack_from("<i", d, c)[0]; _, q = dict_at(c + 4)
        k = struct.unpack_from("<i", d, q)[0]
        nodes[nid] = ("G", struct.unpack_from("<%di" % k, d, q + 4))
    elif cid == b"nSHP":
        nid = struct.unpack_from("<i", d, c)[0]; _, q = dict_at(c + 4)
        nodes[nid] = ("S", struct.unpack_from("<i", d, q + 4)[0])
    p = c + n + m
assert len(sizes) == len(models) == 4, len(sizes)
assert all(max(s) <= 256 for s in sizes), sizes
grid = np.zeros((nz, ny, nx), np.uint8)
def walk(nid, t):
    n = nodes[nid]
    if n[0] == "T":
        walk(n[1], [a + int(b) for a, b in zip(t, n[2].split())])
    elif n[0] == "G":
        for c in n[1]: walk(c, t)
    else:
        s, v = sizes[n[1]], models[n[1]].astype(np.int64)
        assert (v[:, 3] > 0).all()
        i, j, k = (v[:, a] + t[a] - s[a] // 2 for a in range(3))
        assert (grid[k, j, i] == 0).all()  # no voxel twice
        grid[k, j, i] = 1
walk(0, [0, 0, 0])
raw = np.fromfile(sys.argv[2], np.uint8).reshape(nz, ny, nx)
sys.exit(not np.array_equal(grid, raw))
PY
check "nrrd: header (sizes, spacing, origin at the first centre) + raw8 body" python3 - "$TMP/slab.nrrd" "$TMP/slab.raw8" <<'PY'
import re, sys
d = open(sys.argv[1], "rb").read()
head, body = d.split(b"\n\n", 1)
lines = head.decode().split("\n")
assert lines[0].startswith("NRRD000"), lines[0]
f = dict(l.split(": ", 1) for l in lines[1:] if not l.startswith("#"))
assert f["type"] in ("uint8", "uchar", "unsigned char") and f["dimension"] == "3" and f["encoding"] == "raw"
assert list(map(int, f["sizes"].split())) == [300, 280, 270]
dirs = [list(map(float, v.split(","))) for v in re.findall(r"\(([^)]*)\)", f["space directions"])]
h = 0.0075
assert all(abs(dirs[a][b] - (h if a == b else 0)) < 1e-12 for a in range(3) for b in range(3)), dirs
org = list(map(float, re.findall(r"\(([^)]*)\)", f["space origin"])[0].split(",")))
want = [-1.1 + h / 2, -1.05 + h / 2, -1.1 + h / 2]
assert all(abs(o - w) < 1e-12 for o, w in zip(org, want)), org
sys.exit(body != open(sys.argv[2], "rb").read())
PY
check "npy: NumPy reads shape (nx, ny, nz), a[i,j,k] = raw8" "$PY" - "$TMP/slab.npy" "$TMP/slab.raw8" <<'PY'
import sys
import numpy as np
a = np.load(sys.argv[1])
assert a.shape == (300, 280, 270) and a.dtype == np.uint8, (a.shape, a.dtype)
raw = np.fromfile(sys.argv[2], np.uint8)
sys.exit(bool(not np.array_equal(a.flatten(order="F"), raw) or a[150, 140, 20] != raw[150 + 300 * (140 + 280 * 20)]))
PY

finish
