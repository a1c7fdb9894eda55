#!/usr/bin/env bash
# Bad input gets a 4xx with a JSON error body, loses nothing, and leaves the
# daemon serving. Each case names the status and error code it expects.
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon --max-upload-bytes 2M --max-json-bytes 4K --max-triangles 100000 --max-image-pixels 1000000 || exit 1

box_obj "$TMP/box.obj" 0 0 0 1 1 1
upload "$TMP/box.obj"
BOX=$MESH_ID
JSON=(-H "Content-Type: application/json")
bad_obj() { # NAME STATUS CODE TEXT: upload an OBJ given as text
    printf '%b' "$4" >"$TMP/bad.obj"
    api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$TMP/bad.obj"
    expect_error "$1" "$2" "$3"
}

# --- malformed meshes (400) and unusable ones (422) ---
bad_obj "junk token in v" 400 obj_junk 'v 0 0 0\nv 1 0 0\nv 0 1 abc\nf 1 2 3\n'
check "message names the line" jq -e '.error.message | test("line 3")' "$BODY"
bad_obj "unknown keyword" 400 obj_junk 'v 0 0 0\nv 1 0 0\nv 0 1 0\nfoo 1 2\nf 1 2 3\n'
bad_obj "NaN coordinate" 400 obj_nan 'v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n'
bad_obj "Inf coordinate" 400 obj_nan 'v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n'
bad_obj "index out of range" 400 obj_index 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 4\n'
check "index message names the line" jq -e '.error.message | test("line 4")' "$BODY"
bad_obj "index zero" 400 obj_index 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n'
bad_obj "negative index out of range" 400 obj_index 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -4\n'
bad_obj "texcoord index out of range" 400 obj_index 'v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/1 2/2 3/1\n'
bad_obj "face with two vertices" 400 obj_face_short 'v 0 0 0\nv 1 0 0\nf 1 2\n'
bad_obj "face repeating a vertex" 400 obj_face_repeat 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 2\n'
bad_obj "no faces" 422 obj_no_faces 'v 0 0 0\nv 1 0 0\nv 0 1 0\n'
bad_obj "only degenerate triangles" 422 degenerate_mesh 'v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n'
# every engine works in floats: a coordinate past FLT_MAX (a double here)
bad_obj "coordinate past 32-bit floats" 422 coordinate_out_of_range 'v 0 0 0\nv 1e39 0 0\nv 0 1 0\nf 1 2 3\n'
bad_obj "negative coordinate past 32-bit floats" 422 coordinate_out_of_range 'v 0 0 0\nv 1 0 0\nv 0 0 -4e38\nf 1 2 3\n'
# ...and what they derive must stay finite: the bound is 1e30 (a cube at
# 3e38 was stored, and its Gregory surface came out NaN; test_gregory
# stores one at 1e30)
bad_obj "coordinate past 1e30" 422 coordinate_out_of_range 'v 0 0 0\nv 1.5e30 0 0\nv 0 1 0\nf 1 2 3\n'
# noise from a fixed seed: random bytes from /dev/urandom were, once in 256
# runs, a point cloud's header after the magic, and once in about 11,000 a
# mesh header declaring more faces than --max-triangles (413)
python3 -c 'import random, sys; random.seed(1); sys.stdout.buffer.write(random.randbytes(3000))' >"$TMP/noise.bin"
# a mesh header (2.2, edgebreaker, no flags), then the noise
printf 'DRACO\x02\x02\x01\x01\x00\x00' | cat - "$TMP/noise.bin" >"$TMP/corrupt.drc"
api POST /v1/meshes -H "Content-Type: model/x-draco" --data-binary "@$TMP/corrupt.drc"
expect_error "corrupt Draco" 400 draco_corrupt
# a header of junk: an unknown version is corrupt, whatever the type byte
printf 'DRACO\x09\x07\x00\x01\x00\x00' | cat - "$TMP/noise.bin" >"$TMP/corrupt.drc"
api POST /v1/meshes -H "Content-Type: model/x-draco" --data-binary "@$TMP/corrupt.drc"
expect_error "Draco junk header" 400 draco_corrupt
draco_encoder -i "$VX_MESH_DIR/spot_triangulated.obj" -o "$TMP/spot.drc" >/dev/null 2>&1
head -c 2000 "$TMP/spot.drc" >"$TMP/trunc.drc"
api POST /v1/meshes -H "Content-Type: model/x-draco" --data-binary "@$TMP/trunc.drc"
expect_error "truncated Draco" 400 draco_corrupt
draco_encoder -point_cloud -i "$VX_MESH_DIR/spot_triangulated.obj" -o "$TMP/pc.drc" >/dev/null 2>&1
api POST /v1/meshes -H "Content-Type: model/x-draco" --data-binary "@$TMP/pc.drc"
expect_error "Draco point cloud" 422 draco_point_cloud

