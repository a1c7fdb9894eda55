#!/usr/bin/env bash
# Band-limit benchmarks (issue #4): Algorithm I at R = 512 -> N = 128
# against a full 3-D FFT of the same samples (time, peak memory, ratios),
# and 512x512 renders (spectral vs central differences, same caster).
#   bench/bandlimit/run.sh [build dir] [runs]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
runs=${2:-3}
M=$root/../shared/data/meshes
b=$build/bench/bl_bench
echo "## Low-pass R=512 -> N=128: Algorithm I vs full 3-D FFT (best of $runs)"
for m in spot_triangulated.obj stanford-bunny.obj; do
    "$b" lowpass "$M/$m" 512 128 --runs "$runs" 2>/dev/null
    echo
done
echo "## 512x512 render, N=64, L=4 (M=256), orbit camera (best of $runs)"
for m in spot_triangulated.obj fandisk.obj; do
    "$b" render "$M/$m" 64 4 512 --runs "$runs" 2>/dev/null
    echo
done
