#!/usr/bin/env bash
# inside "winding" vs "nonzero" (auto: scan) on the same grids, in one run
# (issue 14's target: winding at most 3x nonzero's engine time). Prints a
# markdown table: median (min-max) of N runs per rule and the ratio of the
# medians. The open meshes (bunny, ogre, suzanne) exercise the evaluation;
# spot (closed) only the crossing counts.
#   bench/voxel/winding.sh [build dir] [runs]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
runs=${2:-5}
M=$root/../shared/data/meshes
"$build/bench/winding_bench" --runs "$runs" "$M/stanford-bunny.obj" "$M/ogre.obj" "$M/suzanne.obj" \
    "$M/spot_triangulated.obj" 128 256 512 2> >(grep -v 'level=' >&2)
