#!/usr/bin/env bash
# kill -9 loses no acknowledged upload or job; queued jobs run after a
# restart; SIGTERM puts the running job back in the queue; results persist.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
umask 022 # a caller's common umask: the daemon narrows it
start_daemon || exit 1

box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
BOX=$MESH_ID
upload "$VX_MESH_DIR/rocker-arm.obj"
ROCKER=$MESH_ID
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
DONE=$(jqb .id)
check "first job done" jq -e '.state == "succeeded"' "$BODY"
api GET "/v1/jobs/$DONE/result"
cp "$BODY" "$TMP/done.png"
api GET "/v1/jobs/$DONE"
cp "$BODY" "$TMP/done.json"
# whatever the caller's umask (this script's is 022), nothing in the data
# dir is readable by others
check "data dir: no file or dir others may read (umask 027)" \
    test -z "$(find "$DATA" -perm /o=rwx -print -quit)"
check "data dir: the result file is there" test -n "$(find "$DATA/results" -type f -print -quit)"

# Many acknowledged jobs, then kill -9 straight away.
JOBS=()
for i in $(seq 1 8); do
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$ROCKER\",\"kind\":\"preview\",\"params\":{\"width\":1024,\"height\":1024,\"azimuth\":$((i * 40))}}"
    [[ "$STATUS" == 202 ]] && JOBS+=("$(jqb .id)")
done
upload "$VX_MESH_DIR/fandisk.obj"
[[ "$STATUS" == 201 ]] && FANDISK=$MESH_ID
kill9_daemon
check "8 jobs were acknowledged" test "${#JOBS[@]}" -eq 8

start_daemon || exit 1
for m in "$BOX" "$ROCKER" "$FANDISK"; do
    api GET "/v1/meshes/$m"
    expect_status "mesh $m after kill -9" 200
done
api GET "/v1/jobs/$DONE/result"
check "finished result kept" cmp -s "$BODY" "$TMP/done.png"
# the journal keeps its times in full: created, started, finished and the
# timings (fractions of a millisecond) read back as they were
api GET "/v1/jobs/$DONE"
check "a finished job reads back the same after kill -9 (times and timings too; the replica name holds the pid)" \
    jq -e --slurpfile was "$TMP/done.json" 'del(.replica) == ($was[0] | del(.replica))' "$BODY"
