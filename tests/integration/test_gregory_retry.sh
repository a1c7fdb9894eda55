#!/usr/bin/env bash
# A gregory job retried after a GL context loss (VOXELD_TEST_LOSE_CONTEXT,
# as in test_job_faults.sh) reports each of its stats once: the retry starts
# the stats over (issue #11; the lost attempt's keys used to stay, so every
# key of the GL stage appeared twice in the JSON text).
source "$(dirname "$0")/lib.sh"
source "$(dirname "$0")/box.sh"
box_obj "$TMP/box.obj" 0 0 0 1 1 1

# dup_keys FILE: the object keys that appear twice in one object of FILE.
dup_keys() {
    python3 - "$1" <<'PY'
import json, sys
dups = []
def hook(pairs):
    seen = set()
    for k, _ in pairs:
        if k in seen: dups.append(k)
        seen.add(k)
    return dict(pairs)
json.load(open(sys.argv[1]), object_pairs_hook=hook)
print(" ".join(dups))
PY
}

VOXELD_TEST_LOSE_CONTEXT=1 start_daemon || exit 1
upload "$TMP/box.obj"
run_job gregory "$MESH_ID" '{"divisions":2}'
job_ok "gregory after a context loss"
check "the job was retried once" jq -e '.stats.context_rebuilds == 1' "$TMP/job.json"
check "it has its stats" jq -e '.stats.patches > 0 and .stats.gpu_ms != null' "$TMP/job.json"
check "each stat key once (twice: $(dup_keys "$TMP/job.json"))" test -z "$(dup_keys "$TMP/job.json")"
stop_daemon
finish
