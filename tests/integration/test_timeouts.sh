#!/usr/bin/env bash
# --job-timeout reaches into long library calls (issue 10, defect 9): with a
# 2 s limit, the biggest jobs of every kind either succeed in time or fail
# with job_timeout, and no run takes more than 50% over the limit
# (timings.run_ms <= 4500: on an idle machine they stop within 10-20%, as
# the run_ms each case prints shows; the suite runs two tests at once on
# two cores, and there voxelize ogre 1024 peel robust took 2.77 s, then 3.2 s,
# beside a GL-heavy test: its first z pass was drawn whole, and growing the
# layer arrays made both arrays at once, each over 0.4 s on llvmpipe; now
# the pass is drawn in bands from the x and y passes' rate and the counts
# array is made only by the count pass, 2.08 s beside two busy loops).
# Before the fix catmull-clark ran 5-10 s inside
# OpenSubdiv, a 8192^2 preview with 8x MSAA 4-16 s in one draw, a 8192^2
# 16-bit render with float outputs 3-4 s in the interpolation and writers,
# gregory approximate-cc on ogre 5-8 s in OpenSubdiv, and with frames 3-5 s
# building its tables in-process. The bound is 2.25x the limit, far below
# those, with room for a slow stop beside another test on a loaded machine.
# After each stopped job the daemon serves, and the next job runs as before
# (the same preview gives the same picture after an aborted one: the GL
# context is sane); a stopped child process is reaped.
source "$(dirname "$0")/lib.sh"
JSON=(-H "Content-Type: application/json")
LIMIT_MS=4500
# Under ASan/UBSan (a Debug build, several times slower) the work between
# two stop checks grows alike (and a loaded machine more so), and ASan's
# allocator poisons the shadow of each buffer it maps or frees: about 0.3 s
# a GB here, inside one malloc of a 8192^2 frame's hits and again in the
# frees after the stop (4.2 s in a loaded CI run): the bound is then 150%.
[[ -n "${VX_SANITIZED:-}" ]] && LIMIT_MS=6000

start_daemon --job-timeout 2 || exit 1
upload "$VX_MESH_DIR/stanford-bunny.obj"
BUNNY=$MESH_ID
upload "$VX_MESH_DIR/ogre.obj"
OGRE=$MESH_ID
upload "$VX_MESH_DIR/suzanne.obj"
SUZ=$MESH_ID
upload "$VX_MESH_DIR/spot_control_mesh.obj"
SPOT=$MESH_ID

# big WHAT KIND MESH PARAMS: a job that may not finish in 2 s.
big() {
    run_job "$2" "$3" "$4" 60
    local state code ms
    state=$(jq -r .state "$TMP/job.json")
    code=$(jq -r '.error.code // "-"' "$TMP/job.json")
    ms=$(jq -r '.timings.run_ms // 1e9' "$TMP/job.json")
    echo "  $1: $state $code run_ms=$ms"
    check "$1: succeeded or job_timeout (got $state $code)" \
        jq -e '.state == "succeeded" or (.state == "failed" and .error.code == "job_timeout")' "$TMP/job.json"
    check "$1: run_ms $ms <= $LIMIT_MS" jq -e ".timings.run_ms <= $LIMIT_MS" "$TMP/job.json"
    BIG_STATE=$state
}

# small WHAT: a small preview of suzanne succeeds; PREV_COVERED = its count.
small() {
    api POST "/v1/jobs?wait=60" "${JSON[@]}" \
        -d "{\"mesh\":\"$SUZ\",\"kind\":\"preview\",\"params\":{\"width\":256,\"height\":192,\"samples\":4}}"
    check "$1: the next job runs" jq -e '.state == "succeeded"' "$BODY"
    COVERED=$(jqb .stats.pixels_covered)
}

small "before"
REF_COVERED=$COVERED
check "reference preview covers pixels ($REF_COVERED)" test "${REF_COVERED:-0}" -gt 1000

# OpenSubdiv: the highest level max_triangles allows on the bunny (6.7M
# triangles; level 4 is refused). Refinement and encoding run in a child
# process that is killed at the limit.
big "catmull-clark bunny levels 3" catmull-clark "$BUNNY" '{"levels":3,"format":"obj"}'
CC_JOB=$JOB
for _ in $(seq 1 100); do [[ -z "$(ps -o pid= --ppid "$PID")" ]] && break; sleep 0.1; done
check "the stopped child is reaped" test -z "$(ps -o pid= --ppid "$PID")"
if [[ "$BIG_STATE" == failed ]]; then
    api GET "/v1/jobs/$CC_JOB/result"
    expect_error "no result for the stopped job" 409 job_failed
    check "no result dir for the stopped job" test ! -e "$DATA/results/$CC_JOB"
