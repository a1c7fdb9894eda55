#!/usr/bin/env bash
# Hostile uploads (issue #10, defects 2 and 8) through the real daemon:
# Draco headers declaring 10^7..10^8 faces in a few dozen bytes, a .bpt
# declaring 4294967294 points, metadata claiming 4 GB. Each gets a 4xx JSON
# error at once, the daemon's peak RSS (VmHWM) stays under 300 MB (before
# the fix: 2.3 GB, or 500 out_of_memory), and it keeps serving. Then the
# parse budget: with a small --max-parse-memory, concurrent uploads get
# some 503 busy_parsing with Retry-After and the others 201; a 503'd upload
# is not stored, every acknowledged one is, and one upload alone over the
# budget is 413 parse_too_big.
source "$(dirname "$0")/lib.sh"
CORPUS="$VX_SOURCE_DIR/tests/fuzz/corpus/fuzz_draco"

# record METHOD PATH FILE: logs a response fetched with plain curl (FILE.status,
# FILE.body, FILE.hdrs) as `api` does, for the contract check.
record() {
    local headers
    headers=$(tr -d '\r' <"$3.hdrs" | awk -F': ' 'NF>=2 && $1 !~ /^HTTP/ {printf "%s\t%s\n", tolower($1), substr($0, length($1)+3)}' |
        jq -R -s 'split("\n") | map(select(length>0) | split("\t") | {(.[0]): .[1]}) | add // {}')
    NREQ=$((NREQ + 1))
    cp "$3.body" "$BODIES/r$NREQ.body"
    jq -cn --arg m "$1" --arg p "$2" --argjson s "$(cat "$3.status")" --arg ct "$(header_of "$3.hdrs" content-type)" \
        --argjson h "$headers" --arg b "$BODIES/r$NREQ.body" \
        '{method:$m, path:$p, status:$s, content_type:$ct, headers:$h, body_file:$b}' >>"$VX_API_LOG"
}
header_of() { tr -d '\r' <"$1" | awk -F': ' -v n="$2" 'tolower($1)==n {print substr($0, length($1)+3)}' | tail -n 1; }

hwm_mb() { awk '/^VmHWM:/ {print int($2 / 1024)}' "/proc/$PID/status"; }

start_daemon || exit 1
api GET /v1/info
expect_status "info" 200
check "info: limits.max_parse_memory_bytes is 8 x max_upload_bytes + 256M by default" \
    jq -e '.limits.max_parse_memory_bytes == 8 * .limits.max_upload_bytes + 268435456' "$BODY"
base=$(hwm_mb)

hostile() { # FILE CT STATUS CODE WHAT
    local t0=$SECONDS
    api POST /v1/meshes -H "Content-Type: $2" --data-binary "@$1" --max-time 20
    expect_error "$5" "$3" "$4"
    check "$5: answered within 5 s" test $((SECONDS - t0)) -le 5
    check "$5: the message names no server path" bash -c "! grep -q '$DATA\|/tmp/' '$BODY'"
}
hostile "$CORPUS/repro-eb-faces-1e8.drc" application/octet-stream 400 draco_corrupt \
    "Draco 2.2 edgebreaker, 10^8 faces in 53 bytes"
hostile "$CORPUS/repro-valence-faces-1e7.drc" model/x-draco 400 draco_corrupt \
    "Draco 2.2 valence, 10^7 faces in 55 bytes"
hostile "$CORPUS/repro-v12-faces-1e8.drc" model/x-draco 400 draco_corrupt \
    "Draco 1.2, 10^8 faces in 45 bytes"
hostile "$CORPUS/repro-seq-points-4e9.drc" model/x-draco 400 draco_corrupt \
    "Draco sequential, 2^32-1 points"
