#!/usr/bin/env bash
# A browser on another origin can reach the API (--cors-origin: preflight
# OPTIONS answered, Access-Control-* on answers to allowed origins only),
# and every request has an X-Request-Id that the request log line carries
# with the concrete path and the client's address (issue #13).
source "$(dirname "$0")/lib.sh"
TOKEN=secret-token
printf '%s\n' "$TOKEN" >"$TMP/token"
start_daemon --token-file "$TMP/token" --cors-origin http://viewer.example \
    --cors-origin "http://b.example:8000, http://c.example" --max-event-streams 0 || exit 1

# Preflight: no credentials, answered 204 with what the browser asks about.
# (Raw curl: OPTIONS is outside the contract's operations.)
pre() { curl -sS -o "$TMP/pre.body" -D "$TMP/pre.h" -w '%{http_code}' -X OPTIONS "$@"; }
ph() { tr -d '\r' <"$TMP/pre.h" | awk -F': ' -v n="${1,,}" 'tolower($1)==n {print substr($0, length($1)+3)}' | tail -n 1; }
st=$(pre -H "Origin: http://viewer.example" -H "Access-Control-Request-Method: POST" \
    -H "Access-Control-Request-Headers: authorization, content-type" "$BASE/v1/jobs")
check "preflight: 204 (got $st)" test "$st" = 204
check "preflight: Allow-Origin is the origin" test "$(ph Access-Control-Allow-Origin)" = http://viewer.example
check "preflight: the route's methods" test "$(ph Access-Control-Allow-Methods)" = "GET, HEAD, POST, OPTIONS"
check "preflight: Authorization may be sent" bash -c "grep -qi '^access-control-allow-headers:.*Authorization' '$TMP/pre.h'"
check "preflight: Content-Type may be sent" bash -c "grep -qi '^access-control-allow-headers:.*Content-Type' '$TMP/pre.h'"
check "preflight: Max-Age" test -n "$(ph Access-Control-Max-Age)"
check "preflight: Vary: Origin" bash -c "grep -qi '^vary: Origin' '$TMP/pre.h'"
check "preflight: no body" test ! -s "$TMP/pre.body"
st=$(pre -H "Origin: http://b.example:8000" -H "Access-Control-Request-Method: GET" "$BASE/v1/jobs/01a200443ae27c41d09b5e3fa2c86d14/result")
check "preflight from a comma-listed origin: 204 (got $st)" test "$st" = 204
check "preflight from a comma-listed origin: allowed" test "$(ph Access-Control-Allow-Origin)" = http://b.example:8000
st=$(pre -H "Origin: http://evil.example" -H "Access-Control-Request-Method: POST" "$BASE/v1/jobs")
check "preflight from another origin: 204 (got $st)" test "$st" = 204
check "another origin gets no CORS headers" bash -c "! grep -qi '^access-control-' '$TMP/pre.h'"
st=$(pre "$BASE/v1/nowhere")
check "OPTIONS on an unknown path: 404 (got $st)" test "$st" = 404

# Normal answers carry Allow-Origin and Expose-Headers for allowed origins.
api GET /v1/info -H "Origin: http://c.example"
expect_status "info from an allowed origin" 200
check "answer: Allow-Origin" test "$(header Access-Control-Allow-Origin)" = http://c.example
check "answer: Expose-Headers names Location and X-Request-Id" bash -c "grep -qi '^access-control-expose-headers:.*Location.*X-Request-Id' '$HDRS'"
api GET /v1/info -H "Origin: http://c.example" -H "Origin: http://evil.example"
check "two Origin lines: no CORS headers" bash -c "! grep -qi '^access-control-' '$HDRS'"
api GET /v1/info -H "Origin: http://c.example http://evil.example"
check "an Origin list: no CORS headers" bash -c "! grep -qi '^access-control-' '$HDRS'"
api GET /v1/info -H "Origin: http://evil.example"
check "answer to another origin: no CORS headers" bash -c "! grep -qi '^access-control-' '$HDRS'"
check "answer to another origin: Vary: Origin all the same" bash -c "grep -qi '^vary: Origin' '$HDRS'"
api GET /v1/info
check "answer without Origin: no CORS headers" bash -c "! grep -qi '^access-control-' '$HDRS'"
# a cache must not give this answer to a page of an allowed origin
check "answer without Origin: Vary: Origin" bash -c "grep -qi '^vary: Origin' '$HDRS'"
SAVED=$TOKEN
TOKEN=
api GET /v1/meshes -H "Origin: http://viewer.example"
expect_error "401 from an allowed origin" 401 unauthorized
check "a 401 is readable by the page (Allow-Origin)" test "$(header Access-Control-Allow-Origin)" = http://viewer.example
TOKEN=$SAVED