# --- content types, sizes ---
api POST /v1/meshes -H "Content-Type: image/png" --data-binary "@$TMP/box.obj"
expect_error "wrong content type for a mesh" 415 unsupported_media_type
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$TMP/spot.drc"
expect_error "OBJ declared, Draco sent" 415 unsupported_media_type
api POST /v1/meshes -H "Content-Type: model/x-draco" --data-binary "@$TMP/box.obj"
expect_error "Draco declared, text sent" 415 unsupported_media_type
api POST /v1/meshes -H "Content-Type: application/octet-stream" --data-binary "@$TMP/noise.bin"
expect_error "binary junk, sniffed" 415 unsupported_media_type
printf '{\x93\x07' | cat - "$TMP/noise.bin" >"$TMP/brace.bin" # (junk can start with a brace)
api POST /v1/meshes -H "Content-Type: application/octet-stream" --data-binary "@$TMP/brace.bin"
expect_error "binary junk that starts with a brace, sniffed (not glTF)" 415 unsupported_media_type
# a binary STL (a header that says nothing, then triangles) declared as text
python3 -c 'import struct, sys
t = [(0,0,0, 0,0,0, 1,0,0, 0,1,0), (0,0,0, 0,0,0, 0,1,0, 0,0,1)]
sys.stdout.buffer.write(b"X" * 80 + struct.pack("<I", len(t)) + b"".join(struct.pack("<12fH", *v, 0) for v in t))' >"$TMP/bin.stl"
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$TMP/bin.stl"
expect_error "OBJ declared, binary STL sent" 415 unsupported_media_type
api POST /v1/meshes -H "Content-Type: text/plain" --data-binary "@$TMP/bin.stl"
expect_error "text declared, binary STL sent" 415 unsupported_media_type
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary ""
expect_error "empty body" 422 obj_no_faces
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$VX_MESH_DIR/stanford-bunny.obj"
expect_error "upload over max-upload-bytes" 413 too_large
api POST /v1/meshes -H "Content-Type: model/obj" -H "Transfer-Encoding: chunked" --data-binary "@$VX_MESH_DIR/stanford-bunny.obj"
expect_error "chunked upload over the limit" 413 too_large
head -c 1900000 "$VX_MESH_DIR/ogre.obj" | awk '/^v /' >"$TMP/many.obj"
nv=$(wc -l <"$TMP/many.obj")
for i in $(seq 1 3 $((nv - 2))); do echo "f $i $((i + 1)) $((i + 2))"; done >>"$TMP/many.obj"
api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$VX_MESH_DIR/ogre.obj" -H "Expect:"
expect_error "ogre over the limit without Expect" 413 too_large
# An answer given before the body is read is followed by a close. Closing a
# socket with unread bytes resets it, and the reset could reach curl before
# the answer (about 1 in 10 on loopback): the socket is drained instead.
lost=0
for i in $(seq 1 20); do
    code=$(curl -s -o /dev/null -w '%{http_code}' -X POST -H "Content-Type: model/obj" -H "Expect:" \
        --data-binary "@$VX_MESH_DIR/ogre.obj" "$BASE/v1/meshes")
    [[ $code == 413 ]] || lost=$((lost + 1))
    code=$(curl -s -o /dev/null -w '%{http_code}' -X POST -H "Content-Type: text/html" -H "Expect:" \
        --data-binary "@$TMP/many.obj" "$BASE/v1/meshes")
    [[ $code == 415 ]] || lost=$((lost + 1))
done
check "40 early answers with a body behind them all arrive ($lost lost)" test "$lost" = 0
# A client that sends its body and never reads: the drain ends (DRAIN_S,
# 5 s) and the socket closes; the client's send then fails.
python3 - "$PORT" >"$TMP/nonreader.txt" <<'PY'
import socket, sys, time
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(b"POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\n"
          b"Content-Length: 4000000000\r\n\r\n")
t0, chunk, ended = time.monotonic(), b"v 0 0 0\n" * 8192, "no"
s.settimeout(1)
while time.monotonic() - t0 < 30:
    try:
        s.send(chunk)
    except socket.timeout:
        continue
    except OSError:
        ended = "yes"
        break
print(ended, round(time.monotonic() - t0, 1))
PY
read -r ended secs <"$TMP/nonreader.txt"
check "a client that never stops sending is cut off after the drain ($ended after $secs s)" \
    test "$ended" = yes
# A chunked body has no length to refuse up front: it is answered 413 as
# soon as it passes the limit (it was read to its end: forever, for one
# that never ends), then closed. Upload and JSON limits alike.
IFS='|' read -r line code secs end < <(endless_chunks /v1/meshes model/obj)
check "an endless chunked upload is answered 413 too_large ($line, $code, after ${secs}s, then $end)" \
    test "$line" = "HTTP/1.1 413 Content Too Large" -a "$code" = too_large -a "$end" != none
IFS='|' read -r line code secs end < <(endless_chunks /v1/jobs application/json)
check "an endless chunked JSON body is answered 413 too_large ($line, $code, after ${secs}s, then $end)" \
    test "$line" = "HTTP/1.1 413 Content Too Large" -a "$code" = too_large -a "$end" != none
