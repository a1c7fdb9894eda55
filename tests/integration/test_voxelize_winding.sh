#!/usr/bin/env bash
# inside "winding" through the API: two overlapping balls, one of them open
# (the union less the segment beyond the hole, where `robust` drops the
# overlap), nested shells (the void kept), the default rule (winding on a
# mesh with boundary edges, nonzero on a closed one) with the stats that
# say so, the open bunny's default at 256^3 with padding 4 (nothing outside
# its bounding box), and the requests refused at submission.
source "$(dirname "$0")/lib.sh"
start_daemon || exit 1

# Shapes (shapes.py's builders) and the grid params: the hole's rim plane on
# a cell boundary, so that the flat cap is not rounded by half a voxel.
python3 - "$TMP" "$(dirname "$0")" <<'PY' || exit 1
import json, math, os, sys
sys.path.insert(0, sys.argv[2])
from shapes import sphere, merge, volume, write
out = sys.argv[1]
r1, r2, d = 1.0, 0.8, 1.1
a = sphere((0.013, 0.007, 0.003), r1, nu=128, nv=64)
b = sphere((0.013 + d, 0.007, 0.003), r2, nu=128, nv=64, skip_cap=0.6)
used = {k for t in b[1] for k in t}
rim = max(b[0][k][2] for k in used)
write(os.path.join(out, "overlap.obj"), *merge(a, b))
ball = lambda r: 4 / 3 * math.pi * r ** 3
lens = math.pi * (r1 + r2 - d) ** 2 * (d * d + 2 * d * (r1 + r2) - 3 * (r1 - r2) ** 2) / (12 * d)
t = 0.003 + r2 - rim
seg = math.pi * t * t * (3 * r2 - t) / 3
k = volume(*sphere((0, 0, 0), 1, nu=128, nv=64)) / ball(1)  # the tessellation's shrinkage
h = 0.015
lo = [0.013 - r1 - 2 * h, 0.007 - r1 - 2 * h, rim - math.ceil((rim - (0.003 - r1 - 2 * h)) / h) * h]
dims = [math.ceil((0.013 + d + r2 + 2 * h - lo[0]) / h), math.ceil((2 * r1 + 4 * h) / h),
        math.ceil((0.003 + r1 + 2 * h - lo[2]) / h)]
s = sphere((0, 0, 0), 1, nu=96, nv=48)
write(os.path.join(out, "nested.obj"), *merge(s, sphere((0, 0, 0), 0.5, nu=96, nv=48, inward=True)))
json.dump({"want": k * (ball(r1) + ball(r2) - lens - seg),
           "grid": {"origin": lo, "voxel_size": h, "dims": dims},
           "nested": volume(*merge(s, sphere((0, 0, 0), 0.5, nu=96, nv=48, inward=True)))},
          open(os.path.join(out, "winding.json"), "w"))
PY
W() { jq -c ".$1" "$TMP/winding.json"; }
near() {
    check "$1: $2 within $4 of $3" awk -v a="$2" -v b="$3" -v t="$4" \
        'BEGIN { d = a - b; if (d < 0) d = -d; exit !(d <= t * b) }'
}
vox() {
    run_job voxelize "$2" "$3"
    VJ=$JOB
    job_ok "$1"
}

upload "$TMP/overlap.obj"
expect_status "upload overlap" 201
M_over=$MESH_ID
upload "$TMP/nested.obj"
M_nest=$MESH_ID

vox "overlap winding" "$M_over" "{\"grid\":$(W grid),\"inside\":\"winding\",\"format\":\"summary\"}"
near "overlap winding = the union less the open ball's segment" "$(st volume)" "$(W want)" 0.005
check "overlap winding: stats inside, method, boundary_edges" \
    jq -e '.stats.inside == "winding" and .stats.method == "winding" and .stats.boundary_edges == 128' "$TMP/job.json"
WIND=$(st voxels_inside)
vox "overlap default" "$M_over" "{\"grid\":$(W grid),\"format\":\"summary\"}"
check "overlap default: params.inside null, winding as run, the same voxels" \
    jq -e --argjson n "$WIND" '.params.inside == null and .stats.inside == "winding" and .stats.voxels_inside == $n' "$TMP/job.json"
