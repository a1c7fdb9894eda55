#!/usr/bin/env bash
# voxelize end to end through the API (issue 14 item 10): per mesh and
# resolution, a `summary` job (the engine alone), then one job per output
# format and VDB grid class: the job's run_ms, its encode_ms, the result's
# bytes, and encode_ms against the summary job's run_ms; the disk's
# sequential write speed (dd, the raw8 size, with fdatasync) in the same run.
#   bench/voxel/jobs.sh [build dir] [res...]   (default 512 1024)
# VX_BENCH_MESHES and VX_BENCH_FORMATS (e.g. "vdb:level_set binvox") limit
# the meshes and the formats.
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
root=$(cd "$here/../.." && pwd)
build=${1:-$root/build}
shift || true
res=("$@")
[[ ${#res[@]} -gt 0 ]] || res=(512 1024)
M=$root/../shared/data/meshes
meshes=(${VX_BENCH_MESHES:-$M/spot_triangulated.obj $M/stanford-bunny.obj})
formats=(${VX_BENCH_FORMATS:-vdb:fog vdb:level_set vdb:bool binvox raw8 raw1 vox nrrd npy})
tmp=$(mktemp -d)
trap 'kill $vpid 2>/dev/null; wait $vpid 2>/dev/null; rm -rf "$tmp"' EXIT
source "$root/bench/lib.sh"
bench_voxeld "$tmp/voxeld.log" --data-dir "$tmp/data" --max-job-memory 16G
# job MESH PARAMS -> the finished job's JSON on stdout
job() {
    local id body
    body=$(curl -s -H 'Content-Type: application/json' \
        -d "{\"mesh\":\"$1\",\"kind\":\"voxelize\",\"params\":$2}" "$base/v1/jobs")
    id=$(jq -r '.id // empty' <<<"$body")
    # refused (e.g. 422 job_memory_limit): the error body, reported as failed
    [[ -n $id ]] || { echo "$body"; return; }
    while :; do
        body=$(curl -s "$base/v1/jobs/$id?wait=30")
        case $(jq -r .state <<<"$body") in succeeded | failed | canceled) break ;; esac
    done
    echo "$body"
}
echo "| mesh | res | format | job run_ms | encode_ms | encode / engine job | result bytes | MB/s |"
echo "|---|---|---|---|---|---|---|---|"
for m in "${meshes[@]}"; do
    id=$(curl -s -H 'Content-Type: model/obj' --data-binary "@$m" "$base/v1/meshes" | jq -r .id)
    name=$(basename "$m")
    for r in "${res[@]}"; do
        job "$id" "{\"resolution\":$r,\"format\":\"summary\"}" >/dev/null # warm-up
        s=$(job "$id" "{\"resolution\":$r,\"format\":\"summary\"}")
        eng=$(jq -r .timings.run_ms <<<"$s")
        dims=$(jq -r '.stats.dims | map(tostring) | join("x")' <<<"$s")
        echo "| $name | $dims | summary (engine) | $eng | | | | |"
        for f in "${formats[@]}"; do
            p="\"format\":\"${f%%:*}\""
            [[ $f == vdb:* ]] && p="$p,\"vdb_grid\":\"${f#vdb:}\""
            j=$(job "$id" "{\"resolution\":$r,$p}")
            jid=$(jq -r .id <<<"$j")
            if [[ $(jq -r .state <<<"$j") != succeeded ]]; then
                echo "| $name | $dims | $f | failed: $(jq -c .error <<<"$j") | | | | |"
                continue
            fi
            bytes=$(curl -s -o /dev/null -w '%{size_download}' "$base/v1/jobs/$jid/result")
            run=$(jq -r .timings.run_ms <<<"$j")
            enc=$(jq -r .stats.encode_ms <<<"$j")
            awk -v n="$name" -v d="$dims" -v f="$f" -v r="$run" -v e="$enc" -v g="$eng" -v b="$bytes" \
                'BEGIN { printf "| %s | %s | %s | %.0f | %.0f | %.2f | %d | %.0f |\n", n, d, f, r, e, e / g, b, b / 1e6 / (e / 1e3) }'
        done
        n=$(jq -r '.stats.dims | .[0] * .[1] * .[2]' <<<"$s")
        mbs=$(dd if=/dev/zero of="$tmp/data/dd.out" bs=1M count=$(((n + 1048575) / 1048576)) conv=fdatasync 2>&1 |
            sed -n 's/.*, \([0-9.]* [MG]B\/s\)$/\1/p')
        rm -f "$tmp/data/dd.out"
        echo "| $name | $dims | disk: dd ${n} bytes, fdatasync | $mbs | | | | |"
    done
done
