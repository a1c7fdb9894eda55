#!/usr/bin/env bash
# OBJ streaming: upload an N-triangle grid mesh (default 10^7 triangles,
# ~350 MB of text) and report the daemon's peak memory growth against the
# size of the mesh it holds (24 B per vertex + 12 B per triangle), and the
# upload + parse time. The body is streamed to disk while hashed, so the
# daemon never holds the text.
#   bench/mesh/obj_stream.sh [build dir] [triangles]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
tris=${2:-10000000}
tmp=$(mktemp -d)
trap 'kill $pid 2>/dev/null; wait $pid 2>/dev/null; rm -rf "$tmp"' EXIT
n=$(awk -v t="$tris" 'BEGIN{printf "%d", sqrt(t/2)}') # n x n quads, 2 triangles each
awk -v n="$n" 'BEGIN{
  for (j = 0; j <= n; j++) for (i = 0; i <= n; i++) printf "v %d %d %.4f\n", i, j, sin(i*0.01)*cos(j*0.01);
  for (j = 0; j < n; j++) for (i = 0; i < n; i++) { a = j*(n+1)+i+1; b = a+1; c = a+n+1; d = c+1;
    printf "f %d %d %d\nf %d %d %d\n", a, b, d, a, d, c } }' >"$tmp/grid.obj"
bytes=$(stat -c %s "$tmp/grid.obj")
verts=$(( (n + 1) * (n + 1) ))
ntri=$(( 2 * n * n ))
"$build/voxeld" --listen 127.0.0.1:0 --data-dir "$tmp/data" --max-upload-bytes 4G \
    --max-triangles 100M 2>"$tmp/log" &
pid=$!
for i in $(seq 100); do port=$(sed -n 's/.*event=voxeld.ready port=\([0-9]*\).*/\1/p' "$tmp/log"); [[ -n "$port" ]] && break; sleep 0.1; done
hwm() { awk '/VmHWM/{print $2 * 1024}' /proc/$pid/status; }
rss() { awk '/VmRSS/{print $2 * 1024}' /proc/$pid/status; }
before=$(rss)
t0=$(date +%s.%N)
code=$(curl -s -o "$tmp/resp" -w '%{http_code}' -H 'Content-Type: model/obj' --data-binary "@$tmp/grid.obj" "http://127.0.0.1:$port/v1/meshes")
t1=$(date +%s.%N)
peak=$(hwm)
mesh=$(( verts * 24 + ntri * 12 ))
echo "grid: $ntri triangles, $verts vertices, $bytes bytes of OBJ; HTTP $code"
awk -v b="$before" -v p="$peak" -v m="$mesh" -v f="$bytes" -v t0="$t0" -v t1="$t1" 'BEGIN{
  printf "upload + stream + hash + parse + analysis: %.2f s (%.0f MB/s)\n", t1-t0, f/(t1-t0)/1e6;
  printf "mesh in memory: %.0f MB; daemon peak growth: %.0f MB = %.2fx the mesh, %.2fx the file\n",
    m/1e6, (p-b)/1e6, (p-b)/m, (p-b)/f }'
