#!/usr/bin/env bash
# GET /v1/jobs/{id}/events (Server-Sent Events) and ?wait&progress: events
# in order with rising progress, ending at a terminal state; a stalled
# reader; the stream limit; keepalives; streams never hold HTTP threads.
source "$(dirname "$0")/lib.sh"
SSE="python3 $VX_SOURCE_DIR/tests/integration/sse.py"

# One HTTP thread: if a stream held it, nothing else would be answered.
# The keepalive comes from the environment (VOXELD_*), the limit from a flag
# that wins over its variable.
VOXELD_EVENT_KEEPALIVE=0.5 VOXELD_MAX_EVENT_STREAMS=50 \
    start_daemon --http-threads 1 --max-event-streams 3 || exit 1
api GET /v1/info
check "info: the limits from the environment and the flag" \
    jq -e '.limits.event_keepalive_s == 0.5 and .limits.max_event_streams == 3' "$BODY"
check "one HTTP thread is not a pool of 1 to libmicrohttpd (it warned that it ignored it)" \
    bash -c "! grep -q 'thread pool size' '$TMP/daemon.log'"
upload "$VX_MESH_DIR/stanford-bunny.obj"
expect_status "upload" 201
submit() { # submit RESOLUTION [MORE PARAMS]: JOB = the new voxelize job
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"voxelize\",\"params\":{\"resolution\":$1${2:+,$2}}}"
    JOB=$(jqb .id)
}
# B and B2 take seconds even on a fast machine: peel with three-axis voting.
SLOW='"method":"peel","inside":"robust"'

# --- streams of a running and a queued job ----------------------------
# B runs (and is canceled later); Q waits behind it and B2, so its streams see
# queued (and keepalives), then running with rising progress, then succeeded.
submit 1024 "$SLOW"
B=$JOB
submit 1024 "$SLOW" # keeps the GL thread busy after B's GL stage
B2=$JOB
submit 512
Q=$JOB
$SSE "$BASE/v1/jobs/$Q/events" --ready "$TMP/1.ready" >"$TMP/s1.json" &
P1=$!
$SSE "$BASE/v1/jobs/$Q/events" --ready "$TMP/2.ready" --stall 3 >"$TMP/stalled.json" &
P2=$!
$SSE "$BASE/v1/jobs/$B/events" --ready "$TMP/3.ready" >"$TMP/b.json" &
P3=$!
for i in $(seq 1 100); do
    [[ -e "$TMP/1.ready" && -e "$TMP/2.ready" && -e "$TMP/3.ready" ]] && break
    sleep 0.1
done
# Three streams open (one not reading at all): the one HTTP thread still
# answers. Were it held by a stream, this would wait until B is canceled
# below, and --max-time would end it.
check "GET beside three streams: answered while they are open" \
    test "$(curl -s -o /dev/null -w '%{http_code}' --max-time 20 "$BASE/v1/jobs/$B")" = 200
api GET "/v1/jobs/$B"
expect_status "GET beside three streams" 200
api GET "/v1/jobs/$B/events"
expect_error "a fourth stream" 503 too_many_streams
check "a fourth stream: Retry-After" test -n "$(header Retry-After)"

# ?wait&progress on the running job.
api GET "/v1/jobs/$B?wait=1&progress=2"
expect_error "progress above 1" 400 invalid_request
api GET "/v1/jobs/$B?wait=1&progress="
expect_error "empty progress" 400 invalid_request
api GET "/v1/jobs/$B?wait=60&progress=0.05"
expect_status "wait for progress 0.05" 200
check "wait&progress: answered at progress >= 0.05 ($(jqb .progress)), before the end ($(jqb .state))" \
    jq -e '.progress >= 0.05 and .state == "running"' "$BODY"
api GET "/v1/jobs/$B?wait=60&progress=0.01"
check "wait&progress: a progress already reached answers at once ($(jqb .state))" jq -e '.state == "running"' "$BODY"
api GET "/v1/jobs/$B?wait=0.3&progress=1"
check "wait&progress: a progress not reached answers at the wait's end ($(jqb .state) $(jqb .progress))" jq -e '.state == "running" and .progress < 1' "$BODY"
sleep 0.5
api DELETE "/v1/jobs/$B2"
api DELETE "/v1/jobs/$B"
wait "$P1" "$P2" "$P3"