# A refused request whose whole body came with its head keeps no socket
# open past a second without a byte, however long the client waits.
sleep 1 # the sockets answered above are closed by now
base=$(ls "/proc/$PID/fd" | wc -l)
python3 - "$PORT" "$TMP/idle.sent" >"$TMP/idle.txt" <<'PY' &
import socket, sys, time
socks = []
for i in range(12):
    s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
    s.sendall(b"POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: text/html\r\n"
              b"Content-Length: 2\r\n\r\nab")
    socks.append(s)
open(sys.argv[2], "w").close()
time.sleep(15)
PY
IDLE=$!
# from when all 12 are sent (python can take seconds to start on a loaded
# machine), the sockets are closed after a second idle: looked at for up to
# 5 s while the client still holds its ends
for _ in $(seq 100); do [[ -e $TMP/idle.sent ]] && break; sleep 0.1; done
for _ in $(seq 50); do
    sleep 0.1
    now=$(ls "/proc/$PID/fd" | wc -l)
    ((now <= base)) && break
done
check "refused bodies already in hold no socket after 1 s idle ($now fds, $base before)" test "$now" -le "$base"
kill "$IDLE" 2>/dev/null
wait "$IDLE"
api GET /livez
check "serving after the drained clients (got $STATUS)" test "$STATUS" = 200
if [[ $(grep -c '^f' "$TMP/many.obj") -gt 100000 && $(stat -c %s "$TMP/many.obj") -lt 2000000 ]]; then
    api POST /v1/meshes -H "Content-Type: model/obj" --data-binary "@$TMP/many.obj"
    expect_error "more triangles than max-triangles" 413 mesh_too_big
fi
code=$(curl -s -o "$TMP/411.body" -w '%{http_code}' -X POST -H "Content-Type: model/obj" -H "Content-Length:" "$BASE/v1/meshes")
check "no length: 411 (got $code)" test "$code" = 411
check "411 JSON error" jq -e '.error.code == "length_required"' "$TMP/411.body"

# --- JSON job requests ---
api POST /v1/jobs "${JSON[@]}" -d '{"mesh": '
expect_error "malformed JSON" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d '{"mesh": "x", "kind": }'
expect_error "a missing value" 400 invalid_json
check "the error gives the byte ($(jqb .error.message))" test "$(jqb .error.message)" = "the body is not valid JSON (at byte 22)"
# cJSON's nesting limit (1000 levels), named as such
deep=$(printf '%*s' 1000 '' | tr ' ' '[')$(printf '%*s' 1000 '' | tr ' ' ']')
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"a\":$deep}}"
expect_error "nesting 1002 levels deep" 400 invalid_json
check "the error names the nesting ($(jqb .error.message))" grep -q 'nest deeper than 1000 levels' <<<"$(jqb .error.message)"
deep=$(printf '%*s' 997 '' | tr ' ' '[')$(printf '%*s' 997 '' | tr ' ' ']')
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"a\":$deep}}"
check "nesting 999 levels deep is JSON: the params are what is refused ($STATUS $(jqb .error.code))" test "$(jqb .error.code)" = invalid_params
api POST /v1/jobs "${JSON[@]}" -d '[1,2]'
expect_error "JSON not an object" 400 invalid_request
# strict JSON (RFC 8259): each of these would otherwise run as a job
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"} x"
expect_error "junk after the JSON value" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}{}"
expect_error "a second JSON value" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"voxelize\",\"params\":{\"resolution\":016}}"
expect_error "a number with a leading zero" 400 invalid_json
# a nonzero number nearer 0 than any double: it read as 0, so a fov of
# 1e-400 (which must be > 0 to be perspective) drew an orthographic image
for tiny in 1e-400 -1e-400 0.000001e-330; do
    api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"fov\":$tiny}}"
    expect_error "fov $tiny, below the smallest double" 400 invalid_json
    check "the error says why ($(jqb .error.message))" grep -q 'nearer 0 than any double' <<<"$(jqb .error.message)"