# created is not before the millisecond its id names
ID_MS=$((16#${DONE:0:12}))
CREATED_MS=$(jq -r '.created' "$BODY" | python3 -c 'import sys, datetime; t = sys.stdin.read().strip(); print(int(datetime.datetime.strptime(t, "%Y-%m-%dT%H:%M:%S.%fZ").replace(tzinfo=datetime.timezone.utc).timestamp() * 1000 + 0.5))')
check "created ($CREATED_MS) is not before the id's time ($ID_MS)" test "$CREATED_MS" -ge "$ID_MS"
for j in "${JOBS[@]}"; do
    wait_job "$j" 300
    check "job $j finished after restart" jq -e '.state == "succeeded"' "$BODY"
done
api GET "/v1/jobs/${JOBS[7]}/result"
"$VX_TOOLS/pngstat" "$BODY" >"$TMP/last.json"
check "re-run job's image is real" jq -e '.width == 1024 and .covered > 1000' "$TMP/last.json"

# SIGTERM with a job running: it is queued again and finishes next time.
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$ROCKER\",\"kind\":\"preview\",\"params\":{\"width\":4096,\"height\":4096,\"samples\":8}}"
LONG=$(jqb .id)
api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
NEXT=$(jqb .id)
# A held request is answered on shutdown, not dropped.
curl -sv -o "$TMP/held.json" -w '%{http_code}' "$BASE/v1/jobs/$NEXT?wait=30" >"$TMP/held.code" \
    2>"$TMP/held.trace" &
CURL=$!
# the request is sent (curl -v prints its head then), and read a moment later
for _ in $(seq 1 200); do grep -q '^> GET' "$TMP/held.trace" && break; sleep 0.1; done
sleep 0.5
stop_daemon
wait "$CURL"
check "held request answered at shutdown ($(cat "$TMP/held.code"))" test "$(cat "$TMP/held.code")" = 200
check "held answer is the job" jq -e '.id == "'"$NEXT"'"' "$TMP/held.json"
check "journal says a clean stop" grep -q 'event=jobs.stopped' "$TMP/daemon.log"
start_daemon || exit 1
for j in "$LONG" "$NEXT"; do
    wait_job "$j" 300
    check "job $j finished after SIGTERM + restart" jq -e '.state == "succeeded"' "$BODY"
done

# A download under way at SIGTERM is let finish (the stop waits for answers
# being sent, --stop-timeout bounding it): it was cut 2 s after the jobs
# had stopped, and the daemon still exited 0. (--stop-timeout 120: the
# read takes about 8 s, longer on a loaded machine.)
stop_daemon
start_daemon --stop-timeout 120 || exit 1
run_job voxelize "$BOX" '{"grid":{"origin":[0,0,0],"voxel_size":0.02,"dims":[256,256,256]},"format":"raw8"}'
job_ok "a 16 MiB result"
# read at about 2 MB/s through a small receive buffer (the kernel's own
# buffers would otherwise hold what is left at the close)
python3 - "$PORT" "/v1/jobs/$JOB/result" >"$TMP/dl.code" <<'PY' &
import socket, sys, time
s = socket.socket()
s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 65536)
s.connect(("127.0.0.1", int(sys.argv[1])))
s.settimeout(60)
s.sendall(("GET %s HTTP/1.1\r\nHost: x\r\n\r\n" % sys.argv[2]).encode())
head, got = b"", 0
while True:
    x = s.recv(65536)
    if not x:
        break
    if b"\r\n\r\n" not in head:
        head += x
        if b"\r\n\r\n" in head:
            head, _, rest = head.partition(b"\r\n\r\n")
            head += b"\r\n\r\n"
            got = len(rest)
    else:
        got += len(x)
    time.sleep(0.02)
print(head.split(b" ")[1].decode(), got)
PY
CURL=$!
sleep 1
stop_daemon
wait "$CURL"
check "a download read at 2 MB/s through the stop got all of it ($(cat "$TMP/dl.code"))" \
    test "$(cat "$TMP/dl.code")" = "200 16777216"
start_daemon || exit 1

# The result budget: a small byte budget evicts the least recently used.
stop_daemon
start_daemon --results-max-bytes 20000 || exit 1
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":32,\"height\":32}}"
EVJ=$(jqb .id)
check "a result within the budget" jq -e '.state == "succeeded"' "$BODY"
api GET "/v1/jobs/$DONE/result"
expect_error "evicted result" 410 result_evicted
api GET "/v1/jobs/$DONE"
check "the evicted job is still known" jq -e '.state == "succeeded"' "$BODY"
# A result larger than the whole budget on its own fails its job (it was
# succeeded, every other result evicted, then its own: a 410 at once),
# its files removed, nothing else evicted.
api GET /metrics
EVICTED=$(awk '$1 == "voxeld_results_evicted_total" {print $2}' "$BODY")
run_job voxelize "$BOX" '{"resolution":80,"format":"raw8"}' # 80x54x27 bytes
check "a result over the whole budget fails its job" \
    jq -e '.state == "failed" and .error.code == "result_too_large"' "$TMP/job.json"
check "the message says its size and the budget" \
    jq -e '.error.message | test("is [0-9]{6} bytes") and test("--results-max-bytes 20000")' "$TMP/job.json"
check "its files are removed" test ! -e "$DATA/results/$JOB"
api GET "/v1/jobs/$EVJ/result"
expect_status "the other results stay" 200
api GET /metrics
check "nothing evicted for it" test "$(awk '$1 == "voxeld_results_evicted_total" {print $2}' "$BODY")" = "$EVICTED"

# A result file cut short on disk (or grown) is not served as the job's:
# 410 result_damaged, each output on its own, across a restart.
stop_daemon
start_daemon || exit 1
run_job voxelize "$BOX" '{"resolution":40,"format":"npy"}'
job_ok "npy job"
DJ=$JOB
api GET "/v1/jobs/$DJ/result"
expect_status "npy result" 200
FULL=$(stat -c %s "$BODY")
stop_daemon
NPY=$(find "$DATA" -path "*$DJ*" -name '*.npy' | head -n 1)
check "the result file is on disk" test -s "$NPY"
truncate -s 1000 "$NPY"
start_daemon || exit 1
api GET "/v1/jobs/$DJ/result"
expect_error "a result cut short" 410 result_damaged
check "the message says the sizes" jq -e --arg f "$FULL" '.error.message | test("1000 of " + $f + " bytes")' "$BODY"
api GET "/v1/jobs/$DJ"
check "the job itself is still known" jq -e '.state == "succeeded"' "$BODY"
# One there that cannot be read (a symlink loop here; a permission for an
# unprivileged daemon) is the server's fault, not an eviction: 500.
rm "$NPY"
ln -s "$(basename "$NPY")" "$NPY"
api GET "/v1/jobs/$DJ/result"
expect_error "a result file that cannot be read" 500 io_error
check "the message says why" jq -e '.error.message | test("cannot read the result file")' "$BODY"
check "logged at error" grep -q "level=error event=result.unreadable job=$DJ" "$TMP/daemon.log"
# A result dir removed behind the running daemon: 410, and out of the
# results budget's count (it stayed counted).
run_job voxelize "$BOX" '{"resolution":24,"format":"raw8"}'
job_ok "raw8 job"
GONE=$JOB
rb() { awk '$1 == "voxeld_results_bytes" {print $2}' "$BODY"; }
api GET /metrics
RB0=$(rb)
rm -rf "$DATA/results/$GONE"
api GET "/v1/jobs/$GONE/result"
expect_error "a result dir removed behind the daemon" 410 result_evicted
api GET /metrics
RB1=$(rb)
check "no longer counted in voxeld_results_bytes ($RB0 -> $RB1)" test "$RB1" -lt "$RB0"

# A mesh file changed on disk is neither served nor read as the mesh: 410
# mesh_damaged (a job on it fails with that code), across a restart; the
# same bytes uploaded again repair it. With one byte changed (same size,
# after the file was checked once), the file gone, a FIFO (which once hung
# every HTTP thread) and a directory in its place.
api GET "/v1/meshes/$BOX/file"
expect_status "the box's file" 200
MF=$(find "$DATA/meshes" -name "$BOX.*" ! -name '*.json' | head -n 1)
check "the box's file is on disk" test -s "$MF"
logged() { grep -c "event=store.mesh_$1 mesh=$BOX" "$TMP/daemon.log"; }
for damage in flip remove fifo directory huge; do
    DAMAGED=$(logged damaged) REPAIRED=$(logged repaired)
    case $damage in
    flip) printf 'X' | dd of="$MF" bs=1 seek=3 conv=notrunc status=none ;;
    remove) rm -f "$MF" ;;
    fifo) rm -f "$MF" && mkfifo "$MF" ;; # must not block a reader
    directory) rm -f "$MF" && mkdir "$MF" && touch "$MF/x" ;;
    # sparse: hashing it whole took a minute a request, every HTTP thread
    # (its size is not the mesh's: that decides, once per version)
    huge) truncate -s 64G "$MF" ;;
    esac
    api GET "/v1/meshes/$BOX/file" -m 20
    expect_error "a mesh file damaged ($damage)" 410 mesh_damaged
    check "logged ($damage)" test "$(logged damaged)" -gt "$DAMAGED"
    # no 304 for a file that is not there as its id says
    api GET "/v1/meshes/$BOX/file" -m 20 -H 'If-None-Match: *'
    expect_error "a mesh file damaged ($damage), If-None-Match: *" 410 mesh_damaged
    api GET "/v1/meshes/$BOX/file" -m 20 -H "If-None-Match: \"$BOX\""
    expect_error "a mesh file damaged ($damage), If-None-Match: its id" 410 mesh_damaged
    if [[ $damage == flip ]]; then
        stop_daemon
        start_daemon || exit 1
        api GET "/v1/meshes/$BOX/file"
        expect_error "a mesh file damaged ($damage), after a restart" 410 mesh_damaged
    fi
    # (the job thread keeps its last mesh loaded: another one first)
    run_job voxelize "$ROCKER" '{"resolution":8,"format":"raw1"}'
    run_job voxelize "$BOX" '{"resolution":16,"format":"raw1"}'
    check "a job on the damaged mesh fails mesh_damaged ($damage)" \
        jq -e '.state == "failed" and .error.code == "mesh_damaged"' "$TMP/job.json"
    FAILED_JOB=$JOB
    api GET "/v1/meshes/$BOX"
    expect_status "the mesh is still listed ($damage)" 200
    upload "$TMP/box.obj"
    expect_status "the same bytes again ($damage)" 200
    check "the upload wrote the file again ($damage)" \
        test "$(sha256sum <"$MF" | cut -c1-64)" = "$BOX"
    check "logged the repair ($damage)" test "$(logged repaired)" -gt "$REPAIRED"
    api GET "/v1/meshes/$BOX/file"
    expect_status "the repaired file ($damage)" 200
    check "served as uploaded ($damage)" cmp -s "$BODY" "$TMP/box.obj"
    run_job voxelize "$BOX" '{"resolution":16,"format":"raw1"}'
    job_ok "a job on the repaired mesh ($damage)"
