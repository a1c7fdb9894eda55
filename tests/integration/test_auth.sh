#!/usr/bin/env bash
# Bearer token on every /v1 route when --token-file is given; none on the
# ops endpoints; off by default. Also the config file and flag precedence.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
printf 's3cret-token\n' >"$TMP/token"
cat >"$TMP/voxeld.conf" <<CONF
# test config
token-file = $TMP/token
max-queued-jobs = 7
log-level = debug
CONF
start_daemon --config "$TMP/voxeld.conf" --max-queued-jobs 5 || exit 1
box_obj "$TMP/box.obj" 0 0 0 1 1 1

api GET /v1/info
expect_error "no token" 401 unauthorized
check "WWW-Authenticate" bash -c "grep -qi '^www-authenticate: Bearer' '$HDRS'"
api GET /v1/meshes -H "Authorization: Bearer wrong"
expect_error "wrong token" 401 unauthorized
api GET /v1/meshes -H "Authorization: Bearer s3cret-token-and-more"
expect_error "token with a suffix" 401 unauthorized
# Authorization comes once: the check reads the first, a proxy may go by
# the last.
api GET /v1/meshes -H "Authorization: Bearer s3cret-token" -H "Authorization: Bearer wrong"
expect_error "two Authorization headers, the first right" 400 invalid_request
check "saying so" jq -e '.error.message | test("more than one Authorization")' "$BODY"
# A body on a method that takes none is refused from the head, before
# auth (it was read into memory first, up to max-json-bytes).
api GET /livez --data-binary "@$TMP/box.obj" -X GET
expect_error "GET with a body" 400 invalid_request
api OPTIONS /v1/jobs -H "Content-Type: application/json" --data-binary '{}' -X OPTIONS
expect_error "OPTIONS with a body, no token" 400 invalid_request
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$TMP/box.obj"
expect_error "upload without token" 401 unauthorized
api GET /v1/jobs/0123456789abcdef0123456789abcdef
expect_error "job without token" 401 unauthorized
api GET /livez
expect_status "livez needs no token" 200
api GET /readyz
expect_status "readyz needs no token" 200
api GET /metrics
expect_status "metrics need no token" 200

TOKEN=s3cret-token
api GET /v1/info
expect_status "info with token" 200
check "info says auth" jq -e '.auth == true' "$BODY"
check "flag beats the config file" jq -e '.limits.max_queued_jobs == 5' "$BODY"
upload "$TMP/box.obj"
expect_status "upload with token" 201
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"preview\",\"params\":{\"width\":32,\"height\":32}}"
check "job with token" jq -e '.state == "succeeded"' "$BODY"
check "debug level from the config file" grep -q 'level=debug' "$TMP/daemon.log"
stop_daemon

TOKEN=
start_daemon || exit 1
api GET /v1/info
expect_status "no token configured: open" 200
check "info says no auth" jq -e '.auth == false' "$BODY"
stop_daemon

# Command line errors fail fast with a message.
"$VOXELD" --max-queued-jobs lots 2>"$TMP/err1"
check "bad flag value exits 2" test $? -eq 2
check "bad flag value is named" grep -q 'max-queued-jobs' "$TMP/err1"
printf 'no-such-key = 1\n' >"$TMP/bad.conf"
"$VOXELD" --config "$TMP/bad.conf" 2>"$TMP/err2"
check "unknown config key exits 2" test $? -eq 2
check "unknown config key is named" grep -q "no-such-key" "$TMP/err2"
# A FIFO named as the config file is refused at once, not waited on (an
# open of a FIFO blocks until a writer comes, deaf to SIGTERM).
mkfifo "$TMP/conf.fifo"
timeout -s KILL 10 "$VOXELD" --config "$TMP/conf.fifo" --listen 127.0.0.1:0 --data-dir "$TMP/d3" \
    2>"$TMP/err3"
