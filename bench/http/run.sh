#!/usr/bin/env bash
# HTTP benchmark: upload throughput and small-GET latency under 16
# concurrent clients (wrk), with nginx serving the same small JSON as the
# peer for GET latency, measured in the same run.
#   bench/http/run.sh [build dir] [seconds per run]
# Needs: scripts/install-deps.sh --bench (wrk, nginx-light).
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=${1:-$root/build}
secs=${2:-10}
mesh=${VX_BENCH_MESH:-$root/../shared/data/meshes/spot_triangulated.obj}
command -v wrk >/dev/null || { echo "wrk missing: scripts/install-deps.sh --bench"; exit 1; }
command -v nginx >/dev/null || [[ -x /usr/sbin/nginx ]] || { echo "nginx missing: scripts/install-deps.sh --bench"; exit 1; }
tmp=$(mktemp -d)
trap 'kill $vpid 2>/dev/null; wait $vpid 2>/dev/null; [[ -f $tmp/nginx.pid ]] && kill $(cat $tmp/nginx.pid) 2>/dev/null; rm -rf "$tmp"' EXIT

"$build/voxeld" --listen 127.0.0.1:0 --data-dir "$tmp/data" --log-level warn --http-threads 4 \
    --max-connections-per-ip 256 2>"$tmp/voxeld.log" &
vpid=$!
for i in $(seq 100); do port=$(sed -n 's/.*event=voxeld.ready port=\([0-9]*\).*/\1/p' "$tmp/voxeld.log"); [[ -n "$port" ]] && break; sleep 0.1; done
# warn level hides the ready line: ask the kernel instead
if [[ -z "${port:-}" ]]; then
    for i in $(seq 100); do
        port=$(ss -ltnpH 2>/dev/null | awk -v p="pid=$vpid," '$0 ~ p {split($4,a,":"); print a[length(a)]}' | head -n1)
        [[ -n "$port" ]] && break; sleep 0.1
    done
fi
base=http://127.0.0.1:$port
id=$(curl -s -H 'Content-Type: model/obj' --data-binary "@$mesh" "$base/v1/meshes" | jq -r .id)

# nginx: the same 15-byte JSON body as /livez, 2 workers like our 2 cores.
nport=$((port + 1))
while ss -ltnH | awk '{print $4}' | grep -q ":$nport\$"; do nport=$((nport + 1)); done
mkdir -p "$tmp/www"
printf '{"status":"ok"}' >"$tmp/www/livez"
cat >"$tmp/nginx.conf" <<CONF
worker_processes 2;
pid $tmp/nginx.pid;
error_log $tmp/nginx.err;
events { worker_connections 1024; }
http {
  access_log off;
  client_body_temp_path $tmp/ncb; proxy_temp_path $tmp/np; fastcgi_temp_path $tmp/nf;
  uwsgi_temp_path $tmp/nu; scgi_temp_path $tmp/ns;
  server { listen 127.0.0.1:$nport; root $tmp/www; default_type application/json; }
}
CONF
/usr/sbin/nginx -c "$tmp/nginx.conf"
sleep 0.3

# wrk summary -> "rps p50_ms p99_ms"
measure() {
    wrk -t2 -c16 -d"${secs}s" --latency "$@" >"$tmp/wrk.out" 2>&1
    awk '
      function ms(v) { if (v ~ /us$/) return v/1000; if (v ~ /ms$/) return v+0; if (v ~ /s$/) return v*1000; return v }
      /^ +50%/ {p50=ms($2)} /^ +99%/ {p99=ms($2)} /^Requests\/sec/ {rps=$2}
      /^BYTES_PER_REQ/ {bytes=$2}
      END {printf "%.0f %.3f %.3f %d\n", rps, p50, p99, bytes}' "$tmp/wrk.out"
}

read -r v_rps v_p50 v_p99 _ < <(measure "$base/livez")
read -r m_rps m_p50 m_p99 _ < <(measure "$base/v1/meshes/$id")
read -r n_rps n_p50 n_p99 _ < <(measure "http://127.0.0.1:$nport/livez")
read -r u_rps u_p50 u_p99 u_bytes < <(VX_BENCH_MESH=$mesh measure -s "$here/upload.lua" "$base")
read -r d_rps d_p50 d_p99 d_bytes < <(VX_BENCH_DEDUP=1 VX_BENCH_MESH=$mesh measure -s "$here/upload.lua" "$base")
stored=$(curl -s "$base/metrics" | awk '$1=="voxeld_meshes"{print $2}')

echo "voxeld $(git -C "$root" rev-parse --short HEAD 2>/dev/null), $(nproc) CPUs, 16 connections, ${secs}s per run, mesh $(basename "$mesh") ($u_bytes bytes)"
printf '%-34s %10s %9s %9s\n' "run" "req/s" "p50 ms" "p99 ms"
printf '%-34s %10s %9s %9s\n' "GET /livez (voxeld)" "$v_rps" "$v_p50" "$v_p99"
printf '%-34s %10s %9s %9s\n' "GET static 15 B (nginx, peer)" "$n_rps" "$n_p50" "$n_p99"
printf '%-34s %10s %9s %9s\n' "GET /v1/meshes/{id} (voxeld)" "$m_rps" "$m_p50" "$m_p99"
printf '%-34s %10s %9s %9s\n' "POST /v1/meshes new (voxeld)" "$u_rps" "$u_p50" "$u_p99"
printf '%-34s %10s %9s %9s\n' "POST /v1/meshes dedup (voxeld)" "$d_rps" "$d_p50" "$d_p99"
awk -v a="$v_rps" -v b="$n_rps" -v c="$v_p50" -v d="$n_p50" 'BEGIN{printf "small GET vs nginx: %.2fx the throughput, %.2fx the median latency\n", a/b, c/d}'
awk -v r="$u_rps" -v b="$u_bytes" -v s="$stored" 'BEGIN{printf "upload throughput (new meshes, hashed+parsed+fsynced): %.1f MB/s, %d meshes stored\n", r*b/1e6, s}'
awk -v r="$d_rps" -v b="$d_bytes" 'BEGIN{printf "upload throughput (same bytes, hashed only): %.1f MB/s\n", r*b/1e6}'
