#!/usr/bin/env bash
# Deleting a mesh does not affect jobs already submitted on it (issue #10,
# defect 6): DELETE answers 204 and the mesh is gone from the API at once
# (404, not listed, new jobs 404), but its file stays until the last
# unfinished job that uses it (as its mesh, or named by its params: a
# gregory frame) has finished; also across a kill -9 between the delete and
# the run. The same bytes uploaded again are a mesh again (201), also while
# the old file is still held.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1

files() { ls "$DATA/meshes/" | grep -c "^$1\." ; }
post_job() { # MESH KIND PARAMS
    api POST /v1/jobs -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$1\",\"kind\":\"$2\",\"params\":$3}"
}
# gone_soon MESH: a job's end is published before its pins are dropped
# (and the files deleted): waits up to 5 s for them to go
gone_soon() {
    for _ in $(seq 50); do
        [[ $(files "$1") == 0 ]] && return
        sleep 0.1
    done
}
# slow: a job that holds the GL thread (voxelizing by slices, about a
# minute) so that the jobs submitted after it stay queued until unblock
# cancels it.
slow() {
    post_job "$OGRE" voxelize '{"resolution":1024,"supersample":2,"method":"slice","format":"summary"}'
    SLOW=$(jqb .id)
    local i
    for i in $(seq 1 100); do
        api GET "/v1/jobs/$SLOW"
        [[ "$(jqb .state)" == running ]] && return 0
        sleep 0.1
    done
}
unblock() {
    api DELETE "/v1/jobs/$SLOW"
    wait_job "$SLOW" 30
    check "the blocking job was canceled" jq -e '.state == "canceled"' "$BODY"
}
# queued JOB: the job is still queued (api in the shell itself: a $(...)
# subshell would lose its request count and reuse a body file).
queued() { api GET "/v1/jobs/$1"; jq -e '.state == "queued"' "$BODY"; }

upload "$VX_MESH_DIR/ogre.obj"
OGRE=$MESH_ID
box_obj "$TMP/a.obj" 0 0 0 1 1 1
upload "$TMP/a.obj"
expect_status "upload A" 201
A=$MESH_ID
box_obj "$TMP/b.obj" 0 0 0 2 1 1
upload "$TMP/b.obj"
B=$MESH_ID
check "A's file and metadata" test "$(files "$A")" = 2

