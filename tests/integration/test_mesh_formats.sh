#!/usr/bin/env bash
# STL (binary, ASCII), PLY (binary LE/BE, ASCII), glTF (embedded), glb (a
# node transform) and OFF uploads: content types and sniffing (curl's
# default form type too), the Mesh JSON's counts and bbox, a voxelization,
# and 400s naming the format for malformed files and for declared counts
# that the file cannot hold (never an allocation sized by them).
source "$(dirname "$0")/lib.sh"
start_daemon --max-triangles 100000 || exit 1

F=$TMP/formats
python3 "$(dirname "$0")/mesh_formats.py" "$F" || exit 1

# cube FILE CONTENT_TYPE FORMAT QUADS [BBOX_MIN BBOX_MAX]: a unit cube upload.
cube() {
    local what="$(basename "$1") as ${2:-curl default type}"
    if [[ -n "$2" ]]; then
        api POST /v1/meshes -H "Content-Type: $2" --data-binary "@$1"
    else
        api POST /v1/meshes --data-binary "@$1" # application/x-www-form-urlencoded
    fi
    MESH_ID=$(jqb '.id // empty')
    check "$what: 201 or 200 (got $STATUS: $(jqb -c .error))" test "$STATUS" = 201 -o "$STATUS" = 200
    check "$what: format $3" test "$(jqb .format)" = "$3"
    check "$what: 8 vertices, 12 triangles, closed" \
        jq -e '.vertices == 8 and .triangles == 12 and .boundary_edges == 0 and .nonmanifold_edges == 0' "$BODY"
    check "$what: $4 quads" jq -e ".faces.quads == $4" "$BODY"
    check "$what: bbox ${5:-[0,0,0]} ${6:-[1,1,1]}" \
        jq -e ".bbox.min == ${5:-[0,0,0]} and .bbox.max == ${6:-[1,1,1]}" "$BODY"
}

# A malformed file: 400 with CODE, the message naming NAME.
bad() { # FILE CONTENT_TYPE CODE NAME
    upload "$F/$1" "$2"
    expect_error "$1" 400 "$3"
    check "$1: the message names $4 ($(jqb .error.message))" jq -e --arg n "$4" '.error.message | contains($n)' "$BODY"
}