done
# A mesh whose file is gone at start-up is damaged as at run time (it
# vanished, 404, its metadata kept and warned about at every start): 410
# mesh_damaged, and its upload repairs it.
rm -f "$MF"
stop_daemon
start_daemon || exit 1
check "logged" grep -q "event=store.missing_mesh_file mesh=$BOX" "$TMP/daemon.log"
api GET "/v1/meshes/$BOX"
expect_status "a mesh without its file after a restart is still there" 200
api GET "/v1/meshes/$BOX/file"
expect_error "a mesh without its file after a restart" 410 mesh_damaged
upload "$TMP/box.obj"
expect_status "its bytes again" 200
api GET "/v1/meshes/$BOX/file"
check "stored anew" cmp -s "$BODY" "$TMP/box.obj"
# DATA/meshes, DATA/tmp and DATA/results removed behind the running daemon
# (an operator's rm -rf): /readyz, uploads and jobs made them again (they
# stayed 503 and 500 until a restart); the same bytes again repair the
# mesh with its metadata, and a restart finds it as it was.
api GET "/v1/meshes/$BOX"
cp "$BODY" "$TMP/box-meta.json"
rm -rf "$DATA/meshes" "$DATA/tmp" "$DATA/results"
api GET /readyz
expect_status "/readyz with DATA/meshes and DATA/tmp removed" 200
check "DATA/meshes made again" test -d "$DATA/meshes"
check "logged" grep -q "event=store.dir_made_again path=.*/meshes" "$TMP/daemon.log"
rm -rf "$DATA/meshes" "$DATA/tmp"
upload "$TMP/box.obj"
expect_status "an upload with DATA/meshes and DATA/tmp removed: the mesh repaired" 200
check "its metadata written again" test -s "$DATA/meshes/$BOX.json"
box_obj "$TMP/box2.obj" 0 0 0 2 2 2
upload "$TMP/box2.obj"
expect_status "a new mesh" 201
run_job voxelize "$BOX" '{"resolution":12,"format":"raw8"}'
job_ok "a job with DATA/results removed"
stop_daemon
start_daemon || exit 1
api GET "/v1/meshes/$BOX"
check "after a restart, the repaired mesh's metadata as it was" jq -e --slurpfile m "$TMP/box-meta.json" '. == $m[0]' "$BODY"
api GET "/v1/meshes/$BOX/file"
check "and its file" cmp -s "$BODY" "$TMP/box.obj"
api GET "/v1/jobs/$JOB/result"
expect_status "the job's result after a restart" 200
# A mesh whose metadata file is damaged after the upload was acknowledged
# (emptied, or garbage) keeps its data file: the metadata is made anew
# from it at start-up, and jobs run on it (before, the data file was
# deleted as an upload that never finished).
upload "$VX_MESH_DIR/spot_triangulated.obj"
SPOT=$MESH_ID
SPOT_TRIS=$(jqb .triangles)
kill9_daemon
: >"$DATA/meshes/$BOX.json"
printf '{garbage' >"$DATA/meshes/$SPOT.json"
start_daemon || exit 1
for m in "$BOX" "$SPOT"; do
    api GET "/v1/meshes/$m"
    expect_status "mesh $m with damaged metadata after a restart" 200
