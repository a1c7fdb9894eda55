#!/usr/bin/env bash
# The GPU check, in one run on a machine with an NVIDIA GPU (the device
# tool's: bare, nothing installable), from the pack bench/gpu/pack.sh made.
# Steps, in this order (VX_GPU_STEPS picks some; default all), each writing
# one file under $OUT (or /tmp/vx-gpu-out):
#   env      env.txt: the machine, the EGL devices voxeld sees, the renderer
#   diag     diag.txt: bench/gpu/gldiag case by case, each in its own
#            process with every stage's GPU time traced (VX_GL_TRACE), two
#            again without timer queries (VX_GL_NO_TIMERS), then all cases
#            in one robust context as voxeld makes it; then the
#            full output of the tests VX_GPU_DIAG_TESTS names (default
#            test_solid) in a debug context
#   jobs     jobs.txt and voxeld.log: jobs through the API (jobs.py): each
#            method's run_ms at 512^3 and 1024^3, each format's encode_ms,
#            render, preview and Gregory
#   compare  compare.txt: voxel_bench compare, voxeld against OpenVDB's
#            narrow band in the same run (the peer of bench/RESULTS.md)
#   tests    tests.txt: the GL unit tests (every GPU method against the CPU
#            references; Gregory, preview, band-limit), 60 s each
#   engines  engines.txt: gregory_bench (vs OpenSubdiv) and bl_bench
# The files are written as it goes, so a run stopped at the call's limit
# still returns the steps before.
#   bash bench/gpu/run.sh                        (carry .gpu)
#   VX_GPU_STEPS="env diag" bash bench/gpu/run.sh  (bring-up)
# To try it on a machine without a GPU: VX_GPU_SOFTWARE=1 (no
# --require-gpu), VX_GPU_RES="64 128" and VX_GPU_TESTS="test_gl" to shorten.
set -uo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
out=${OUT:-/tmp/vx-gpu-out}
mkdir -p "$out"
W=${VX_GPU_WORK:-/tmp/vx-gpu}
rm -rf "$W" && mkdir -p "$W"
python3 -c 'import sys, tarfile; tarfile.open(sys.argv[1]).extractall(sys.argv[2])' \
    "$root/.gpu/vx.tar.xz" "$W" || { echo "no pack: run bench/gpu/pack.sh here first" >&2; exit 1; }