check "a FIFO as --config exits 2 ($?)" test $? -eq 2
check "and says it is not a regular file" grep -q 'not a regular file' "$TMP/err3"
# An empty token file name (VOXELD_TOKEN_FILE=$UNSET in a unit) would
# leave /v1 open: refused like an empty token file.
"$VOXELD" --token-file "" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err4"
check "an empty --token-file exits 2" test $? -eq 2
VOXELD_TOKEN_FILE= "$VOXELD" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err5"
check "an empty VOXELD_TOKEN_FILE exits 2" test $? -eq 2
check "and says so" grep -q 'token-file is empty' "$TMP/err5"
# A limit of 0 that would refuse every upload, or remember no job, is a
# mistake: exit 2 naming it.
for opt in max-upload-bytes max-json-bytes job-history; do
    "$VOXELD" --$opt 0 --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err0"
    check "--$opt 0 exits 2" test $? -eq 2
    check "--$opt 0 is named" grep -q "$opt must be at least 1" "$TMP/err0"
done
# --listen must be ADDR:PORT with a port of 16 bits (99999 had wrapped to
# another port; a missing port exited 1 after the GL context was made).
for l in 127.0.0.1:99999 127.0.0.1 ::1:8080 localhost:http; do
    timeout 20 "$VOXELD" --listen "$l" --data-dir "$TMP/d3" 2>"$TMP/errl"
    rc=$?
    check "--listen $l exits 2 ($rc)" test $rc -eq 2
    check "--listen $l: said why" grep -q "voxeld: listen: '$l' is not ADDR:PORT" "$TMP/errl"
done
"$VOXELD" --workers 0 --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/errw"
check "--workers 0 exits 2 naming the range" sh -c "test $? -eq 2 && grep -q 'a whole number from 1 to 1024' '$TMP/errw'"
"$VOXELD" --blob-part-size 1M --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/errp"
check "--blob-part-size 1M exits 2 without an s3 store too" sh -c "test $? -eq 2 && grep -q 'blob-part-size must be at least 5M' '$TMP/errp'"
# Values only the queue can parse: a malformed database URL is a bad option
# too (exit 2), said before any connection is tried.
"$VOXELD" --database 'postgresql://u@[::1' --blob-store "file://$TMP/shared" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err6"
check "a malformed --database URL exits 2" test $? -eq 2
check "and says why" grep -q 'voxeld: --database: bad database URL' "$TMP/err6"
"$VOXELD" --database 'mysql://x/y' --blob-store "file://$TMP/shared" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err7"
check "a --database URL of another scheme exits 2" test $? -eq 2
# A token file is visible ASCII: a NUL cut the token short silently (the
# file's first 2 bytes became the whole token), a control character or a
# byte over 0x7e cannot be sent in a header.
printf 'k7\000Q9-the-rest-of-a-long-secret\n' >"$TMP/token_nul"
"$VOXELD" --token-file "$TMP/token_nul" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err9"
check "a token file with a NUL exits 2" test $? -eq 2
check "naming the byte" grep -q 'token file .* holds a byte that cannot be sent in an HTTP header (byte 2 is 0x00' "$TMP/err9"
printf '  s3cret\tmore\n' >"$TMP/token_tab"
"$VOXELD" --token-file "$TMP/token_tab" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err10"
check "a token file with a tab inside exits 2" test $? -eq 2
# Cluster mode with the data dir as the store: replicas could not read
# each other's meshes and results, so it is a bad option (exit 2).
"$VOXELD" --database 'postgresql://127.0.0.1:1/x' --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err8"
check "--database without --blob-store exits 2" test $? -eq 2
check "and says it needs a shared store" grep -q 'voxeld: database: cluster mode needs a --blob-store every replica shares' "$TMP/err8"
# A replica name that is not UTF-8 (the database refused it at every
# claim while /readyz said ready), or holds a blank or a control character
# (a newline forged log fields): exit 2 at start.
for name in $'\xff\xfe' $'a\nts=x level=error' 'node 1' $'n\x7f'; do
    timeout 20 "$VOXELD" --replica-name "$name" --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err_rn"
    rc=$?
    check "replica-name $(printf %q "$name"): exit 2 (rc $rc)" test $rc -eq 2
    check "replica-name $(printf %q "$name"): says why" grep -q 'replica-name must be UTF-8 without blanks or control characters' "$TMP/err_rn"