vox "overlap robust" "$M_over" "{\"grid\":$(W grid),\"inside\":\"robust\",\"format\":\"summary\"}"
echo "note: overlap robust $(st volume) vs winding union $(W want)"
check "overlap robust drops part of the overlap (> 3% short; winding is the fix)" \
    awk -v a="$(st volume)" -v b="$(W want)" 'BEGIN { exit !(a < 0.97 * b) }'

# A cube written face by face (24 vertices, every edge a seam) is closed
# once welded: the default stays nonzero. Without one face it is open there
# and the default runs winding.
python3 - "$TMP" <<'PY'
import sys
quad = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]
c = [(-1, -1, -1), (1, -1, -1), (1, 1, -1), (-1, 1, -1), (-1, -1, 1), (1, -1, 1), (1, 1, 1), (-1, 1, 1)]
for name, faces in (("split", 6), ("split_open", 5)):
    with open(f"{sys.argv[1]}/{name}.obj", "w") as f:
        for q in quad[:faces]:
            for v in q:
                f.write("v %d %d %d\n" % c[v])
        for i in range(faces):
            f.write("f %d %d %d %d\n" % (4 * i + 1, 4 * i + 2, 4 * i + 3, 4 * i + 4))
PY
upload "$TMP/split.obj"
check "split cube: 24 seams, closed welded" jq -e '.boundary_edges == 24 and .boundary_edges_welded == 0' "$BODY"
M_split=$MESH_ID
vox "split cube default" "$M_split" '{"resolution":16,"format":"summary"}'
check "split cube default: nonzero, both counts in the stats" \
    jq -e '.stats.inside == "nonzero" and .stats.boundary_edges == 24 and .stats.boundary_edges_welded == 0' "$TMP/job.json"
upload "$TMP/split_open.obj"
check "split cube without one face: open welded" jq -e '.boundary_edges == 20 and .boundary_edges_welded == 4' "$BODY"
vox "split open box default" "$MESH_ID" '{"resolution":16,"format":"summary"}'
check "split open box default: winding" jq -e '.stats.inside == "winding" and .stats.boundary_edges_welded == 4' "$TMP/job.json"

vox "nested default" "$M_nest" '{"resolution":96,"format":"summary"}'
check "nested default: closed, nonzero" jq -e '.stats.inside == "nonzero" and .stats.boundary_edges == 0 and .stats.misoriented_edges == 0' "$TMP/job.json"
NZ=$(st voxels_inside)
# A closed ball with every 7th face turned round: nonzero made streaks
# from the surface to the grid's edge (the crossing count is no winding
# number); the default is parity, which needs no orientation, and gives
# the voxels of the ball turned the right way.
python3 - "$TMP" "$(dirname "$0")" <<'PY' || exit 1
import os, sys
sys.path.insert(0, sys.argv[2])
from shapes import icosphere, write
vs, ts = icosphere(4, 1.0, (0.011, 0.007, 0.003))
write(os.path.join(sys.argv[1], "ball.obj"), vs, ts)
write(os.path.join(sys.argv[1], "flipped.obj"), vs,
      [(t[0], t[2], t[1]) if i % 7 == 0 else t for i, t in enumerate(ts)])
PY
upload "$TMP/ball.obj"
check "the ball: no misoriented edges" jq -e '.misoriented_edges == 0 and .boundary_edges == 0' "$BODY"
M_ball=$MESH_ID
upload "$TMP/flipped.obj"
check "the ball with faces turned round: misoriented edges counted ($(jqb .misoriented_edges))" jq -e '.misoriented_edges > 0 and .boundary_edges == 0' "$BODY"
M_flip=$MESH_ID
G='"grid":{"origin":[-1.1,-1.1,-1.1],"voxel_size":0.0392857,"dims":[56,56,56]}'
vox "the ball" "$M_ball" "{$G,\"format\":\"summary\"}"
BALL=$(st voxels_inside)
vox "the ball turned round, by default" "$M_flip" "{$G,\"format\":\"summary\"}"
check "by default parity, the ball's voxels ($(st voxels_inside) vs $BALL)" \
    jq -e --argjson n "$BALL" '.stats.inside == "parity" and .stats.voxels_inside == $n and .stats.misoriented_edges > 0' "$TMP/job.json"
