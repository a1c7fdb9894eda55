#!/usr/bin/env bash
# Lenient where it costs nothing (issue #13): `outputs: ["image"]` in a
# render is accepted (the image is always made), and error messages are
# valid UTF-8 whatever the input (a UTF-16 OBJ once echoed 0xFE 0xFF).
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
start_daemon || exit 1

utf8_json() { python3 -c 'import json,sys; json.loads(open(sys.argv[1],"rb").read().decode("utf-8","strict"))' "$1"; }

# A UTF-16 (big-endian, with BOM) OBJ.
printf 'v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n' | iconv -f UTF-8 -t UTF-16 >"$TMP/u16.obj"
check "the file starts with a UTF-16 BOM" bash -c "head -c 2 '$TMP/u16.obj' | od -An -tx1 | grep -Eq 'fe ff|ff fe'"
upload "$TMP/u16.obj"
check "UTF-16 OBJ refused (got $STATUS)" test "$STATUS" -ge 400 -a "$STATUS" -lt 500
check "the error body is UTF-8 JSON" utf8_json "$BODY"
check "an error body" jq -e '.error.code and .error.message' "$BODY"
# Latin-1 bytes in an OBJ statement are quoted in the message, as '?'.
printf 'v 0 0 0\n\xe9t\xe9 1 2\n' >"$TMP/latin1.obj"
upload "$TMP/latin1.obj"
check "Latin-1 OBJ refused (got $STATUS)" test "$STATUS" -ge 400 -a "$STATUS" -lt 500
check "its error body is UTF-8 JSON" utf8_json "$BODY"

box_obj "$TMP/box.obj" 0 0 0 1 1 1
upload "$TMP/box.obj"
expect_status "upload box" 201
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"render\",\"params\":{\"N\":16,\"width\":32,\"height\":32,\"outputs\":[\"image\"]}}"
expect_status "render with outputs [image]" 202
check "the normalised params do not list image" jq -e '.params.outputs == []' "$BODY"
J=$(jqb .id)
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"render\",\"params\":{\"N\":16,\"width\":32,\"height\":32,\"outputs\":[\"image\",\"normal\"]}}"
expect_status "render with outputs [image, normal]" 202
check "normal kept, image dropped" jq -e '.params.outputs == ["normal"]' "$BODY"
wait_job "$J"
check "the render succeeded" jq -e '.state == "succeeded" and (.outputs | keys) == ["image"]' "$BODY"
api POST /v1/jobs -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$MESH_ID\",\"kind\":\"render\",\"params\":{\"outputs\":[\"picture\"]}}"
expect_error "an unknown output is still refused" 422 invalid_params

stop_daemon
finish