done
check "its metadata made anew from the file" jq -e ".format == \"obj\" and .triangles == $SPOT_TRIS" "$BODY"
check "logged at warn" grep -q 'event=store.metadata_rebuilt' "$TMP/daemon.log"
run_job voxelize "$BOX" '{"resolution":16,"format":"raw1"}'
job_ok "a job on the mesh whose metadata was rebuilt"
# A metadata file gone (removed) is made anew the same way: its data file
# was deleted as a commit cut short. A data file of other bytes than its
# name says, and the temp files of writes a crash cut short, go.
kill9_daemon
rm "$DATA/meshes/$SPOT.json"
OTHER=$(printf '%064d' 7)
printf 'v 0 0 0\n' >"$DATA/meshes/$OTHER.obj"
printf '{"format":' >"$DATA/meshes/$BOX.json.tmp.999"
printf 'x' >"$DATA/meshes/tmp-1-1"
start_daemon || exit 1
api GET "/v1/meshes/$SPOT"
expect_status "a mesh whose metadata file was removed, after a restart" 200
check "its metadata made anew" jq -e ".format == \"obj\" and .triangles == $SPOT_TRIS" "$BODY"
check "logged" grep -q "event=store.metadata_rebuilt mesh=$SPOT" "$TMP/daemon.log"
api GET "/v1/meshes/$SPOT/file"
check "its file served" cmp -s "$BODY" "$VX_MESH_DIR/spot_triangulated.obj"
check "a data file of other bytes goes" test ! -e "$DATA/meshes/$OTHER.obj"
check "a metadata write's temp file goes" test ! -e "$DATA/meshes/$BOX.json.tmp.999"
check "a staged file goes" test ! -e "$DATA/meshes/tmp-1-1"
stop_daemon
# Results of a job the journal names but not as succeeded are removed at
# start-up: partial outputs of a job that never finished (it runs again
# from nothing), or failed. They had stayed across every restart, counted
# against the results budget. Results of a job no record names (a journal
# emptied, removed or damaged) are not a crash's: moved aside into
# DATA/lost+found/results-TIME/, said at error level (they were deleted,
# every one of them with a lost journal).
ORPHAN=0123456789abcdef0123456789abcdef
mkdir -p "$DATA/results/$ORPHAN" "$DATA/results/$FAILED_JOB"
head -c 4096 /dev/zero >"$DATA/results/$ORPHAN/voxels.raw"
head -c 4096 /dev/zero >"$DATA/results/$FAILED_JOB/voxels.raw"
start_daemon || exit 1
check "a failed job's results dir is removed at start-up" test ! -e "$DATA/results/$FAILED_JOB"
check "and logged" grep -q "event=store.result_pruned job=$FAILED_JOB" "$TMP/daemon.log"
check "a dir no job record names is moved aside" \
    bash -c "test ! -e '$DATA/results/$ORPHAN' && test -s '$DATA'/lost+found/results-*/$ORPHAN/voxels.raw"