# Declared and sniffed.
cube "$F/cube_bin.stl" model/stl stl 0
cube "$F/cube_bin.stl" "" stl 0
cube "$F/cube_ascii.stl" model/stl stl 0
cube "$F/cube_ascii.stl" application/octet-stream stl 0
cube "$F/cube_bin.ply" model/x-ply ply 0
cube "$F/cube_be.ply" application/ply ply 0
cube "$F/cube_ascii.ply" "" ply 6
cube "$F/cube.gltf" model/gltf+json gltf 0
cube "$F/cube.gltf" "" gltf 0
cube "$F/cube.glb" model/gltf-binary glb 0 '[10,20,30]' '[12,22,32]'
cube "$F/cube.glb" "" glb 0 '[10,20,30]' '[12,22,32]'
cube "$F/cube.off" model/x-off off 6
cube "$F/cube.off" "" off 6
OFF_ID=$MESH_ID
# What exporters write too: STL keywords in capitals (sniffed as well), a
# byte order mark, OBJ names in Latin-1 (read again by the job: it takes
# the upload's format, not a sniff of bytes that are not UTF-8), OFF lines
# of any length, glTF nodes 200 deep, OBJ with CR line ends (classic Mac
# OS) or RGBA vertex colours, 4OFF (x y z w) and nOFF of dimension 3.
cube "$F/cube_upper.stl" model/stl stl 0
cube "$F/cube_upper.stl" application/octet-stream stl 0
cube "$F/cube_bom.stl" model/stl stl 0
cube "$F/cube_latin1.obj" model/obj obj 6
LATIN1_ID=$MESH_ID
cube "$F/cube_latin1.obj" "" obj 6
cube "$F/cube_long.off" model/x-off off 6
cube "$F/cube_cr.obj" model/obj obj 6
cube "$F/cube_cr.obj" "" obj 6
cube "$F/cube_rgba.obj" model/obj obj 6
cube "$F/cube_4.off" model/x-off off 6
cube "$F/cube_4.off" "" off 6
cube "$F/cube_n.off" model/x-off off 6
cube "$F/cube_deep.gltf" model/gltf+json gltf 0
# Morph targets at their default weights (the mesh's, or the node's over
# them), and a skinned mesh placed by its joint and inverse bind matrix, its
# node's own translation ignored (glTF 2.0; both were read as the base cube
# and the node's transform).
cube "$F/cube_morph.gltf" model/gltf+json gltf 0 '[10,0,0]' '[11,1,1]'
cube "$F/cube_morph_node.gltf" model/gltf+json gltf 0 '[5,0,0]' '[6,1,1]'
cube "$F/cube_skin.gltf" model/gltf+json gltf 0 '[2,0,0]' '[3,1,1]'
# Accessors with no bufferView are zeros, then their sparse values: a
# morph target moving four vertices (what Blender writes for a shape key
# that moves few), positions wholly sparse, and inverse bind matrices that
# declare 2^32 - 1 (only the joint's is read); a count that nothing backs is
# held to the triangle limit before any read (all were 400 before).
cube "$F/cube_sparse_morph.gltf" model/gltf+json gltf 0 '[0,0,0]' '[11,1,1]'
cube "$F/cube_sparse_pos.gltf" model/gltf+json gltf 0 '[20,0,0]' '[21,1,1]'
cube "$F/cube_sparse_ibm.gltf" model/gltf+json gltf 0 '[2,0,0]' '[3,1,1]'
upload "$F/zero_huge.gltf" model/gltf+json
expect_error "3 x 10^9 vertices of zeros" 413 mesh_too_big
bad zero_2e33.gltf model/gltf+json gltf_corrupt "elements of zeros (at most 2^32 - 1)"
bad skin_short.gltf model/gltf+json gltf_corrupt "skin accessor"
t0=$(date +%s.%N)
upload "$F/skin_many.gltf" model/gltf+json
t1=$(date +%s.%N)
check "8000 skinned nodes on one skin of 8000 joints: 201 (got $STATUS $(jqb .error.message))" test "$STATUS" = 201
check "... in well under the 9 s it took (its joints made once: $(awk -v a="$t0" -v b="$t1" 'BEGIN{print b-a}') s)" \
    awk -v a="$t0" -v b="$t1" 'BEGIN{exit !(b-a < 4)}'
# A binary STL with bytes after its last triangle (they are ignored; it
# was 400 declared and 415 sniffed), its header "solid" too; ASCII STL
# normals that are no numbers (not read) and a solid name longer than the
# sniffed bytes (taken for OBJ); ModelNet's "OFF8 6 0"; OBJ's maplib,
# usemap, csh and old patch statements (obj_junk).
cube "$F/cube_trailing.stl" model/stl stl 0
cube "$F/cube_trailing.stl" "" stl 0
cube "$F/cube_trailing_solid.stl" model/stl stl 0
cube "$F/cube_trailing_solid.stl" application/octet-stream stl 0
cube "$F/cube_ind.stl" model/stl stl 0
cube "$F/cube_ind.stl" "" stl 0
cube "$F/cube_glued.off" model/x-off off 6
cube "$F/cube_glued.off" "" off 6
cube "$F/cube_maplib.obj" model/obj obj 6
run_job voxelize "$MESH_ID" '{"resolution":8,"format":"summary"}'
job_ok "voxelize the OBJ with maplib"
check "maplib OBJ: 512 voxels in 8^3" jq -e '.stats.voxels_inside == 512' "$TMP/job.json"
upload "$F/cube_trailing.stl" application/octet-stream
TRAILING_ID=$MESH_ID
run_job voxelize "$TRAILING_ID" '{"resolution":8,"format":"summary"}'
job_ok "voxelize the STL with trailing bytes"
check "trailing-bytes STL: 512 voxels in 8^3" jq -e '.stats.voxels_inside == 512' "$TMP/job.json"
run_job voxelize "$LATIN1_ID" '{"resolution":8,"format":"summary"}'
job_ok "voxelize the OBJ with Latin-1 names"
check "Latin-1 OBJ: 512 voxels in 8^3" jq -e '.stats.voxels_inside == 512' "$TMP/job.json"
upload "$F/cube_bin.stl" model/x-draco
expect_error "STL declared as Draco" 415 unsupported_media_type
upload "$F/cube_bin.ply" model/stl
expect_error "PLY declared as STL" 415 unsupported_media_type
check "the message names both" jq -e '.error.message == "Content-Type says STL but the body is a PLY file"' "$BODY"