check "stream: 200 text/event-stream" jq -e '.status == 200 and (.content_type | startswith("text/event-stream"))' "$TMP/s1.json"
check "stream: the server ends it" jq -e '.complete and (.error | not)' "$TMP/s1.json"
check "stream: several events ($(jq '.events | length' "$TMP/s1.json"))" jq -e '(.events | length) >= 3' "$TMP/s1.json"
check "stream: every event is 'job' with the job's id" jq -e --arg j "$Q" 'all(.events[]; .event == "job" and .data.id == $j)' "$TMP/s1.json"
check "stream: ids count 1, 2, 3, ..." jq -e '[.events[].id | tonumber] == [range(1; (.events | length) + 1)]' "$TMP/s1.json"
check "stream: progress never falls and rises" jq -e '[.events[].data.progress] as $p | ($p == ($p | sort)) and ($p[-1] > $p[0])' "$TMP/s1.json"
check "stream: queued, running, ..., succeeded" jq -e '[.events[].data.state] | .[0] == "queued" and .[-1] == "succeeded" and index("running") != null' "$TMP/s1.json"
check "stream: states only move forward" jq -e '[.events[].data.state | {queued: 0, running: 1, succeeded: 2}[.]] as $s | $s == ($s | sort) and all($s[]; . != null)' "$TMP/s1.json"
check "stream: no two events alike" jq -e '[.events[].data | [.state, .progress]] | length == (unique | length)' "$TMP/s1.json"
check "stream: keepalive comments while queued ($(jq .comments "$TMP/s1.json"))" jq -e '.comments >= 1' "$TMP/s1.json"
api GET "/v1/jobs/$Q"
check "stream: the last event is the job as GET answers it" jq -e --slurpfile s "$TMP/s1.json" '($s[0].events[-1].data | del(.timings)) == del(.timings)' "$BODY"
check "stalled reader: complete, ends succeeded" jq -e '.complete and .events[-1].data.state == "succeeded"' "$TMP/stalled.json"
check "stalled reader: events in order" jq -e '[.events[].id | tonumber] as $i | $i == ($i | sort) and ($i | length) >= 2' "$TMP/stalled.json"
check "stalled reader: progress never falls" jq -e '[.events[].data.progress] as $p | $p == ($p | sort)' "$TMP/stalled.json"
# B is canceled, unless it was done by then (a fast machine: the DELETE
# then deleted it, 404 now): its stream ends either way, at B's last state.
api GET "/v1/jobs/$B"
B_STATE=$(jq -r 'if .error.code == "job_not_found" then "succeeded" else .state end' "$BODY")
check "B's stream: complete, ends at B's final state ($B_STATE)" \
    jq -e --arg st "$B_STATE" '.complete and .events[-1].data.state == $st and ($st == "canceled" or $st == "succeeded")' "$TMP/b.json"
check "the limit counts open streams only: a new one is taken" \
    test "$($SSE "$BASE/v1/jobs/$Q/events" | jq -r '.status')" = 200

# A finished job: one event, then the end (recorded for the contract check).
api GET "/v1/jobs/$Q/events"
expect_status "finished job's stream" 200
check "finished job: text/event-stream" test "${CTYPE%%;*}" = text/event-stream
check "finished job: one event with the terminal state" \
    test "$(grep -c '^event: job$' "$BODY")-$(sed -n 's/^data: //p' "$BODY" | jq -r .state)" = "1-succeeded"
check "finished job: no-store" grep -qi '^cache-control: no-store' "$HDRS"
tr -d '\r' <"$HDRS" | grep -iE '^(content-type|cache-control|x-accel-buffering):' | tr A-Z a-z | sort >"$TMP/get.h"
api HEAD "/v1/jobs/$Q/events"
expect_status "HEAD events" 200
tr -d '\r' <"$HDRS" | grep -iE '^(content-type|cache-control|x-accel-buffering):' | tr A-Z a-z | sort >"$TMP/head.h"
check "HEAD events: GET's stream headers ($(tr '\n' ' ' <"$TMP/head.h"))" \
    bash -c "cmp -s '$TMP/get.h' '$TMP/head.h' && test \$(wc -l <'$TMP/head.h') -eq 3"
