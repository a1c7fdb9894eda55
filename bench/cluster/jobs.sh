#!/usr/bin/env bash
# Cluster mode end to end: jobs/s and job latency (submit to succeeded) for
# 1, 2 and 3 replicas on one machine, each its own llvmpipe GL context,
# sharing a throw-away PostgreSQL (tests/support/pg.sh, durable commits)
# and a file:// store; against one daemon in local mode (its journal) on
# the same jobs, measured in the same run. Jobs: small voxelizes of the
# bunny (resolution 48, summary output: the queue's cost, not the GPU's,
# dominates; RES for heavier ones) submitted by 8 concurrent clients, round-robin over the
# replicas. Figures in bench/RESULTS.md.
#   bench/cluster/jobs.sh [BUILD_DIR=build] [JOBS=120] [REPLICAS=1,2,3]
#   RES=192 bench/cluster/jobs.sh ...   heavier jobs (the GPU's cost dominates)
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
njobs=${2:-120}
counts=${3:-1,2,3}
mesh=${VX_MESH_DIR:-$root/../shared/data/meshes}/stanford-bunny.obj
[[ -f $mesh ]] || { echo "no $mesh" >&2; exit 1; }
work=$(mktemp -d /tmp/vxbench.XXXXXX)
pgdir=$(mktemp -d /tmp/vxpg.XXXXXX)
pids=()
cleanup() {
    for p in "${pids[@]}"; do kill -KILL "$p" 2>/dev/null || true; done
    "$root/tests/support/pg.sh" stop "$pgdir" >/dev/null 2>&1 || true
    rm -rf "$work" "$pgdir"
}
trap cleanup EXIT
url=$("$root/tests/support/pg.sh" start "$pgdir")
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores; $njobs jobs, 8 clients"

# start N MODE: N replicas (cluster) or one local daemon; sets bases[].
start() {
    local n=$1 mode=$2 i
    bases=()
    for i in $(seq 1 "$n"); do
        local log=$work/$mode$n-$i.log flags=()
        if [[ $mode == cluster ]]; then
            flags=(--database "$url" --blob-store "file://$work/shared-$n" --replica-name "r$i")
        fi
        "$build/voxeld" --listen 127.0.0.1:0 --data-dir "$work/$mode$n-data$i" --workers 2 \
            --max-queued-jobs 1000 "${flags[@]}" 2>"$log" &
        pids+=($!)
        local port=
        for _ in $(seq 300); do
            port=$(sed -n 's/.*event=voxeld.ready port=\([0-9]*\).*/\1/p' "$log")
            [[ -n "$port" ]] && break
            sleep 0.1
        done
        [[ -n "$port" ]] || { echo "voxeld did not start" >&2; tail -5 "$log" >&2; exit 1; }
        bases+=("http://127.0.0.1:$port")
    done
}
stop() {
    for p in "${pids[@]}"; do kill -TERM "$p" 2>/dev/null || true; done
    for p in "${pids[@]}"; do wait "$p" 2>/dev/null || true; done
    pids=()
}

# run LABEL: uploads the mesh, then njobs jobs from 8 clients; prints jobs/s
# and the latency quantiles.
run() {
    local label=$1
    local id
    id=$(curl -sf -H 'Content-Type: model/obj' --data-binary "@$mesh" "${bases[0]}/v1/meshes" | jq -r .id)
    python3 - "$id" "$njobs" "${RES:-48}" "${bases[@]}" <<'PY' | sed "s/^/$label: /"
import json, sys, threading, time, urllib.request
mesh, njobs, res, bases = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
lat, lock = [], threading.Lock()
def post(base, body):
    r = urllib.request.Request(base + "/v1/jobs", data=json.dumps(body).encode(),
                               headers={"Content-Type": "application/json"})
    return json.load(urllib.request.urlopen(r, timeout=60))
def get(base, jid):
    return json.load(urllib.request.urlopen(base + "/v1/jobs/%s?wait=30" % jid, timeout=60))
def client(k):
    for n in range(k, njobs, 8):
        base = bases[n % len(bases)]
        t0 = time.monotonic()
        j = post(base, {"mesh": mesh, "kind": "voxelize",
                        "params": {"resolution": res + n % 7, "format": "summary"}})
        while j["state"] not in ("succeeded", "failed", "canceled"):
            j = get(bases[(n + 1) % len(bases)], j["id"])
        assert j["state"] == "succeeded", j
        with lock:
            lat.append(time.monotonic() - t0)
t0 = time.monotonic()
ts = [threading.Thread(target=client, args=(k,)) for k in range(8)]
[t.start() for t in ts]
[t.join() for t in ts]
wall = time.monotonic() - t0
lat.sort()
q = lambda f: lat[min(len(lat) - 1, int(f * len(lat)))] * 1e3
print("%d jobs in %.1f s: %.1f jobs/s, latency p50 %.0f ms, p90 %.0f ms, max %.0f ms"
      % (len(lat), wall, len(lat) / wall, q(0.5), q(0.9), lat[-1] * 1e3))
PY
}

start 1 local
run "local, 1 daemon"
stop
IFS=, read -r -a ns <<<"$counts"
for n in "${ns[@]}"; do
    start "$n" cluster
    run "cluster, $n replica(s)"
    stop
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
