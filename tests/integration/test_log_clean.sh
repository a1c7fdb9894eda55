#!/usr/bin/env bash
# Ordinary jobs of every kind and voxelize method leave no error line in the
# log: an operator alerting on level=error hears of real faults only. With
# Mesa's shader cache off every shader is compiled here, so the compiler's
# warnings come too (KHR_debug gives them severity high: peel's fill shader
# logged five "used uninitialized" lines at level=error on a cold cache).
source "$(dirname "$0")/lib.sh"
SPOT="$VX_MESH_DIR/spot_triangulated.obj"
QUAD="$VX_MESH_DIR/spot_quadrangulated.obj"
BPT="$VX_MESH_DIR/newell-teapot.bpt"
for f in "$SPOT" "$QUAD" "$BPT"; do [[ -f "$f" ]] || { echo "skip: $f missing"; exit 77; }; done
export MESA_SHADER_CACHE_DISABLE=true
start_daemon || exit 1

upload "$SPOT"
expect_status "upload spot" 201
TRI=$MESH_ID
upload "$QUAD"
QID=$MESH_ID
upload "$BPT" text/plain
expect_status "upload teapot" 201
TEA=$MESH_ID

for p in '"method":"peel"' '"method":"scan"' '"method":"slice"' '"method":"cpu"' \
    '"method":"slice","supersample":2' '"supersample":2,"samples":"faces"' \
    '"inside":"robust"' '"inside":"winding"' '"fill":"surface"' '"method":"peel","inside":"parity"' \
    '"format":"vdb","vdb_grid":"level_set"'; do
    run_job voxelize "$TRI" "{\"resolution\":48,$p}"
    job_ok "voxelize $p"
done
run_job render "$TRI" '{"width":48,"height":48}'
job_ok "render"
run_job preview "$TRI" '{"width":48,"height":48}'
job_ok "preview"
run_job gregory "$QID" '{"divisions":2}'
job_ok "gregory on quads"
run_job gregory "$TEA" '{"divisions":2}'
job_ok "gregory on Bezier patches"
run_job catmull-clark "$QID" '{"levels":1}'
job_ok "catmull-clark"
stop_daemon

grep -a 'level=error' "$TMP/daemon.log" | head -n 5
check "no level=error line in the log" test "$(grep -ac 'level=error' "$TMP/daemon.log")" = 0
check "the shaders were compiled here (gl lines logged)" grep -aq 'event=gl.context' "$TMP/daemon.log"
finish