# Request ids: made when absent, echoed when sane, replaced when not.
api GET /v1/meshes
RID=$(header X-Request-Id)
check "a request id is made ($RID)" bash -c "[[ '$RID' =~ ^[0-9a-f]{16}$ ]]"
api GET /v1/meshes
check "each request its own id" test "$(header X-Request-Id)" != "$RID"
api GET "/v1/jobs/01a200443ae27c41d09b5e3fa2c86d14" -H "X-Request-Id: client-abc.123"
expect_error "unknown job" 404 job_not_found
check "the client's id is echoed" test "$(header X-Request-Id)" = client-abc.123
api GET /v1/meshes -H "X-Request-Id: bad id with spaces"
check "an unsafe id is replaced" bash -c "[[ '$(header X-Request-Id)' =~ ^[0-9a-f]{16}$ ]]"
# log_line EVENT ID: the last log line of EVENT with request_id=ID into LINE
# (written once the answer is sent: it may come after curl returns)
log_line() {
    for _ in $(seq 1 100); do
        LINE=$(grep -a "event=$1" "$TMP/daemon.log" | grep -a "request_id=$2 " | tail -n 1)
        [[ -n $LINE ]] && break
        sleep 0.1
    done
}
log_line http.request client-abc.123
check "the log line has the request id" test -n "$LINE"
check "the log line has the concrete path" bash -c "grep -q 'path=/v1/jobs/01a200443ae27c41d09b5e3fa2c86d14 ' <<<'$LINE'"
check "the log line has the template route" bash -c "grep -q 'route=/v1/jobs/{id} ' <<<'$LINE'"
check "the log line has the client address" bash -c "grep -q 'client=127.0.0.1 ' <<<'$LINE'"
check "off the journal, lines start with ts= (no syslog priority)" bash -c "grep -q '^ts=' <<<'$LINE'"
# What a terminal would act on reaches no log line, nor a space that would
# split a bare value into two fields (DEL, C1 controls, bidi controls and
# bytes that are not UTF-8 went through as they were; a DEL made a space
# was the next): DEL, U+009B (8-bit CSI), U+0085 (NEL), U+202E
# (right-to-left override), U+2028 and a lone 0xff, in a path.
n=0
for p in a%7fb a%c2%9b31mb a%c2%85b a%e2%80%aeb a%e2%80%a8b a%ffb; do
    n=$((n + 1))
    api GET "/v1/jobs/$p" -H "X-Request-Id: clean-$n"
    log_line http.request "clean-$n"
done
check "those lines are clean UTF-8 with the characters replaced" python3 - "$TMP/daemon.log" <<'PY'
import re, sys
lines = [l for l in open(sys.argv[1], "rb").read().split(b"\n") if b"request_id=clean-" in l]
bad = re.compile("[\x00-\x1f\x7f-\x9f\u061c\u200e\u200f\u2028-\u202e\u2066-\u2069]")
ok = len(lines) == 6 and all(not bad.search(l.decode("utf-8")) and
                             re.search(rb"path=/v1/jobs/a\?(31m)?b ", l) for l in lines)