done
"$VOXELD" --replica-name 'nœud-1.eu' --database 'postgresql://127.0.0.1:1/x' --listen 127.0.0.1:0 --data-dir "$TMP/d3" 2>"$TMP/err_rn"
check "a UTF-8 replica name is taken (the next complaint is the store's)" grep -q 'needs a --blob-store' "$TMP/err_rn"
# The URL's connect_timeout sets the start-up wait: six of them (12 s for
# 2), not 30 s (it was read from an option nothing set). In the
# background while the checks below run.
T_CT=$(date +%s%N)
"$VOXELD" --database 'postgresql://127.0.0.1:1/x?connect_timeout=2' --blob-store "file://$TMP/shared" \
    --listen 127.0.0.1:0 --data-dir "$TMP/d5" 2>"$TMP/dbwait_ct.log" &
CTPID=$!
# SIGTERM while start-up waits for a database that is not up: exit 0 at
# once, not at the end of the wait (30 s).
"$VOXELD" --database 'postgresql://127.0.0.1:1/x' --blob-store "file://$TMP/shared" --listen 127.0.0.1:0 --data-dir "$TMP/d4" 2>"$TMP/dbwait.log" &
DPID=$!
for i in $(seq 1 100); do grep -q cluster.database_wait "$TMP/dbwait.log" && break; sleep 0.1; done
check "start-up waits for the database" grep -q cluster.database_wait "$TMP/dbwait.log"
T0=$(date +%s%N)
kill -TERM $DPID
wait $DPID
rc=$?
ms=$((($(date +%s%N) - T0) / 1000000))
check "SIGTERM during the database wait: exit 0 in ${ms} ms (rc $rc)" test $rc -eq 0 -a $ms -lt 5000
check "and logs why" grep -q 'event=voxeld.stop stage=database reason=signal' "$TMP/dbwait.log"
wait $CTPID
rc=$?
ms=$((($(date +%s%N) - T_CT) / 1000000))
check "connect_timeout=2: start-up gives up after six of them, exit 1 in ${ms} ms (rc $rc)" \
    test $rc -eq 1 -a $ms -ge 11000 -a $ms -lt 24000
"$VOXELD" --version >"$TMP/version"
check "--version" grep -q '^voxeld [0-9]' "$TMP/version"
"$VOXELD" --help >"$TMP/help"
check "--help lists every limit" bash -c "for f in max-upload-bytes max-triangles max-queued-jobs job-timeout request-timeout connection-timeout max-connections-per-ip; do grep -q -- \"--\$f\" '$TMP/help' || exit 1; done"
"$VOXELD" --egl-device 99 --listen 127.0.0.1:0 --data-dir "$TMP/d2" 2>"$TMP/err3"
rc=$?
check "missing EGL device is a configuration error: exit 2 (rc $rc)" test $rc -eq 2
check "missing EGL device is explained" grep -q -- '--egl-device: EGL device 99 does not exist' "$TMP/err3"
check "and logged with its own code" grep -q 'code=bad_egl_device' "$TMP/err3"
# --require-gpu first probes the device, then starts on it: exit 2 too
"$VOXELD" --egl-device 99 --require-gpu yes --listen 127.0.0.1:0 --data-dir "$TMP/d2" 2>"$TMP/err3g"
rc=$?
check "missing EGL device with --require-gpu: exit 2 (rc $rc)" test $rc -eq 2
STATE_DIRECTORY=$TMP/statedir timeout 20 "$VOXELD" --listen 127.0.0.1:0 2>"$TMP/sd.log" &
SPID=$!
for i in $(seq 1 100); do grep -q voxeld.ready "$TMP/sd.log" && break; sleep 0.1; done
kill -TERM $SPID; wait $SPID
check "STATE_DIRECTORY is the default data dir" test -f "$TMP/statedir/journal.log"
finish
