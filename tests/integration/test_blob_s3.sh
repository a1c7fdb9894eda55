#!/usr/bin/env bash
# --blob-store s3:// against a real S3 server (s3rver, tools/s3rver) started
# here on a free port: meshes and results round-trip through the bucket, a
# fresh data dir (empty cache) reads them back byte for byte, an outage
# answers 503 with Retry-After (and /readyz says so) and heals by itself,
# and a file over the part size goes up as a multipart upload.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"

S3RVER=$VX_SOURCE_DIR/tools/s3rver/node_modules/.bin/s3rver
if [[ ! -x "$S3RVER" ]] || ! command -v node >/dev/null; then
    echo "SKIP: s3rver not installed (npm ci --prefix tools/s3rver)"
    exit 77
fi
S3DIR=$TMP/s3
S3PID=
S3PORT=$(python3 -c 'import socket; s=socket.socket(); s.bind(("127.0.0.1",0)); print(s.getsockname()[1])')
start_s3() {
    "$S3RVER" -d "$S3DIR" -a 127.0.0.1 -p "$S3PORT" --configure-bucket vx-bucket >>"$TMP/s3rver.log" 2>&1 &
    S3PID=$!
    local i
    for i in $(seq 1 100); do
        curl -s -o /dev/null "http://127.0.0.1:$S3PORT/" && return 0
        sleep 0.1
    done
    echo "s3rver did not start"; cat "$TMP/s3rver.log"; return 1
}
stop_s3() { kill "$S3PID" 2>/dev/null; wait "$S3PID" 2>/dev/null; S3PID=; }
trap 'stop_s3; cleanup' EXIT
mkdir -p "$S3DIR"
start_s3 || exit 1

# s3rver's one account; the credentials come from a --blob-credentials file.
cat >"$TMP/creds" <<'EOF'
# comments and [profile] lines are skipped
[default]
aws_access_key_id = S3RVER
aws_secret_access_key = S3RVER
EOF
URL="s3://vx-bucket/voxeld/a?endpoint=http://127.0.0.1:$S3PORT&region=us-east-1"
FLAGS=(--blob-store "$URL" --blob-credentials "$TMP/creds" --blob-part-size 5M --blob-retries 2
    --blob-timeout 5)
start_daemon "${FLAGS[@]}" || exit 1

api GET /readyz
expect_status "readyz with the bucket up" 200
check "readyz names the s3 backend" jq -e '.blob_store == {"backend":"s3","ok":true}' "$BODY"

box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
expect_status "upload to s3" 201
BOX=$MESH_ID
check "the mesh is an object in the bucket" \
    test -n "$(find "$S3DIR/vx-bucket/voxeld/a/meshes" -name "$BOX.obj*" 2>/dev/null)"
run_job voxelize "$BOX" '{"resolution":16,"format":"binvox"}'
job_ok "voxelize over s3"
VJ=$JOB
api GET "/v1/jobs/$VJ/result"
expect_status "result download" 200
cp "$BODY" "$TMP/result1"
check "the result is in the bucket" test -d "$S3DIR/vx-bucket/voxeld/a/results/$VJ"
api GET "/v1/meshes/$BOX/file"
[[ "$STATUS" == 200 ]] && cp "$BODY" "$TMP/mesh1"
stop_daemon

# A fresh data dir (no journal, no cache) on the same bucket: the index is
# rebuilt by listing the bucket, the bytes come back from it.
DATA=$TMP/data2
start_daemon "${FLAGS[@]}" || exit 1
api GET "/v1/meshes/$BOX"
expect_status "mesh listed from the bucket" 200
check "metadata read back" jq -e --arg id "$BOX" '.id == $id' "$BODY"
api GET "/v1/meshes/$BOX/file"
if [[ "$STATUS" == 200 ]]; then
    check "mesh bytes equal after the restart" cmp -s "$BODY" "$TMP/box.obj"
fi
run_job voxelize "$BOX" '{"resolution":16,"format":"binvox"}'
job_ok "voxelize of a mesh fetched from the bucket"
api GET "/v1/jobs/$JOB/result"
check "same voxelization from the fetched mesh" cmp -s "$BODY" "$TMP/result1"
check "the mesh was fetched into the cache" test -f "$DATA/blobcache/meshes/$BOX.obj"