done
# a subnormal double and a zero written small are numbers like any other
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"voxelize\",\"params\":{\"resolution\":8,\"padding\":0e-400}}"
check "0e-400 is 0 ($STATUS)" test "$STATUS" = 202
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":16,\"height\":16,\"fov\":1e-320}}"
check "fov 1e-320, a subnormal, is accepted ($STATUS)" test "$STATUS" = 202
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"voxelize\",\"params\":{\"resolution\":8,\"resolution\":16}}"
expect_error "a key twice" 400 invalid_json
check "the error names the key" jq -e '.error.message | contains("resolution")' "$BODY"
api POST /v1/jobs "${JSON[@]}" --data-binary "$(printf '{"mesh":"%s","kind":"pre\tview"}' "$BOX")"
expect_error "a raw tab in a string" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d '{"kind":"preview"}'
expect_error "missing mesh" 400 invalid_request
check "missing mesh: said so" jq -e '.error.message | contains("is required")' "$BODY"
api POST /v1/jobs "${JSON[@]}" -d '{"kind":"preview","mesh":123}'
expect_error "mesh not a string" 400 invalid_request
check "mesh not a string: said so, not 'required'" jq -e '.error.message == "\"mesh\" must be a mesh id string"' "$BODY"
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":7}"
expect_error "kind not a string" 400 invalid_request
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"color\":1}"
expect_error "unknown top-level field" 400 invalid_request
check "it names the field ($(jqb .error.message))" grep -q 'unknown field "color"' <<<"$(jqb .error.message)"
api POST /v1/jobs -H "Content-Type: text/plain" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "job body not JSON content type" 415 unsupported_media_type
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"pad\":\"$(head -c 5000 /dev/zero | tr '\0' x)\"}}"
expect_error "JSON over max-json-bytes" 413 too_large
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$(printf '0%.0s' {1..64})\",\"kind\":\"preview\"}"
expect_error "unknown mesh id" 404 mesh_not_found
api POST /v1/jobs "${JSON[@]}" -d '{"mesh":"../../etc/passwd","kind":"preview"}'
expect_error "malformed mesh id in a job" 400 invalid_request
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":null}"
expect_error "params null" 400 invalid_request
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"teleport\"}"
expect_error "unknown kind" 422 unknown_kind
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":-5}}"
expect_error "negative width" 422 invalid_params
check "message names the field" jq -e '.error.message | test("width")' "$BODY"
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":5000,\"height\":5000}}"
expect_error "image over max-image-pixels" 422 invalid_params
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"elevation\":\"high\"}}"
expect_error "string for a number" 422 invalid_params
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"zoom\":2}}"
expect_error "unknown parameter" 422 invalid_params
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"samples\":3}}"
expect_error "samples not a power of two" 422 invalid_params
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"color\":[1,0]}}"
expect_error "colour with two components" 422 invalid_params
api POST "/v1/jobs?wait=soon" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "bad wait" 400 invalid_request

# --- ids, routes, methods, queries ---
api GET "/v1/jobs/0123456789abcdef0123456789abcdef"
expect_error "unknown job" 404 job_not_found
api GET "/v1/jobs/not-a-job"
expect_error "malformed job id" 404 job_not_found
api DELETE "/v1/jobs/0123456789abcdef0123456789abcdef"
expect_error "cancel unknown job" 404 job_not_found
api GET "/v1/jobs/0123456789abcdef0123456789abcdef/result"
expect_error "result of unknown job" 404 job_not_found
api GET "/v1/meshes/xyz"
expect_error "malformed mesh id" 404 mesh_not_found
api GET /v1/nothing
expect_error "unknown route" 404 not_found
api PUT "/v1/meshes/$BOX"
expect_error "PUT on a mesh" 405 method_not_allowed
check "405 lists Allow ($(header Allow))" test "$(header Allow)" = "GET, HEAD, DELETE, OPTIONS"
# A method that is not HTTP's: 501 on any path, known or not, before auth.
api PROPFIND "/v1/meshes/$BOX"
expect_error "PROPFIND on a mesh" 501 not_implemented
check "501 has no Allow" test -z "$(header Allow)"
api FOO /nothing
expect_error "an unknown method on an unknown path" 501 not_implemented
api get /livez
expect_error "methods are case-sensitive" 501 not_implemented
api DELETE /v1/meshes
expect_error "DELETE the collection" 405 method_not_allowed
api POST /livez
expect_error "POST livez" 405 method_not_allowed
api PATCH /v1/jobs
expect_error "PATCH jobs" 405 method_not_allowed
api POST "/v1/jobs/0123456789abcdef0123456789abcdef/result"
expect_error "POST a result" 405 method_not_allowed
api GET "/v1/meshes?limit=0"
expect_error "limit 0" 400 invalid_request
api GET "/v1/meshes?limit=abc"
expect_error "limit not a number" 400 invalid_request
api GET "/v1/meshes?after=zzz"
expect_error "after not an id" 400 invalid_request
api GET "/v1/jobs?state=sleeping"
expect_error "unknown state filter" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait=-1"
expect_error "negative wait" 400 invalid_request

