#!/usr/bin/env bash
# GET /v1/jobs filters (kind, mesh, state) and order=desc; Idempotency-Key
# on POST /v1/jobs (also across a restart); reuse: true; deleting a
# finished job removes it and its result files (issue #13, Jobs).
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1
json() { echo -H "Content-Type: application/json"; }

box_obj "$TMP/a.obj" 0 0 0 1 1 1
box_obj "$TMP/b.obj" 0 0 0 2 1 1
upload "$TMP/a.obj"
A=$MESH_ID
upload "$TMP/b.obj"
B=$MESH_ID
run_job preview "$A" '{"width":32,"height":32,"samples":1}'
J1=$JOB
run_job voxelize "$A" '{"resolution":16,"format":"raw8"}'
J2=$JOB
job_ok "voxelize A"
run_job preview "$B" '{"width":32,"height":32,"samples":1}'
J3=$JOB

# ---- listing ----
api GET "/v1/jobs?order=desc"
expect_status "newest first" 200
check "order=desc: newest first" test "$(jqb '[.items[].id] | join(",")')" = "$J3,$J2,$J1"
api GET "/v1/jobs?order=asc"
check "order=asc: oldest first" test "$(jqb '[.items[].id] | join(",")')" = "$J1,$J2,$J3"
api GET "/v1/jobs?order=desc&limit=2"
check "desc page 1" test "$(jqb '[.items[].id] | join(",")')" = "$J3,$J2"
check "desc page 1 next" test "$(jqb .next)" = "$J2"
api GET "/v1/jobs?order=desc&limit=2&after=$J2"
check "desc page 2: older than after" test "$(jqb '[.items[].id] | join(",")')" = "$J1"
check "desc page 2: last" jq -e '.next == null' "$BODY"
api GET "/v1/jobs?kind=preview"
check "kind=preview" test "$(jqb '[.items[].id] | join(",")')" = "$J1,$J3"
api GET "/v1/jobs?mesh=$A"
check "mesh=A" test "$(jqb '[.items[].id] | join(",")')" = "$J1,$J2"
api GET "/v1/jobs?mesh=$A&kind=preview&order=desc"
check "mesh and kind together" test "$(jqb '[.items[].id] | join(",")')" = "$J1"
api GET "/v1/jobs?kind=voxelize&state=failed"
check "kind and state together: none" jq -e '.items == []' "$BODY"
api GET "/v1/jobs?order=newest"
expect_error "order=newest" 400 invalid_request
api GET "/v1/jobs?kind=nosuchkind"
expect_error "unknown kind" 400 invalid_request
api GET "/v1/jobs?kind=Preview"
expect_error "kind not in form" 400 invalid_request
api GET "/v1/jobs?mesh=1234"
expect_error "mesh not an id" 400 invalid_request
api GET "/v1/jobs?kind=preview&kind=voxelize"
expect_error "kind twice" 400 invalid_request

# ---- Idempotency-Key ----
REQ="{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"resolution\":16,\"format\":\"raw8\"}}"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-1" -d "$REQ"
expect_status "first keyed submission" 202
K1=$(jqb .id)
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-1" -d "$REQ"
expect_status "same key, same body: the same job" 200
check "same job id" test "$(jqb .id)" = "$K1"
check "with its Location" test "$(header Location)" = "/v1/jobs/$K1"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-1" \
    -d "{\"kind\":\"voxelize\",\"mesh\":\"$B\",\"params\":{\"format\":\"raw8\",\"resolution\":16}}"
expect_status "same key, same request written otherwise" 200
check "still the same job" test "$(jqb .id)" = "$K1"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-1" \
    -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"resolution\":17,\"format\":\"raw8\"}}"
expect_error "same key, another body" 422 idempotency_key_reused
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key 2" -d "$REQ"
expect_error "a key with a space" 400 invalid_request
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-2" -d "$REQ"
expect_status "another key: a new job" 202
check "a new job id" test "$(jqb .id)" != "$K1"
wait_job "$K1"

# ---- reuse ----
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16},\"reuse\":true}"
expect_status "reuse: an existing succeeded job" 200
check "reuse: it is J2" test "$(jqb .id)" = "$J2"
check "reuse: succeeded" jq -e '.state == "succeeded"' "$BODY"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16}}"
expect_status "without reuse: a new job" 202
NEWJ=$(jqb .id)
check "without reuse: a new id" test "$NEWJ" != "$J2"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":18},\"reuse\":true}"
expect_status "reuse with other params: a new job" 202
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"reuse\":\"yes\"}"
expect_error "reuse must be a boolean" 400 invalid_request
wait_job "$NEWJ"
# With a key the key's own job answers: a reused job would answer only
# the first request, and its retries would queue new jobs. (J3, B's
# preview, is the job reuse would answer.)
PREVB="{\"mesh\":\"$B\",\"kind\":\"preview\",\"params\":{\"width\":32,\"height\":32,\"samples\":1}"
api POST /v1/jobs -H "Content-Type: application/json" -d "$PREVB,\"reuse\":true}"
expect_status "reuse without a key: J3" 200
check "J3 reused" test "$(jqb .id)" = "$J3"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-3" -d "$PREVB,\"reuse\":true}"
expect_status "reuse with a key: the key's new job" 202
K3=$(jqb .id)
check "not J3" test "$K3" != "$J3"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-3" -d "$PREVB}"
expect_status "the key's retry without reuse" 200
check "the key's job" test "$(jqb .id)" = "$K3"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-3" -d "$PREVB,\"reuse\":true}"
expect_status "the key's retry with reuse" 200
check "the key's job again" test "$(jqb .id)" = "$K3"
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-3" \
    -d "{\"mesh\":\"$B\",\"kind\":\"preview\",\"params\":{\"width\":33},\"reuse\":true}"
expect_error "the key with another request and reuse" 422 idempotency_key_reused
wait_job "$K3"

# ---- delete a finished job ----
check "J2's results are on disk" test -d "$DATA/results/$J2"
api DELETE "/v1/jobs/$J2"
expect_status "delete a finished job" 204
check "its result files are gone" test ! -e "$DATA/results/$J2"
api GET "/v1/jobs/$J2"
expect_error "a deleted job" 404 job_not_found
api GET "/v1/jobs/$J2/result"
expect_error "a deleted job's result" 404 job_not_found
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16},\"reuse\":true}"
expect_status "reuse after the delete: the other succeeded copy" 200
check "reuse picks the copy that is left" test "$(jqb .id)" = "$NEWJ"