hostile "$CORPUS/repro-metadata-4g.drc" model/x-draco 400 draco_corrupt \
    "Draco metadata entry of 4 GB"
{
    printf '1\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n4294967294\n'
    for i in $(seq 1 16); do echo "$i,0,0"; done
} >"$TMP/points.bpt"
hostile "$TMP/points.bpt" model/x-bpt 400 bpt_truncated ".bpt declaring 4294967294 points"
printf '4194303\n1,2,3,4,5,6,7,8,9,10,11,12,13,14,15,16\n' >"$TMP/patches.bpt"
hostile "$TMP/patches.bpt" text/plain 413 mesh_too_big ".bpt declaring 4194303 patches"
# A header that passes the check (2 million faces declared in 1 KB: the
# most 2048 faces a byte allows) is bounded by it: libdraco's tables for
# 2 million faces, then a corrupt-data error.
python3 - "$CORPUS/tet.cl7.drc" "$TMP/dense.drc" <<'EOF'
import sys
d = open(sys.argv[1], 'rb').read()
def var(v):
    o = b''
    while True:
        b, v = v & 0x7f, v >> 7
        if v: o += bytes([b | 0x80])
        else: return o + bytes([b])
# 2.2 edgebreaker: traversal at 11, then varints vertices, faces, a byte, symbols
assert d[8] == 1 and d[12] == 4 and d[13] == 4 and d[15] == 3
n = 2000000
out = d[:12] + var(4) + var(n) + d[14:15] + var(n) + d[16:]
open(sys.argv[2], 'wb').write(out + b'\0' * (1000 - len(out)))
EOF
hostile "$TMP/dense.drc" model/x-draco 400 draco_corrupt "Draco, 2 million faces in 1000 bytes"
peak=$(hwm_mb)
check "peak RSS under 300 MB after the hostile uploads (base $base MB, peak $peak MB)" \
    test "$peak" -lt 300

# still serving, and real files still read
api GET /v1/info
expect_status "info after the hostile uploads" 200
upload "$VX_MESH_DIR/newell-teapot.bpt" model/x-bpt
expect_status "the teapot" 201
for f in suzanne.cl10.drc tet.cl0.drc tet.cl7.meta.drc; do
    upload "$CORPUS/$f" model/x-draco
    expect_status "real Draco $f" 201
done
stop_daemon

# ---- the parse budget ---------------------------------------------------
# OBJ reserves 8 x the file + 16 MiB: 5 MB files reserve 56 MB, so a 100 MB
# budget parses one at a time.
rm -rf "$DATA"
start_daemon --max-parse-memory 100M --http-threads 8 || exit 1
api GET /v1/info
check "info: max_parse_memory_bytes 100M" jq -e '.limits.max_parse_memory_bytes == 104857600' "$BODY"
python3 - "$TMP/base.obj" <<'EOF'
import sys
n = 200
with open(sys.argv[1], 'w') as f:
    for j in range(n):
        for i in range(n):
            f.write(f"v {i * 0.01:.6f} {j * 0.01:.6f} {((i * j) % 7) * 0.001:.6f}\n")
    for j in range(n - 1):
        for i in range(n - 1):
            a = j * n + i + 1
            f.write(f"f {a} {a + 1} {a + n + 1}\nf {a} {a + n + 1} {a + n}\n")
    while f.tell() < 5_000_000:
        f.write("vn 0.000000 0.000000 1.000000\n")
EOF
upload "$TMP/base.obj"
expect_status "one 5 MB OBJ alone fits" 201
{ cat "$TMP/base.obj" "$TMP/base.obj" "$TMP/base.obj"; } >"$TMP/big.obj"
upload "$TMP/big.obj"
expect_error "a 15 MB OBJ alone (reserves 136 MB) is over the budget" 413 parse_too_big
check "parse_too_big: not stored" test "$(curl -s -o /dev/null -w '%{http_code}' "$BASE/v1/meshes/$(sha256sum "$TMP/big.obj" | cut -c1-64)")" = 404

