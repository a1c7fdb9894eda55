#!/usr/bin/env bash
# The seed 002 figures, rendered through the daemon's HTTP API (the
# `render` kind) into docs/figures/:
#   bandlimit_{hyperboloid,sphere,cube}_r64_n8.png   R = 64, N = 8, M = 64 (L = 8)
#   bandlimit_cube_n16_r{16,32,64}.png                N = 16, M = 64, R = 16, 32, 64
#   bandlimit_compare_hyperboloid.png                 the five older shadings next to
#                                                     the band-limited one (64^3 voxels)
#   bandlimit_fused_spheres.png                       two spheres summed (meshes)
#   bench/bandlimit/figures.sh [build dir]
set -uo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
export VOXELD=$build/voxeld VX_TOOLS=$build/tools VX_MESH_DIR=$root/../shared/data/meshes VX_SOURCE_DIR=$root
source "$root/tests/integration/lib.sh"
out=$root/docs/figures
mkdir -p "$out"
start_daemon || exit 1
python3 "$root/bench/bandlimit/seed_shapes.py" "$TMP" || exit 1
for s in hyperboloid sphere cube; do
    upload "$TMP/$s.obj"
    declare "M_$s=$MESH_ID"
done
# two unit spheres 1.6 apart (their blend is seed 002's fused-spheres example)
awk '/^v / { printf "v %.9f %.9f %.9f\n", $2 - 0.8, $3, $4; next } { print }' "$TMP/sphere.obj" >"$TMP/sa.obj"
awk '/^v / { printf "v %.9f %.9f %.9f\n", $2 + 0.8, $3, $4; next } { print }' "$TMP/sphere.obj" >"$TMP/sb.obj"
upload "$TMP/sa.obj"; M_sa=$MESH_ID
upload "$TMP/sb.obj"; M_sb=$MESH_ID

# render NAME MESH PARAMS
render() {
    api POST "/v1/jobs?wait=300" -H "Content-Type: application/json" \
        -d "{\"mesh\":\"$2\",\"kind\":\"render\",\"params\":$3}"
    local j
    j=$(jqb .id)
    if [[ "$(jqb .state)" != succeeded ]]; then wait_job "$j" 600; fi
    if [[ "$(jqb .state)" != succeeded ]]; then echo "$1 failed: $(cat "$BODY")"; FAIL=$((FAIL + 1)); return; fi
    echo "$1: $(jq -c '.stats | {N, R, M, lowpass_ms, interp_ms, render_ms}' "$BODY")"
    api GET "/v1/jobs/$j/result"
    cp "$BODY" "$out/$1.png"
}
CAM='"camera":{"type":"orbit","azimuth":30,"elevation":25,"fov":0}'
for s in hyperboloid sphere cube; do
    id=M_$s
    render "bandlimit_${s}_r64_n8" "${!id}" "{\"R\":64,\"N\":8,\"L\":8,\"filter\":{\"D0\":4},\"width\":256,\"height\":256,$CAM}"
done
for r in 16 32 64; do
    render "bandlimit_cube_n16_r$r" "$M_cube" "{\"R\":$r,\"N\":16,\"L\":4,\"width\":256,\"height\":256,$CAM}"
done
render bandlimit_compare_hyperboloid "$M_hyperboloid" \
    "{\"N\":64,\"width\":256,\"height\":256,\"compare\":true,\"camera\":{\"type\":\"axis\",\"axis\":\"+y\"}}"
render bandlimit_fused_spheres "$M_sa" "{\"N\":32,\"meshes\":[\"$M_sb\"],\"iso\":0.5,\"width\":384,\"height\":256,$CAM}"
stop_daemon
echo "figures in $out"
[[ $FAIL -eq 0 ]]
