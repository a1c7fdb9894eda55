#!/usr/bin/env bash
# Uploads: every shared mesh as OBJ and as Draco, dedup, listing, paging,
# metadata, delete; ops endpoints.
source "$(dirname "$0")/lib.sh"
start_daemon || exit 1

api GET /livez
expect_status livez 200
check "livez body" jq -e '.status == "ok"' "$BODY"
api GET /readyz
expect_status readyz 200
check "readyz checks" jq -e '.status == "ready" and .checks.gl and .checks.data_dir and .queue.full == false and .queue.capacity > 0' "$BODY"
check "readyz: the default blob store is the data dir" jq -e '.blob_store == {"backend":"local","ok":true}' "$BODY"
api GET /v1/info
expect_status info 200
check "info renderer" jq -e '(.gl.renderer|length) > 0 and (.gl.version|test("4\\.[5-9]|[5-9]\\."))' "$BODY"
check "info kinds has preview" jq -e '[.kinds[].name] | index("preview")' "$BODY"
check "info limits" jq -e '.limits.max_upload_bytes > 0 and .limits.max_queued_jobs > 0' "$BODY"

declare -A ids
for f in "$VX_MESH_DIR"/*.obj; do
    name=$(basename "$f" .obj)
    upload "$f"
    expect_status "upload $name" 201
    check "$name: id is the sha256 of the bytes" test "$MESH_ID" = "$(sha256sum "$f" | cut -d' ' -f1)"
    check "$name: Location" test "$(header Location)" = "/v1/meshes/$MESH_ID"
    check "$name: format obj" jq -e '.format == "obj" and .bytes > 0 and .vertices > 0 and .triangles > 0' "$BODY"
    ids[$name]=$MESH_ID
    cp "$BODY" "$TMP/$name.meta"
    # the same bytes again: 200, same id
    upload "$f" text/plain
    expect_status "re-upload $name" 200
    check "$name: dedup keeps the id" test "$MESH_ID" = "${ids[$name]}"

    # the same surface as Draco (draco_encoder keeps positions at -qp 30)
    draco_encoder -i "$f" -o "$TMP/$name.drc" -qp 30 -cl 7 >/dev/null 2>&1
    upload "$TMP/$name.drc" model/x-draco
    expect_status "upload $name.drc" 201
    check "$name.drc: format draco" jq -e '.format == "draco"' "$BODY"
    check "$name.drc: same triangle count as OBJ" test "$(jqb .triangles)" = "$(jq .triangles "$TMP/$name.meta")"
    check "$name.drc: same bbox" jq -e --slurpfile o "$TMP/$name.meta" \
        '[range(3) as $i | ((.bbox.min[$i] - $o[0].bbox.min[$i])|fabs) < 1e-3 * (1 + ($o[0].bbox.max[$i]-$o[0].bbox.min[$i])|fabs)] | all' "$BODY"
    # sniffed by content
    upload "$TMP/$name.drc" application/octet-stream
    expect_status "re-upload $name.drc sniffed" 200
done

# Known facts of the shared meshes (../shared/data/meshes/README.md).
check "bunny is open: 223 boundary edges" jq -e '.boundary_edges == 223 and .triangles == 69451' "$TMP/stanford-bunny.meta"
check "spot_triangulated closed" jq -e '.boundary_edges == 0 and .triangles == 5856' "$TMP/spot_triangulated.meta"
check "spot_quadrangulated quads" jq -e '.faces.quads == 2928 and .faces.total == 2928 and .triangles == 5856' "$TMP/spot_quadrangulated.meta"
check "fandisk closed" jq -e '.boundary_edges == 0' "$TMP/fandisk.meta"
check "rocker-arm closed" jq -e '.boundary_edges == 0' "$TMP/rocker-arm.meta"
check "suzanne open" jq -e '.boundary_edges == 42 and .faces.total == 500' "$TMP/suzanne.meta"
check "ogre open" jq -e '.boundary_edges == 236 and .triangles == 124008' "$TMP/ogre.meta"

api GET "/v1/meshes/${ids[suzanne]}"
expect_status "get mesh" 200
check "get mesh = upload metadata" test "$(jq -S 'del(.created)' "$BODY")" = "$(jq -S 'del(.created)' "$TMP/suzanne.meta")"
api HEAD "/v1/meshes/${ids[suzanne]}"
expect_status "head mesh" 200

# Paging through every mesh, 5 at a time: each id once, sorted.
after=""
: >"$TMP/listed"
for page in $(seq 1 20); do
    api GET "/v1/meshes?limit=5${after:+&after=$after}"
    expect_status "list page $page" 200
    jqb '.items[].id' >>"$TMP/listed"
    after=$(jqb '.next // empty')
    [[ -z "$after" ]] && break
done
total=$(wc -l <"$TMP/listed")
check "listing has all 16 meshes (got $total)" test "$total" -eq 16
check "listing sorted and unique" cmp -s "$TMP/listed" <(sort -u "$TMP/listed")

api DELETE "/v1/meshes/${ids[suzanne]}"
expect_status "delete mesh" 204
api GET "/v1/meshes/${ids[suzanne]}"
expect_error "deleted mesh" 404 mesh_not_found
api DELETE "/v1/meshes/${ids[suzanne]}"
expect_error "delete twice" 404 mesh_not_found
upload "$VX_MESH_DIR/suzanne.obj"
expect_status "upload after delete" 201

# Chunked upload (no Content-Length) streams too.
api POST /v1/meshes -H "Content-Type: model/obj" -H "Transfer-Encoding: chunked" --data-binary "@$VX_MESH_DIR/spot_control_mesh.obj"
expect_status "chunked re-upload" 200

api GET /metrics
expect_status metrics 200
check "metrics content type" bash -c "echo '$CTYPE' | grep -q 'text/plain'"
check "metrics: upload counter" grep -q 'voxeld_http_requests_total{route="/v1/meshes",method="POST",status="201"}' "$BODY"
check "metrics: info gauge" grep -q '^voxeld_info{.*gl_renderer=' "$BODY"
check "metrics: queue depth" grep -q '^voxeld_queue_depth 0' "$BODY"
check "metrics: bytes received" grep -Eq '^voxeld_http_bytes_received_total [1-9]' "$BODY"
# Every sample line parses as the exposition format.
check "metrics parse" bash -c "grep -v '^#' '$BODY' | grep -v -E '^[a-zA-Z_:][a-zA-Z0-9_:]*(\\{([a-zA-Z_][a-zA-Z0-9_]*=\"([^\"\\\\]|\\\\.)*\",?)*\\})? [-+0-9.eEInfa]+$' | grep -q . && exit 1 || exit 0"

stop_daemon
finish