n503=0
n201=0
acked=()
for round in 1 2 3 4 5 6 7 8; do
    pids=()
    for k in 1 2 3 4 5 6 7 8; do
        f=$TMP/c$round-$k.obj
        { echo "# round $round copy $k"; cat "$TMP/base.obj"; } >"$f"
    done
    for k in 1 2 3 4 5 6 7 8; do
        f=$TMP/c$round-$k.obj
        curl -sS -o "$f.body" -D "$f.hdrs" -w '%{http_code}' -H 'Content-Type: model/obj' \
            --data-binary "@$f" "$BASE/v1/meshes" >"$f.status" &
        pids+=($!)
    done
    wait "${pids[@]}"
    for k in 1 2 3 4 5 6 7 8; do
        f=$TMP/c$round-$k.obj
        st=$(cat "$f.status")
        sha=$(sha256sum "$f" | cut -c1-64)
        case "$st" in
        201)
            n201=$((n201 + 1))
            record POST /v1/meshes "$f"
            acked+=("$sha")
            check "201 body is the mesh" jq -e --arg id "$sha" '.id == $id' "$f.body"
            ;;
        503)
            n503=$((n503 + 1))
            record POST /v1/meshes "$f"
            check "503 busy_parsing JSON error" jq -e '.error.code == "busy_parsing" and (.error|length)==2' "$f.body"
            check "503 has Retry-After" grep -qi '^retry-after: [1-9]' "$f.hdrs"
            check "503'd upload not stored" test "$(curl -s -o /dev/null -w '%{http_code}' "$BASE/v1/meshes/$sha")" = 404
            # retried after Retry-After (the first one: each retry waits), it is stored
            ((n503 > 1)) && continue
            for try in 1 2 3 4 5 6 7 8 9 10; do
                sleep 2
                st=$(curl -sS -o "$f.body" -w '%{http_code}' -H 'Content-Type: model/obj' --data-binary "@$f" "$BASE/v1/meshes")
                [[ "$st" != 503 ]] && break
            done
            check "503'd upload retried: 201 (got $st)" test "$st" = 201
            [[ "$st" == 201 ]] && acked+=("$sha")
            ;;
        *) check "concurrent upload: 201 or 503 (got $st: $(head -c 200 "$f.body"))" false ;;
        esac
    done
    ((n503 > 0 && n201 > 0)) && break
done
check "concurrent uploads: some 503 ($n503) and some 201 ($n201)" test "$n503" -gt 0 -a "$n201" -gt 0
api GET /v1/info
expect_status "info after the concurrent uploads" 200
stop_daemon

# nothing acknowledged is lost, across a restart too
start_daemon --max-parse-memory 100M || exit 1
lost=0
for sha in "${acked[@]}"; do
    [[ "$(curl -s -o /dev/null -w '%{http_code}' "$BASE/v1/meshes/$sha")" == 200 ]] || lost=$((lost + 1))
done
check "all ${#acked[@]} acknowledged uploads stored after a restart ($lost lost)" test "$lost" -eq 0
stop_daemon

# A JSON job body reserves 32 times its bytes from the same budget (16 MiB
# of "[]," held 420 MB while read): one alone over it is 413.
start_daemon --max-parse-memory 2M || exit 1
python3 -c 'import json; print(json.dumps({"mesh": "0" * 64, "kind": "voxelize", "params": {"pad": [[]] * 40000}}))' >"$TMP/big.json"
api POST /v1/jobs -H "Content-Type: application/json" --data-binary "@$TMP/big.json"
expect_error "a $(stat -c %s "$TMP/big.json")-byte job body over max-parse-memory / 32" 413 too_large
check "saying why" jq -e '.error.message | test("may take up to [0-9]+ bytes of memory to read")' "$BODY"
api POST /v1/jobs -H "Content-Type: application/json" -d '{"mesh":"'"$(printf '%064d' 0)"'","kind":"voxelize"}'
expect_error "a small one still goes through (to its 404)" 404 mesh_not_found
# A compressed body is refused by its coding (a gzip'd OBJ was parsed as
# it is: a format error about bytes the client never meant); identity is
# taken.
gzip -c "$VX_SOURCE_DIR/examples/meshes/torus.obj" >"$TMP/torus.obj.gz"
api POST /v1/meshes -H "Content-Type: model/obj" -H "Content-Encoding: gzip" --data-binary "@$TMP/torus.obj.gz"
expect_error "a gzip'd upload" 415 unsupported_media_type
check "... naming the coding" jq -e '.error.message | test("^Content-Encoding gzip: the body must come uncompressed")' "$BODY"
api POST /v1/jobs -H "Content-Type: application/json" -H "Content-Encoding: br" -d '{"mesh":"'"$(printf '%064d' 0)"'","kind":"voxelize"}'
expect_error "a job body with Content-Encoding br" 415 unsupported_media_type
api POST /v1/jobs -H "Content-Type: application/json" -H "Content-Encoding: Identity" -d '{"mesh":"'"$(printf '%064d' 0)"'","kind":"voxelize"}'
expect_error "Content-Encoding identity is taken (to its 404)" 404 mesh_not_found
stop_daemon
finish
