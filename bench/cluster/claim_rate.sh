#!/usr/bin/env bash
# Claims/s the PostgreSQL queue sustains with 1, 2 and 4 claimers, on a
# throw-away server (tests/support/pg.sh, default durability: fsync and
# synchronous_commit on). Figures in bench/RESULTS.md.
#   bench/cluster/claim_rate.sh [BUILD_DIR=build] [JOBS=2000] [CLAIMERS=1,2,4]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
echo "load before: $(cut -d' ' -f1-3 /proc/loadavg) on $(nproc) cores"
"$root/tests/support/pg.sh" run bash -c \
    "'$build/bench/claim_rate' \"\$VX_PG_URL\" '${2:-2000}' '${3:-1,2,4}'"
echo "load after: $(cut -d' ' -f1-3 /proc/loadavg)"
