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
source "$root/bench/cluster/lib.sh"
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores; $njobs jobs, 8 clients"

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

start 1 local --max-queued-jobs 1000
run "local, 1 daemon"
stop
IFS=, read -r -a ns <<<"$counts"
for n in "${ns[@]}"; do
    start "$n" cluster --max-queued-jobs 1000
    run "cluster, $n replica(s)"
    stop
done
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