# ---- across a restart ----
stop_daemon
start_daemon || exit 1
api GET "/v1/jobs/$J2"
expect_error "a deleted job stays deleted after a restart" 404 job_not_found
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: key-1" -d "$REQ"
expect_status "the key survives a restart" 200
check "the same job after the restart" test "$(jqb .id)" = "$K1"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16},\"reuse\":true}"
expect_status "reuse after a restart" 200
check "reuse after a restart: the same job" test "$(jqb .id)" = "$NEWJ"
# A result damaged (another size than its job wrote) or removed under the
# daemon is no result to reuse: the download would be 410.
RF=$(find "$DATA/results/$NEWJ" -type f | head -n 1)
truncate -s 10 "$RF"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16},\"reuse\":true}"
expect_status "reuse of a job whose result was damaged: a new job" 202
FRESH=$(jqb .id)
check "not the damaged one" test "$FRESH" != "$NEWJ"
wait_job "$FRESH"
rm -rf "$DATA/results/$FRESH"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$A\",\"kind\":\"voxelize\",\"params\":{\"format\":\"raw8\",\"resolution\":16},\"reuse\":true}"
expect_status "reuse of a job whose result dir was removed: a new job" 202
check "neither old one" bash -c "test '$(jqb .id)' != '$FRESH' -a '$(jqb .id)' != '$NEWJ'"
wait_job "$(jqb .id)"

# ---- jobs canceled while queued, the history's limit, a 429's count ----
# A slow preview holds the GL thread; the jobs queued behind it are
# canceled: each says its cancel was asked for, and the history keeps its
# 3 finished jobs (canceled ones were kept past it until others finished).
# The queued jobs are slow previews too: once the first one's GL stage
# ends (its PNG is encoded on a worker) the next holds the GL thread, so
# two or more are still queued or running at the stop, on a loaded
# machine too (tiny ones ran and finished there before the stop).
stop_daemon
start_daemon --job-history 3 --max-queued-jobs 5 || exit 1
api GET "/v1/jobs?state=succeeded&limit=1000"
check "a history of 3 at the start" test "$(jqb '.items | length')" -le 3
slow_preview
Q=()
for i in 1 2 3 4 5; do
    api POST /v1/jobs -H "Content-Type: application/json" -d "{\"mesh\":\"$OGRE\",\"kind\":\"preview\",\"params\":{\"width\":$((8192 - i)),\"height\":8192,\"samples\":8}}"
    expect_status "queued $i" 202
    Q+=("$(jqb .id)")
done
for i in 0 1 2; do
    api DELETE "/v1/jobs/${Q[$i]}"
    expect_status "cancel queued $i" 200
    check "queued $i: canceled, its cancel asked for" jq -e '.state == "canceled" and .cancel_requested == true' "$BODY"
done
api GET "/v1/jobs/${Q[0]}"
check "the cancel stays asked for" jq -e '.state == "canceled" and .cancel_requested == true' "$BODY"
api GET "/v1/jobs?limit=1000"
check "3 finished jobs in the history ($(jqb -c '[.items[].state]'))" jq -e '[.items[] | select(.state != "queued" and .state != "running")] | length == 3' "$BODY"
# A restart with room for 1: of the slow job and the last two queued ones
# (all requeued) one runs and the others are queued: 2 (3 before the GL
# thread takes one) in a queue of 1, and a submission is told the depth.
stop_daemon
start_daemon --job-history 3 --max-queued-jobs 1 || exit 1
api POST /v1/jobs -H "Content-Type: application/json" -d "$SLOWREQ"
expect_error "a queue over its capacity" 429 queue_full
check "the 429 counts the jobs queued ($(jqb -r .error.message))" jq -e '.error.message | test("[(][23] queued[)]")' "$BODY"
api DELETE "/v1/jobs/$SLOW"
check "the slow job: canceled or its cancel asked for ($STATUS)" test "$STATUS" = 202 -o "$STATUS" = 200
wait_job "${Q[4]}" 120
check "the last queued job ran" jq -e '.state == "succeeded"' "$BODY"

stop_daemon
finish
