#!/usr/bin/env bash
# The `gregory` kind through the API: spot's control mesh (quads, pentagons,
# triangles; closed), suzanne (quads, triangles, boundaries, several parts)
# and an n-gon prism made here; every format read back; predicted vertex and
# triangle counts; welded closed input -> no boundary edges (the output is
# uploaded back and the daemon's own mesh analysis counts them); frames as
# position arrays and as mesh ids, compared with fresh jobs; max_edge; errors.
source "$(dirname "$0")/lib.sh"
# 100000 triangles: 2 * 256^2 per patch is then over the limit at submission.
start_daemon --max-triangles 100000 || exit 1

# A closed pentagonal prism, one side split into two triangles.
prism() { # FILE TWIST LIFT
    python3 - "$@" <<'EOF'
import math, sys
path, tw, lift = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
with open(path, "w") as f:
    for k in range(5):
        for top in (0, 1):
            a = 2 * math.pi * k / 5 + (tw if top else 0)
            r = 0.8 if top else 1.0 + 0.1 * k
            z = (1.2 + lift + 0.1 * math.sin(3 * a)) if top else 0.05 * k
            f.write("v %.17g %.17g %.17g\n" % (r * math.cos(a), r * math.sin(a), z))
    # vertex 2k+1 = bottom k, 2k+2 = top k (one-based)
    b = lambda k: 2 * (k % 5) + 1
    t = lambda k: 2 * (k % 5) + 2
    f.write("f %s\n" % " ".join(str(b(k)) for k in (4, 3, 2, 1, 0)))
    f.write("f %s\n" % " ".join(str(t(k)) for k in range(5)))
    f.write("f %d %d %d\nf %d %d %d\n" % (b(0), b(1), t(1), b(0), t(1), t(0)))
    for k in range(1, 5):
        f.write("f %d %d %d %d\n" % (b(k), b(k + 1), t(k + 1), t(k)))
EOF
}
prism "$TMP/prism.obj" 0.3 0
prism "$TMP/prism2.obj" 0.5 0.4

upload "$VX_MESH_DIR/spot_control_mesh.obj"
expect_status "upload spot" 201
M_spot=$MESH_ID
upload "$VX_MESH_DIR/suzanne.obj"
M_suz=$MESH_ID
upload "$TMP/prism.obj"
expect_status "upload prism" 201
M_prism=$MESH_ID
upload "$TMP/prism2.obj"
M_prism2=$MESH_ID

api GET /v1/info
check "info lists gregory" jq -e '[.kinds[].name] | index("gregory") != null' "$BODY"

# greg WHAT MESH PARAMS: a gregory job, waited for; body in $TMP/job.json.
greg() {
    run_job gregory "$2" "$3"
    GJ=$JOB
}
# fetch NAME FILE: output NAME of job GJ.
fetch() {
    api GET "/v1/jobs/$GJ/result/$1"
    check "result $1 of $GJ: 200" test "$STATUS" = 200
    cp "$BODY" "$2"
}
# meta ID: the mesh's metadata into $TMP/meta.json.
meta() { api GET "/v1/meshes/$1"; cp "$BODY" "$TMP/meta.json"; }
mv_() { jq -r ".$1" "$TMP/meta.json"; }

# --- counts, welded, closed input with n-gons: spot ---
meta "$M_spot"
V=$(mv_ vertices); F=$(mv_ faces.total); T=$(mv_ triangles)
C=$((T + 2 * F)) # face corners (fan triangulation: n - 2 triangles per n-gon)
for N in 1 3 8; do
    greg "spot N=$N" "$M_spot" "{\"divisions\":$N}"
    job_ok "spot N=$N"
    check "spot N=$N: $C patches" test "$(st patches)" = "$C"
    want_v=$((V + C / 2 + F + 2 * C * (N - 1) + C * (N - 1) * (N - 1)))
    check "spot N=$N: $want_v vertices (got $(st vertices))" test "$(st vertices)" = "$want_v"
    check "spot N=$N: $((2 * C * N * N)) triangles" test "$(st triangles)" = "$((2 * C * N * N))"
    check "spot N=$N: primary output is mesh" jq -e '.outputs | keys == ["mesh"]' "$TMP/job.json"
