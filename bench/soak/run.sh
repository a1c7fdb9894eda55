#!/usr/bin/env bash
# Soak: 16 clients, a mix of GETs, uploads, jobs and downloads for MINUTES
# (bench/soak/soak.py prints statuses, 5xx, RSS and fd growth per 1,000
# requests). bench/soak/run.sh [build dir] [minutes]
set -euo pipefail
here=$(cd "$(dirname "$0")" && pwd)
build=${1:-$here/../../build}
exec python3 "$here/soak.py" --voxeld "$build/voxeld" --minutes "${2:-2}" --clients 16
