#!/usr/bin/env bash
# Jobs that go wrong fail cleanly and the daemon keeps serving: GL context
# loss (rebuilt, job retried once), loss twice (job fails), the job time
# limit. VOXELD_TEST_LOSE_CONTEXT=N makes the runner treat the next N GL
# stages as if the context had been reset (robustness reset status), since
# a real reset cannot be provoked on llvmpipe.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
box_obj "$TMP/box.obj" 0 0 0 1 1 1
JSON=(-H "Content-Type: application/json")

VOXELD_TEST_LOSE_CONTEXT=1 start_daemon || exit 1
upload "$TMP/box.obj"
BOX=$MESH_ID
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "job survives a context loss" jq -e '.state == "succeeded" and .stats.context_rebuilds == 1' "$BODY"
check "loss logged" grep -q 'event=gl.context_lost' "$TMP/daemon.log"
api GET "$(jqb .outputs.image)"
"$VX_TOOLS/pngstat" "$BODY" >"$TMP/p.json"
check "image after the rebuild is real" jq -e '.covered > 100' "$TMP/p.json"
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "next job needs no rebuild" jq -e '.state == "succeeded" and (.stats.context_rebuilds == null)' "$BODY"
stop_daemon

VOXELD_TEST_LOSE_CONTEXT=2 start_daemon || exit 1
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "lost twice: the job fails" jq -e '.state == "failed" and .error.code == "context_lost"' "$BODY"
api GET "/v1/jobs/$(jqb .id)/result"
expect_error "no result for a failed job" 409 job_failed
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "the daemon still runs jobs" jq -e '.state == "succeeded"' "$BODY"
stop_daemon

start_daemon --job-timeout 0.2 || exit 1
upload "$VX_MESH_DIR/ogre.obj"
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"preview\",\"params\":{\"width\":4096,\"height\":4096,\"samples\":4}}"
check "over the time limit: job_timeout" jq -e '.state == "failed" and .error.code == "job_timeout"' "$BODY"
check "no result dir for the failed job" test ! -e "$DATA/results/$(jqb .id)"
api GET /metrics
check "failed job counted" grep -q 'voxeld_jobs_total{kind="preview",state="failed"} 1' "$BODY"
stop_daemon
# A canceled job whose GL stage is done and waits for the one CPU worker
# (busy with another job's long CPU stage) ends at once: it stayed running,
# holding its memory and the GL thread's next job, until the worker took it.
start_daemon --workers 1 || exit 1
upload "$VX_MESH_DIR/stanford-bunny.obj"
for iso in 0.62 0.63; do
    api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"render\",\"params\":{\"N\":128,\"iso\":$iso}}"
    expect_status "render $iso submitted" 202
    RJ+=("$(jqb .id)")
done
until_running "${RJ[1]}"
check "the second render started (its GL stage)" test "$(jqb .state)" = running
sleep 1 # its GL stage done: it waits for the worker
api DELETE "/v1/jobs/${RJ[1]}"
expect_status "cancel the waiting render" 202
api GET "/v1/jobs/${RJ[1]}?wait=3"
check "canceled within 3 s" jq -e '.state == "canceled" and .error.code == "canceled"' "$BODY"
api GET "/v1/jobs/${RJ[0]}"
check "while the first still runs" test "$(jqb .state)" = running
api DELETE "/v1/jobs/${RJ[0]}"
wait_job "${RJ[0]}" 60
check "the first canceled too" test "$(jqb .state)" = canceled
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "the next job runs" jq -e '.state == "succeeded"' "$BODY"
stop_daemon
# The journal alone removed, then replaced by another file: the daemon is
# not ready (it said ready while every submission answered 500
# journal_failed), says why, and the jobs it holds are still answered.
start_daemon || exit 1
api GET /readyz
check "readyz: the journal is intact" jq -e '.checks.journal == true' "$BODY"
rm "$DATA/journal.log"
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"preview\"}"
expect_error "a job with the journal removed" 500 journal_failed
api GET /readyz
expect_status "readyz with the journal removed" 503
check "... checks.journal false, the reason says so ($(jqb -r .reason))" \
    jq -e '.checks.journal == false and (.reason | test("journal was removed or replaced"))' "$BODY"
echo '{}' >"$DATA/journal.log"
api GET /readyz
expect_status "readyz with another file as the journal" 503
api GET "/v1/jobs/${RJ[0]}"
expect_status "the jobs held are still answered" 200
kill9_daemon
# The data dir removed under a running daemon: the journal takes appends
# into a file no restart reads, so a job is not acknowledged (it was 202,
# then gone after a restart). The write check before the body finds the
# data dir gone: 503 not_ready, as /readyz (journal_failed, 500, was the
# journal's own check behind it).
start_daemon || exit 1
upload "$VX_SOURCE_DIR/examples/meshes/torus.obj"
M=$MESH_ID
rm -rf "$DATA"
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$M\",\"kind\":\"preview\"}"
expect_error "job on a removed data dir" 503 not_ready
api GET /readyz
expect_status "readyz on a removed data dir" 503
api GET /metrics
expect_status "metrics on a removed data dir" 200
check "voxeld_ready 0" grep -q '^voxeld_ready 0$' "$BODY"
# its free space is unknown, not 2^64 - 1 bytes (16 EiB on a dashboard)
check "voxeld_data_dir_free_bytes NaN ($(grep '^voxeld_data_dir_free_bytes' "$BODY"))" \
    grep -q '^voxeld_data_dir_free_bytes NaN$' "$BODY"
kill -KILL "$PID"
wait "$PID" 2>/dev/null
PID=
mkdir -p "$DATA"
finish
