#!/usr/bin/env bash
# One daemon per data dir (issue #10, defect 1): a second voxeld on the same
# data dir exits non-zero with a clear message and touches nothing (the
# first one's journal is not compacted under it, its jobs survive kill -9);
# the lock goes with the process, so a restart after kill -9 just works.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1
FIRST=$PID
box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
BOX=$MESH_ID
run_job preview "$BOX" '{"width":32,"height":32}'
job_ok "job before the second start"
DONE=$JOB
JOURNAL_INODE=$(stat -c %i "$DATA/journal.log")

rc=0
timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" 2>"$TMP/second.log" || rc=$?
check "second daemon on the same data dir exits non-zero (got $rc)" test "$rc" -ne 0 -a "$rc" -ne 124
check "it says the data dir is in use, naming the first pid" grep -q "in use by another voxeld (pid $FIRST)" "$TMP/second.log"
check "it did not compact the first one's journal" test "$(stat -c %i "$DATA/journal.log")" = "$JOURNAL_INODE"
check "it never listened" bash -c "! grep -q 'event=http.listen' '$TMP/second.log'"
# The same through a symlink and a relative path to the same directory.
ln -s "$DATA" "$TMP/alias"
rc=0
(cd "$TMP" && timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir alias 2>"$TMP/third.log") || rc=$?
check "a symlink to the same data dir is refused too (got $rc)" test "$rc" -ne 0 -a "$rc" -ne 124
# The lock file deleted under the first daemon: the directory's own lock
# still refuses a second one (it had made a new lock file, started, and
# its journal compaction replaced the first one's: acknowledged jobs were
# lost at the next stop).
rm "$DATA/voxeld.lock"
rc=0
timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" 2>"$TMP/fourth.log" || rc=$?
check "with the lock file deleted, a second daemon is refused (got $rc: $(grep -m1 -o 'in use.*' "$TMP/fourth.log"))" \
    test "$rc" -eq 1
check "... saying the data dir is in use" grep -q "in use by another voxeld" "$TMP/fourth.log"
check "... and the journal is still the first one's" test "$(stat -c %i "$DATA/journal.log")" = "$JOURNAL_INODE"

api GET /livez
expect_status "first daemon still serving" 200
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":40,\"height\":40}}"
expect_status "job acknowledged after the refused start" 202
LATE=$(jqb .id)
kill9_daemon

# The lock died with the process: the next start takes it.
start_daemon || exit 1
api GET "/v1/jobs/$DONE"
check "earlier job kept" jq -e '.state == "succeeded"' "$BODY"
wait_job "$LATE" 60
check "job acknowledged beside the refused daemon ran" jq -e '.state == "succeeded"' "$BODY"
check "the lock file is back, holding the new pid" test "$(cat "$DATA/voxeld.lock")" = "$PID"
stop_daemon

# Started with its stdout and stderr closed (`voxeld 1>&- 2>&-`): the files
# it opened took descriptors 1 and 2, and its log went into the lock file
# (a second daemon then named "pid ts=..." as the holder).
FREE=$(python3 -c 'import socket; s = socket.socket(); s.bind(("127.0.0.1", 0)); print(s.getsockname()[1])')
"$VOXELD" --listen "127.0.0.1:$FREE" --data-dir "$DATA" 1>&- 2>&- &
PID=$!
for _ in $(seq 1 300); do curl -sf -o /dev/null "http://127.0.0.1:$FREE/livez" && break; sleep 0.1; done
check "with fds 1 and 2 closed it serves" curl -sf -o /dev/null "http://127.0.0.1:$FREE/livez"
check "the lock file holds its pid only ($(head -c 80 "$DATA/voxeld.lock"))" test "$(cat "$DATA/voxeld.lock")" = "$PID"
rc=0
timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" 2>"$TMP/fifth.log" || rc=$?
check "a second daemon names it as the holder" grep -q "in use by another voxeld (pid $PID)" "$TMP/fifth.log"
stop_daemon
finish
