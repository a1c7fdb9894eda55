#!/usr/bin/env bash
# Operators' metrics and logs (issue #13): the process_* family, failed jobs
# by error code (and logged at warn), the queue-wait histogram, job-duration
# buckets up to the job timeout, evictions, GL context losses, voxeld_ready.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
# Three lost contexts: the first job loses two (fails context_lost), the
# second loses one and succeeds on the retry. A 6000-byte results budget
# holds one 16^3 raw8 result (4096 bytes): the third job's evicts the
# second's.
VOXELD_TEST_LOSE_CONTEXT=3 start_daemon --job-timeout 90 --results-max-bytes 6000 || exit 1
metric() { awk -v n="$1" '$1 == n {print $2}' "$BODY"; }

box_obj "$TMP/box.obj" 0 0 0 1 1 1
upload "$TMP/box.obj"
run_job voxelize "$MESH_ID" '{"resolution":16,"format":"raw8"}'
check "job 1 fails: context_lost" jq -e '.state == "failed" and .error.code == "context_lost"' "$TMP/job.json"
J1=$JOB
run_job voxelize "$MESH_ID" '{"resolution":16,"format":"raw8"}'
job_ok "job 2 (retried once)"
J2=$JOB
run_job voxelize "$MESH_ID" '{"resolution":15,"format":"raw8"}'
job_ok "job 3"
api GET "/v1/jobs/$J2/result"
expect_error "job 2's result was evicted by the budget" 410 result_evicted

sleep 0.3
LINE=$(grep -a 'event=job.finished' "$TMP/daemon.log" | grep -a "job=$J1" | tail -n 1)
check "the failed job is logged at warn" bash -c "grep -q 'level=warn' <<<'$LINE'"
LINE=$(grep -a 'event=job.finished' "$TMP/daemon.log" | grep -a "job=$J2" | tail -n 1)
check "a succeeded job is logged at info" bash -c "grep -q 'level=info' <<<'$LINE'"

api GET /metrics
expect_status "metrics" 200
check "voxeld_ready 1" test "$(metric voxeld_ready)" = 1
check "voxeld_up is gone" bash -c "! grep -q '^voxeld_up' '$BODY'"
check "failed by code" test "$(metric 'voxeld_jobs_failed_total{kind="voxelize",code="context_lost"}')" = 1
check "GL context losses" test "$(metric voxeld_gl_context_losses_total)" = 3
check "evictions" test "$(metric voxeld_results_evicted_total)" -ge 1
check "queue wait: the three jobs that ran" test "$(metric voxeld_job_queue_wait_seconds_count)" = 3
check "queue wait +Inf bucket" test "$(metric 'voxeld_job_queue_wait_seconds_bucket{le="+Inf"}')" = 3
check "job duration: the job timeout is the last bucket" \
    grep -q '^voxeld_job_duration_seconds_bucket{kind="voxelize",le="90"} 3$' "$BODY"
check "job duration: no bucket past the timeout" \
    bash -c "! grep -q 'voxeld_job_duration_seconds_bucket{kind=\"voxelize\",le=\"120\"}' '$BODY'"
RSS=$(metric process_resident_memory_bytes)
check "resident memory ($RSS) above 4 MB" test "${RSS:-0}" -gt 4000000
check "resident memory = /proc's VmRSS, within 25%" \
    awk -v m="$RSS" -v k="$(awk '/VmRSS/ {print $2}' /proc/$PID/status)" 'BEGIN {exit !(m > 0.75 * k * 1024 && m < 1.25 * k * 1024)}'
FDS=$(metric process_open_fds)
check "open fds ($FDS)" test "${FDS:-0}" -gt 3
check "max fds at least the open ones" awk -v a="$(metric process_max_fds)" -v b="$FDS" 'BEGIN {exit !(a >= b)}'
check "cpu seconds counted" awk -v a="$(metric process_cpu_seconds_total)" 'BEGIN {exit !(a > 0)}'
# (date +%s truncates, and the start time carries /proc's boot time, whole
# seconds: a second of slack)
check "start time in the past" awk -v a="$(metric process_start_time_seconds)" -v now="$(date +%s)" 'BEGIN {exit !(a > 0 && a <= now + 1)}'
check "HELP and TYPE for the new families" bash -c "for f in voxeld_jobs_failed_total voxeld_job_queue_wait_seconds voxeld_results_evicted_total voxeld_gl_context_losses_total process_open_fds process_max_fds process_cpu_seconds_total process_resident_memory_bytes; do grep -q \"^# TYPE \$f \" '$BODY' || exit 1; done"