done
fetch mesh "$TMP/spot.obj"
check "spot obj: one vn per v" test "$(grep -c '^vn ' "$TMP/spot.obj")" = "$(grep -c '^v ' "$TMP/spot.obj")"
check "spot obj: no groups when welded" test "$(grep -c '^g ' "$TMP/spot.obj")" = 0
upload "$TMP/spot.obj"
expect_status "upload the spot result" 201
meta "$MESH_ID"
check "welded spot: no boundary edges" test "$(mv_ boundary_edges)" = 0
check "welded spot: no non-manifold edges" test "$(mv_ nonmanifold_edges)" = 0
check "welded spot: vertices as reported" test "$(mv_ vertices)" = "$(jq -r .stats.vertices "$TMP/job.json")"

# --- unwelded PLY: every patch its own vertices and a patch id per face ---
greg "spot unwelded ply" "$M_spot" '{"divisions":4,"weld":false,"format":"ply"}'
job_ok "spot unwelded ply"
check "unwelded: C * 25 vertices" test "$(st vertices)" = "$((C * 25))"
fetch mesh "$TMP/spot.ply"
check "ply: binary little endian" grep -aq '^format binary_little_endian 1.0' "$TMP/spot.ply"
check "ply: vertex count" grep -aq "^element vertex $((C * 25))\$" "$TMP/spot.ply"
check "ply: face count" grep -aq "^element face $((32 * C))\$" "$TMP/spot.ply"
check "ply: normals" grep -aq '^property float nx' "$TMP/spot.ply"
check "ply: patch id per face" grep -aq '^property int patch' "$TMP/spot.ply"

# --- suzanne: triangles, quads, boundaries; OBJ groups when unwelded; Draco ---
greg "suzanne unwelded obj" "$M_suz" '{"divisions":2,"weld":false}'
job_ok "suzanne unwelded obj"
P=$(st patches)
fetch mesh "$TMP/suz.obj"
check "suzanne: one group per patch ($P)" test "$(grep -c '^g patch' "$TMP/suz.obj")" = "$P"
greg "suzanne drc" "$M_suz" '{"divisions":3,"format":"drc"}'
job_ok "suzanne drc"
fetch mesh "$TMP/suz.drc"
upload "$TMP/suz.drc" model/x-draco
expect_status "upload the Draco result" 201
meta "$MESH_ID"
check "suzanne drc: triangles as reported" test "$(mv_ triangles)" = "$(jq -r .stats.triangles "$TMP/job.json")"
check "suzanne: open input stays open" test "$(mv_ boundary_edges)" -gt 0
check "suzanne drc: edgebreaker coded (method byte 1)" test "$(od -An -tu1 -j8 -N1 "$TMP/suz.drc" | tr -d ' ')" = 1
# One triangle 2000 times: its welded patches put thousands of faces on
# each edge, where Draco's edgebreaker takes time quadratic in them (30,000
# copies: 11 s against 1 s as glb). Coded sequentially: the same counts.
python3 - "$TMP/same.ply" <<'PY'
import struct, sys
n = 2000
h = ("ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
     "property float z\nelement face %d\nproperty list uchar int vertex_indices\nend_header\n" % n)
