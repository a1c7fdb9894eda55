#!/usr/bin/env bash
# Big job params stay out of the job history (issue #10, defect 5): gregory
# jobs with 2 MB of frames each. Their frames are kept as blobs while the
# jobs are unfinished (GET shows a reference), the daemon's RSS and the
# journal grow by little over 100 such jobs, the blobs go when the jobs
# end, and after a restart (SIGTERM, then kill -9 with one still queued)
# the jobs are there, the succeeded one still downloadable. Then the
# history's byte budget (--job-history-bytes) drops the oldest jobs.
source "$(dirname "$0")/lib.sh"
# The issue's target is 100 jobs under 50 MB; 25 jobs keep the test short,
# under the same 50 MB. Before frames became blobs each job kept 14 MB.
# VX_MEMORY_JOBS=100 runs the full count (measured: RSS 115 -> 113 MiB,
# journal +180 KB).
# The daemon runs with --keep-memory 0: by default glibc keeps up to 32 MiB
# free at the top of each thread's arena (M_TRIM_THRESHOLD, which
# malloc_trim does not override there), and the HTTP threads' arenas kept
# their parse peaks, 20-30 MB each, reached after a varying number of jobs
# (RSS 126-167 -> 186-216 MiB over the same 25 jobs). With 0 freed memory
# goes back, and what stays is what the jobs leak (RSS flat within 3 MB).
start_daemon --keep-memory 0 || exit 1

rss_kb() { awk '/^VmRSS:/ {print $2}' "/proc/$PID/status"; }
# Under AddressSanitizer freed memory sits in its quarantine (256 MB): RSS
# says nothing there, the other checks still hold.
ASAN=0
if [[ $(ldd "$VOXELD" 2>/dev/null) == *libasan* ]]; then ASAN=1; echo "ASan build: RSS not checked"; fi
# Under ASan 8 jobs (about 2 s each on a quiet machine, 25 s in a loaded CI
# run) still check the journal and the blobs.
JOBS=${VX_MEMORY_JOBS:-$((ASAN == 1 ? 8 : 25))}
check_rss() { # WHAT KB LIMIT_KB
    [[ $ASAN == 1 ]] || check "$1" test "$2" -lt "$3"
}
blobs() { find "$DATA/blobs" -type f 2>/dev/null | wc -l; }

# A 17 x 17 vertex grid of quads (289 vertices).
python3 - "$TMP/grid.obj" <<'EOF'
import sys
with open(sys.argv[1], "w") as f:
    for j in range(17):
        for i in range(17):
            f.write("v %g %g 0\n" % (i / 16, j / 16))
    for j in range(16):
        for i in range(16):
            a = j * 17 + i + 1
            f.write("f %d %d %d %d\n" % (a, a + 1, a + 18, a + 17))
EOF
upload "$TMP/grid.obj"
expect_status "upload grid" 201
GRID=$MESH_ID

# 256 frames of the grid's 289 vertices (about 2 MB of JSON). rest.json is
# the body after the first number of frame 0, so that each job's frames
# can differ: ",y0,z0,x1,...],[...],...]".
python3 - "$TMP/rest.json" <<'EOF'
import math, sys
frames = []
for k in range(256):
    f = []
    for j in range(17):
        for i in range(17):
            x, y = i / 16, j / 16
            f += [x, y, 0.05 * math.sin(0.1 * k + 3 * x) * math.cos(2 * y)]
    frames.append(",".join("%.6f" % v for v in f))
with open(sys.argv[1], "w") as out:
    out.write(frames[0][frames[0].index(","):] + "]")
    for f in frames[1:]:
        out.write(",[" + f + "]")
    out.write("]")
EOF
body() { # MESH I [PARAM]: a gregory job on MESH whose frames start with I
    { printf '{"mesh":"%s","kind":"gregory","params":{%s,"frames":[[%s' "$1" "${3:-\"divisions\":1}" "$2"; cat "$TMP/rest.json"; printf '}}'; } >"$TMP/body.json"
}
submit() { # MESH I [wait [PARAM]]
    body "$1" "$2" "${4:-\"divisions\":1}"
    api POST "/v1/jobs?wait=${3:-30}" -H "Content-Type: application/json" --data-binary "@$TMP/body.json"
}
# A job that fails at once, after its frames were taken: the grid's 256
# patches at max_edge 1e-6 take the most divisions, 256, and so make
# 33,554,432 triangles, over max_triangles (adaptive divisions are the
# job's to count; uniform ones over it, and frames of another vertex
# count, are 422 at submission).
# A job not ended within the request's 30 s (a loaded machine) is waited for.
fails() {
    submit "$GRID" "$1" 30 '"max_edge":1e-6'
    local id st=$STATUS
    id=$(jqb '.id // empty')
    if [[ "$st" == 202 && -n "$id" ]] && jq -e '.state == "queued" or .state == "running"' "$BODY" >/dev/null; then
        wait_job "$id" 300
        STATUS=$st # the submission's
    fi
}
failed_ok() { jq -e '.state == "failed" and .error.code == "triangle_limit"' "$BODY" >/dev/null; }
body "$GRID" 0
SIZE=$(stat -c %s "$TMP/body.json")
check "a body of about 2 MB ($SIZE bytes)" test "$SIZE" -gt 1900000
check "the body is JSON" jq -e '.params.frames | length == 256 and all(length == 867)' "$TMP/body.json"