# ---- a scanner's pass does not stop the counting of new series ------------------
# Every route with every method, with and without a body size, a token and a
# query: some 250 (route, method, status) series. The table of series was a
# fixed 256 rows: once full, a first 201 was never counted.
python3 - "$PORT" <<'PY'
import concurrent.futures, http.client, itertools, sys
port = int(sys.argv[1])
paths = ("/livez /readyz /metrics /v1/info /v1/meshes /v1/meshes/x /v1/meshes/x/file /v1/jobs "
         "/v1/jobs/x /v1/jobs/x/result /v1/jobs/x/result/y / /docs /openapi.yaml /ui/x "
         "/v1/jobs/x/events /nope").split()
methods = "GET HEAD POST PUT DELETE OPTIONS PATCH TRACE FOO".split()
headers = [{}, {"Authorization": "Bearer x"}, {"Content-Length": "99999999999"},
           {"Content-Type": "application/json", "Content-Length": "2"}]
def one(a):
    path, method, h, q = a
    try:
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=5)
        c.putrequest(method, path + q, skip_accept_encoding=True)
        for k, v in h.items():
            c.putheader(k, v)
        c.endheaders()
        if h.get("Content-Length") == "2":
            c.send(b"{}")
        c.getresponse().read()
        c.close()
    except Exception:
        pass
with concurrent.futures.ThreadPoolExecutor(8) as ex:
    list(ex.map(one, itertools.product(paths, methods, headers, ["", "?wait=x&limit=-1"])))
PY
api GET /metrics
NSERIES=$(grep -c '^voxeld_http_requests_total{' "$BODY")
echo "note: $NSERIES request series after the scan"
check "the scan made over 256 series ($NSERIES)" test "$NSERIES" -gt 256
box_obj "$TMP/box2.obj" 0 0 0 2 1 1
upload "$TMP/box2.obj"
expect_status "an upload after the scan" 201
api DELETE "/v1/meshes/$MESH_ID"
expect_status "a mesh deleted after the scan" 204
api GET /metrics
check "the first DELETE 204, a new series, is counted" \
    grep -q '^voxeld_http_requests_total{route="/v1/meshes/{id}",method="DELETE",status="204"} 1$' "$BODY"
stop_daemon

# ---- /v1/info reports the limits as configured, 0 = no limit included ----------
# Held requests lowered to half of --max-connections in proportion: a
# share that rounded down to 0 (none held) is 1.
start_daemon --max-connections 100 --max-event-streams 100 --max-waits 1 || exit 1
api GET /v1/info
check "waits 1 of streams 100 in a half of 50: 1 and 49 ($(jq -c '.limits | [.max_waits, .max_event_streams]' "$BODY"))" \
    jq -e '.limits.max_waits == 1 and .limits.max_event_streams == 49' "$BODY"
stop_daemon
start_daemon --max-connections 100 --max-event-streams 1 --max-waits 100 || exit 1
api GET /v1/info
check "streams 1 of waits 100: 49 and 1 ($(jq -c '.limits | [.max_waits, .max_event_streams]' "$BODY"))" \
    jq -e '.limits.max_waits == 49 and .limits.max_event_streams == 1' "$BODY"
stop_daemon

# Every option whose 0 is documented as "no limit" / "never" / "at once", set
# to 0: /v1/info must say 0, and still fit api/openapi.yaml's Limits (which
# once required these to be above 0, so a valid configuration answered a
# /v1/info outside the contract). max_connections is reported as in effect.
start_daemon --job-timeout 0 --request-timeout 0 --connection-timeout 0 --max-triangles 0 \
    --max-connections-per-ip 0 --max-image-pixels 0 --max-job-memory 0 --header-timeout 0 \
    --min-body-rate 0 --min-send-rate 0 --max-parse-memory 0 --results-max-bytes 0 \
    --results-max-age 0 --job-history-bytes 0 --max-event-streams 0 --max-connections 300 \
    --keep-memory 0 --max-cc-valence 0 --brick-threshold 0 --event-keepalive 0 || exit 1