fi
small "after catmull-clark"

# The largest preview: rendered in bands of rows with a poll between them.
big "preview 8192x8192 samples 8" preview "$OGRE" '{"width":8192,"height":8192,"samples":8}'
small "after preview"
check "same picture after an aborted preview ($COVERED vs $REF_COVERED)" test "$COVERED" = "$REF_COVERED"

# render: a 8192^2 16-bit PNG and three float images of 8192^2.
big "render 8192x8192 16-bit with float outputs" render "$SUZ" \
    '{"N":64,"R":512,"width":8192,"height":8192,"bits":16,"outputs":["normal","position","depth"]}'
# render: the six-panel comparison (Sobel gradients, both volumes).
big "render compare 3344x3344" render "$SUZ" '{"N":64,"R":512,"width":3344,"height":3344,"compare":true}'
small "after render"

# voxelize: a 2048^3 bit grid (the largest resolution), raw.
big "voxelize ogre 2048 raw1" voxelize "$OGRE" '{"resolution":2048,"format":"raw1"}'
# voxelize robust: the z rays of the whole mesh are peeled in one slab, ~1 s
# a pass at 1024^2 on llvmpipe, so later passes are drawn in bands of rows
# with a stop check between them.
big "voxelize ogre 1024 peel robust" voxelize "$OGRE" \
    '{"resolution":1024,"method":"peel","inside":"robust","format":"raw1"}'
# winding (the default on an open mesh) on a soup of 20,000 large random
# triangles, every edge a boundary: a band of rows holds thousands of
# them and a column seconds of winding numbers, so the stop check comes
# every 64 triangles and every column (it overran a 20 s limit by 30 s).
python3 - "$TMP/soup.obj" <<'PY'
import random, sys
random.seed(5)
with open(sys.argv[1], "w") as f:
    n = 60000
    for i in range(n):
        f.write("v %f %f %f\n" % (random.random(), random.random(), random.random()))
    for i in range(1, n - 1, 3):
        f.write("f %d %d %d\n" % (i, i + 1, i + 2))
PY
upload "$TMP/soup.obj"
big "voxelize a triangle soup 128 winding" voxelize "$MESH_ID" '{"resolution":128,"format":"summary"}'
check "the soup ran winding" bash -c "[[ \$(jq -r '.stats.inside // .error.code' '$TMP/job.json') =~ ^(winding|job_timeout)$ ]]"
# a preview of the soup: every triangle covers every band, so its draws
# are sized by their time, not by a triangle count (it overran 20 s by 5 s)
big "preview 8192x8192 of the triangle soup" preview "$MESH_ID" '{"width":8192,"height":8192}'
# gregory: 13.5M triangles, welded, Draco (the encoder runs in a child).
big "gregory spot divisions 96 drc" gregory "$SPOT" '{"divisions":96,"format":"drc"}'
big "gregory spot divisions 96 obj" gregory "$SPOT" '{"divisions":96,"format":"obj"}'
# gregory approximate-cc on ogre: OpenSubdiv's patch table for 372k quads is
# one call of ~5 s (built in a child process).
big "gregory ogre approximate-cc" gregory "$OGRE" '{"divisions":1,"construction":"approximate-cc"}'
# With deformation frames the tables are built once for every frame: in the
# child too (before, in-process: 3.1 s interpolate, 4.5 s approximate-cc).
big "gregory ogre frames interpolate" gregory "$OGRE" "{\"divisions\":2,\"frames\":[\"$OGRE\"]}"
big "gregory ogre frames approximate-cc" gregory "$OGRE" \
    "{\"divisions\":2,\"construction\":\"approximate-cc\",\"frames\":[\"$OGRE\",\"$OGRE\"]}"
small "after gregory"

# Jobs within the limit are not affected.
run_job catmull-clark "$SUZ" '{"levels":2,"format":"ply"}'
job_ok "catmull-clark suzanne levels 2"
# level 2: 4 quads per corner of the input
CORNERS=$(awk '$1 == "f" {n += NF - 1} END {print n}' "$VX_MESH_DIR/suzanne.obj")
check "catmull-clark stats from the child" \
    jq -e ".stats.faces == 4 * $CORNERS and .stats.triangles == 8 * $CORNERS and .stats.vertices > 0 and .stats.refine_ms >= 0" "$TMP/job.json"
