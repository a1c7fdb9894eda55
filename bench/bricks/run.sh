#!/usr/bin/env bash
# Single-node bricked voxelize (issue 15): the bunny at a resolution far
# past one job (default 8192) as one pruned .vdb, bricks run one after
# another in the job and merged by OpenVDB. Prints the job's time (run_ms,
# and the merge's encode_ms), the daemon's peak RSS (VmHWM, before the job
# and after it: the job's peak is the difference, llvmpipe's buffers
# included), the merged tree's bytes, and the result file's size.
#   bench/bricks/run.sh [build dir] [resolution] [brick size] [vdb_grid]
#   (defaults: build 8192 512 bool); VX_BENCH_MEMORY: --max-job-memory (16G)
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=${1:-$root/build}
res=${2:-8192}
size=${3:-512}
cls=${4:-bool}
mesh=$root/../shared/data/meshes/stanford-bunny.obj
tmp=$(mktemp -d)
trap 'kill $vpid 2>/dev/null; wait $vpid 2>/dev/null; rm -rf "$tmp"' EXIT
source "$root/bench/lib.sh"
bench_voxeld "$tmp/voxeld.log" --data-dir "$tmp/data" --workers 2 \
    --max-job-memory "${VX_BENCH_MEMORY:-16G}" --job-timeout 86400
hwm() { awk '/VmHWM/ {print $2 * 1024}' "/proc/$vpid/status"; }
id=$(curl -s -H 'Content-Type: model/obj' --data-binary "@$mesh" "$base/v1/meshes" | jq -r .id)
before=$(hwm)
params="{\"resolution\":$res,\"format\":\"vdb\",\"vdb_grid\":\"$cls\",\"bricks\":{\"size\":$size}}"
jid=$(curl -s -H 'Content-Type: application/json' \
    -d "{\"mesh\":\"$id\",\"kind\":\"voxelize\",\"params\":$params}" "$base/v1/jobs" | jq -r '.id // empty')
[[ -n "$jid" ]] || { echo "submission refused"; exit 1; }
t0=$(date +%s.%N)
while :; do
    body=$(curl -s "$base/v1/jobs/$jid?wait=30")
    case $(jq -r .state <<<"$body") in succeeded | failed | canceled) break ;; esac
done
t1=$(date +%s.%N)
after=$(hwm)
if [[ $(jq -r .state <<<"$body") != succeeded ]]; then
    echo "job $(jq -r .state <<<"$body"): $(jq -c .error <<<"$body")"
    exit 1
fi
file=$(find "$tmp/data" -name 'voxels.vdb' | head -n 1)
bytes=$(stat -c %s "$file")
jq -r --arg wall "$(echo "$t1 - $t0" | bc)" --arg before "$before" --arg after "$after" \
    --arg bytes "$bytes" --arg cls "$cls" '
    "bunny resolution \(.params.resolution), dims \(.stats.dims | map(tostring) | join("x")), vdb_grid \($cls)",
    "bricks of \(.stats.brick_size): \(.stats.brick_grid | map(tostring) | join("x")) = \(.stats.bricks | length)",
    "voxels inside: \(.stats.voxels_inside)",
    "wall s: \($wall)  run_ms: \(.timings.run_ms)  merge+write (encode_ms): \(.stats.encode_ms)",
    "brick ms: median \(.stats.bricks | map(.ms) | sort | .[length / 2 | floor]), max \(.stats.bricks | map(.ms) | max)",
    "merged tree bytes (before prune): \(.stats.merged_tree_bytes)",
    "daemon peak RSS: \($before | tonumber / 1048576 | floor) MiB idle, \($after | tonumber / 1048576 | floor) MiB after the job",
    "result file bytes: \($bytes)"' <<<"$body"
echo "load: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