open(sys.argv[1], "wb").write(h.encode() + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<B3i", 3, 0, 1, 2) * n)
PY
upload "$TMP/same.ply" model/x-ply
greg "one triangle 2000 times, drc" "$MESH_ID" '{"divisions":2,"format":"drc"}'
job_ok "one triangle 2000 times, drc"
fetch mesh "$TMP/same.drc"
check "repeated triangle drc: sequentially coded (method byte 0)" test "$(od -An -tu1 -j8 -N1 "$TMP/same.drc" | tr -d ' ')" = 0
upload "$TMP/same.drc" model/x-draco
expect_status "upload the sequential Draco result" 201
meta "$MESH_ID"
check "repeated triangle drc: triangles as reported" test "$(mv_ triangles)" = "$(jq -r .stats.triangles "$TMP/job.json")"

# --- n-gon prism: closed, welded output closed ---
greg "prism" "$M_prism" '{"divisions":6}'
job_ok "prism"
check "prism: 32 patches" test "$(st patches)" = 32
fetch mesh "$TMP/prism_out.obj"
upload "$TMP/prism_out.obj"
meta "$MESH_ID"
check "welded prism: no boundary edges" test "$(mv_ boundary_edges)" = 0

# --- frames: positions array and mesh id vs fresh jobs ---
FR=$(python3 -c '
import sys
print([[float(x) for x in l.split()[1:4]] for l in open(sys.argv[1]) if l.startswith("v ")])' "$TMP/prism2.obj")
greg "prism frames (positions)" "$M_prism" "{\"divisions\":5,\"frames\":[$FR]}"
job_ok "prism frames (positions)"
check "frames: outputs mesh, frame_001" jq -e '.outputs | keys == ["frame_001", "mesh"]' "$TMP/job.json"
fetch frame_001 "$TMP/f1.obj"
greg "prism frames (ids)" "$M_prism" "{\"divisions\":5,\"frames\":[\"$M_prism2\",\"$M_prism\"]}"
job_ok "prism frames (ids)"
check "frames: outputs mesh, frame_001, frame_002" jq -e '.outputs | keys == ["frame_001", "frame_002", "mesh"]' "$TMP/job.json"
check "frames: 3 frames, 3 frame times" jq -e '.stats.frames == 3 and (.stats.frame_ms | length) == 3' "$TMP/job.json"
# the engine: cpu where the renderer is a CPU rasterizer (voxeld_info's gl_renderer)
RENDERER=$(curl -s "$BASE/metrics" | sed -n 's/^voxeld_info{.*gl_renderer="\([^"]*\)".*/\1/p')
WANT_ENGINE=gpu
[[ $RENDERER =~ llvmpipe|softpipe|swrast ]] && WANT_ENGINE=cpu
check "tess_engine is $WANT_ENGINE on $RENDERER" jq -e --arg e "$WANT_ENGINE" '.stats.tess_engine == $e' "$TMP/job.json"
fetch mesh "$TMP/f0.obj"
fetch frame_001 "$TMP/f2.obj"
fetch frame_002 "$TMP/f3.obj"
greg "prism2 fresh" "$M_prism2" '{"divisions":5}'
job_ok "prism2 fresh"
fetch mesh "$TMP/fresh2.obj"
greg "prism fresh" "$M_prism" '{"divisions":5}'
fetch mesh "$TMP/fresh0.obj"
# maxdiff A B: largest coordinate difference of v and vn lines, relative to
# A's bounding-box diagonal; "inf" when the structure differs.
maxdiff() {
    python3 - "$1" "$2" <<'EOF'
import sys
def read(p):
    v, n, f = [], [], []
    for l in open(p):
        t = l.split()
        if not t: continue
        if t[0] == "v": v.append([float(x) for x in t[1:4]])
        elif t[0] == "vn": n.append([float(x) for x in t[1:4]])
        elif t[0] == "f": f.append(t[1:])
    return v, n, f
a, b = read(sys.argv[1]), read(sys.argv[2])
if len(a[0]) != len(b[0]) or a[2] != b[2]: print("inf"); sys.exit()
lo = [min(p[i] for p in a[0]) for i in range(3)]; hi = [max(p[i] for p in a[0]) for i in range(3)]
d = sum((h - l) ** 2 for h, l in zip(hi, lo)) ** 0.5
dv = max(abs(x - y) for p, q in zip(a[0], b[0]) for x, y in zip(p, q)) / d
dn = max(abs(x - y) for p, q in zip(a[1], b[1]) for x, y in zip(p, q))
print("%.3g %.3g" % (dv, dn))
EOF
}
small() { awk -v s="$1" -v tv="$2" -v tn="$3" 'BEGIN { split(s, x, " "); exit !(x[1] != "inf" && x[1] <= tv && x[2] <= tn) }'; }
D=$(maxdiff "$TMP/fresh2.obj" "$TMP/f2.obj")
check "frame 2 (mesh id) = fresh job on that mesh ($D)" small "$D" 1e-6 1e-5
D=$(maxdiff "$TMP/fresh2.obj" "$TMP/f1.obj")
check "frame 1 (positions) = fresh job on those positions ($D)" small "$D" 1e-6 1e-5
D=$(maxdiff "$TMP/fresh0.obj" "$TMP/f0.obj")
check "frame 0 = fresh job on the mesh ($D)" small "$D" 0 0
D=$(maxdiff "$TMP/fresh0.obj" "$TMP/f3.obj")
check "frame 2 (the mesh itself) = frame 0 ($D)" small "$D" 0 0
D=$(maxdiff "$TMP/fresh0.obj" "$TMP/f1.obj")
check "frames differ from frame 0 ($D)" awk -v s="$D" 'BEGIN { split(s, x, " "); exit !(x[1] > 1e-3) }'
# Frames far from the mesh or much smaller than it: each frame's grid
# holds floats relative to its own centre (relative to the mesh's, a frame
# at +1e7 was off by 0.4 of its size and one at 1e-10 the size by 25 times).
python3 - "$TMP/prism2.obj" "$TMP" <<'EOF'
import sys
src = open(sys.argv[1]).read().splitlines()
for name, f in (("far", lambda c: c + 1e7), ("small", lambda c: c * 1e-10)):
    with open("%s/prism_%s.obj" % (sys.argv[2], name), "w") as o:
        for l in src:
            t = l.split()
            o.write("v %.17g %.17g %.17g\n" % tuple(f(float(x)) for x in t[1:4]) if t and t[0] == "v" else l + "\n")
EOF
upload "$TMP/prism_far.obj"
M_far=$MESH_ID
upload "$TMP/prism_small.obj"
M_small=$MESH_ID
greg "prism frames far and small" "$M_prism" "{\"divisions\":5,\"frames\":[\"$M_far\",\"$M_small\"]}"
job_ok "prism frames far and small"
fetch frame_001 "$TMP/ffar.obj"
fetch frame_002 "$TMP/fsmall.obj"
for m in far small; do
    id=M_$m
    greg "prism $m fresh" "${!id}" '{"divisions":5}'
    job_ok "prism $m fresh"
    fetch mesh "$TMP/fresh_$m.obj"
    D=$(maxdiff "$TMP/fresh_$m.obj" "$TMP/f$m.obj")
    check "a frame $m from the mesh = a fresh job on it ($D)" small "$D" 1e-6 1e-5
done

# --- approximate-cc: one patch per quad of the (once refined) cage, close
# to OpenSubdiv's limit surface, welded closed, frames as fresh jobs ---
greg "spot approximate-cc" "$M_spot" '{"construction":"approximate-cc","divisions":4}'
job_ok "spot approximate-cc"
check "approximate-cc: one patch per quad of the refined cage ($C)" test "$(st patches)" = "$C"
check "approximate-cc: construction and distance reported" jq -e \
    '.stats.construction == "approximate-cc" and .stats.cc_distance > 0 and .stats.cc_distance < 0.006' "$TMP/job.json"
fetch mesh "$TMP/spot_cc.obj"
upload "$TMP/spot_cc.obj"
meta "$MESH_ID"
check "approximate-cc spot: welded, no boundary edges" test "$(mv_ boundary_edges)" = 0
check "approximate-cc spot: no non-manifold edges" test "$(mv_ nonmanifold_edges)" = 0
greg "prism approximate-cc frames" "$M_prism" '{"construction":"approximate-cc","divisions":5,"frames":["'"$M_prism2"'"]}'
job_ok "prism approximate-cc frames"
fetch frame_001 "$TMP/cc_f1.obj"
greg "prism2 approximate-cc fresh" "$M_prism2" '{"construction":"approximate-cc","divisions":5}'
job_ok "prism2 approximate-cc fresh"
fetch mesh "$TMP/cc_fresh2.obj"
D=$(maxdiff "$TMP/cc_fresh2.obj" "$TMP/cc_f1.obj")
check "approximate-cc frame 1 = fresh job on that mesh ($D)" small "$D" 1e-6 1e-5

# --- max_edge: N per patch, transition strips where neighbours differ ---
greg "suzanne max_edge" "$M_suz" '{"max_edge":0.1}'
job_ok "suzanne max_edge"
check "max_edge: params normalised" jq -e '.params.divisions == null and .params.max_edge == 0.1' "$TMP/job.json"
check "max_edge: suzanne gets different N" jq -e '.stats.divisions_max > .stats.divisions_min and .stats.divisions_min >= 1' "$TMP/job.json"
fetch mesh "$TMP/suz_me.obj"
upload "$TMP/suz_me.obj"
meta "$MESH_ID"
check "max_edge: suzanne open only where the input is" test "$(mv_ boundary_edges)" -gt 0
check "max_edge: suzanne, no non-manifold edges" test "$(mv_ nonmanifold_edges)" = 0
# spot is one closed component: different N inside it, and the welded
# result is still closed and manifold (shared edges of patches with
# different N match point for point: no cracks, no T-junctions).
greg "spot max_edge" "$M_spot" '{"max_edge":0.09}'
job_ok "spot max_edge"
check "max_edge: different N inside one component" jq -e '.stats.divisions_max > .stats.divisions_min and .stats.divisions_min >= 2' "$TMP/job.json"
jq -c '.stats | {divisions_min, divisions_max, vertices, triangles}' "$TMP/job.json"
fetch mesh "$TMP/spot_me.obj"
upload "$TMP/spot_me.obj"
meta "$MESH_ID"
check "max_edge: spot welded, 0 boundary edges" test "$(mv_ boundary_edges)" = 0
check "max_edge: spot, no non-manifold edges" test "$(mv_ nonmanifold_edges)" = 0
check "max_edge: spot, vertices and triangles as reported" test "$(mv_ vertices) $(mv_ triangles)" = "$(jq -r '"\(.stats.vertices) \(.stats.triangles)"' "$TMP/job.json")"

# --- errors ---
post() { api POST /v1/jobs -H "Content-Type: application/json" -d "$1"; }
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"divisions\":4,\"max_edge\":1}}"
expect_error "divisions and max_edge" 422 invalid_params
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"construction\":\"loop\"}}"
expect_error "unknown construction" 422 invalid_params
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"divisions\":300}}"
expect_error "divisions 300" 422 invalid_params
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"divisions\":256}}"
expect_error "divisions over the triangle limit" 422 invalid_params
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"format\":\"stl\"}}"
expect_error "format stl" 422 invalid_params
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"frames\":[\"$(printf '%064d' 0)\"]}}"
expect_error "unknown frame mesh" 404 mesh_not_found
post "{\"mesh\":\"$M_spot\",\"kind\":\"gregory\",\"params\":{\"divisions\":16}}"
expect_error "spot's patches over max_triangles: 422 at submission, from its face counts" 422 invalid_params
check "naming params.divisions and the patches" jq -e '.error.message | test("params.divisions = 16 makes at least [0-9]+ triangles on the mesh.s [0-9]+ patches")' "$BODY"
greg "spot over max_triangles with max_edge (the job counts)" "$M_spot" '{"max_edge":1e-6}'
check "triangle limit: job error" jq -e '.state == "failed" and .error.code == "triangle_limit"' "$TMP/job.json"
greg "frame of another topology" "$M_prism" "{\"divisions\":2,\"frames\":[\"$M_spot\"]}"
check "frame topology (mesh id): job error" jq -e '.state == "failed" and .error.code == "frame_topology"' "$TMP/job.json"
# The same tetrahedron as OBJ and as OFF (read into other structures: the
# OFF reader keeps face offsets even for triangles): each is a frame of the
# other (it failed with frame_topology).
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n' >"$TMP/tet.obj"
printf 'OFF\n4 4 0\n0 0 0\n2 0 0\n0 2 0\n0 0 2\n3 0 2 1\n3 0 1 3\n3 0 3 2\n3 1 2 3\n' >"$TMP/tet.off"
upload "$TMP/tet.obj"
M_tet_obj=$MESH_ID
upload "$TMP/tet.off" model/x-off
M_tet_off=$MESH_ID
greg "an OFF frame of an OBJ mesh" "$M_tet_obj" "{\"divisions\":2,\"frames\":[\"$M_tet_off\"]}"
job_ok "an OFF frame of an OBJ mesh"
greg "an OBJ frame of an OFF mesh" "$M_tet_off" "{\"divisions\":2,\"frames\":[\"$M_tet_obj\"]}"
job_ok "an OBJ frame of an OFF mesh"
# Frames as positions must have the mesh's vertex count: told at submission
# from its metadata (422), not by a failed job.
for fr in '[[0,0,0],[1,0,0],[0,1,0]]' '[]' '[0,0,0,1,0,0,0,1,0,0,0,1,1,1,1]'; do
    post "{\"mesh\":\"$M_tet_obj\",\"kind\":\"gregory\",\"params\":{\"frames\":[$fr]}}"
    expect_error "a frame of $fr for 4 vertices" 422 invalid_params
    check "the message gives both counts ($(jqb -r .error.message))" jq -e '.error.message | test("has [0-9]+ vertices, the mesh 4")' "$BODY"
done
post "{\"mesh\":\"$M_tet_obj\",\"kind\":\"gregory\",\"params\":{\"divisions\":2,\"frames\":[[0,0,0,2,0,0,0,2,0,0,0,2]]}}"
expect_status "a flat frame of 4 vertices" 202
# No further frames is the default: [] normalises to null (reuse and
# idempotency keys took [] and no frames for different requests).
post "{\"mesh\":\"$M_tet_obj\",\"kind\":\"gregory\",\"params\":{\"divisions\":2,\"frames\":[]}}"
expect_status "frames []" 202
check "frames [] normalised to null" jq -e '.params.frames == null' "$BODY"
# frame positions are tessellated in floats: a coordinate past what a mesh
# may hold (1e30) is refused at submission (3e38 came out as NaN vertices)
for c in 1e39 3e38 2e30; do
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$M_prism\",\"kind\":\"gregory\",\"params\":{\"frames\":[[$c,0,0]]}}"
    expect_error "frame coordinate $c" 422 invalid_params
    check "frame coordinate $c: message names params.frames[0][0]" \
        jq -e '.error.message | test("frames\\[0\\]\\[0\\]")' "$BODY"
done
# A mesh at the bound gives a finite surface.
printf 'v -1e30 -1e30 -1e30\nv 1e30 -1e30 -1e30\nv 1e30 1e30 -1e30\nv -1e30 1e30 -1e30\nv -1e30 -1e30 1e30\nv 1e30 -1e30 1e30\nv 1e30 1e30 1e30\nv -1e30 1e30 1e30\nf 1 4 3 2\nf 5 6 7 8\nf 1 2 6 5\nf 2 3 7 6\nf 3 4 8 7\nf 4 1 5 8\n' >"$TMP/cube30.obj"
upload "$TMP/cube30.obj"
expect_status "a cube at 1e30" 201
greg "a cube at 1e30" "$MESH_ID" '{"divisions":2}'
job_ok "a cube at 1e30"
api GET "/v1/jobs/$JOB/result"
check "a cube at 1e30: every vertex finite" sh -c "grep '^v ' '$BODY' | grep -qiv 'nan\|inf' && ! grep '^v ' '$BODY' | grep -qi 'nan\|inf'"
post "{\"mesh\":\"$M_prism\",\"kind\":\"gregory\",\"params\":{\"divisions\":2,\"frames\":[[0,0,0,1,1,1]]}}"
expect_error "frame with too few vertices (positions)" 422 invalid_params

# The mesh's scale: the same cube 1e10 and 1e-20 across has the unit cube's
# normals and its positions times the scale (the tangents' products had
# overflowed floats, giving zero normals from ~1e9 across, and underflowed
# them below ~1e-18).
cube_at() { # FILE SCALE
    python3 - "$1" "$2" <<'EOF2'
import sys
s = float(sys.argv[2])
with open(sys.argv[1], "w") as f:
    for z in (-1, 1):
        for y in (-1, 1):
            for x in (-1, 1):
                f.write("v %r %r %r\n" % (x * s, y * s, z * s))
    for q in ((1, 3, 4, 2), (5, 6, 8, 7), (1, 2, 6, 5), (2, 4, 8, 6), (4, 3, 7, 8), (3, 1, 5, 7)):
        f.write("f %d %d %d %d\n" % q)
EOF2
}
for sc in 1 1e10 1e-20; do
    cube_at "$TMP/cube_$sc.obj" "$sc"
    upload "$TMP/cube_$sc.obj"
    greg "cube at scale $sc" "$MESH_ID" '{"divisions":6}'
    job_ok "cube at scale $sc"
    fetch mesh "$TMP/cube_out_$sc.obj"
done
for sc in 1e10 1e-20; do
    check "cube at scale $sc: the unit cube's normals, positions times $sc" python3 - "$TMP/cube_out_1.obj" "$TMP/cube_out_$sc.obj" "$sc" <<'EOF2'
import sys
def load(p):
    v, n = [], []
    for l in open(p):
        t = l.split()
        if t and t[0] in ("v", "vn"):
            (v if t[0] == "v" else n).append([float(x) for x in t[1:4]])
    return v, n
v1, n1 = load(sys.argv[1])
v, n = load(sys.argv[2])
s = float(sys.argv[3])
assert len(v) == len(v1) > 0 and len(n) == len(n1) == len(v)
assert max(abs(a / s - b) for p, q in zip(v, v1) for a, b in zip(p, q)) < 1e-5
assert max(abs(a - b) for p, q in zip(n, n1) for a, b in zip(p, q)) < 1e-4
assert min(sum(a * a for a in p) for p in n) > 0.99
EOF2
done
stop_daemon

# Frames given as mesh ids whose copies cannot fit --max-job-memory: 422 at
# submission (the job had loaded every frame first, then failed).
start_daemon --max-job-memory 1M || exit 1
upload "$VX_MESH_DIR/spot_quadrangulated.obj"
SPOTQ=$MESH_ID
F=$(python3 -c "import json,sys; print(json.dumps([sys.argv[1]] * 40))" "$SPOTQ")
post "{\"mesh\":\"$SPOTQ\",\"kind\":\"gregory\",\"params\":{\"divisions\":2,\"frames\":$F}}"
expect_error "40 frame meshes over a 1M job memory limit" 422 invalid_params
check "it says so ($(jqb .error.message))" grep -q 'frame meshes of .* vertices need about .* over the job memory limit' <<<"$(jqb .error.message)"
post "{\"mesh\":\"$SPOTQ\",\"kind\":\"gregory\",\"params\":{\"divisions\":2,\"frames\":[\"$SPOTQ\"]}}"
check "one frame mesh fits: accepted ($STATUS)" test "$STATUS" = 202 -o "$STATUS" = 200 -o "$STATUS" = 201
stop_daemon

# approximate-cc past --max-cc-valence faces around a vertex (a flat fan)
# or vertices in a face (an n-gon, refined into a vertex of n faces):
# cc_valence_limit at once, naming it (OpenSubdiv's end caps took seconds
# to minutes: a fan of 2,000 triangles 20 s); interpolate takes them; at
# the limit it runs
start_daemon --max-cc-valence 40 || exit 1
api GET /v1/info
check "info: limits.max_cc_valence 40" jq -e '.limits.max_cc_valence == 40' "$BODY"
fan() { # FILE N: a flat fan of N triangles; FILE.ply: the N-gon around it
    python3 - "$1" "$2" <<'EOF2'
import math, sys
f, n = sys.argv[1], int(sys.argv[2])
pts = [(math.cos(2 * math.pi * k / n), math.sin(2 * math.pi * k / n)) for k in range(n)]
with open(f, "w") as o:
    o.write("v 0 0 0\n" + "".join("v %r %r 0\n" % p for p in pts))
    o.write("".join("f 1 %d %d\n" % (k + 2, (k + 1) % n + 2) for k in range(n)))
with open(f + ".ply", "w") as o:
    o.write("ply\nformat ascii 1.0\nelement vertex %d\nproperty float x\nproperty float y\n"
            "property float z\nelement face 1\nproperty list int int vertex_indices\nend_header\n" % n)
    o.write("".join("%r %r 0\n" % p for p in pts) + "%d %s\n" % (n, " ".join(map(str, range(n)))))
EOF2
}
fan "$TMP/fan41.obj" 41
fan "$TMP/fan40.obj" 40
for m in obj obj.ply; do
    [[ $m == obj ]] && upload "$TMP/fan41.obj" || upload "$TMP/fan41.obj.ply" model/x-ply
    run_job gregory "$MESH_ID" '{"divisions":2,"construction":"approximate-cc"}'
    said=$([[ $m == obj ]] && echo "vertex 1 has more than 40 faces" || echo "face 1 has 41 vertices")
    check "approximate-cc, 41 around a vertex ($m): cc_valence_limit, '$said' ($(jq -c .error "$TMP/job.json"))" \
        jq -e --arg s "$said" '.state == "failed" and .error.code == "cc_valence_limit" and (.error.message | contains($s))' "$TMP/job.json"
    run_job gregory "$MESH_ID" '{"divisions":2}'
    job_ok "interpolate on it ($m)"
done
upload "$TMP/fan40.obj"
run_job gregory "$MESH_ID" '{"divisions":2,"construction":"approximate-cc"}'
job_ok "approximate-cc, 40 around a vertex"
upload "$TMP/fan40.obj.ply" model/x-ply
run_job gregory "$MESH_ID" '{"divisions":2,"construction":"approximate-cc"}'
job_ok "approximate-cc, a 40-gon"
stop_daemon
finish