print(lines if not ok else "clean")
sys.exit(0 if ok else 1)
PY
# A 5xx's error line carries the request's id too (--max-event-streams 0:
# every stream is 503).
upload "$VX_SOURCE_DIR/examples/meshes/torus.obj"
run_job voxelize "$MESH_ID" '{"resolution":8,"format":"summary"}'
api GET "/v1/jobs/$JOB/events" -H "X-Request-Id: client-503.1"
expect_error "no event streams allowed" 503 too_many_streams
log_line http.error client-503.1
check "the http.error line names the request id" test -n "$LINE"
check "and the status and code" bash -c "grep -q 'status=503 code=too_many_streams' <<<'$LINE'"

stop_daemon

# A list option takes its values from the last source that names it: a
# flag narrows what the config file allowed (they were merged: a file's *
# let every origin in whatever the flag said).
printf 'cors-origin = *\n' >"$TMP/cors.conf"
VOXELD_CORS_ORIGIN=http://env.example start_daemon --config "$TMP/cors.conf" \
    --cors-origin http://viewer.example || exit 1
api GET /readyz -H "Origin: http://evil.example"
check "the file's * is gone under the flag" bash -c "! grep -qi '^access-control-allow-origin' '$HDRS'"
api GET /readyz -H "Origin: http://env.example"
check "the environment's origin is gone under the flag" bash -c "! grep -qi '^access-control-allow-origin' '$HDRS'"
api GET /readyz -H "Origin: http://viewer.example"
check "the flag's origin is allowed" test "$(header Access-Control-Allow-Origin)" = http://viewer.example
stop_daemon

# With * every origin is echoed back, but one only: an Origin list (RFC
# 6454 7.1) or two Origin lines would make an Allow-Origin a browser refuses.
start_daemon --cors-origin '*' || exit 1
api GET /readyz -H "Origin: http://a.example"
check "*: the origin is echoed" test "$(header Access-Control-Allow-Origin)" = http://a.example
api GET /readyz -H "Origin: http://a.example http://b.example"
check "*: an Origin list gets no Allow-Origin" bash -c "! grep -qi '^access-control-allow-origin' '$HDRS'"
api GET /readyz -H "Origin: http://a.example" -H "Origin: http://b.example"
check "*: two Origin lines get no Allow-Origin" bash -c "! grep -qi '^access-control-allow-origin' '$HDRS'"
api POST /v1/meshes -H "Origin: http://a.example" -H 'Content-Type: text/plain' --data-binary @"$VX_SOURCE_DIR/examples/meshes/torus.obj"
check "*: a write from any origin is taken ($STATUS)" test "$STATUS" = 200 -o "$STATUS" = 201
stop_daemon

