#!/usr/bin/env bash
# Cluster mode over an S3 bucket (issue 15): two replicas sharing one
# PostgreSQL (tests/support/pg.sh) and one s3rver bucket (tools/s3rver),
# each with its own data dir and cache:
# - upload on r1, submit on r2, the result read back byte for byte from
#   both;
# - the S3 server stopped for 10 s with a job queued: uploads (and a
#   submission on a replica that cannot check the mesh) answer 503
#   store_failed with Retry-After, /readyz is 503 naming the blob store, the
#   job's attempts that cannot reach the bucket fail as retryable; the S3
#   server back, the replicas recover by themselves and the job succeeds on
#   a later attempt, its result readable from both.
source "$(dirname "$0")/lib.sh"

S3RVER=$VX_SOURCE_DIR/tools/s3rver/node_modules/.bin/s3rver
if [[ ! -x "$S3RVER" ]] || ! command -v node >/dev/null; then
    echo "skip: s3rver not installed (npm ci --prefix tools/s3rver)"
    exit 77
fi
BUNNY="$VX_MESH_DIR/stanford-bunny.obj"
[[ -f "$BUNNY" ]] || { echo "skip: $BUNNY missing"; exit 77; }
source "$(dirname "$0")/cluster.sh"
S3DIR=$TMP/s3
mkdir -p "$S3DIR"
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
CLUSTER_STOP=stop_s3
start_s3 || exit 1
cat >"$TMP/creds" <<'EOF'
aws_access_key_id = S3RVER
aws_secret_access_key = S3RVER
EOF
BUCKET="s3://vx-bucket/cluster?endpoint=http://127.0.0.1:$S3PORT&region=us-east-1"
# Retries that outlast a 10 s outage: 2, 4, 8, 16 s between attempts.
REPLICA_FLAGS=(--blob-store "$BUCKET" --blob-credentials "$TMP/creds" --blob-retries 1
    --blob-timeout 2 --lease-ttl 3 --retry-backoff 2 --max-attempts 5)
for i in 1 2; do start_replica "$i" || exit 1; done

on 1
upload "$BUNNY"
expect_status "upload on r1 into the bucket" 201
B=$MESH_ID
on 2
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"resolution\":32,\"format\":\"raw8\"}}"
expect_status "submit on r2" 202
J=$(jqb .id)
wait_final 1 "$J" 60
check "succeeded" jq -e '.state == "succeeded" and .attempt == 1' "$BODY"
for i in 1 2; do
    on "$i"
    api GET "/v1/jobs/$J/result"
    expect_status "result from r$i" 200
    cp "$BODY" "$TMP/res$i"
done
check "the same bytes from both replicas" cmp "$TMP/res1" "$TMP/res2"

# A mesh neither replica has run yet, then the S3 server goes away.
box() { printf 'v 0 0 0\nv %s 0 0\nv 0 1 0\nv 0 0 1\nf 1 3 2\nf 1 2 4\nf 1 4 3\nf 2 3 4\n' "$1" >"$TMP/tet$1.obj"; }
box 2
on 2
upload "$TMP/tet2.obj"
expect_status "upload of a second mesh" 201
T2=$MESH_ID
# A mesh to delete during the outage, and a finished job whose result no
# one has asked for yet.
box 4
upload "$TMP/tet4.obj"
TD=$MESH_ID
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$B\",\"kind\":\"voxelize\",\"params\":{\"resolution\":20,\"format\":\"raw8\"}}"
JR=$(jqb .id)
wait_final 2 "$JR" 60
stop_s3
t_down=$(date +%s)
# A result the bucket cannot be asked about is no evicted one: 503 (or
# 200 from a replica's copy), never 410.
for i in 1 2; do
    on "$i"
    api GET "/v1/jobs/$JR/result"
    check "a result during the outage from r$i: $STATUS $(jqb '.error.code // empty'), not 410" \
        bash -c "test '$STATUS' = 200 || { test '$STATUS' = 503 && test -n '$(header Retry-After)'; }"
done
# The catalog takes the delete; the bytes' purge waits for the bucket
# (a purge the bucket did not take had dropped the row, and the next start
# cataloged the bytes again: the mesh was back).
on 1
api DELETE "/v1/meshes/$TD"
expect_status "a mesh deleted during the outage" 204
# r2 indexed the mesh at its upload: the submission is acknowledged; its
# attempts fail as retryable while the bucket is away (the mesh or the
# results unreachable) and back off 2, 4, 8 s.
on 2
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$T2\",\"kind\":\"voxelize\",\"params\":{\"resolution\":24,\"format\":\"raw8\"}}"
expect_status "a job submitted during the outage" 202
J2=$(jqb '.id // empty')
# r1 never saw that mesh: it cannot tell whether the bucket has it.
on 1
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$T2\",\"kind\":\"voxelize\",\"params\":{\"resolution\":25,\"format\":\"raw8\"}}"
expect_error "a submission on a replica that cannot check the mesh" 503 store_failed
check "Retry-After on it" test -n "$(header Retry-After)"
box 3
upload "$TMP/tet3.obj"
expect_error "upload during the outage" 503 store_failed
check "Retry-After on it" test -n "$(header Retry-After)"
api GET /readyz
check "readyz 503 names the blob store" bash -c "test '$STATUS' = 503 && jq -e '.blob_store.ok == false and (.reason | test(\"blob store\"))' '$BODY'"
sleep $((10 - ($(date +%s) - t_down) > 0 ? 10 - ($(date +%s) - t_down) : 0))
start_s3 || exit 1
ok=0
for t in $(seq 1 100); do
    api GET /readyz
    if [[ $STATUS == 200 ]]; then ok=1; break; fi
    sleep 0.2
done
check "r1 ready again by itself" test $ok = 1
wait_final 2 "$J2" 120
check "the job submitted during the outage succeeded on a later attempt, the failed ones store_failed ($(jq -c '{attempt, e: [.attempt_errors[]?.code]}' "$BODY"))" \
    jq -e '.state == "succeeded" and .attempt >= 2 and ([.attempt_errors[].code] | all(. == "store_failed"))' "$BODY"
for i in 1 2; do
    on "$i"
    api GET "/v1/jobs/$J2/result"
    expect_status "its result from r$i" 200
    cp "$BODY" "$TMP/t$i"
done
check "the same bytes from both" cmp "$TMP/t1" "$TMP/t2"
upload "$TMP/tet3.obj"
expect_status "upload after the outage" 201
# The purge ran again once the bucket was back (every renewal, 1 s); a
# restarted replica does not catalog the deleted mesh anew.
sleep 3
kill -TERM "${RPID[1]}"
wait "${RPID[1]}"
RPID[1]=
start_replica 1 || exit 1
for i in 1 2; do
    on "$i"
    api GET "/v1/meshes/$TD"
    expect_error "the mesh deleted during the outage, after r1's restart, on r$i" 404 mesh_not_found
done

for i in 1 2; do
    kill -TERM "${RPID[$i]}"
    rc=0
    wait "${RPID[$i]}" || rc=$?
    RPID[$i]=
    check "r$i exits 0" test $rc -eq 0
done
finish