V=$W/vx
export LD_LIBRARY_PATH=$V/lib${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}
# libstdc++/libgcc_s from the pack only when the machine's are older.
if ! "$V/bin/voxeld" --version >/dev/null 2>&1; then
    export LD_LIBRARY_PATH=$V/lib:$V/lib/cxx${LD_LIBRARY_PATH#"$V/lib"}
fi
# NVIDIA's EGL vendor file where the container runtime puts it.
for j in /usr/local/nvidia/share/glvnd/egl_vendor.d/10_nvidia.json \
    /usr/share/glvnd/egl_vendor.d/10_nvidia.json /etc/glvnd/egl_vendor.d/10_nvidia.json; do
    if [[ -f $j ]]; then export __EGL_VENDOR_LIBRARY_FILENAMES=$j; break; fi
done
# The driver's libraries (libEGL_nvidia and what it loads) where the
# container runtime mounts them, in case the loader's cache lacks them.
for d in /usr/local/nvidia/lib64 /usr/local/nvidia/lib; do
    [[ -d $d ]] && LD_LIBRARY_PATH=$LD_LIBRARY_PATH:$d
done
export PYTHONUNBUFFERED=1
# The tests find the meshes at the path compiled into them.
md=$(cat "$V/meshdir")
[[ -d $md ]] || { mkdir -p "$(dirname "$md")" && ln -sfn "$V/meshes" "$md"; }
M=$V/meshes
cores=$(nproc)
read -r -a res <<<"${VX_GPU_RES:-512 1024}"
tests=()
for t in ${VX_GPU_TESTS:-$(cd "$V/bin" && ls test_*)}; do tests+=("$V/bin/$t"); done
gpu_flag=(--require-gpu yes)
[[ -n ${VX_GPU_SOFTWARE:-} ]] && gpu_flag=()
steps=" ${VX_GPU_STEPS:-env diag jobs compare tests engines} "
step() { [[ $steps == *" $1 "* ]]; }

step env && {
    echo "# GPU check: voxeld $(cat "$V/commit"), $(date -u +%FT%TZ)"
    uname -a
    echo "cores: $cores, memory: $(awk '/MemTotal/{print $2 " kB"}' /proc/meminfo)"
    nvidia-smi --query-gpu=name,driver_version,memory.total --format=csv 2>&1 | head -3
    echo "EGL vendor: ${__EGL_VENDOR_LIBRARY_FILENAMES:-default search}"
    echo "LD_LIBRARY_PATH: $LD_LIBRARY_PATH"
    echo "missing libraries:"; ldd "$V/bin/voxeld" | grep 'not found' || echo "  none"
    "$V/bin/voxeld" --version
    echo "NVIDIA EGL in the loader's cache:"; ldconfig -p 2>/dev/null | grep -i 'EGL_nvidia' || echo "  none"
    echo "## voxeld --list-egl-devices"
    timeout 60 "$V/bin/voxeld" --list-egl-devices 2>&1
} >"$out/env.txt" 2>&1

step diag && {
    # each case in its own process (a fault cannot spoil the next), every
    # stage's GPU time traced; then all of them in one robust context, as
    # voxeld makes it
    for c in probe cube0 cube2 box sphere robust surface mesh; do
        echo "## gldiag --case $c"
        VX_GL_TRACE=1 timeout 30 "$V/bin/gldiag" --case "$c" "$M/spot_triangulated.obj" 2>&1
        echo "rc $?"
    done
    # the two cases that stalled on the H200, without timer queries
    for c in cube0 surface; do
        echo "## gldiag --case $c, VX_GL_NO_TIMERS=1"
        VX_GL_NO_TIMERS=1 VX_GL_TRACE=1 timeout 30 "$V/bin/gldiag" --case "$c" 2>&1
        echo "rc $?"
    done
    echo "## gldiag --robust"
    VX_GL_TRACE=1 timeout 60 "$V/bin/gldiag" --robust "$M/spot_triangulated.obj" 2>&1
    echo "rc $?"
    for t in ${VX_GPU_DIAG_TESTS:-test_solid}; do
        echo "## $t (the last 300 lines)"
        VX_TEST_GL_DEBUG=1 timeout 60 stdbuf -oL -eL "$V/bin/$t" 2>&1 | tail -300
        echo "rc ${PIPESTATUS[0]}"
    done
} >"$out/diag.txt" 2>&1

# The daemon on the GPU (refusing a software renderer), and jobs through it.
step jobs && {
log=$out/voxeld.log
"$V/bin/voxeld" --listen 127.0.0.1:0 --data-dir "$W/data" "${gpu_flag[@]}" \
    --max-job-memory 32G --workers "$cores" 2>"$log" &
vpid=$!
port=
for _ in $(seq 300); do
    port=$(sed -n 's/.*event=voxeld.ready port=\([0-9]*\).*/\1/p' "$log")
    [[ -n $port ]] && break
    sleep 0.1
done
{
    if [[ -z $port ]]; then
        echo "voxeld did not start"
    else
        echo "## /readyz"
        python3 -c 'import sys, urllib.request as u
try: print(u.urlopen(sys.argv[1]).read().decode())
except Exception as e: print(e, e.read().decode() if hasattr(e, "read") else "")' \
            "http://127.0.0.1:$port/readyz"
        timeout 300 python3 "$root/bench/gpu/jobs.py" "http://127.0.0.1:$port" "$M" --runs 3 --res "${res[@]}"
    fi
} >"$out/jobs.txt" 2>&1
kill "$vpid" 2>/dev/null
}

step compare && {
    echo "## voxel_bench compare (best of 3; OpenVDB narrow band is the peer)"
    for m in auto peel scan slice; do
        timeout 150 "$V/bin/voxel_bench" compare "$M/spot_triangulated.obj" "$M/stanford-bunny.obj" \
            "${res[@]}" --method "$m" --runs 3 --no-filled 2>&1 | grep -v 'level=info'
    done
} >"$out/compare.txt" 2>&1

# The GL unit tests, each on its own limit.
step tests && {
    for t in "${tests[@]}"; do
        s=$(date +%s.%N)
        timeout 60 stdbuf -oL -eL "$t" >"$W/t.log" 2>&1
        rc=$?
        e=$(awk -v s="$s" -v e="$(date +%s.%N)" 'BEGIN{printf "%.1f", e - s}')
        echo "## $(basename "$t"): rc $rc, $e s"
        grep -E 'gl.context|PASSED|FAILED|\[  FAILED|ERROR|Assertion|failure' "$W/t.log" | head -40
    done
} >"$out/tests.txt" 2>&1

step engines && {
    echo "## gregory_bench rate (vs OpenSubdiv)"
    timeout 90 "$V/bin/gregory_bench" rate "$M/spot_control_mesh.obj" 16 64 128 --runs 3 2>&1 | grep -v 'level=info'
    echo "## bl_bench render spot N=64 L=4 512^2"
    timeout 60 "$V/bin/bl_bench" render "$M/spot_triangulated.obj" 64 4 512 --runs 3 2>&1 | grep -v 'level=info'
    echo "## bl_bench lowpass spot R=512 N=128"
    timeout 60 "$V/bin/bl_bench" lowpass "$M/spot_triangulated.obj" 512 128 --runs 3 2>&1 | grep -v 'level=info'
} >"$out/engines.txt" 2>&1
echo "bench/gpu/run.sh: done; $(ls "$out")"