# --- strict query parameters (issue #10): repeated, empty, not plain decimal ---
api GET "/v1/meshes?limit=5&limit=abc"
expect_error "limit given twice" 400 invalid_request
check "message names limit" jq -e '.error.message | test("limit")' "$BODY"
api GET "/v1/meshes?limit=5&limit=5"
expect_error "limit given twice, same value" 400 invalid_request
api GET "/v1/meshes?limit"
expect_error "limit without a value" 400 invalid_request
api GET "/v1/meshes?limit="
expect_error "limit empty" 400 invalid_request
api GET "/v1/meshes?limit=+5"
expect_error "limit with a sign" 400 invalid_request
api GET "/v1/meshes?limit=0x10"
expect_error "limit in hex" 400 invalid_request
api GET "/v1/meshes?limit=5%00x"
expect_error "limit with a NUL" 400 invalid_request
api GET "/v1/meshes?after="
expect_error "after empty" 400 invalid_request
api GET "/v1/jobs?state=queued&state=failed"
expect_error "state given twice" 400 invalid_request
api GET "/v1/meshes?limit=5&colour=blue&colour=red"
expect_status "unknown parameters are ignored, even repeated" 200
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait=0x10"
expect_error "wait in hex" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait="
expect_error "wait empty" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait"
expect_error "wait without a value" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait=1e1"
expect_error "wait with an exponent" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait=1&wait=2"
expect_error "wait given twice" 400 invalid_request
api GET "/v1/jobs/0123456789abcdef0123456789abcdef?wait=0.25"
expect_error "a good wait on an unknown job" 404 job_not_found
api POST "/v1/jobs?wait=0x10" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "wait in hex on a submission" 400 invalid_request
api POST "/v1/jobs?wait=" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\"}"
expect_error "wait empty on a submission" 400 invalid_request

# --- JSON text: UTF-8 only, no \u0000 (cJSON would cut the string there) ---
printf '{"mesh":"%s","kind":"pre\xff\xfeview"}' "$BOX" >"$TMP/badutf8.json"
api POST /v1/jobs "${JSON[@]}" --data-binary "@$TMP/badutf8.json"
expect_error "kind not UTF-8" 400 invalid_json
check "the answer is valid UTF-8" python3 -c 'import sys; open(sys.argv[1], "rb").read().decode("utf-8")' "$BODY"
printf '{"mesh":"%s","kind":"preview","params":{"x\xc0\xaf":1}}' "$BOX" >"$TMP/overlong.json"
api POST /v1/jobs "${JSON[@]}" --data-binary "@$TMP/overlong.json"
expect_error "overlong UTF-8 in a params key" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\\u0000junk\"}"
expect_error "kind with \\u0000" 400 invalid_json
api POST /v1/jobs "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\\\\u0000junk\"}"
expect_error "an escaped backslash before u0000 is text: unknown kind" 422 unknown_kind
api POST /v1/meshes -H $'Content-Type: model/\xff\xfeobj' --data-binary "@$TMP/box.obj"
expect_error "a Content-Type that is not UTF-8" 415 unsupported_media_type
check "415 answer is valid UTF-8" python3 -c 'import sys; open(sys.argv[1], "rb").read().decode("utf-8")' "$BODY"