vox "the ball turned round, nonzero" "$M_flip" "{$G,\"inside\":\"nonzero\",\"format\":\"summary\"}"
check "nonzero on it sets voxels the ball lacks ($(st voxels_inside) vs $BALL; why parity is its default)" test "$(st voxels_inside)" -gt "$BALL"
vox "nested winding" "$M_nest" '{"resolution":96,"inside":"winding","format":"summary"}'
check "nested winding: the void kept, the same voxels as nonzero ($(st voxels_inside) vs $NZ)" test "$(st voxels_inside)" = "$NZ"
near "nested winding: shell volume" "$(st volume)" "$(W nested)" 0.01
vox "nested winding faces" "$M_nest" '{"resolution":48,"inside":"winding","supersample":2,"samples":"faces","threshold":1,"format":"summary"}'
check "winding with samples faces" jq -e '.stats.inside == "winding" and .stats.method == "winding"' "$TMP/job.json"

# The open bunny: the default at 256^3 with padding 4 runs winding and sets
# nothing outside the bounding box (+ a voxel); nonzero sets some there.
upload "$VX_MESH_DIR/stanford-bunny.obj"
M_bunny=$MESH_ID
# numpy: the Debian python3's (a python3 earlier on PATH may lack it)
PYNP=$(for p in python3 /usr/bin/python3; do "$p" -c 'import numpy' 2>/dev/null && echo "$p" && break; done)
outside() {
    "${PYNP:-python3}" - "$1" "$TMP/job.json" "$VX_MESH_DIR/stanford-bunny.obj" <<'PY'
import json, sys
import numpy as np
j = json.load(open(sys.argv[2]))["stats"]
vs = np.array([[float(x) for x in l.split()[1:4]] for l in open(sys.argv[3]) if l.startswith("v ")])
lo, hi = vs.min(0), vs.max(0)
nx, ny, nz = j["dims"]
bits = np.unpackbits(np.fromfile(sys.argv[1], np.uint8), bitorder="little")[:nx * ny * nz]
v = bits.reshape(nz, ny, nx)
h, o = j["voxel_size"], j["origin"]
bad = 0
for a, n in enumerate((nx, ny, nz)):
    c = o[a] + (np.arange(n) + 0.5) * h
    out = (c < lo[a] - h) | (c > hi[a] + h)
    axis = 2 - a  # v is [z][y][x]
    bad += int(np.take(v, np.nonzero(out)[0], axis=axis).sum())
print(bad)
PY
}
vox "bunny default 256 padding 4" "$M_bunny" '{"resolution":256,"padding":4,"format":"raw1"}'
check "bunny default: winding, 223 boundary edges" jq -e '.stats.inside == "winding" and .stats.boundary_edges == 223 and .params.inside == null' "$TMP/job.json"
api GET "/v1/jobs/$VJ/result"
cp "$BODY" "$TMP/bunny.raw1"
OUT=$(outside "$TMP/bunny.raw1")
check "bunny default: no voxel outside the bbox + a voxel (got $OUT)" test "$OUT" = 0
echo "note: bunny winding $(st voxels_inside) voxels, run $(jq .timings.run_ms "$TMP/job.json") ms"
vox "bunny nonzero 256 padding 4" "$M_bunny" '{"resolution":256,"padding":4,"inside":"nonzero","format":"raw1"}'
api GET "/v1/jobs/$VJ/result"
cp "$BODY" "$TMP/bunny-nz.raw1"
OUT=$(outside "$TMP/bunny-nz.raw1")
check "bunny nonzero sets voxels outside the bbox (got $OUT; why winding is the default)" test "$OUT" -gt 0
echo "note: bunny nonzero run $(jq .timings.run_ms "$TMP/job.json") ms"

# Refused at submission.
for p in '{"inside":"winding","method":"peel"}' '{"inside":"winding","method":"slice"}' \
    '{"inside":"winding","supersample":2}' '{"inside":"winding","supersample":2,"samples":"cube"}' \
    '{"inside":"winding","fill":"surface"}'; do
    api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$M_nest\",\"kind\":\"voxelize\",\"params\":$p}"
    expect_error "refused: $p" 422 invalid_params
done

stop_daemon
finish
