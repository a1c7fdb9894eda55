#!/usr/bin/env bash
# Result downloads (issue #14 item 9): Content-Encoding zstd / gzip by
# Accept-Encoding, byte ranges (206, 416, If-Range) so a download can
# resume, and a 304 that keeps Cache-Control and carries no Content-Length.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1

box_obj "$TMP/box.obj" 0 0 0 3 2 1
upload "$TMP/box.obj"
expect_status "upload box" 201
run_job voxelize "$MESH_ID" '{"resolution":64,"format":"raw8"}'
job_ok "voxelize raw8"
R=/v1/jobs/$JOB/result
RAW_JOB=$JOB

api GET "$R"
expect_status "identity download" 200
cp "$BODY" "$TMP/full"
SIZE=$(stat -c %s "$TMP/full")
ETAG=$(header ETag)
check "identity: no Content-Encoding" test -z "$(header Content-Encoding)"
check "identity: Content-Length = file size" test "$(header Content-Length)" = "$SIZE"
check "Accept-Ranges: bytes" test "$(header Accept-Ranges)" = bytes
check "Vary: Accept-Encoding" grep -qi '^vary: Accept-Encoding' "$HDRS"

api GET "$R" -H "Accept-Encoding: zstd"
expect_status "zstd download" 200
check "Content-Encoding: zstd" test "$(header Content-Encoding)" = zstd
check "zstd body is smaller" test "$(stat -c %s "$BODY")" -lt "$((SIZE / 4))"
check "zstd body decodes to the file" bash -c "zstd -dc '$BODY' | cmp -s - '$TMP/full'"
check "the zstd representation has its own ETag" test "$(header ETag)" != "$ETAG"
ZETAG=$(header ETag)
# its log line and the metrics count the bytes sent (the log said 0)
ZBYTES=$(stat -c %s "$BODY")
sleep 0.2
ZLINE=$(grep -a 'event=http.request' "$TMP/daemon.log" | grep -a "route=/v1/jobs/{id}/result" | tail -n 1)
check "the zstd download's log line: bytes_out=$ZBYTES ($ZLINE)" grep -q "bytes_out=$ZBYTES " <<<"$ZLINE "

api GET "$R" -H "Accept-Encoding: gzip, deflate"
expect_status "gzip download" 200
check "Content-Encoding: gzip" test "$(header Content-Encoding)" = gzip
check "gzip body decodes to the file" bash -c "gzip -dc <'$BODY' | cmp -s - '$TMP/full'"

api GET "$R" -H "Accept-Encoding: zstd;q=0, gzip;q=0.5"
check "zstd;q=0 picks gzip" test "$(header Content-Encoding)" = gzip
api GET "$R" -H "Accept-Encoding: gzip;q=0.4, zstd;q=0.8"
check "the higher q wins" test "$(header Content-Encoding)" = zstd
api GET "$R" -H "Accept-Encoding: *"
check "* picks zstd" test "$(header Content-Encoding)" = zstd
api GET "$R" -H "Accept-Encoding: *;q=0, identity"
check "*;q=0: identity" test -z "$(header Content-Encoding)"
check "*;q=0: the whole file" cmp -s "$BODY" "$TMP/full"
api GET "$R" -H "Accept-Encoding: gzip;q=0.5, zstd;q=0.5, identity"
check "identity preferred by its q: sent as it is" test -z "$(header Content-Encoding)"
check "identity preferred: the whole file" cmp -s "$BODY" "$TMP/full"
api HEAD "$R" -H "Accept-Encoding: zstd"
expect_status "HEAD with zstd" 200
check "HEAD says the coding GET would send" test "$(header Content-Encoding)" = zstd

# Ranges apply to the identity bytes and are never compressed.
api GET "$R" -H "Range: bytes=100-199" -H "Accept-Encoding: zstd"
expect_status "a byte range" 206
check "range: identity" test -z "$(header Content-Encoding)"
check "Content-Range" test "$(header Content-Range)" = "bytes 100-199/$SIZE"
check "range: 100 bytes" test "$(header Content-Length)" = 100
check "range: the right bytes" cmp -s "$BODY" <(tail -c +101 "$TMP/full" | head -c 100)
check "range: the identity ETag" test "$(header ETag)" = "$ETAG"
api GET "$R" -H "Range: bytes=-10"
expect_status "a suffix range" 206
check "suffix: the last 10 bytes" cmp -s "$BODY" <(tail -c 10 "$TMP/full")
check "suffix Content-Range" test "$(header Content-Range)" = "bytes $((SIZE - 10))-$((SIZE - 1))/$SIZE"

# Resume: the first half, then the rest from where it stopped (If-Range).
HALF=$((SIZE / 2))
api GET "$R" -H "Range: bytes=0-$((HALF - 1))"
expect_status "first half" 206
cp "$BODY" "$TMP/resumed"
api GET "$R" -H "Range: bytes=$HALF-" -H "If-Range: $ETAG"
expect_status "resume with If-Range" 206
cat "$BODY" >>"$TMP/resumed"
check "first half + rest = the file" cmp -s "$TMP/resumed" "$TMP/full"
api GET "$R" -H "Range: bytes=$HALF-" -H 'If-Range: "stale"'
expect_status "If-Range with another ETag: the whole file" 200
check "stale If-Range: all bytes" cmp -s "$BODY" "$TMP/full"
api GET "$R" -H "Range: bytes=0-1,5-9"
expect_status "several ranges: the whole file" 200
api GET "$R" -H "Range: bytes=0-1" -H "Range: bytes=5-9"
expect_status "two Range lines are two ranges: the whole file" 200
check "two Range lines: all bytes" cmp -s "$BODY" "$TMP/full"
api GET "$R" -H "Range: bytes=0-9" -H "If-Range: $ETAG" -H "If-Range: $ETAG"
expect_status "two If-Range lines are a list, which matches nothing: the whole file" 200