# --- framing, spoken raw (curl would fix these requests up) ---
# raw_http NAME BYTES [all]: sends BYTES (printf escapes), reads the answer
# (closing the connection after 5 s at most; with all, everything until the
# server closes or 3 s pass) into $TMP/NAME.raw.
raw_http() {
    python3 - "$PORT" "$2" "${3:-}" >"$TMP/$1.raw" <<'PY'
import socket, sys
s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
s.sendall(sys.argv[2].encode().decode("unicode_escape").encode("latin-1"))
whole = sys.argv[3] == "all"
s.settimeout(3 if whole else 5)
got = b""
try:
    while True:
        b = s.recv(65536)
        if not b:
            break
        got += b
        if not whole and b"\r\n\r\n" in got:
            head, body = got.split(b"\r\n\r\n", 1)
            n = [int(l.split(b":")[1]) for l in head.split(b"\r\n") if l.lower().startswith(b"content-length:")]
            if n and len(body) >= n[0]:
                break
except OSError:
    pass
sys.stdout.buffer.write(got)
PY
}
# expect_raw NAME STATUS CODE: the answer's status line and JSON error code.
expect_raw() {
    local f=$TMP/$1.raw
    check "$1: status $2 ($(head -c 60 "$f" | tr -d '\r' | head -n 1))" bash -c "head -n 1 '$f' | grep -q '^HTTP/1.1 $2 '"
    check "$1: JSON content type" bash -c "tr -d '\r' <'$f' | sed '/^$/q' | grep -qi '^content-type: application/json'"
    check "$1: error code $3" bash -c "tr -d '\r' <'$f' | sed '1,/^$/d' | jq -e '.error.code == \"$3\" and (.error|length) == 2'"
}
raw_http nohost 'GET /livez HTTP/1.1\r\n\r\n'
expect_raw nohost 400 invalid_request
raw_http twohosts 'GET /livez HTTP/1.1\r\nHost: a\r\nHost: b\r\n\r\n'
expect_raw twohosts 400 invalid_request
raw_http http10 'GET /livez HTTP/1.0\r\n\r\n'
check "HTTP/1.0 needs no Host" bash -c "head -n 1 '$TMP/http10.raw' | grep -q '^HTTP/1.1 200 '"
raw_http gzip 'POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nTransfer-Encoding: gzip\r\n\r\n{}'
expect_raw gzip 501 not_implemented
raw_http telist 'POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\nTransfer-Encoding: gzip, chunked\r\n\r\n0\r\n\r\n'
expect_raw telist 501 not_implemented
# "chunked " with trailing white space: libmicrohttpd keeps it and reads no
# chunks (the body ran to the connection's end, then 408 or nothing), so
# it is not chunked here either; and two Transfer-Encoding lines are one
# list, whichever comes first (the second was ignored and the upload taken).
raw_http tespace 'POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\nTransfer-Encoding: chunked \r\n\r\n0\r\n\r\n'
expect_raw tespace 501 not_implemented
raw_http tetwo 'POST /v1/meshes HTTP/1.1\r\nHost: x\r\nContent-Type: model/obj\r\nTransfer-Encoding: chunked\r\nTransfer-Encoding: gzip\r\n\r\n0\r\n\r\n'
expect_raw tetwo 501 not_implemented
raw_http clte 'POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 2\r\nTransfer-Encoding: chunked\r\n\r\n2\r\n{}\r\n0\r\n\r\n'
expect_raw clte 400 invalid_request
# Two Content-Lengths: 400, and the connection closes, so the rest of the
# body is never read as a second request (smuggling behind a proxy that
# took the other length).
# The body is 36 bytes: {} and a GET /v1/info.
raw_http twolen 'POST /v1/jobs HTTP/1.1\r\nHost: x\r\nContent-Type: application/json\r\nContent-Length: 2\r\nContent-Length: 36\r\n\r\n{}GET /v1/info HTTP/1.1\r\nHost: x\r\n\r\n' all
expect_raw twolen 400 invalid_request
check "twolen: one answer only (no smuggled request)" test "$(grep -ac '^HTTP/1.1 ' "$TMP/twolen.raw")" = 1
check "twolen: the answer closes the connection" bash -c "tr -d '\r' <'$TMP/twolen.raw' | sed '/^$/q' | grep -qi '^connection: close'"
# What libmicrohttpd 0.9.75 hides (daemon/http.c check_in_place), each a
# second request smuggled in a body a proxy in front would frame: a field
# folded onto the next line (its value was glued to the NAME: the body
# read as empty, its bytes as the next request), a NUL in a value (the
# length cut at it) or in the target (/livez\0junk was /livez), a line
# with an empty field name (taken for the head's end). Each 400,
# one answer, the connection closed.
SMUGGLED='GET /v1/info HTTP/1.1\r\nHost: x\r\n\r\n'
raw_http foldlen "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nContent-Length:\\r\\n 36\\r\\n\\r\\n$SMUGGLED" all
raw_http foldte "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nTransfer-Encoding:\\r\\n\\tchunked\\r\\n\\r\\n0\\r\\n\\r\\n$SMUGGLED" all
raw_http foldother "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-A: one\\r\\n two\\r\\n\\r\\n$SMUGGLED" all
raw_http foldspaces "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nContent-Length:        \\r\\n 2\\r\\n\\r\\n{}$SMUGGLED" all
raw_http nullen "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nContent-Length: 2\\x0034\\r\\n\\r\\n{}$SMUGGLED" all
raw_http nulvalue "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-A: a\\x00b\\r\\n\\r\\n$SMUGGLED" all
raw_http emptyname "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-A: a\\r\\n: x\\r\\n$SMUGGLED" all
raw_http emptyname2 "GET /livez HTTP/1.1\\r\\nHost: x\\r\\n:\\r\\n$SMUGGLED" all
raw_http nulcrlf "POST /v1/jobs HTTP/1.1\\r\\nContent-Length: 0\\x00\\x0036\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\n\\r\\n$SMUGGLED" all
raw_http nulend "GET /livez HTTP/1.1\\r\\nX-A: b\\x00\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
raw_http nulmethod "GET\\x00X /livez HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
raw_http nulversion "GET /livez\\x00HTTP/junk HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
raw_http emptyfirst "GET /livez HTTP/1.1\\r\\n: x\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
raw_http emptylf "GET /livez HTTP/1.1\\nHost: x\\n:x\\n$SMUGGLED" all
raw_http nultarget "GET /livez\\x00junk HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
raw_http nultarget2 "GET /livez\\x00 HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n$SMUGGLED" all
# HTTP/1.0 with Transfer-Encoding: its framing is faulty (RFC 9112 6.1);
# two Content-Types: the upload reads the first, a proxy may the last.
raw_http te10 "POST /v1/jobs HTTP/1.0\\r\\nConnection: keep-alive\\r\\nContent-Type: application/json\\r\\nTransfer-Encoding: chunked\\r\\n\\r\\n2\\r\\n{}\\r\\n0\\r\\n\\r\\n$SMUGGLED" all
raw_http twotypes "POST /v1/meshes HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: text/plain\\r\\nContent-Type: model/obj\\r\\nContent-Length: 2\\r\\n\\r\\n{}$SMUGGLED" all
for t in foldlen foldte foldother foldspaces nullen nulvalue nulcrlf nulend nulmethod nulversion emptyname emptyname2 emptyfirst emptylf nultarget nultarget2 te10 twotypes; do
    expect_raw $t 400 invalid_request
    check "$t: one answer only (no smuggled request)" test "$(grep -ao 'HTTP/1.1 [0-9]' "$TMP/$t.raw" | wc -l)" = 1
    check "$t: the answer closes the connection" bash -c "tr -d '\r' <'$TMP/$t.raw' | sed '/^$/q' | grep -qi '^connection: close'"
