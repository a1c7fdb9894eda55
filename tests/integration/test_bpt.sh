#!/usr/bin/env bash
# .bpt uploads (Newell's teapot): the content types, the metadata, errors
# naming the line, and the tessellation drawn by preview and refined by
# catmull-clark.
source "$(dirname "$0")/lib.sh"
start_daemon || exit 1

TEAPOT="$VX_MESH_DIR/newell-teapot.bpt"
upload "$TEAPOT" text/plain
expect_status "teapot as text/plain" 201
check "format bpt" test "$(jqb .format)" = bpt
check "32 patches" test "$(jqb .patches)" = 32
check "306 points and the tessellation's vertices" jq -e '.vertices > 306' "$BODY"
check "no n-gons, at most 64 faces per patch" jq -e '.faces.ngons == 0 and .faces.total <= 2048 and .faces.quads > 1800' "$BODY"
check "bbox of the teapot" jq -e '.bbox.min[2] == 0 and .bbox.max[2] == 3.15' "$BODY"
TP=$MESH_ID
upload "$TEAPOT" model/x-bpt
expect_status "teapot as model/x-bpt (same bytes)" 200
check "same id" test "$MESH_ID" = "$TP"
upload "$TEAPOT" application/octet-stream
expect_status "teapot sniffed" 200

# an OBJ carries no patches
upload "$VX_MESH_DIR/spot_control_mesh.obj"
check "OBJ: patches 0, format obj" jq -e '.patches == 0 and .format == "obj"' "$BODY"
upload "$VX_MESH_DIR/spot_control_mesh.obj" model/x-bpt
expect_error "OBJ declared as .bpt" 415 unsupported_media_type

printf '1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,99\n16\n' >"$TMP/bad.bpt"
upload "$TMP/bad.bpt" model/x-bpt
expect_error "index out of range" 400 bpt_index
check "message names line 2" jq -e '.error.message | startswith("line 2: ")' "$BODY"
{
    printf '1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n16\n'
    for i in $(seq 1 15); do echo "$i,0,0"; done
    echo "1,nan,0"
} >"$TMP/nan.bpt"
upload "$TMP/nan.bpt" text/plain
expect_error "NaN" 400 bpt_nan
check "message names line 19" jq -e '.error.message | startswith("line 19: ")' "$BODY"

# the tessellation is what the engines draw
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$TP\",\"kind\":\"preview\",\"params\":{\"width\":128,\"height\":128}}"
check "preview of the teapot ($(jqb -c .error))" jq -e '.state == "succeeded" and .stats.pixels_covered > 2000' "$BODY"
api POST "/v1/jobs?wait=60" -H "Content-Type: application/json" \
    -d "{\"mesh\":\"$TP\",\"kind\":\"catmull-clark\",\"params\":{\"levels\":1}}"
check "catmull-clark of the teapot" jq -e '.state == "succeeded" and .stats.faces > 7000' "$BODY"

finish
