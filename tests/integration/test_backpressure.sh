#!/usr/bin/env bash
# The GL stage runs at most one job ahead of the CPU workers (helper
# report, session 15): a burst of render jobs, each with a long CPU stage,
# stays in the bounded job queue (429 queue_full past --max-queued-jobs)
# instead of piling up as "running" with its memory held (8 renders all got
# 202 on a queue of 3 and held 6 GB); a job's wait for a free worker is
# reported (stats.cpu_wait_ms) and not held against --job-timeout.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
WORKERS=1 QUEUE=2
start_daemon --workers "$WORKERS" --max-queued-jobs "$QUEUE" --job-timeout 60 || exit 1
box_obj "$TMP/box.obj" 0 0 0 1 2 3
upload "$TMP/box.obj"
check "box uploaded" test -n "$MESH_ID"

# One render alone: its run time, and the CPU stage is most of it.
P='{"N":16,"R":1024,"L":1,"width":64,"height":64}'
run_job render "$MESH_ID" "$P"
job_ok "one render"
alone=$(jq '.timings.run_ms' "$TMP/job.json")
echo "note: one render alone $alone ms, gl $(jq '.stats.gl_ms' "$TMP/job.json") ms"

running_now() { curl -s "$BASE/metrics" | awk '$1 == "voxeld_jobs_running" {print $2}'; }
accepted=() refused=0 pids=()
# ten at once (more than workers + 2 + the queue)
for i in $(seq 1 10); do
    curl -s -o "$TMP/burst$i.json" -w '%{http_code}' -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"render\",\"params\":{\"N\":16,\"R\":1024,\"L\":1,\"width\":$((64 + i)),\"height\":64}}" \
        "$BASE/v1/jobs" >"$TMP/burst$i.code" &
    pids+=($!)
done
wait "${pids[@]}" # not a bare wait: the daemon is a child too
for i in $(seq 1 10); do
    case "$(cat "$TMP/burst$i.code")" in
    202) accepted+=("$(jq -r .id "$TMP/burst$i.json")") ;;
    429) refused=$((refused + 1)) ;;
    esac
done
echo "note: ${#accepted[@]} accepted, $refused refused"
check "a burst past the queue gets 429 (accepted ${#accepted[@]}, refused $refused)" test "$refused" -gt 0
most=0
for i in $(seq 1 100); do
    n=$(running_now)
    [[ -n "$n" && "$n" -gt "$most" ]] && most=$n
    [[ "$n" == 0 ]] && break
    sleep 0.1
done
check "running jobs stay at workers + 2 at most (saw $most)" test "$most" -le $((WORKERS + 2))
bad=0 waited=0
for jid in "${accepted[@]}"; do
    wait_job "$jid" 120
    if ! jq -e '.state == "succeeded"' "$BODY" >/dev/null; then
        bad=$((bad + 1))
        echo "job $jid: $(jq -c '{state, error}' "$BODY")"
    fi
    w=$(jq '.stats.cpu_wait_ms // 0 | floor' "$BODY")
    ((w > waited)) && waited=$w
done
check "every accepted render succeeds (failed $bad)" test "$bad" = 0
check "a job behind another waited for the worker, and says so (longest $waited ms)" test "$waited" -gt 0
stop_daemon
finish