done
check "foldlen: the message names the fold" bash -c "tr -d '\r' <'$TMP/foldlen.raw' | sed '1,/^$/d' | jq -e '.error.message | test(\"obs-fold\")'"
check "nullen: the message names the NUL" bash -c "tr -d '\r' <'$TMP/nullen.raw' | sed '1,/^$/d' | jq -e '.error.message | test(\"NUL\")'"
# and what looks like them but is not: lines ended by a bare LF, values
# after tabs and spaces, empty values, all in one head; then the same
# pipelined twice on one connection.
raw_http lfonly "GET /livez HTTP/1.1\\nHost: x\\nX-A: one\\nX-B:\\t \\t b \\nX-C:\\nX-D:   \\nAccept: */*\\n\\n" all
check "bare LF lines, tabs, empty values: 200" bash -c "head -n 1 '$TMP/lfonly.raw' | grep -q '^HTTP/1.1 200 '"
spaces=$(printf ' %.0s' {1..5000})
raw_http widespace "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-Wide:$spaces v\\r\\n\\r\\n"
check "5000 spaces after a colon: 200" bash -c "head -n 1 '$TMP/widespace.raw' | grep -q '^HTTP/1.1 200 '"
raw_http crlfmix "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-B:\\t \\t b \\r\\nX-C:\\r\\nX-D:   \\r\\n\\r\\nGET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-C:\\r\\n\\r\\n" all
check "CRLF lines, tabs, empty values, two pipelined: two 200s" test "$(grep -ao 'HTTP/1.1 200 ' "$TMP/crlfmix.raw" | wc -l)" = 2
# Host: a host and port (RFC 9112 3.2: 400 for an invalid value).
raw_http hostspace 'GET /livez HTTP/1.1\r\nHost: a b\r\n\r\n'
expect_raw hostspace 400 invalid_request
raw_http hostbytes 'GET /livez HTTP/1.1\r\nHost: \xff\xfe\r\n\r\n'
expect_raw hostbytes 400 invalid_request
# An empty Transfer-Encoding is malformed (400), not a coding voxeld lacks
# (it was 501); two spaces in the request line are said to be that (the
# message spoke of a NUL).
raw_http teempty 'POST /v1/jobs HTTP/1.1\r\nHost: x\r\nTransfer-Encoding: \r\n\r\n'
expect_raw teempty 400 invalid_request
raw_http twospaces 'GET  /livez HTTP/1.1\r\nHost: x\r\n\r\n'
expect_raw twospaces 400 invalid_request
check "twospaces: the message says so" bash -c "tr -d '\r' <'$TMP/twospaces.raw' | sed '1,/^$/d' | jq -e '.error.message | test(\"single spaces\")'"
# (names under .localhost: this daemon, on a loopback address without a
# token, answers no other dotted name; test_cors_request_id.sh)
for h in '[::1]:8080' 'app.localhost:80' '127.0.0.1' '' 'a.localhost  ' 'a.localhost\t'; do
    raw_http hostok "GET /livez HTTP/1.1\\r\\nHost: $h\\r\\n\\r\\n"
    check "Host: '$h': 200" bash -c "head -n 1 '$TMP/hostok.raw' | grep -q '^HTTP/1.1 200 '"