api GET "$R" -H "Range: bytes=$SIZE-"
expect_error "range past the end" 416 range_not_satisfiable
check "416 Content-Range" test "$(header Content-Range)" = "bytes */$SIZE"

# 304: no Content-Length, the validators and Cache-Control of the 200.
api GET "$R" -H "If-None-Match: $ETAG"
expect_status "conditional GET" 304
check "304 has no Content-Length" bash -c "! grep -qi '^content-length' '$HDRS'"
check "304 keeps Cache-Control" test -n "$(header Cache-Control)"
check "304 ETag" test "$(header ETag)" = "$ETAG"
api GET "$R" -H "If-None-Match: $ZETAG" -H "Accept-Encoding: zstd"
expect_status "conditional GET of the zstd representation" 304
api GET "$R" -H "If-None-Match: $ETAG" -H "Accept-Encoding: zstd"
expect_status "the identity ETag does not validate the zstd representation" 200

# If-Match (RFC 9110 13.1.1): strong, before If-None-Match and Range.
api GET "$R" -H "If-Match: $ETAG"
expect_status "If-Match with the ETag" 200
check "If-Match: all bytes" cmp -s "$BODY" "$TMP/full"
api GET "$R" -H "If-Match: \"other\", $ZETAG" -H "Accept-Encoding: zstd"
expect_status "If-Match with the zstd ETag in a list" 200
api GET "$R" -H "If-Match: $ETAG" -H "Accept-Encoding: zstd"
expect_status "If-Match with the identity ETag, zstd sent" 200
api GET "$R" -H "If-Match: *" -H "Range: bytes=0-9"
expect_status "If-Match: * and a range" 206
api GET "$R" -H 'If-Match: "stale"'
expect_error "If-Match with another ETag" 412 precondition_failed
api GET "$R" -H "If-Match: W/$ETAG"
expect_error "If-Match compares strongly" 412 precondition_failed
api GET "$R" -H 'If-Match: "stale"' -H "If-None-Match: $ETAG" -H "Range: bytes=$SIZE-"
expect_error "If-Match before If-None-Match and Range" 412 precondition_failed
api HEAD "$R" -H 'If-Match: "stale"'
expect_status "HEAD with a failing If-Match" 412

# PNG is compressed already: sent as it is.
run_job preview "$MESH_ID" '{"width":64,"height":64,"samples":1}'
job_ok "preview"
api GET "/v1/jobs/$JOB/result" -H "Accept-Encoding: zstd, gzip"
expect_status "png download" 200
check "png is not compressed again" test -z "$(header Content-Encoding)"

# Framing and header edges on raw sockets (tests/integration/http_edges.py):
# HEAD of a coded result or an event stream sends no length and no body,
# 304s no Content-Length, list headers over several lines, If-Range with a
# list, a space before a colon (smuggling), a space in the target,
# absolute-form targets, Host values that are not a host and port.
python3 "$(dirname "$0")/http_edges.py" "$PORT" "$RAW_JOB" >"$TMP/edges.txt" 2>&1
check "http_edges.py ran ($(tail -n 1 "$TMP/edges.txt"))" grep -q '^PASS ' "$TMP/edges.txt"
while read -r verdict rest; do
    check "$rest" test "$verdict" = PASS
done <"$TMP/edges.txt"

# A result cut short on disk while it is sent as it is: the connection
# closes at once, so the client sees the answer end short of its
# Content-Length (libmicrohttpd waited for the missing bytes until
# --connection-timeout, 30 s). 27 MB, more than the sockets buffer.
run_job voxelize "$MESH_ID" '{"resolution":500,"format":"raw8"}'
job_ok "a 27 MB raw8"
CUT=$(python3 - "$PORT" "$JOB" "$DATA/results/$JOB" <<'PY'
import glob, os, socket, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(("GET /v1/jobs/%s/result HTTP/1.1\r\nHost: x\r\n\r\n" % sys.argv[2]).encode())
head = b""
while b"\r\n\r\n" not in head:
    head += s.recv(65536)
clen = int([l.split(b":")[1] for l in head.split(b"\r\n") if l.lower().startswith(b"content-length")][0])
got = len(head.split(b"\r\n\r\n", 1)[1])
os.truncate(glob.glob(sys.argv[3] + "/*")[0], 100000)
t0 = time.monotonic()
s.settimeout(60)
while got < clen:
    d = s.recv(1 << 20)
    if not d:
        break
    got += len(d)
print("%d %d %.1f" % (got, clen, time.monotonic() - t0))
PY
)
read -r CUT_GOT CUT_LEN CUT_S <<<"$CUT"
check "cut short while sent: the answer ends short ($CUT)" test "${CUT_GOT:-0}" -lt "${CUT_LEN:-0}"
check "cut short while sent: closed within 5 s ($CUT_S s)" awk -v t="${CUT_S:-99}" 'BEGIN{exit !(t < 5)}'
check "logged" grep -q "event=http.file_cut_short" "$TMP/daemon.log"

stop_daemon
finish