# Malformed files and lying counts: 400 naming the format.
bad bad.stl model/stl stl_corrupt STL
bad bad.ply model/x-ply ply_corrupt PLY
bad bad.gltf model/gltf+json gltf_corrupt glTF
bad bad.glb model/gltf-binary gltf_corrupt glTF
bad bad.off model/x-off off_corrupt OFF
bad lie.stl model/stl stl_corrupt STL
bad mode7.gltf model/gltf+json gltf_corrupt "mode 7 (glTF's are 0 to 6)"
bad lie.stl application/octet-stream stl_corrupt STL
bad lie.ply model/x-ply ply_corrupt PLY
bad lie_faces.ply application/octet-stream ply_corrupt PLY
bad lie.gltf model/gltf+json gltf_corrupt glTF
bad lie.glb application/x-www-form-urlencoded gltf_corrupt glTF
bad lie.off model/x-off off_corrupt OFF
bad repeat.off model/x-off off_corrupt "uses vertex 1 twice"
bad repeat.ply model/x-ply ply_corrupt "uses vertex 2 twice"
# Faces that are points or edges only: 422, said so.
printf 'OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n2 0 1\n' >"$F/edges.off"
upload "$F/edges.off" model/x-off
expect_error "an OFF of edges only" 422 off_no_faces
check "edges only: the message says why" jq -e '.error.message | test("point or an edge")' "$BODY"
bad external.gltf model/gltf+json gltf_corrupt "external file"
bad data_no_type.gltf model/gltf+json gltf_corrupt "data: URI is not base64 of a media type the reader decodes"
bad data_upper.gltf model/gltf+json gltf_corrupt "data: URI is not base64 of a media type the reader decodes"
bad cycle.glb model/gltf-binary gltf_corrupt "reached twice"
bad call.obj model/obj obj_junk "'call'"
bad trailing_short.stl model/stl stl_corrupt "has only 683 bytes"
bad too_deep.gltf model/gltf+json gltf_corrupt "nested more than 256 deep"
bad draco.gltf model/gltf+json gltf_corrupt "requires KHR_draco_mesh_compression"
bad short_matrix.gltf model/gltf+json gltf_corrupt "matrix is not 16"
bad zero_rotation.gltf model/gltf+json gltf_corrupt "not all 0"
# Counts too small (the rest read out of step), an index that is no integer
bad short.off model/x-off off_corrupt "more after the last face"
bad float_index.off model/x-off off_corrupt "whole-number indices"
bad n4.off model/x-off off_corrupt "nOFF of dimension 4"
bad w0.off model/x-off off_corrupt "w is 0"
bad short.ply model/x-ply ply_corrupt "after the last element"
bad trailing.ply model/x-ply ply_corrupt "4 bytes after the last element"
# 200000 instances of the cube: the header check indexes the file's arrays
# once (item by item, cJSON's lists made it quadratic: 158 s), so the
# triangle count is over the limit in well under a minute.
api POST /v1/meshes -H "Content-Type: model/gltf-binary" --max-time 60 --data-binary "@$F/instances.glb"
expect_error "200000 glTF instances over --max-triangles 100000" 413 mesh_too_big
# An ASCII STL declares no count: 20000 facets as exporters write them
# (about 250 bytes each, 5 MB: size / 32 is 156000) are under
# --max-triangles 100000 (it was 413 mesh_too_big "declares 156000"), and
# 100001 compact facets over it are 413 from the reader, which counts them.
python3 - "$TMP/ascii20k.stl" "$TMP/ascii100k.stl" <<'PY'
import sys
with open(sys.argv[1], "w") as f:
    f.write("solid exported\n")
    for i in range(20000):
        x = float(i)
        f.write("  facet normal 0.000000e+00 0.000000e+00 1.000000e+00\n    outer loop\n")
        for v in ((x, 0.0, 0.0), (x + 1, 0.0, 0.0), (x, 1.0, 0.0)):
            f.write("      vertex %e %e %e\n" % v)
        f.write("    endloop\n  endfacet\n")
    f.write("endsolid exported\n")