done
# A client that shuts its side after the request (nc -N): it gets the
# answer and then the close, not a socket held in CLOSE-WAIT until
# --connection-timeout (libmicrohttpd read that EOF with the request).
halfclosed=$(python3 - "$PORT" <<'PY'
import socket, sys, time
slow = 0
for i in range(10):
    s = socket.create_connection(("127.0.0.1", int(sys.argv[1])))
    s.sendall(b"GET /livez HTTP/1.1\r\nHost: x\r\n\r\n")
    s.shutdown(socket.SHUT_WR)
    s.settimeout(3)
    t0, got = time.monotonic(), b""
    try:
        while True:
            b = s.recv(65536)
            if not b:
                break
            got += b
    except OSError:
        pass
    if b" 200 " not in got or time.monotonic() - t0 > 2:
        slow += 1
    s.close()
print(slow)
PY
)
check "10 half-closed clients: each answered and closed within 2 s ($halfclosed not)" test "$halfclosed" = 0
# Blanks after a header's value are not part of it (RFC 9110 5.5):
# libmicrohttpd keeps them; an Idempotency-Key with one was 400 and an
# X-Request-Id with one was replaced.
IDB="{\"mesh\":\"$BOX\",\"kind\":\"voxelize\",\"params\":{\"resolution\":6,\"format\":\"summary\"}}"
raw_http idemows "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nIdempotency-Key: ows-key \\t\\r\\nX-Request-Id: ows-rid\\t \\r\\nContent-Length: ${#IDB}\\r\\n\\r\\n$IDB"
check "a key with blanks after it: 202 ($(head -n 1 "$TMP/idemows.raw" | tr -d '\r'))" bash -c "head -n 1 '$TMP/idemows.raw' | grep -q '^HTTP/1.1 202 '"
check "the request id without its blanks is echoed" bash -c "tr -d '\r' <'$TMP/idemows.raw' | sed '/^$/q' | grep -qx 'X-Request-Id: ows-rid'"
OWSJ=$(tr -d '\r' <"$TMP/idemows.raw" | sed '1,/^$/d' | jq -r .id)
api POST /v1/jobs -H "Content-Type: application/json" -H "Idempotency-Key: ows-key" -d "$IDB"
expect_status "the same key without the blanks: the same job" 200
check "its id ($OWSJ)" test "$(jqb .id)" = "$OWSJ"
raw_http twoidem "POST /v1/jobs HTTP/1.1\\r\\nHost: x\\r\\nContent-Type: application/json\\r\\nIdempotency-Key: a\\r\\nIdempotency-Key: b\\r\\nContent-Length: 2\\r\\n\\r\\n{}"
expect_raw twoidem 400 invalid_request
long=$(printf 'a%.0s' {1..20000})
raw_http longuri "GET /v1/meshes?x=$long HTTP/1.1\\r\\nHost: x\\r\\n\\r\\n"
expect_raw longuri 414 uri_too_long
check "longuri: the 414 has a request id" bash -c "tr -d '\r' <'$TMP/longuri.raw' | sed '/^$/q' | grep -Eq '^X-Request-Id: [0-9a-f]{16}$'"
big=$(printf 'b%.0s' {1..70000})
raw_http bighead "GET /livez HTTP/1.1\\r\\nHost: x\\r\\nX-Big: $big\\r\\n\\r\\n"
expect_raw bighead 431 header_too_large
api GET /livez
expect_status "serving after the raw requests" 200

# Nothing was lost and the daemon still serves.
api GET "/v1/meshes/$BOX"
expect_status "the box is still there" 200
api POST "/v1/jobs?wait=60" "${JSON[@]}" -d "{\"mesh\":\"$BOX\",\"kind\":\"preview\",\"params\":{\"width\":64,\"height\":64}}"
check "a good job still runs" jq -e '.state == "succeeded"' "$BODY"
GJ=$(jqb .id)
# A path with %00 or %2F names nothing: libmicrohttpd decodes them before
# routing, so the job (and its result) answered as if they were not there.
# A %2F last is a trailing '/' once decoded: the resource's 404 too (it
# was the route table's not_found).
for p in "/v1/jobs/$GJ%00" "/v1/jobs/$GJ%00x" "/v1/jobs/$GJ%2fresult" "/v1/jobs/$GJ%2Fresult" \
    "/v1/jobs/$GJ/result/image%00x" "/v1/meshes/$BOX%00" "/v1/jobs/$GJ%2F" "/v1/jobs/$GJ%2F%2f" \
    "/v1/meshes/$BOX%2F" "/v1/jobs/$GJ/result/image%2F"; do
    api GET "$p"
    want=job_not_found
    [[ $p == /v1/meshes/* ]] && want=mesh_not_found
    expect_error "GET $p" 404 "$want"
    [[ $p == /v1/jobs/* ]] && check "GET $p: the message says why ($(jqb .error.message))" \
        bash -c "jq -r .error.message '$BODY' | grep -qF '(a path with %00 or %2F)'"
done
api GET "/v1/jobs/$GJ/result/image"
expect_status "the same output by its plain path" 200
api GET /v1/meshes
check "only the box was stored" jq -e '(.items|length) == 1' "$BODY"
check "no temp files left" test -z "$(ls -A "$DATA/tmp")"
stop_daemon

# A burst of early answers larger than a quarter of --max-connections: each
# socket is drained after its answer, as many at once as the connections
# when the descriptor limit leaves room (2-3 of 40 were reset with a
# quarter), and with a low limit the one drained longest makes room.
burst() { # -> how many of 40 concurrent over-limit uploads got no answer
    local i
    for i in $(seq 1 40); do
        curl -s -o /dev/null -w '%{http_code}\n' -X POST -H "Content-Type: model/obj" -H "Expect:" \
            --data-binary "@$VX_MESH_DIR/ogre.obj" "$BASE/v1/meshes" >"$TMP/burst$i.txt" &
    done
    wait
    cat "$TMP"/burst*.txt | grep -vc '^413$'
}
start_daemon --max-upload-bytes 2M --max-connections 32 || exit 1
lost=$(burst)
check "40 concurrent early 413s at --max-connections 32 all arrive ($lost lost)" test "$lost" = 0
stop_daemon
nofile=$(ulimit -S -n)
ulimit -S -n 200
start_daemon --max-upload-bytes 2M --max-connections 32 || exit 1
ulimit -S -n "$nofile"
lost=$(burst)
check "the same with 200 descriptors (a quarter drained at once, the oldest makes room; $lost lost)" \
    test "$lost" = 0
stop_daemon
finish
