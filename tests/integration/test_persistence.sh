#!/usr/bin/env bash
# kill -9 loses no acknowledged upload or job; queued jobs run after a
# restart; SIGTERM puts the running job back in the queue; results persist.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
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

# The result budget: a tiny byte budget evicts the least recently used.
stop_daemon
start_daemon --results-max-bytes 1 || exit 1
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":32,\"height\":32}}"
EVJ=$(jqb .id)
api GET "/v1/jobs/$DONE/result"
expect_error "evicted result" 410 result_evicted
api GET "/v1/jobs/$DONE"
check "the evicted job is still known" jq -e '.state == "succeeded"' "$BODY"

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
# A mesh whose file is gone at start-up is not indexed (404), and its
# upload stores it anew.
rm -f "$MF"
stop_daemon
start_daemon || exit 1
api GET "/v1/meshes/$BOX"
expect_error "a mesh without its file after a restart" 404 mesh_not_found
upload "$TMP/box.obj"
expect_status "its bytes again" 201
api GET "/v1/meshes/$BOX/file"
check "stored anew" cmp -s "$BODY" "$TMP/box.obj"
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
stop_daemon
# Results no succeeded job names are removed at start-up: a dir left by a
# delete that a crash cut short (no such job), and partial outputs of a job
# that never finished (it runs again from nothing). They had stayed across
# every restart, counted against the results budget.
ORPHAN=0123456789abcdef0123456789abcdef
mkdir -p "$DATA/results/$ORPHAN"
head -c 4096 /dev/zero >"$DATA/results/$ORPHAN/voxels.raw"
start_daemon || exit 1
check "an orphaned results dir is removed at start-up" test ! -e "$DATA/results/$ORPHAN"
check "and logged" grep -q "event=store.result_pruned job=$ORPHAN" "$TMP/daemon.log"
run_job voxelize "$BOX" '{"resolution":16,"format":"raw1"}'
job_ok "a succeeded job's results"
KEPT=$JOB
stop_daemon
check "a succeeded job's results stay" test -d "$DATA/results/$KEPT"
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