with open(sys.argv[2], "w") as f:
    f.write("solid c\n")
    f.write("facet normal 0 0 1 outer loop vertex 0 0 0 vertex 1 0 0 vertex 0 1 0 endloop endfacet\n" * 100001)
PY
api POST /v1/meshes -H "Content-Type: model/stl" --data-binary "@$TMP/ascii20k.stl"
check "ASCII STL of 20000 facets (5 MB) under --max-triangles 100000: 201 (got $STATUS $(jqb .error.message))" test "$STATUS" = 201
check "its 20000 triangles" jq -e '.triangles == 20000' "$BODY"
api POST /v1/meshes -H "Content-Type: model/stl" --data-binary "@$TMP/ascii100k.stl"
expect_error "ASCII STL of 100001 facets over --max-triangles 100000" 413 mesh_too_big
# 40000 one-triangle primitives over one accessor of 400000 vertices: each
# decodes only the 3 it indexes (decoded whole for each, it took minutes).
api POST /v1/meshes -H "Content-Type: model/gltf-binary" --max-time 60 --data-binary "@$F/primitives.glb"
check "40000 primitives over one shared accessor: 201 (got $STATUS)" test "$STATUS" = 201
check "40000 primitives: 40000 triangles, 120000 vertices" \
    jq -e '.triangles == 40000 and .vertices == 120000' "$BODY"
# A count the bytes could hold but the limit does not: 413 before decoding.
python3 - "$F/big.stl" <<'EOF'
import struct, sys
n = 100001
open(sys.argv[1], "wb").write(b"big".ljust(80) + struct.pack("<I", n) + bytes(50 * n))
EOF
upload "$F/big.stl" model/stl
expect_error "100001 triangles over --max-triangles 100000" 413 mesh_too_big
grep -a 'event=mesh.rejected' "$TMP/daemon.log" | tail -n 3 >/dev/null

# The daemon is fine, and an OFF cube voxelizes like the OBJ one.
api GET /readyz
expect_status "ready after the bad uploads" 200
run_job voxelize "$OFF_ID" '{"resolution":8,"method":"slice","format":"summary"}'
job_ok "voxelize the OFF cube"
check "OFF cube: 512 voxels in 8^3" jq -e '.stats.voxels_inside == 512 and .stats.dims == [8,8,8]' "$TMP/job.json"