# and no body: the next answer on the same connection starts clean
HP=$(curl -sv -o /dev/null -w '%{http_code}' -I "$BASE/v1/jobs/$Q/events" --next -sv -o "$TMP/after.json" -w ' %{http_code}' "$BASE/livez" 2>"$TMP/after.err")
check "HEAD events then GET /livez on one connection ($HP)" test "$HP" = "200 200"
check "no bytes after HEAD's head ($(head -c 200 "$TMP/after.err"))" bash -c "! grep -qi excess '$TMP/after.err' && jq -e .status '$TMP/after.json' >/dev/null"
api GET /v1/jobs/0123456789abcdef0123456789abcdef/events
expect_error "unknown job's events" 404 job_not_found
api GET /v1/jobs/nothex/events
expect_error "malformed job id's events" 404

# --- a client that resets its stream is not a warning ------------------
# Two streams of a running job closed with a reset: the keepalive (0.5 s)
# writes to them within the second after, and libmicrohttpd reports the
# failed send; that is logged at debug (it had been a warning a stream).
submit 1024 "$SLOW"
from=$(($(wc -l <"$TMP/daemon.log") + 1))
python3 - "$PORT" "$JOB" <<'PY'
import socket, struct, sys, time
for _ in range(2):
    s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
    s.sendall(("GET /v1/jobs/%s/events HTTP/1.1\r\nHost: x\r\n\r\n" % sys.argv[2]).encode())
    s.recv(4096)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
    s.close()
time.sleep(1.5)
PY
n=$(tail -n +"$from" "$TMP/daemon.log" | grep -ac 'level=warn event=http.mhd' || true)
check "streams reset by their clients: no warnings ($n)" test "$n" = 0
api DELETE "/v1/jobs/$JOB"

# --- shutdown ends open streams ---------------------------------------
submit 1024
$SSE "$BASE/v1/jobs/$JOB/events" --ready "$TMP/last.ready" >"$TMP/shutdown.json" &
P4=$!
for i in $(seq 1 100); do [[ -e "$TMP/last.ready" ]] && break; sleep 0.1; done
stop_daemon
wait "$P4"
check "shutdown: the stream is ended, not reset" jq -e '.complete and (.events | length) >= 1' "$TMP/shutdown.json"

# --- clients gone between events free their stream slots at once ------
# (not at the next keepalive's failed write: 30 s here). One stream slot,
# a ?wait slot: a client closes, another resets, and the next is served.
start_daemon --max-event-streams 1 --event-keepalive 30 --max-waits 1 || exit 1
upload "$VX_MESH_DIR/stanford-bunny.obj"
submit 1024 "$SLOW"
RUN=$JOB
submit 64 # queued behind RUN: its streams get no event meanwhile
gone() { # gone PATH RST HEAD: a request whose client closes (RST 1: resets) after 1 s
    python3 - "$PORT" "$1" "$2" "$3" <<'PY'
import socket, struct, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(("GET %s HTTP/1.1\r\nHost: x\r\n\r\n" % sys.argv[2]).encode())
if sys.argv[4] == "1":
    s.settimeout(10)
    assert s.recv(4096).startswith(b"HTTP/1.1 200"), "no stream"
time.sleep(1)
if sys.argv[3] == "1":
    s.setsockopt(socket.SOL_SOCKET, socket.SO_LINGER, struct.pack("ii", 1, 0))
s.close()
PY
}
for rst in 0 1; do
    gone "/v1/jobs/$JOB/events" $rst 1
    sleep 0.8
    check "a stream after one whose client went away (reset $rst)" \
        test "$($SSE "$BASE/v1/jobs/$JOB/events" --max-time 1 | jq -r '.status')" = 200
    gone "/v1/jobs/$JOB?wait=30" $rst 0
    sleep 0.8
    api GET "/v1/jobs/$JOB?wait=0.2"
    expect_status "a ?wait after one whose client went away (reset $rst)" 200
done
api DELETE "/v1/jobs/$JOB"
api DELETE "/v1/jobs/$RUN"
stop_daemon

finish