# --- delete while one job on A and one naming A (gregory frame) are queued
slow
post_job "$A" preview '{"width":64,"height":64}'
Q1=$(jqb .id)
post_job "$B" gregory "{\"divisions\":2,\"frames\":[\"$A\"]}"
Q2=$(jqb .id)
KREQ="{\"mesh\":\"$A\",\"kind\":\"preview\",\"params\":{\"width\":40,\"height\":40}}"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: del-key" -d "$KREQ"
expect_status "a keyed job on A" 202
QK=$(jqb .id)
api DELETE "/v1/meshes/$A"
expect_status "delete A with jobs queued" 204
check "a 204 has no Content-Type" test -z "$CTYPE"
check "A's file kept while jobs use it" test -f "$DATA/meshes/$A.obj"
check "Q1 was still queued at the delete" queued "$Q1"
check "Q2 was still queued at the delete" queued "$Q2"
api GET "/v1/meshes/$A"
expect_error "deleted A" 404 mesh_not_found
api GET "/v1/meshes?limit=100"
check "A is not listed" jq -e '[.items[].id] | index("'"$A"'") == null and length == 2' "$BODY"
post_job "$A" preview '{}'
expect_error "a new job on A" 404 mesh_not_found
# a retry under its Idempotency-Key still answers its job (it was 404)
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: del-key" -d "$KREQ"
expect_status "the keyed job's retry after A's delete" 200
check "the same job" test "$(jqb .id)" = "$QK"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: del-key" \
    -d "{\"mesh\":\"$A\",\"kind\":\"preview\",\"params\":{\"width\":41}}"
expect_error "the key with another request on the deleted A" 404 mesh_not_found
post_job "$B" gregory "{\"frames\":[\"$A\"]}"
expect_error "a new job naming A" 404 mesh_not_found
api DELETE "/v1/meshes/$A"
expect_error "delete A twice" 404 mesh_not_found
check "A's file still kept" test -f "$DATA/meshes/$A.obj"
check "Q1 still queued" queued "$Q1"
unblock
wait_job "$Q1"
check "Q1 on the deleted mesh succeeded ($(jqb -c .error))" jq -e '.state == "succeeded"' "$BODY"
wait_job "$Q2"
check "Q2 naming the deleted mesh succeeded ($(jqb -c .error))" jq -e '.state == "succeeded" and (.outputs | has("frame_001"))' "$BODY"
gone_soon "$A"
check "A's files gone once its jobs ended" test "$(files "$A")" = 0
upload "$TMP/a.obj"
expect_status "the same bytes again" 201
check "A is back" test "$MESH_ID" = "$A"
api GET "/v1/meshes/$A"
expect_status "A again" 200
run_job preview "$A" '{"width":32,"height":32}'
job_ok "a job on A again"

# --- kill -9 between the delete and the run
slow
post_job "$A" preview '{"width":64,"height":64}'
Q3=$(jqb .id)
api DELETE "/v1/meshes/$A"
expect_status "delete A, Q3 queued" 204
check "Q3 queued at the delete" queued "$Q3"
kill9_daemon
check "after kill -9: A's file still there" test -f "$DATA/meshes/$A.obj"
start_daemon || exit 1
api GET "/v1/meshes/$A"
expect_error "after restart: A is still deleted" 404 mesh_not_found
post_job "$A" preview '{}'
expect_error "after restart: a new job on A" 404 mesh_not_found
check "after restart: Q3 queued behind the blocking job" queued "$Q3"
unblock
wait_job "$Q3"
check "after restart: Q3 succeeded ($(jqb -c .error))" jq -e '.state == "succeeded"' "$BODY"
gone_soon "$A"
check "after restart: A's files gone once Q3 ended" test "$(files "$A")" = 0

# --- A again, for the last part
upload "$TMP/a.obj"
expect_status "A uploaded a third time" 201

# --- re-upload while the old file is still held: stays after the jobs end
slow
post_job "$A" preview '{"width":64,"height":64}'
Q4=$(jqb .id)
api DELETE "/v1/meshes/$A"
expect_status "delete A, Q4 queued" 204
upload "$TMP/a.obj"
expect_status "re-upload while Q4 holds the file" 201
check "Q4 queued at the re-upload" queued "$Q4"
unblock
api GET "/v1/meshes?limit=100"
check "A listed again" jq -e '[.items[].id] | index("'"$A"'") != null' "$BODY"
wait_job "$Q4"
check "Q4 succeeded" jq -e '.state == "succeeded"' "$BODY"
api GET "/v1/meshes/$A"
expect_status "A stays after Q4" 200
check "A's file and metadata stay" test "$(files "$A")" = 2
stop_daemon
start_daemon || exit 1
api GET "/v1/meshes/$A"
expect_status "A after a restart" 200
api DELETE "/v1/meshes/$A"
expect_status "delete A with no job" 204
check "A's files gone at once" test "$(files "$A")" = 0

# Uploads of the same bytes racing deletes of that mesh: never a 5xx, no
# "repaired" damage that was a delete, and a mesh listed has its bytes.
# (The upload checked the file outside the lock, the delete removed it in
# between; the upload then moved its bytes in as a repair, failed to
# commit them again: 500, once in about a thousand.)
python3 - "$PORT" "$VX_MESH_DIR/spot_control_mesh.obj" >"$TMP/race.json" <<'PY'
import hashlib, http.client, json, sys, threading, time
port, src = int(sys.argv[1]), open(sys.argv[2], "rb").read()
bad, counts, lock = [], {}, threading.Lock()
for rnd in range(4):
    body = src + b"# race %d\n" % rnd
    mid = hashlib.sha256(body).hexdigest()
    stop = threading.Event()
    def loop(method):
        c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
        while not stop.is_set():
            if method == "POST":
                c.request("POST", "/v1/meshes", body, {"Content-Type": "model/obj"})
            else:
                c.request("DELETE", "/v1/meshes/" + mid)
            r = c.getresponse()
            text = r.read()
            with lock:
                counts[method + " %d" % r.status] = counts.get(method + " %d" % r.status, 0) + 1
                if r.status >= 500:
                    bad.append("%s %d %s" % (method, r.status, text[:120]))
    ts = [threading.Thread(target=loop, args=(m,)) for m in ["POST"] * 4 + ["DELETE"] * 2]
    [t.start() for t in ts]
    time.sleep(1.0)
    stop.set()
    [t.join() for t in ts]
    c = http.client.HTTPConnection("127.0.0.1", port, timeout=30)
    c.request("GET", "/v1/meshes/%s/file" % mid)
    r = c.getresponse()
    data = r.read()
    if r.status == 200 and hashlib.sha256(data).hexdigest() != mid:
        bad.append("round %d: the mesh is listed but its file is not its bytes" % rnd)
print(json.dumps({"counts": counts, "bad": bad}))
PY
check "uploads racing deletes: no 5xx, no listed mesh without its bytes ($(jq -c . "$TMP/race.json" | head -c 400))" \
    jq -e '.bad == [] and .counts["POST 201"] > 0 and .counts["DELETE 204"] > 0' "$TMP/race.json"
check "no mesh logged as repaired by the race" bash -c "! grep -q 'event=store.mesh_repaired' '$TMP/daemon.log'"
stop_daemon
finish
