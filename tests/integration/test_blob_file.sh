#!/usr/bin/env bash
# --blob-store file:///DIR: meshes, blobs and results live in DIR (a shared
# mount in production), the data dir keeps only local state. A daemon with a
# fresh data dir over the existing DIR serves what the first one stored; two
# daemons storing the same content-addressed mesh in one DIR agree.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"

# DIR on another file system than the data dir where there is one (as a
# mount would be): uploads are then copied in, not renamed.
SHARED=$TMP/shared
if [[ -d /dev/shm && -w /dev/shm && $(stat -c %d /dev/shm) != $(stat -c %d "$TMP") ]]; then
    SHARED=$(mktemp -d /dev/shm/voxeld-shared.XXXXXX)
fi
D1_PID=
trap '[[ -n "$D1_PID" ]] && kill -KILL "$D1_PID" 2>/dev/null; [[ $SHARED == /dev/shm/* ]] && rm -rf "$SHARED"; cleanup' EXIT
start_daemon --blob-store "file://$SHARED" || exit 1
api GET /readyz
expect_status "readyz over file://" 200
check "readyz names the file backend" jq -e '.blob_store == {"backend":"file","ok":true}' "$BODY"
box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
expect_status "upload to file://" 201
BOX=$MESH_ID
check "the mesh is in DIR" test -f "$SHARED/meshes/$BOX.obj" -a -f "$SHARED/meshes/$BOX.json"
check "not in the data dir" test ! -e "$DATA/meshes/$BOX.obj"
run_job voxelize "$BOX" '{"resolution":16,"format":"binvox"}'
job_ok "voxelize over file://"
J1=$JOB
api GET "/v1/jobs/$J1/result"
expect_status "result download" 200
cp "$BODY" "$TMP/result1"
check "the result is in DIR" test -d "$SHARED/results/$J1"
check "no staged leftovers" test -z "$(find "$SHARED" -name 'tmp-*')"

# A second daemon, own data dir, the same DIR, running at the same time:
# it lists what the first stored, and an upload of the same bytes is
# idempotent (same id, the file unchanged).
D1_PID=$PID D1_BASE=$BASE
DATA=$TMP/data2
start_daemon --blob-store "file://$SHARED" || exit 1
api GET "/v1/meshes/$BOX"
expect_status "second daemon lists the mesh from DIR" 200
api GET "/v1/meshes/$BOX/file"
check "mesh bytes equal through the second daemon" cmp -s "$BODY" "$TMP/box.obj"
upload "$TMP/box.obj"
check "same upload again: the same id ($STATUS)" test "$MESH_ID" = "$BOX"
run_job voxelize "$BOX" '{"resolution":16,"format":"binvox"}'
job_ok "voxelize on the second daemon"
api GET "/v1/jobs/$JOB/result"
check "same result from the second daemon" cmp -s "$BODY" "$TMP/result1"
stop_daemon
PID=$D1_PID BASE=$D1_BASE D1_PID=
box_obj "$TMP/box2.obj" 0 0 0 1 1 1
upload "$TMP/box2.obj"
expect_status "first daemon still writes" 201
stop_daemon

# A fresh data dir over the existing DIR after both stopped: everything is
# read back, including the results budget.
DATA=$TMP/data3
export VOXELD_BLOB_STORE="file://$SHARED" # the flag's environment variable
start_daemon || exit 1
unset VOXELD_BLOB_STORE
api GET "/v1/meshes?limit=10"
check "both meshes listed from DIR" jq -e '[.items[].id] | length == 2' "$BODY"
api GET /metrics
check "results bytes counted from DIR" grep -Eq '^voxeld_results_bytes [1-9]' "$BODY"
stop_daemon
check "the data dirs hold no meshes" test -z "$(ls "$TMP/data3/meshes" "$TMP/data2/meshes" 2>/dev/null)"

# A store on a file system mounted read-only (root only: a tmpfs remounted
# ro under a daemon that made its dirs): an upload is 503 store_failed with
# Retry-After (EROFS is the operator's to fix, not a 500), /readyz and
# voxeld_ready say not ready, and the daemon keeps serving.
RO=$TMP/rostore
mkdir -p "$RO"
if [[ $(id -u) -eq 0 ]] && mount -t tmpfs -o size=8m voxeld-ro "$RO" 2>/dev/null; then
    DATA=$TMP/data5
    start_daemon --blob-store "file://$RO" || exit 1
    stop_daemon
    if mount -o remount,ro "$RO"; then
        start_daemon --blob-store "file://$RO" || exit 1
        upload "$TMP/box.obj"
        expect_error "upload to a read-only store" 503 store_failed
        check "Retry-After on it" test -n "$(header Retry-After)"
        api GET /readyz
        check "readyz 503, the blob store not ok" bash -c "test '$STATUS' = 503 && jq -e '.blob_store.ok == false' '$BODY'"
        api GET /metrics
        check "voxeld_ready 0 with it" grep -q '^voxeld_ready 0$' "$BODY"
        api GET /livez
        expect_status "still serving" 200
        stop_daemon
    fi
    umount -l "$RO"
else
    echo "SKIP (part): a read-only store needs root to mount a tmpfs"
fi

api_bad_url() {
    "$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/data4" --blob-store "$1" 2>"$TMP/bad.log"
}
api_bad_url "file://relative/dir"
check "a relative file:// dir is refused at start, as a bad option (exit 2)" test $? -eq 2
check "saying it must be absolute" grep -q 'voxeld: --blob-store: .*absolute' "$TMP/bad.log"
api_bad_url "ftp://x"
check "an unknown scheme is refused at start, as a bad option (exit 2)" test $? -eq 2
check "with a message" grep -q 'bad_blob_store' "$TMP/bad.log"
finish