api GET "/v1/jobs/$JOB/result/mesh"
check "catmull-clark result is a PLY" sh -c "head -c 3 '$BODY' | grep -q ply"
run_job gregory "$SPOT" '{"divisions":4,"format":"drc"}'
job_ok "gregory spot divisions 4"

api GET /readyz
expect_status "daemon still ready" 200
stop_daemon

# A job that does not stop after SIGTERM (VOXELD_TEST_STOP_HANG: the stop
# never returns) holds the process only --stop-timeout: then exit 1, said.
VOXELD_TEST_STOP_HANG=1 start_daemon --stop-timeout 1 || exit 1
T0=$(date +%s.%N)
kill -TERM "$PID"
rc=0
wait "$PID" || rc=$?
T1=$(date +%s.%N)
PID=
check "a stop that hangs: exit 1 (got $rc)" test "$rc" -eq 1
check "within --stop-timeout and a second" awk -v a="$T0" -v b="$T1" 'BEGIN {exit !(b - a < 2.5)}'
check "logged as voxeld.stop_timeout" grep -q 'event=voxeld.stop_timeout seconds=1 ' "$TMP/daemon.log"

# Jobs that stop at once with a client's keep-alive connection open and
# idle: exit 0, at once. (The stop waited the connections' 2 s grace for
# it, and a --stop-timeout under that exited 1 saying a job had not
# stopped, where there was none.)
from=$(($(wc -l <"$TMP/daemon.log") + 1))
start_daemon --stop-timeout 1 || exit 1
python3 - "$PORT" "$PID" >"$TMP/idle_stop.txt" <<'PY'
import os, signal, socket, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
s.recv(1000)
t0 = time.monotonic()
os.kill(int(sys.argv[2]), signal.SIGTERM)
try:
    os.waitpid(int(sys.argv[2]), 0)
except ChildProcessError:  # not our child: wait for it to go
    while os.path.exists("/proc/%s" % sys.argv[2]):
        time.sleep(0.02)
print("%.2f" % (time.monotonic() - t0))
PY
rc=0
wait "$PID" || rc=$?
PID=
check "an idle keep-alive connection at SIGTERM: exit 0 (got $rc)" test "$rc" -eq 0
check "... within a second ($(cat "$TMP/idle_stop.txt") s)" awk '{exit !($1 < 1.0)}' "$TMP/idle_stop.txt"
check "... and no stop_timeout line" bash -c "! tail -n +$from '$TMP/daemon.log' | grep -q 'event=voxeld.stop_timeout'"

# A GL thread that stops answering (VOXELD_TEST_GL_STALL=6: its third ping,
# about 2 s after the start, sleeps 6 s, as a driver call that does not
# return would): /livez answers 503 gl_stalled once it has been silent past
# --gl-stall-timeout, and 200 again when it answers; logged once.
VOXELD_TEST_GL_STALL=6 start_daemon --gl-stall-timeout 2 || exit 1
api GET /v1/info
check "info lists gl_stall_timeout_s" jq -e '.limits.gl_stall_timeout_s == 2' "$BODY"
seen503=0 seen200after=0
for i in $(seq 1 60); do
    api GET /livez
    if [[ $STATUS == 503 ]] && jq -e '.error.code == "gl_stalled"' "$BODY" >/dev/null; then
        seen503=1
    elif [[ $STATUS == 200 && $seen503 == 1 ]]; then
        seen200after=1
        break
    fi
    sleep 0.25
done
check "a stalled GL thread: /livez 503 gl_stalled" test "$seen503" = 1
check "then 200 once it answers again" test "$seen200after" = 1
check "logged as gl.stalled" grep -q 'event=gl.stalled ' "$TMP/daemon.log"
stop_daemon
# The default: a GL thread that answers keeps /livez at 200.
start_daemon --gl-stall-timeout 2 || exit 1
bad=0
for i in $(seq 1 16); do
    api GET /livez
    [[ $STATUS == 200 ]] || bad=$((bad + 1))
    sleep 0.25
done
check "an idle GL thread that answers: /livez 200 for 4 s ($bad not)" test "$bad" = 0
stop_daemon
finish