# The bucket goes away: writes answer 503 with Retry-After, /readyz turns
# 503, nothing hangs or crashes; then it comes back and so does the daemon.
stop_s3
box_obj "$TMP/box2.obj" 0 0 0 2 2 2
t0=$(date +%s)
upload "$TMP/box2.obj"
t1=$(date +%s)
expect_status "upload while the bucket is down" 503
check "503 has Retry-After" test -n "$(header Retry-After)"
check "the error is JSON" jq -e '.error.code | type == "string"' "$BODY"
check "the message says the server refused the connection ($(jqb .error.message))" \
    grep -q 'Connection refused' <<<"$(jqb .error.message)"
check "answered within 20 s ($((t1 - t0)) s)" test $((t1 - t0)) -lt 20
api GET /readyz
expect_status "readyz while the bucket is down" 503
check "readyz says the blob store is not ok" jq -e '.blob_store.ok == false' "$BODY"
api GET "/v1/jobs/$JOB/result"
expect_status "result download while the bucket is down" 503
check "its 503 has Retry-After" test -n "$(header Retry-After)"
# A job on the cached mesh runs, but its result cannot be uploaded: it
# fails store_failed (it said succeeded, and the result was gone after a
# restart).
KEEP=$JOB
run_job voxelize "$BOX" '{"resolution":17,"format":"binvox"}'
JOB=$KEEP
check "a result the bucket did not take fails the job ($(jq -c '{state,error}' "$TMP/job.json"))" \
    jq -e '.state == "failed" and .error.code == "store_failed"' "$TMP/job.json"
# A delete the bucket does not take is not answered 204 (the mesh came
# back with the bucket).
api DELETE "/v1/meshes/$BOX"
expect_error "delete while the bucket is down" 503 store_failed
check "its message says why ($(jqb .error.message))" grep -q 'Connection refused' <<<"$(jqb .error.message)"
check "its 503 has Retry-After" test -n "$(header Retry-After)"
# A mesh not in the cache cannot be fetched: 503, not "deleted" (404).
rm -f "$DATA/blobcache/meshes/$BOX.obj"
api GET "/v1/meshes/$BOX/file"
expect_error "a mesh's bytes while the bucket is down" 503 store_failed
check "daemon still alive" kill -0 "$PID"
start_s3 || exit 1
api GET /readyz
expect_status "readyz after the bucket is back" 200
api GET "/v1/jobs/$JOB/result"
check "result served again after the outage" cmp -s "$BODY" "$TMP/result1"
api GET "/v1/meshes/$BOX"
expect_status "the mesh whose delete failed is still there" 200
upload "$TMP/box2.obj"
expect_status "upload after the bucket is back" 201
BOX2=$MESH_ID
check "its object is in the bucket" test -n "$(find "$S3DIR/vx-bucket/voxeld/a/meshes" -name "$BOX2.obj*")"
api DELETE "/v1/meshes/$BOX2"
expect_status "delete a mesh on s3" 204
check "its objects left the bucket" test -z "$(find "$S3DIR/vx-bucket/voxeld/a/meshes" -name "$BOX2.*")"

# Over the part size (5M here): a multipart upload; s3rver's stored object
# equals the input.
python3 - "$TMP/big.obj" <<'EOF'
import sys
with open(sys.argv[1], "w") as f:
    f.write("# a long comment block makes the file big\n" * 1)
    for i in range(300000):
        f.write("v %d 0 0\nv %d 1 0\nv %d 0 1\n" % (i, i, i))
    for i in range(300000):
        f.write("f %d %d %d\n" % (3 * i + 1, 3 * i + 2, 3 * i + 3))
EOF
upload "$TMP/big.obj"
expect_status "upload of a multipart-sized mesh" 201
BIG=$MESH_ID
check "it went up in parts" grep -q 'event=blob.s3_multipart' "$TMP/daemon.log"
OBJ=$(find "$S3DIR/vx-bucket/voxeld/a/meshes" -name "$BIG.obj*" -type f -size +1M | head -n 1)
if [[ -z "$OBJ" ]]; then OBJ=$(find "$S3DIR/vx-bucket/voxeld/a/meshes" -path "*$BIG.obj*" -type f -size +1M | head -n 1); fi
check "s3rver's stored object equals the input" cmp -s "$OBJ" "$TMP/big.obj"
stop_daemon

