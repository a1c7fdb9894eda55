#!/usr/bin/env bash
# A bricked voxelize in cluster mode against the same job on one node, in
# the same run: the bunny at RES (default 2048) as one pruned BoolGrid
# .vdb, bricks of SIZE (default 512). One node runs the bricks one after
# another inside the job (bench/bricks/run.sh measures that alone); in
# cluster mode each brick is a child job that any of N replicas claims
# (PostgreSQL from tests/support/pg.sh, a file:// store), and the parent
# merges them. Prints per setup: wall time (submit to succeeded), the
# merge (the parent's run), each replica's brick count and peak RSS, the
# result's size and active voxels (vdbinfo: equal in every setup).
#   bench/cluster/bricks.sh [BUILD_DIR=build] [RES=2048] [SIZE=512] [REPLICAS=1,2]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
res=${2:-2048}
size=${3:-512}
counts=${4:-1,2}
mesh=${VX_MESH_DIR:-$root/../shared/data/meshes}/stanford-bunny.obj
[[ -f $mesh ]] || { echo "no $mesh" >&2; exit 1; }
work=$(mktemp -d /tmp/vxbench.XXXXXX)
source "$root/bench/cluster/lib.sh"
big=(--max-job-memory 16G --job-timeout 86400 --max-queued-jobs 100000)
echo "bunny at $res, bricks of $size; load before: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"

run() {
    local label=$1
    local id jid body t0 t1 i
    id=$(curl -sf -H 'Content-Type: model/obj' --data-binary "@$mesh" "${bases[0]}/v1/meshes" | jq -r .id)
    params="{\"resolution\":$res,\"format\":\"vdb\",\"vdb_grid\":\"bool\",\"bricks\":{\"size\":$size}}"
    t0=$(date +%s.%N)
    jid=$(curl -s -H 'Content-Type: application/json' \
        -d "{\"mesh\":\"$id\",\"kind\":\"voxelize\",\"params\":$params}" "${bases[0]}/v1/jobs" | tee "$work/submit.json" | jq -r ".id // empty")
    [[ -n "$jid" ]] || { echo "$label: submission refused: $(cat "$work/submit.json")"; return; }
    while :; do
        body=$(curl -s "${bases[0]}/v1/jobs/$jid?wait=30")
        case $(jq -r .state <<<"$body") in succeeded | failed | canceled) break ;; esac
    done
    t1=$(date +%s.%N)
    [[ $(jq -r .state <<<"$body") == succeeded ]] || { echo "$label: $(jq -c .error <<<"$body")"; return; }
    curl -s -o "$work/out.vdb" "${bases[0]}/v1/jobs/$jid/result"
    local active reps=""
    active=$("$build/tools/vdbinfo" "$work/out.vdb" | jq -r '.grids[0].active_voxels')
    for i in "${!pids[@]}"; do
        reps+=" r$((i + 1)): $(grep -c 'event=job.finished .*state=succeeded' "$work/$label-$((i + 1)).log" || true) jobs,"
        reps+=" $(awk '/VmHWM/ {print int($2 / 1024)}' "/proc/${pids[$i]}/status") MiB peak;"
    done
    printf '%s: wall %.1f s, merge (the parent'"'"'s run) %.1f s, %s bytes, %s active voxels;%s\n' \
        "$label" "$(echo "$t1 - $t0" | bc)" "$(jq -r '.timings.run_ms / 1000' <<<"$body")" \
        "$(stat -c %s "$work/out.vdb")" "$active" "$reps"
}

start 1 local "${big[@]}"
run local1
stop
IFS=, read -ra ns <<<"$counts"
for n in "${ns[@]}"; do
    start "$n" cluster "${big[@]}" --lease-ttl 120
    run "cluster$n"
    stop
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
