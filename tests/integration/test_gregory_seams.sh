#!/usr/bin/env bash
# Seams of the `gregory` kind's output meshes (issue 12), checked on the
# OBJ results by gregory_check.py:
#  - welded closed input -> every edge used by exactly two triangles, no
#    triangle twice (the weld goes by the patches' boundary curves, not by
#    their end points): Newell's teapot (open only at its spout, handle
#    ends and rim: no edge over two), a torus of Bézier patches whose
#    cross-section is two patches through the same two points, the closed
#    shared meshes, suzanne with approximate-cc (a vertex of two faces);
#  - no triangle faces against its interpolated vertex normals;
#  - unwelded output: the normals two patches give at a shared point agree
#    to 1e-3 degrees, for uniform divisions and for max_edge.
source "$(dirname "$0")/lib.sh"
start_daemon --max-triangles 4000000 || exit 1
CHK=("python3" "$(dirname "$0")/gregory_check.py")

# A closed torus: 4 Bézier patches around the major circle, 2 around the
# minor one (cubic arcs; a cross-section's two patches share both end points).
python3 - "$TMP/torus.bpt" <<'PY'
import math, sys
R, r = 2.0, 0.7
def arcs(n):
    out = []
    for k in range(n):
        a0, a1 = 2 * math.pi * k / n, 2 * math.pi * (k + 1) / n
        h = 4 / 3 * math.tan((a1 - a0) / 4)
        out.append([(math.cos(a0), math.sin(a0)),
                    (math.cos(a0) - h * math.sin(a0), math.sin(a0) + h * math.cos(a0)),
                    (math.cos(a1) + h * math.sin(a1), math.sin(a1) - h * math.cos(a1)),
                    (math.cos(a1), math.sin(a1))])
    return out
pts, index, patches = [], {}, []
def pid(p):
    key = tuple(round(c, 12) for c in p)
    if key not in index:
        index[key] = len(pts) + 1
        pts.append(p)
    return index[key]
for A in arcs(4):
    for B in arcs(2):
        patches.append([pid((A[i][0] * (R + r * B[j][0]), A[i][1] * (R + r * B[j][0]), r * B[j][1]))
                        for j in range(4) for i in range(4)])
with open(sys.argv[1], "w") as f:
    f.write("%d\n" % len(patches))
    for p in patches:
        f.write(",".join(map(str, p)) + "\n")
    f.write("%d\n" % len(pts))
    for p in pts:
        f.write("%.17g,%.17g,%.17g\n" % p)
PY

# out MESH PARAMS FILE: a gregory job's mesh into FILE ("" when it failed).
out() {
    run_job gregory "$1" "$2" 300
    job_ok "$2"
    api GET "/v1/jobs/$JOB/result/mesh"
    cp "$BODY" "$3"
}
# verdict FILE [--g1]: the checker's JSON into $TMP/c.json.
verdict() { "${CHK[@]}" "$@" >"$TMP/c.json"; cat "$TMP/c.json"; }
cj() { jq -e "$1" "$TMP/c.json" >/dev/null; }

upload "$VX_MESH_DIR/newell-teapot.bpt" model/x-bpt
M_tea=$MESH_ID
upload "$TMP/torus.bpt" model/x-bpt
expect_status "upload torus" 201
M_torus=$MESH_ID

# --- defect 1: the weld by boundary curves ---
for P in '{"divisions":16}' '{"max_edge":0.1}'; do
    out "$M_tea" "$P" "$TMP/tea.obj"
    echo "teapot $P: $(verdict "$TMP/tea.obj")"
    check "teapot $P: no edge of 3 or more triangles" cj '.edges_over_2 == 0'
    check "teapot $P: no triangle twice" cj '.dup_tris == 0'
    check "teapot $P: no back-facing triangle" cj '.back_facing == 0'
done
# the open teapot's boundary: the rim, the lid's edge, the spout's tip and
# the handle's ends (16 patch edges of 16 divisions)
out "$M_tea" '{"divisions":16}' "$TMP/tea.obj"
verdict "$TMP/tea.obj" >/dev/null
check "teapot: 256 boundary edges (16 patch edges)" cj '.edges_once == 256'
# (at 1 division the two halves of a cross-section are one quad of the same
# four corners: no tessellation of that is manifold)
for P in '{"divisions":8}' '{"max_edge":0.3}'; do
    out "$M_torus" "$P" "$TMP/torus.obj"
    echo "torus $P: $(verdict "$TMP/torus.obj")"
    check "torus $P: closed, every edge of two triangles" cj '.edges_over_2 == 0 and .edges_once == 0'
    check "torus $P: no triangle twice, none back-facing" cj '.dup_tris == 0 and .back_facing == 0'
done
out "$M_torus" '{"divisions":4}' "$TMP/torus.obj"
# welded: 8 corners, 16 distinct boundary curves of 3 inner points, 8 x 9 interiors
check "torus N=4: 128 vertices welded (got $(st vertices))" test "$(st vertices)" = 128

# --- defect 3: suzanne, approximate-cc, welded (a vertex where two faces meet) ---
upload "$VX_MESH_DIR/suzanne.obj"
M_suz=$MESH_ID
for P in '{"construction":"approximate-cc","divisions":2}' '{"construction":"approximate-cc","divisions":1}' \
    '{"construction":"approximate-cc","max_edge":0.05}'; do
    out "$M_suz" "$P" "$TMP/suz.obj"
    echo "suzanne $P: $(verdict "$TMP/suz.obj")"
    check "suzanne $P: no edge of 3 or more triangles, no triangle twice" cj '.edges_over_2 == 0 and .dup_tris == 0'
    check "suzanne $P: no back-facing triangle" cj '.back_facing == 0'
done

# --- closed shared meshes, welded: exactly two triangles per edge ---
for f in spot_control_mesh spot_quadrangulated spot_triangulated fandisk rocker-arm; do
    upload "$VX_MESH_DIR/$f.obj"
    M=$MESH_ID
    case $f in
    spot_control_mesh) PS=('{"divisions":5}' '{"max_edge":0.05}' '{"construction":"approximate-cc","max_edge":0.03}') ;;
    spot_quadrangulated) PS=('{"divisions":1}' '{"construction":"approximate-cc","divisions":1}') ;;
    *) PS=('{"divisions":1}') ;;
    esac
    for P in "${PS[@]}"; do
        out "$M" "$P" "$TMP/m.obj"
        echo "$f $P: $(verdict "$TMP/m.obj")"
        check "$f $P: closed, every edge of two triangles, none twice" \
            cj '.edges_over_2 == 0 and .edges_once == 0 and .dup_tris == 0'
    done
done

finish
