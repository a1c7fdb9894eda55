#!/usr/bin/env bash
# --require-gpu (VOXELD_REQUIRE_GPU), issue #15: on a software GL renderer
# the daemon serves but is not ready: /readyz answers 503 naming the
# renderer (checks.gpu false), the start log says why, writes answer 503
# not_ready, and the jobs the journal queued again do not run (they run after
# a restart without the flag). Without the flag nothing changes. The context
# is put on Mesa's software EGL device explicitly (--egl-device), so the test
# means the same on a machine that has a GPU; exit 77 without that device.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"

SOFT=$("$VOXELD" --list-egl-devices 2>/dev/null | awk '$2 == "software" {print $1; exit}')
if [[ -z "$SOFT" ]]; then
    echo "SKIP: no Mesa software EGL device (EGL_MESA_device_software) to force llvmpipe on"
    exit 77
fi
DEV=(--egl-device "$SOFT")

# ---- without the flag: ready on llvmpipe, jobs run ---------------------------------
start_daemon "${DEV[@]}" || exit 1
api GET /v1/info
RENDERER=$(jqb .gl.renderer)
check "the software device's renderer is a software one ($RENDERER)" \
    grep -Eiq 'llvmpipe|softpipe|swrast' <<<"$RENDERER"
api GET /readyz
expect_status "readyz without --require-gpu" 200
check "checks.gpu is true and no reason" jq -e '.status == "ready" and .checks.gpu == true and (has("reason") | not)' "$BODY"
box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
BOX=$MESH_ID
run_job preview "$BOX" '{"width":32,"height":32}'
job_ok "a job on llvmpipe without the flag"
# Jobs acknowledged, then the daemon killed: the journal has them queued (or
# running), and replays them as queued on the next start.
JIDS=()
for i in 1 2 3 4; do
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":2048,\"height\":2048,\"samples\":4,\"azimuth\":$i}}"
    JIDS+=("$(jqb .id)")
done
kill9_daemon
check "no 'software' refusal logged without the flag" bash -c "! grep -q 'event=voxeld.gpu_required' '$TMP/daemon.log'"

# ---- with the flag: not ready, names the renderer, runs nothing ---------------------
start_daemon "${DEV[@]}" --require-gpu yes || exit 1
api GET /readyz
expect_status "readyz with --require-gpu on llvmpipe" 503
check "not_ready, checks.gpu false, reason names the renderer" \
    jq -e --arg r "$RENDERER" '.status == "not_ready" and .checks.gpu == false and (.reason | contains($r)) and (.reason | contains("--require-gpu"))' "$BODY"
check "the data dir checks still pass" jq -e '.checks.data_dir and .checks.disk_space' "$BODY"
check "the start log says why (event=voxeld.gpu_required, the renderer)" \
    grep -q "event=voxeld.gpu_required.*renderer=\"$RENDERER\"" "$TMP/daemon.log"
check "stderr says what to check" grep -q 'voxeld: --require-gpu: the GL renderer .* is a software one' "$TMP/daemon.log"
check "no gl.ready line for the refused context" bash -c "[ \$(grep -c 'event=gl.ready' '$TMP/daemon.log') -eq 1 ]"
api GET /livez
expect_status "livez stays 200 (the process is healthy, only unready)" 200
api GET /v1/info
check "/v1/info names the refused renderer" jq -e --arg r "$RENDERER" '.gl.renderer == $r' "$BODY"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":32,\"height\":32}}"
expect_error "job submission on the refused renderer" 503 not_ready
check "its message names the renderer" jq -e --arg r "$RENDERER" '.error.message | contains($r)' "$BODY"
upload "$TMP/box.obj"
expect_error "upload on the refused renderer" 503 not_ready
api GET /metrics
check "voxeld_ready is 0" grep -q '^voxeld_ready 0' "$BODY"
# The GL thread runs one job at a time: the later ones were still queued (or
# running) when the daemon was killed, and are queued again now.
QUEUED=()
for j in "${JIDS[@]}"; do
    api GET "/v1/jobs/$j"
    check "job $j is queued or had finished before the kill (no job running)" \
        jq -e '.state == "queued" or .state == "succeeded"' "$BODY"
    if [[ $(jqb .state) == queued ]]; then QUEUED+=("$j"); fi
done
check "some of the jobs were replayed as queued (${#QUEUED[@]})" test "${#QUEUED[@]}" -ge 1
sleep 3
for j in "${QUEUED[@]}"; do
    api GET "/v1/jobs/$j"
    check "replayed job $j stays queued 3 s later (no job runs on llvmpipe)" \
        jq -e '.state == "queued" and .started == null' "$BODY"
done
stop_daemon

# ---- the environment variable does the same; the systemd watchdog is fed ---------------
# The GL thread, which feeds the watchdog (WATCHDOG=1), does not run here: the
# main thread must feed it, or systemd (WatchdogSec=30 in the unit) would kill
# the refusing daemon with SIGABRT and restart it every 30 s. A watchdog of
# 2 s: a ping at least every second.
NOTIFY=$TMP/notify.sock
NLOG=$TMP/notify.log
: >"$NLOG"
python3 "$(dirname "$0")/notify_listen.py" "$NOTIFY" "$NLOG" &
LISTENER=$!
trap 'kill "$LISTENER" 2>/dev/null; cleanup' EXIT
for i in $(seq 1 50); do [[ -S "$NOTIFY" ]] && break; sleep 0.1; done
NOTIFY_SOCKET=$NOTIFY WATCHDOG_USEC=2000000 VOXELD_REQUIRE_GPU=yes start_daemon "${DEV[@]}" || exit 1
api GET /readyz
expect_status "readyz with VOXELD_REQUIRE_GPU=yes" 503
check "reason names the renderer" jq -e --arg r "$RENDERER" '.checks.gpu == false and (.reason | contains($r))' "$BODY"
sleep 4
stop_daemon
sleep 0.3
kill "$LISTENER" 2>/dev/null
wait "$LISTENER" 2>/dev/null
check "READY=1 sent" grep -q ' READY=1$' "$NLOG"
NW=$(awk '/ READY=1$/ {r=1} / STOPPING=1$/ {r=0} r && / WATCHDOG=1$/ {n++} END {print n+0}' "$NLOG")
GAP=$(awk '/ READY=1$/ {r=1; last=$1} / STOPPING=1$/ {r=0} r && / WATCHDOG=1$/ {g=$1-last; if (g>m) m=g; last=$1} END {printf "%.2f", m+0}' "$NLOG")
# (pings every second; a loaded machine may delay one: at least 3 in 4 s,
# and no gap as long as the watchdog itself)
check "WATCHDOG=1 fed while refusing the renderer ($NW pings in 4 s)" test "$NW" -ge 3
check "longest WATCHDOG=1 gap ${GAP}s under the 2 s watchdog" awk -v g="$GAP" 'BEGIN {exit !(g > 0 && g < 2.0)}'

# ---- without the flag again: the queued jobs run, nothing was lost ------------------
start_daemon "${DEV[@]}" || exit 1
api GET /readyz
expect_status "ready again without the flag" 200
for j in "${JIDS[@]}"; do
    wait_job "$j" 120
    check "job $j ran after the restart without the flag" jq -e '.state == "succeeded"' "$BODY"
done
stop_daemon
finish