check "logged at error" grep -q "level=error event=store.results_quarantined results=1 moved=1" "$TMP/daemon.log"
run_job voxelize "$BOX" '{"resolution":16,"format":"raw1"}'
job_ok "a succeeded job's results"
KEPT=$JOB
stop_daemon
check "a succeeded job's results stay" test -d "$DATA/results/$KEPT"
for lost in emptied removed; do
    cp "$DATA/journal.log" "$TMP/journal.keep"
    case $lost in
    emptied) : >"$DATA/journal.log" ;;
    removed) rm "$DATA/journal.log" ;;
    esac
    rm -rf "$DATA/lost+found"
    start_daemon || exit 1
    stop_daemon
    check "a journal $lost: no result is deleted" \
        bash -c "ls -A '$DATA'/lost+found/results-*/$KEPT | grep -q ."
    check "a journal $lost: logged at error" \
        grep -q "level=error event=store.results_quarantined results=[0-9]* moved=" "$TMP/daemon.log"
    # (back as it was: the results and the journal)
    mv "$DATA"/lost+found/results-*/* "$DATA/results/"
    cp "$TMP/journal.keep" "$DATA/journal.log"
done
# A meshes/ or results/ that cannot be listed (a plain file in its place,
# chmod 000): the daemon started with an empty index, or without its
# results (each 410, none counted by the budget), or /readyz 200 with
# every job failing io_error. It exits 1, saying which.
for dir in meshes results; do
    mv "$DATA/$dir" "$TMP/$dir.keep"
    printf 'x' >"$DATA/$dir"
    timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" 2>"$TMP/unlisted.log"
    rc=$?
    check "$dir a plain file: exit 1 (rc $rc)" test "$rc" -eq 1
    check "$dir a plain file: saying so" grep -q "cannot list .*/$dir: Not a directory" "$TMP/unlisted.log"
    rm "$DATA/$dir"
    mv "$TMP/$dir.keep" "$DATA/$dir"