# One that succeeds: 257 outputs, frames shown as a reference.
submit "$GRID" 0 60
expect_status "2 MB frames on the grid" 202
OK=$(jqb .id)
wait_job "$OK" 120
check "grid job succeeded ($(jqb -c .error))" jq -e '.state == "succeeded"' "$BODY"
check "frames shown as a blob reference" jq -e '.params.frames | (.blob | test("^[0-9a-f]{64}$")) and .count == 256 and .bytes > 1000000 and (keys | length) == 3' "$BODY"
check "257 outputs" jq -e '.outputs | length == 257 and has("frame_256")' "$BODY"
BLOB=$(jqb .params.frames.blob)
check "the blob is gone once the job ended" test "$(blobs)" = 0
api GET "/v1/jobs/$OK/result/frame_256"
expect_status "frame_256" 200
cp "$BODY" "$TMP/frame_256.obj"
check "frame_256 is a mesh" test "$(grep -c '^v ' "$TMP/frame_256.obj")" -gt 0

# Warm-up: the first failing jobs set the parser's transient peak.
for i in 1 2; do fails "0.00000$i"; done
check "warm-up: triangle_limit ($(jqb -c .error))" failed_ok
RSS0=$(rss_kb)
JSZ0=$(stat -c %s "$DATA/journal.log")
t0=$(date +%s)
nfail=0
for i in $(seq 1 "$JOBS"); do
    fails "$i"
    if [[ "$STATUS" != 202 ]] || ! failed_ok; then
        nfail=$((nfail + 1))
        echo "job $i: $STATUS $(head -c 300 "$BODY")"
    fi
    if [[ -n "${VX_DEBUG_RSS:-}" ]] && ((i % 5 == 0)); then echo "after $i jobs: RSS $(($(rss_kb) / 1024)) MiB"; fi
done
LAST=$(jqb .id)
RSS1=$(rss_kb)
JSZ1=$(stat -c %s "$DATA/journal.log")
echo "$JOBS jobs of 2 MB frames in $(($(date +%s) - t0)) s: RSS $((RSS0 / 1024)) -> $((RSS1 / 1024)) MiB, journal $JSZ0 -> $JSZ1 bytes"
check "$JOBS jobs answered 202 and failed with triangle_limit ($nfail did not)" test "$nfail" = 0
check_rss "$JOBS jobs of 2 MB frames add under 50 MB RSS ($((RSS0 / 1024)) -> $((RSS1 / 1024)) MiB)" \
    $((RSS1 - RSS0)) $((50 * 1024))
check "the journal grows by under 1 MB ($JSZ0 -> $JSZ1)" test $((JSZ1 - JSZ0)) -lt 1048576
check "no blob left" test "$(blobs)" = 0
api GET "/v1/jobs?limit=1000"
check "every job listed" test "$(jqb '.items | length')" -ge $((JOBS + 3))
check "listed with references" jq -e '[.items[] | select(.kind == "gregory") | .params.frames.count] | all(. == 256)' "$BODY"

# Restart: the jobs are there, the succeeded one downloadable.
stop_daemon
JSZ2=$(stat -c %s "$DATA/journal.log")
check "compacted journal under 1 MB ($JSZ2)" test "$JSZ2" -lt 1048576
start_daemon --keep-memory 0 || exit 1
api GET "/v1/jobs/$OK"
check "after restart: succeeded, reference kept" jq -e '.state == "succeeded" and .params.frames.blob == "'"$BLOB"'" and (.outputs | length) == 257' "$BODY"
api GET "/v1/jobs/$OK/result/frame_256"
expect_status "after restart: frame_256" 200
check "after restart: the same frame_256" cmp -s "$BODY" "$TMP/frame_256.obj"
api GET "/v1/jobs/$LAST"
check "after restart: the last failed job" jq -e '.state == "failed" and .params.frames.count == 256' "$BODY"
check_rss "after restart: RSS under the first run's + 50 MB ($(( $(rss_kb) / 1024 )) MiB)" "$(rss_kb)" $((RSS0 + 50 * 1024))

# kill -9 with a 2 MB frames job queued behind a slow one: its blob is
# durable before the 202, kept at the restart, and the job runs.
upload "$VX_MESH_DIR/ogre.obj"
OGRE=$MESH_ID
# (voxelizing by slices holds the GL thread for a minute; canceled below)
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$OGRE\",\"kind\":\"voxelize\",\"params\":{\"resolution\":1024,\"supersample\":2,\"method\":\"slice\",\"format\":\"summary\"}}"
SLOW=$(jqb .id)
until_running "$SLOW"
submit "$GRID" 7 0
expect_status "queued 2 MB frames job" 202
Q=$(jqb .id)
check "queued behind the slow job" jq -e '.state == "queued"' "$BODY"
check "its blob is stored" test "$(blobs)" = 1
kill9_daemon
start_daemon || exit 1
check "after kill -9: the blob is still there" test "$(blobs)" = 1
api DELETE "/v1/jobs/$SLOW"
wait_job "$Q" 120
check "after kill -9: the queued job succeeded ($(jqb -c .error))" jq -e '.state == "succeeded" and (.outputs | length) == 257' "$BODY"
check "after it: no blob left" test "$(blobs)" = 0
api GET "/v1/jobs/$Q/result/frame_001"
expect_status "its frame_001" 200

# The history's byte budget: at 32 KiB only the newest jobs stay (the one
# with 257 outputs takes 24 KiB).
stop_daemon
start_daemon --job-history-bytes 32K || exit 1
api GET "/v1/jobs?limit=1000"
N=$(jqb '.items | length')
check "a 32 KiB history keeps fewer jobs ($N)" test "$N" -lt 16
check "and still some" test "$N" -ge 3
api GET "/v1/jobs/$OK"
expect_error "the oldest job was dropped" 404 job_not_found
api GET "/v1/jobs/$Q"
expect_status "the newest job stays" 200
api GET /v1/info
check "info: job_history_bytes" jq -e '.limits.job_history_bytes == 32768 and .limits.job_history == 10000' "$BODY"
stop_daemon
finish