INFO_FROM=$(wc -l <"$VX_API_LOG")
api GET /v1/info
expect_status "info with zero limits" 200
check "every zero limit reported as 0" jq -e '.limits | [.job_timeout_s, .max_wait_s, .request_timeout_s,
    .connection_timeout_s, .max_triangles, .max_connections_per_ip, .max_image_pixels,
    .max_job_memory_bytes, .header_timeout_s, .min_body_rate, .min_send_rate,
    .max_parse_memory_bytes, .results_max_bytes, .results_max_age_s, .job_history_bytes,
    .max_event_streams, .keep_memory_bytes, .max_cc_valence] | all(. == 0)' "$BODY"
check "max_connections reported" jq -e '.limits.max_connections == 300' "$BODY"
# those whose 0 is "the default" say the default they give (they said 0)
check "brick_threshold_cells and event_keepalive_s 0: the defaults in effect" \
    jq -e '.limits.brick_threshold_cells == 1073741824 and .limits.event_keepalive_s == 15' "$BODY"
tail -n +"$((INFO_FROM + 1))" "$VX_API_LOG" >"$TMP/info-api.jsonl"
check "the zero-limit /v1/info fits api/openapi.yaml" \
    python3 "$VX_SOURCE_DIR/tests/tools/openapi_check.py" "$VX_SOURCE_DIR/api/openapi.yaml" "$TMP/info-api.jsonl"
python3 "$VX_SOURCE_DIR/tests/tools/openapi_check.py" "$VX_SOURCE_DIR/api/openapi.yaml" "$TMP/info-api.jsonl" | head -n 12
# --keep-memory 0: a job's 16 MB grid is given back
upload "$TMP/box.obj"
run_job voxelize "$MESH_ID" '{"resolution":512,"format":"summary"}'
job_ok "a 512^3 job"
api GET /metrics
check "keep-memory 0: nothing kept ($(metric voxeld_kept_memory_bytes))" test "$(metric voxeld_kept_memory_bytes)" = 0
stop_daemon

# ---- --keep-memory: a job's big buffers stay mapped for the next --------------------
start_daemon --keep-memory 20M || exit 1
api GET /v1/info
check "info: keep_memory_bytes" jq -e '.limits.keep_memory_bytes == 20971520' "$BODY"
api GET /metrics
check "nothing kept before a job" test "$(metric voxeld_kept_memory_bytes)" = 0
# The unit box, then one an eighth of it on the same 512^3 grid (16 MB of
# bits): each grid after the first is the memory kept from the one before,
# and must hold its own voxels only.
upload "$TMP/box.obj"
FULL=$MESH_ID
box_obj "$TMP/small.obj" 0 0 0 0.5 0.5 0.5
upload "$TMP/small.obj"
SMALL=$MESH_ID
G='"grid":{"origin":[0,0,0],"voxel_size":0.001953125,"dims":[512,512,512]},"format":"raw1"'
for m in FULL SMALL FULL; do
    run_job voxelize "${!m}" "{$G}"
    job_ok "a 512^3 job ($m)"
    [[ $m == FULL ]] && n=$((512 * 512 * 512)) || n=$((256 * 256 * 256))
    check "the $m box's voxels: $n" jq -e ".stats.voxels_inside == $n" "$TMP/job.json"
    api GET /metrics
    K=$(metric voxeld_kept_memory_bytes)
    check "after it its grid is kept, within the 20M ($K)" test "$K" -ge 16777216 -a "$K" -le 20971520
