#!/usr/bin/env bash
# One daemon per port (issue #10, defect 1): a second voxeld on a port that
# is taken exits non-zero and says the address is in use; sharing the port
# (SO_REUSEPORT) happens only when both ask for it with --reuse-port yes.
# A restart on the port a stopped daemon served binds at once, with the
# closed connections still in TIME_WAIT (SO_REUSEADDR).
source "$(dirname "$0")/lib.sh"
start_daemon || exit 1

# second_daemon LOG [flags...]: runs a voxeld on $PORT with its own data dir
# until it is ready (then stops it: rc 0) or exits (rc = its exit status).
second_daemon() {
    local log=$1 pid i
    shift
    "$VOXELD" --listen "127.0.0.1:$PORT" --data-dir "$TMP/data2" --workers 1 "$@" 2>"$log" &
    pid=$!
    for i in $(seq 1 600); do
        if grep -aq 'event=voxeld.ready' "$log"; then
            kill -TERM "$pid"
            wait "$pid"
            return 0
        fi
        if ! kill -0 "$pid" 2>/dev/null; then
            wait "$pid"
            return
        fi
        sleep 0.1
    done
    kill -KILL "$pid"
    return 99
}

second_daemon "$TMP/second.log"
rc=$?
check "a second daemon on a taken port exits non-zero (got $rc)" test "$rc" -ne 0 -a "$rc" -ne 99
check "its stderr says listen_failed" grep -aq 'code=listen_failed' "$TMP/second.log"
check "its stderr says the address is in use" grep -aqi 'address in use' "$TMP/second.log"
check "its message names no server path" bash -c "! grep -a 'listen_failed' '$TMP/second.log' | grep -q '$TMP'"
# ... and fails before it starts: no data dir opened (its journal's queued
# jobs were replayed and started, then stopped again), no GL context made.
check "it never opened its data dir" test ! -e "$TMP/data2"
check "  ... nor made a GL context" bash -c "! grep -aqE 'event=(store.open|gl.context|jobs.replayed)' '$TMP/second.log'"
api GET /livez
expect_status "the first daemon still serves" 200
# connections the server closes leave it TIME_WAIT sockets on the port
for i in 1 2 3; do
    python3 -c 'import sys, urllib.request; urllib.request.urlopen(sys.argv[1] + "/livez").read()' "$BASE"
done
stop_daemon
tw=$(ss -tan state time-wait "( sport = :$PORT )" 2>/dev/null | tail -n +2 | wc -l)
echo "note: $tw TIME_WAIT sockets on port $PORT"
second_daemon "$TMP/restart.log"
rc=$?
check "a restart on the stopped daemon's port starts at once (got $rc)" test "$rc" -eq 0

# --reuse-port yes on both: the second one starts.
start_daemon --reuse-port yes || exit 1
second_daemon "$TMP/third.log" --reuse-port yes
rc=$?
check "with --reuse-port yes on both, a second daemon starts (got $rc)" test "$rc" -eq 0
api GET /v1/info
expect_status "info" 200
stop_daemon

# [::]:PORT, the IPv6 wildcard, serves IPv4 clients too (dual stack: the one
# listen address for both); it was IPv6 only. :PORT is IPv4's every interface.
if [[ -e /proc/net/if_inet6 ]] && python3 -c 'import socket; s = socket.socket(socket.AF_INET6); s.bind(("::1", 0))' 2>/dev/null; then
    start_daemon --listen '[::]:0' || exit 1
    check "[::]:PORT answers over IPv6" curl -fsS -o /dev/null "http://[::1]:$PORT/livez"
    check "[::]:PORT answers over IPv4" curl -fsS -o /dev/null "http://127.0.0.1:$PORT/livez"
    stop_daemon
else
    echo "note: no IPv6 loopback: the dual-stack check is skipped"
fi
finish