# A cache budget of 1 byte: copies older than the grace time (5 s) are
# evicted when another one comes in; an evicted mesh is fetched again.
DATA=$TMP/data4
start_daemon "${FLAGS[@]}" --blob-cache-max-bytes 1 || exit 1
api GET "/v1/meshes/$BOX/file"
check "mesh served with a tiny cache" cmp -s "$BODY" "$TMP/box.obj"
CACHED=$(find "$DATA/blobcache" -name "$BOX.obj")
check "and cached" test -n "$CACHED"
sleep 6
box_obj "$TMP/box4.obj" 0 0 0 4 4 1
upload "$TMP/box4.obj"
expect_status "upload with a tiny cache" 201
check "the older copy was evicted" test ! -e "$CACHED"
check "the eviction was logged" grep -q 'event=blob.cache_evicted' "$TMP/daemon.log"
api GET "/v1/meshes/$BOX/file"
check "an evicted mesh is fetched again" cmp -s "$BODY" "$TMP/box.obj"
stop_daemon

# A bucket that does not exist: the daemon does not start, and says so.
NOB=("${FLAGS[@]}")
NOB[1]="s3://no-such-bucket?endpoint=http://127.0.0.1:$S3PORT&region=us-east-1"
"$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/data4" "${NOB[@]}" 2>"$TMP/nob.log"
check "a missing bucket: the daemon exits ($?)" test $? -ne 0
check "saying the bucket is missing ($(grep -o 'cannot list[^"]*' "$TMP/nob.log" | head -n 1))" \
    grep -q 'no such bucket or directory' "$TMP/nob.log"

# The credentials reach the server: an unknown access key is refused, and
# a daemon that cannot list the bucket does not start (an empty index it
# would never reload). (s3rver checks a V4 request's access key, not its
# signature: test_sigv4 checks the signing against AWS's vectors.)
sed -i 's/^aws_access_key_id = .*/aws_access_key_id = NOBODY/' "$TMP/creds"
"$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/data3" "${FLAGS[@]}" 2>"$TMP/bad.log"
check "a daemon that cannot list the bucket exits ($?)" test $? -ne 0
check "saying why" grep -q 'blob_store_unreachable' "$TMP/bad.log"
check "the server refused the key" grep -q 'event=blob.s3_failed.*status=403' "$TMP/bad.log"
stop_s3
sed -i 's/^aws_access_key_id = .*/aws_access_key_id = S3RVER/' "$TMP/creds"
# With the server down it waits (an S3 server starting beside the
# replicas: it exited 1 at once), each second for 30 s: a SIGTERM ends
# the wait (exit 0), and a server that comes up is used
"$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/data3" "${FLAGS[@]}" 2>"$TMP/down.log" &
DPID=$!
for _ in $(seq 100); do grep -q 'event=store.blob_wait' "$TMP/down.log" && break; sleep 0.1; done
check "with the server down: it waits, said ($(grep -c blob_wait "$TMP/down.log") waits)" \
    sh -c "kill -0 $DPID && grep -q 'event=store.blob_wait.*blob_store_unreachable' '$TMP/down.log'"
kill -TERM "$DPID"
t0=$(date +%s)
wait "$DPID"
rc=$?
check "SIGTERM ends the wait: exit 0 ($rc) within 6 s ($(($(date +%s) - t0)) s)" \
    sh -c "test $rc = 0 && test $(($(date +%s) - t0)) -le 6"
"$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/data3" "${FLAGS[@]}" 2>"$TMP/down2.log" &
DPID=$!
for _ in $(seq 100); do grep -q 'event=store.blob_wait' "$TMP/down2.log" && break; sleep 0.1; done
start_s3 || exit 1
for _ in $(seq 300); do grep -q 'event=voxeld.ready' "$TMP/down2.log" && break; sleep 0.1; done
check "the server up during the wait: ready ($(grep -o 'event=[a-z_.]*' "$TMP/down2.log" | sort | uniq -c | tr '\n' ' '))" \
    sh -c "kill -0 $DPID && grep -q 'event=voxeld.ready' '$TMP/down2.log'"
kill -TERM "$DPID"
wait "$DPID"
finish