done
stop_daemon
# --pretouch-memory: the 20M mapped at start, the grids pieces of it, the
# whole 20M kept again after each job
start_daemon --keep-memory 20M --pretouch-memory yes || exit 1
check "pretouched at start (logged)" grep -q 'event=memory.pretouched bytes=20971520 ' "$TMP/daemon.log"
api GET /metrics
check "pretouched: 20M kept before a job ($(metric voxeld_kept_memory_bytes))" test "$(metric voxeld_kept_memory_bytes)" = 20971520
for m in FULL SMALL; do
    run_job voxelize "${!m}" "{$G}"
    job_ok "pretouched: a 512^3 job ($m)"
    [[ $m == FULL ]] && n=$((512 * 512 * 512)) || n=$((256 * 256 * 256))
    check "pretouched: the $m box's voxels: $n" jq -e ".stats.voxels_inside == $n" "$TMP/job.json"
    api GET /metrics
    check "pretouched: 20M kept after it ($(metric voxeld_kept_memory_bytes))" test "$(metric voxeld_kept_memory_bytes)" = 20971520
done
stop_daemon

# ---- the default --workers are the CPUs voxeld may use ----------------------------
# Pinned to one CPU (taskset: a cpuset, as docker --cpuset-cpus makes) it
# runs one worker, not one per CPU of the host; an explicit --workers wins.
if command -v taskset >/dev/null && taskset -c 0 true 2>/dev/null; then
    : >"$TMP/pin.log"
    taskset -c 0 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/pin-data" 2>"$TMP/pin.log" &
    PIN=$!
    for i in $(seq 1 300); do grep -q 'event=voxeld.ready' "$TMP/pin.log" && break; sleep 0.1; done
    kill -TERM "$PIN"
    wait "$PIN"
    check "pinned to CPU 0: workers=1 logged" grep -q 'event=voxeld.start .*workers=1 ' "$TMP/pin.log"
    taskset -c 0 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/pin-data" --workers 3 2>"$TMP/pin3.log" &
    PIN=$!
    for i in $(seq 1 300); do grep -q 'event=voxeld.ready' "$TMP/pin3.log" && break; sleep 0.1; done
    kill -TERM "$PIN"
    wait "$PIN"
    check "  ... --workers 3 wins" grep -q 'event=voxeld.start .*workers=3 ' "$TMP/pin3.log"
else
    echo "note: taskset cannot pin here: the --workers default check is skipped"
fi

# ---- a value with a blank stays one key=value pair in the log --------------------
# The data dir is the operator's: "data dir" logged bare was data_dir=.../data
# and a stray key "dir".
DATA="$TMP/my data" start_daemon || exit 1
stop_daemon
check "data_dir with a blank is quoted in voxeld.start" \
    grep -qF "data_dir=\"$TMP/my data\"" "$TMP/daemon.log"
check "  ... and in store.open" grep -qF "event=store.open dir=\"$TMP/my data\"" "$TMP/daemon.log"

# SIGUSR1 and SIGUSR2 are logged and ignored as SIGHUP (they killed it:
# 138, 140); with a notify socket but no watchdog (no WATCHDOG_USEC) the
# daemon says READY=1 and never WATCHDOG=1 (sd_watchdog_enabled's rule)
python3 "$VX_SOURCE_DIR/tests/integration/notify_listen.py" "$TMP/ops-notify" "$TMP/ops-notify.log" &
npid=$!
for _ in $(seq 50); do [[ -S "$TMP/ops-notify" ]] && break; sleep 0.1; done
NOTIFY_SOCKET=$TMP/ops-notify start_daemon || exit 1
upload "$VX_SOURCE_DIR/examples/meshes/torus.obj"
run_job voxelize "$MESH_ID" '{"resolution":16,"format":"summary"}' 60
job_ok "a job with a notify socket and no watchdog"
kill -USR1 "$PID"
kill -USR2 "$PID"
sleep 0.5
api GET /livez
check "SIGUSR1, SIGUSR2: still serving" test "$STATUS" = 200
check "... each logged" sh -c "grep -q 'signal=USR1 action=none' '$TMP/daemon.log' && grep -q 'signal=USR2 action=none' '$TMP/daemon.log'"
stop_daemon
sleep 0.3
kill "$npid"
check "no watchdog asked for: READY=1, no WATCHDOG=1 ($(cut -d' ' -f2- "$TMP/ops-notify.log" | cut -c1-40 | sort | uniq -c | tr '\n' ' '))" \
    sh -c "grep -q ' READY=1$' '$TMP/ops-notify.log' && ! grep -q 'WATCHDOG=1' '$TMP/ops-notify.log'"
finish
