#!/usr/bin/env bash
# Gregory tessellation benchmarks (issue #5, seed 001): voxeld's one-pass
# tessellation (the GPU pass and the CPU engine, tess_cpu.c; the table says
# which one the daemon runs here) vs OpenSubdiv 3.5's CPU limit evaluation of the same mesh
# (same run: OpenSubdiv's OmpEvaluator on 2 threads, the peer, and one
# thread of Far), the seed's table 3.2 (3x3 quad mesh, 10
# generations, vs uniform Catmull-Clark by OpenSubdiv), and the time per
# deformation frame on spot's control mesh at N = 16.
#   bench/gregory/run.sh [build dir] [runs]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
runs=${2:-5}
M=$root/../shared/data/meshes
b=$build/bench/gregory_bench
echo "## Tessellation rate vs OpenSubdiv limit evaluation (best of $runs)"
"$b" rate "$M/spot_control_mesh.obj" 16 32 64 128 --runs "$runs"
"$b" rate "$M/suzanne.obj" 16 64 --runs "$runs"
echo; echo "## Seed 001 table 3.2 (3x3 quad mesh, 10 generations)"
"$b" seed --runs "$runs"
echo; echo "## Re-tessellation per deformation frame (spot control mesh, N = 16)"
"$b" frames "$M/spot_control_mesh.obj" 16