# Another site's page cannot write through a visitor's browser (a
# text/plain POST needs no preflight: the upload was stored, 201), and a
# daemon without a token answers only its own Host names (DNS rebinding:
# a page of evil.example resolved to 127.0.0.1 read the API as
# same-origin).
TOKEN=
DATA=$TMP/data-origin
start_daemon --cors-origin http://viewer.example || exit 1
TORUS=$VX_SOURCE_DIR/examples/meshes/torus.obj
api POST /v1/meshes -H "Origin: http://evil.example" -H 'Content-Type: text/plain' --data-binary @"$TORUS"
expect_error "a text/plain upload from another origin" 403 cross_origin
api GET /v1/meshes
check "... nothing stored ($(jq -c '[.items[].id]' "$BODY"))" jq -e '.items | length == 0' "$BODY"
api POST /v1/meshes -H "Origin: null" -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_error "an upload from an opaque origin (null)" 403 cross_origin
api POST /v1/meshes -H "Origin: http://127.0.0.1:$PORT" -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_status "an upload from the daemon's own origin (its page)" 201
M=$(jq -r .id "$BODY")
api POST /v1/meshes -H "Origin: http://127.0.0.1:$PORT" -H 'Sec-Fetch-Site: cross-site' -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_error "Sec-Fetch-Site cross-site (the browser's word over Origin's)" 403 cross_origin
api POST /v1/meshes -H "Origin: https://voxeld.example" -H 'Sec-Fetch-Site: same-origin' -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_status "Sec-Fetch-Site same-origin (a proxy's name in Origin)" 200
api POST /v1/meshes -H "Origin: http://viewer.example" -H 'Sec-Fetch-Site: cross-site' -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_status "an origin --cors-origin allows" 200
api DELETE "/v1/meshes/$M" -H "Origin: http://evil.example"
expect_error "a DELETE from another origin" 403 cross_origin
api GET "/v1/meshes/$M" -H "Origin: http://evil.example"
expect_status "a GET from another origin is answered (the browser keeps it from the page)" 200
# A plain-HTTP proxy that rewrote Host (nginx's default) says the page's
# own in X-Forwarded-Host (browsers send no Sec-Fetch-Site there)
api POST /v1/meshes -H "Origin: http://voxel.test:8081" -H "X-Forwarded-Host: voxel.test:8081, inner" -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_status "an upload through a proxy that rewrote Host (X-Forwarded-Host)" 200
api POST /v1/meshes -H "Origin: http://voxel.test:8081" -H "X-Forwarded-Host: other.test:8081" -H 'Content-Type: model/obj' --data-binary @"$TORUS"
expect_error "... whose X-Forwarded-Host is another" 403 cross_origin
for h in evil.example "evil.example:$PORT" "a.b.c" "evil%2eexample" "[v1.evil.example]"; do
    api GET /v1/meshes -H "Host: $h"
    expect_error "Host $h on a loopback address without a token" 403 host_not_allowed
done
for h in "127.0.0.1:$PORT" "localhost:$PORT" "LOCALHOST." "app.localhost:$PORT" "[::1]:$PORT" "x" "voxeld:$PORT"; do
    api GET /livez -H "Host: $h"
    expect_status "Host $h" 200
done
check "HTTP/1.0 with two Host lines: 400" sh -c "printf 'GET /livez HTTP/1.0\r\nHost: 127.0.0.1\r\nHost: evil.example\r\n\r\n' | timeout 5 curl -s telnet://127.0.0.1:$PORT 2>/dev/null | head -n 1 | grep -q ' 400 '"
stop_daemon
# Every interface (0.0.0.0 answers on 127.0.0.1 too): the same, without a token
start_daemon --listen 0.0.0.0:0 || exit 1
api GET /v1/meshes -H "Host: evil.example"
expect_error "Host evil.example on 0.0.0.0 without a token" 403 host_not_allowed
stop_daemon
rc=0
timeout 10 "$VOXELD" --allowed-hosts 'a.test:8080' --data-dir "$TMP/nodata" 2>"$TMP/ah.err" || rc=$?
check "--allowed-hosts with a port: exit 2, said ($(cat "$TMP/ah.err"))" sh -c "test $rc = 2 && grep -q 'without a port' '$TMP/ah.err'"
start_daemon --allowed-hosts ".example.com, voxeld.test, dotted.test., *.star.test" || exit 1
for h in example.com a.b.example.com voxeld.test dotted.test "dotted.test." star.test a.star.test; do
    api GET /livez -H "Host: $h"
    expect_status "--allowed-hosts: Host $h" 200
done
api GET /livez -H "Host: example.com.evil"
expect_error "--allowed-hosts: Host example.com.evil" 403 host_not_allowed
stop_daemon
printf 'tok\n' >"$TMP/tok2"
TOKEN=tok
start_daemon --token-file "$TMP/tok2" || exit 1
api GET /v1/meshes -H "Host: voxeld.example.com"
expect_status "with a token any Host is answered (rebinding reaches nothing)" 200
stop_daemon
finish