done
# A journal with a long damaged tail (here 600 MB of zeros, sparse) is read
# in pieces (it was read whole: its size in memory, seconds), and the copy
# kept as evidence keeps the zeros as holes (it was written out densely).
# Peak memory against the same start without the tail: a line is kept up
# to 64 MiB, which ASan's quarantine of the grown buffers doubles or so.
start_daemon || exit 1
HWM0=$(awk '/VmHWM/ {print $2}' "/proc/$PID/status")
stop_daemon
JSIZE=$(stat -c %s "$DATA/journal.log")
truncate -s +600M "$DATA/journal.log"
start_daemon || exit 1
HWM=$(awk '/VmHWM/ {print $2}' "/proc/$PID/status")
check "logged as damage" grep -q 'level=error event=journal.damaged_tail' "$TMP/daemon.log"
echo "note: peak memory with a 600 MB damaged tail: $HWM kB, without: $HWM0 kB"
check "read in pieces: peak memory ${HWM} kB, ${HWM0} kB without the tail" test $((HWM - HWM0)) -lt 300000
check "the tail is cut" test "$(stat -c %s "$DATA/journal.log")" -le "$JSIZE"
COPY=$(ls -t "$DATA"/journal.log.damaged-* | head -n 1)
check "the damaged copy has the file's size" test "$(stat -c %s "$COPY")" -eq $((JSIZE + 600 * 1048576))
check "the damaged copy is sparse ($(du -k "$COPY" | cut -f1) kB)" test "$(du -k "$COPY" | cut -f1)" -lt 10000
api GET "/v1/jobs/$KEPT/result"
expect_status "the jobs are all there" 200
stop_daemon
rm -f "$DATA"/journal.log.damaged-*
# A FIFO where a file should be: start-up blocked in its open (or read)
# forever, deaf to SIGTERM. As a mesh's metadata it is made anew; as the
# journal the daemon exits 1, saying so.
rm "$DATA/meshes/$BOX.json"
mkfifo "$DATA/meshes/$BOX.json"
start_daemon || exit 1
api GET "/v1/meshes/$BOX"
expect_status "a FIFO as a mesh's metadata: made anew" 200
stop_daemon
mv "$DATA/journal.log" "$TMP/journal.keep"
mkfifo "$DATA/journal.log"
timeout 20 "$VOXELD" --listen 127.0.0.1:0 --data-dir "$DATA" 2>"$TMP/fifo.log"
rc=$?
check "a FIFO as the journal: exit 1 at once (rc $rc)" test "$rc" -eq 1
check "saying it is not a regular file" grep -q 'the journal is not a regular file' "$TMP/fifo.log"
rm "$DATA/journal.log"
mv "$TMP/journal.keep" "$DATA/journal.log"
finish