# GET /v1/meshes/{id}/file: the uploaded bytes, typed, with a strong ETag.
for f in cube_bin.stl:model/stl cube.glb:model/gltf-binary cube_ascii.ply:model/x-ply cube.off:model/x-off; do
    file=${f%%:*} type=${f#*:}
    upload "$F/$file" application/octet-stream
    id=$MESH_ID
    api GET "/v1/meshes/$id/file"
    expect_status "file of $file" 200
    check "file of $file: the same bytes" cmp -s "$BODY" "$F/$file"
    check "file of $file: Content-Type $type (got $CTYPE)" test "$CTYPE" = "$type"
    check "file of $file: ETag is the id" test "$(header ETag)" = "\"$id\""
    api GET "/v1/meshes/$id/file" -H "If-None-Match: \"$id\""
    expect_status "file of $file, If-None-Match" 304
    check "file of $file, 304: ETag and Cache-Control kept" \
        test "$(header ETag)-$(header Cache-Control)" = "\"$id\"-private, max-age=86400, immutable"
done
api GET "/v1/meshes/$(printf 'f%.0s' $(seq 64))/file"
expect_error "file of an unknown mesh" 404 mesh_not_found

# A name from ?name= or a Content-Disposition filename: kept, listed, in
# the result's file name. (Bytes stored before keep the name they got.)
{ cat "$F/cube.off"; echo "# named"; } >"$F/named.off"
sed 's/solid cube/solid box/' "$F/cube_ascii.stl" >"$F/box.stl"
api POST "/v1/meshes?name=Cube%20%C3%A9t%C3%A9.off" -H "Content-Type: model/x-off" \
    --data-binary "@$F/named.off"
check "?name= is kept ($(jqb .name))" test "$(jqb .name)" = "Cube été.off"
api POST /v1/meshes -H "Content-Type: model/stl" \
    -H 'Content-Disposition: attachment; filename="C:\\models\\box.stl"' --data-binary "@$F/box.stl"
check "Content-Disposition filename, directories dropped ($(jqb .name))" test "$(jqb .name)" = box.stl
BOX=$(jqb .id)
api GET "/v1/meshes/$BOX"
check "the name in the mesh" test "$(jqb .name)" = box.stl
api GET "/v1/meshes?limit=1000"
check "the name in the list" jq -e --arg id "$BOX" '.items[] | select(.id == $id) | .name == "box.stl"' "$BODY"
api POST "/v1/meshes?name=a/b" -H "Content-Type: model/stl" --data-binary "@$F/cube_ascii.stl"
expect_error "a name with a slash" 400 invalid_request
api POST "/v1/meshes?name=.." -H "Content-Type: model/stl" --data-binary "@$F/cube_ascii.stl"
expect_error "the name .." 400 invalid_request
api POST "/v1/meshes?name=evil%E2%80%AEgpj.stl" -H "Content-Type: model/stl" --data-binary "@$F/cube_ascii.stl"
expect_error "a name holding U+202E (right-to-left override)" 400 invalid_request
api POST /v1/meshes -H "Content-Type: model/stl" -H 'Content-Disposition: attachment; filename=".."' \
    --data-binary "@$F/cube_ascii.stl"
expect_error "a Content-Disposition filename .." 400 invalid_request
# filename* (RFC 8187) wins over filename; only it, UTF-8 or ISO-8859-1
sed 's/solid cube/solid star/' "$F/cube_ascii.stl" >"$F/star.stl"
api POST /v1/meshes -H "Content-Type: model/stl" \
    -H "Content-Disposition: attachment; filename=\"plain.stl\"; filename*=UTF-8''%C3%A9toile.stl" \
    --data-binary "@$F/star.stl"
check "filename* is preferred ($(jqb .name))" test "$(jqb .name)" = "étoile.stl"
sed 's/solid cube/solid latin/' "$F/cube_ascii.stl" >"$F/latin.stl"
api POST /v1/meshes -H "Content-Type: model/stl" \
    -H "Content-Disposition: attachment; filename*=iso-8859-1'fr'caf%E9.stl" --data-binary "@$F/latin.stl"
check "filename* alone, ISO-8859-1 ($(jqb .name))" test "$(jqb .name)" = "café.stl"
api POST /v1/meshes -H "Content-Type: model/stl" \
    -H "Content-Disposition: attachment; filename*=UTF-8''x%E2%80%AE.stl" --data-binary "@$F/latin.stl"
expect_error "filename* holding U+202E" 400 invalid_request
# If-Match on the file: its id, or *
api GET "/v1/meshes/$BOX/file" -H "If-Match: \"$BOX\""
expect_status "mesh file, If-Match of its id" 200
api GET "/v1/meshes/$BOX/file" -H "If-Match: *"
expect_status "mesh file, If-Match: *" 200
api GET "/v1/meshes/$BOX/file" -H "If-Match: \"$(printf 'e%.0s' $(seq 64))\""
expect_error "mesh file, If-Match of another id" 412 precondition_failed
api POST "/v1/meshes?name=$(printf 'x%.0s' $(seq 101))" -H "Content-Type: model/stl" --data-binary "@$F/cube_ascii.stl"
expect_error "a name of 101 bytes" 400 invalid_request

# glb results: catmull-clark and gregory, parsed here (JSON chunk, counts,
# the buffer holding what the accessors say).
glb_check() { # FILE WHAT
    python3 - "$1" >"$TMP/glb.txt" 2>&1 <<'EOF'
import json, struct, sys
d = open(sys.argv[1], "rb").read()
magic, ver, total = struct.unpack_from("<4sII", d, 0)
assert magic == b"glTF" and ver == 2 and total == len(d), (magic, ver, total, len(d))
jlen, jtype = struct.unpack_from("<I4s", d, 12)
assert jtype == b"JSON"
g = json.loads(d[20:20 + jlen])
at = 20 + jlen
blen, btype = struct.unpack_from("<I4s", d, at)
assert btype == b"BIN\0" and at + 8 + blen <= len(d)
assert g["buffers"][0]["byteLength"] <= blen
prim = g["meshes"][0]["primitives"][0]
pos = g["accessors"][prim["attributes"]["POSITION"]]
idx = g["accessors"][prim["indices"]]
for a in (pos, idx):
    v = g["bufferViews"][a["bufferView"]]
    assert v.get("byteOffset", 0) + v["byteLength"] <= blen
print(pos["count"], idx["count"] // 3)
EOF
    check "$2: the glb parses ($(tr '\n' ' ' <"$TMP/glb.txt"))" test "$(wc -w <"$TMP/glb.txt")" = 2
}
run_job catmull-clark "$OFF_ID" '{"levels":1,"format":"glb"}'
job_ok "catmull-clark to glb"
api GET "/v1/jobs/$JOB/result"
check "catmull-clark glb: model/gltf-binary" test "$CTYPE" = model/gltf-binary
cp "$BODY" "$TMP/cc.glb"
glb_check "$TMP/cc.glb" "catmull-clark"
check "catmull-clark glb: 26 vertices, 48 triangles (24 quads) (got $(cat "$TMP/glb.txt"))" test "$(cat "$TMP/glb.txt")" = "26 48"
# The glb goes back in as an upload (tinygltf reads what libdraco wrote).
upload "$TMP/cc.glb" model/gltf-binary
check "the catmull-clark glb uploads: 48 triangles, closed" jq -e '.triangles == 48 and .boundary_edges == 0' "$BODY"
run_job catmull-clark "$BOX" '{"levels":1,"format":"glb"}'
api GET "/v1/jobs/$JOB/result"
DISP=$(header Content-Disposition)
check "the result is named after the mesh ($DISP)" grep -qE "filename=\"$JOB-mesh.glb\"; filename\*=UTF-8''box-$JOB-mesh.glb$" <<<"$DISP"
run_job gregory "$OFF_ID" '{"divisions":4,"format":"glb"}'
job_ok "gregory to glb"
api GET "/v1/jobs/$JOB/result"
check "gregory glb: model/gltf-binary" test "$CTYPE" = model/gltf-binary
cp "$BODY" "$TMP/g.glb"
glb_check "$TMP/g.glb" "gregory"

finish
