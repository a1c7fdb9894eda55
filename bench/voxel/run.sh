#!/usr/bin/env bash
# Voxelization benchmarks (issue #3): voxeld vs OpenVDB's meshToVolume +
# interior mask on the same mesh and grid (time ratio and IoU; OpenVDB both
# with a narrow band, the peer, and with the interior band filled), every
# writer beside the engine and the disk (voxel_encode_bench; issue 14), the
# same through the API (jobs.sh: run_ms, encode_ms, bytes), the seed 000
# Table 1 (peel and fill time vs faces) and the seed 003 Table 1 (mean
# distance of surface voxel centres to the mesh, supersampling off/on).
#   bench/voxel/run.sh [build dir] [method: peel|slice|auto]
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=${1:-$root/build}
method=${2:-auto}
M=$root/../shared/data/meshes
b=$build/bench/voxel_bench
echo "## voxeld vs OpenVDB (method $method)"
# stanford-bunny.obj:2 = the bunny split 1->4 twice: 1,111,216 triangles
"$b" compare "$M/spot_triangulated.obj" "$M/fandisk.obj" "$M/stanford-bunny.obj" "$M/ogre.obj" \
    "$M/stanford-bunny.obj:2" 128 256 512 1024 --method "$method" --runs 2
echo; echo "## Encoders (voxel_encode_bench; files in a temp dir on the data disk)"
enc=$(mktemp -d "${TMPDIR:-/tmp}/vx-enc.XXXXXX")
for m in spot_triangulated stanford-bunny; do
    "$build/bench/voxel_encode_bench" "$enc" "$M/$m.obj" 512 1024 --runs 2
done
rm -rf "$enc"
echo; echo "## Jobs through the API (jobs.sh)"
"$root/bench/voxel/jobs.sh" "$build" 512 1024
echo; echo "## Seed 000 Table 1 (fandisk split 1->4 up to 3 times)"
"$b" seed000 "$M/fandisk.obj" --runs 2
echo; echo "## Seed 003 Table 1 (512^3, slice)"
"$b" seed003 "$M/spot_triangulated.obj" "$M/fandisk.obj" "$M/rocker-arm.obj" --res 512
