#!/usr/bin/env bash
# Packs what bench/gpu/run.sh needs on a bare GPU machine that cannot
# install packages (the device tool's machine: only the working tree and
# a few carried paths travel, 64 MiB in all): the stripped daemon, client,
# benchmarks and GPU unit tests of a build, every shared library they load
# except glibc's and the GL vendor's, and the shared test meshes, as one
# .gpu/vx.tar.xz. .gpu/ is ignored through .git/info/exclude.
#   bench/gpu/pack.sh [build dir]      then carry .gpu and run bench/gpu/run.sh
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
build=$(cd "${1:-$root/build}" && pwd)
dest=$root/.gpu
meshes=$(sed -n 's/^VX_MESH_DIR:PATH=//p' "$build/CMakeCache.txt")
meshes=$(realpath "$meshes")
# The unit tests whose subject is the GL engines (they compare every GPU
# method with the CPU references); the rest do not touch the GPU.
tests=(test_gl test_solid test_voxel_bricks test_peel test_slice test_voxel_exact
    test_gregory test_preview test_bandlimit)
bins=(voxeld voxelctl bench/voxel_bench bench/voxel_encode_bench bench/gregory_bench
    bench/bl_bench bench/gldiag)

stage=$(mktemp -d)
trap 'rm -rf "$stage"' EXIT
mkdir -p "$stage/vx/bin" "$stage/vx/lib/cxx" "$stage/vx/meshes"
for b in "${bins[@]}" "${tests[@]/#/tests/}"; do
    [[ -x $build/$b ]] || { echo "pack: $build/$b is not built (VX_TESTS=ON VX_BENCH=ON)" >&2; exit 1; }
    strip -o "$stage/vx/bin/$(basename "$b")" "$build/$b"
done
# Libraries: everything ldd resolves, less glibc (the machine's own, which
# runs Debian's binaries when it is as new) and the GL vendor-neutral
# dispatch (libglvnd: kept, it finds the machine's NVIDIA EGL vendor).
# libstdc++ and libgcc_s go to lib/cxx, used only when the machine's own
# are older than these binaries need.
for b in "$stage"/vx/bin/*; do ldd "$b"; done | awk '/=> \//{print $3}' | sort -u | while read -r f; do
    n=$(basename "$f")
    case $n in
    libc.so.* | libm.so.* | libdl.so.* | librt.so.* | libpthread.so.* | libresolv.so.* | ld-linux*) continue ;;
    libstdc++.so.* | libgcc_s.so.*) out=$stage/vx/lib/cxx/$n ;;
    *) out=$stage/vx/lib/$n ;;
    esac
    cp -L "$f" "$out"
    strip --strip-unneeded "$out" 2>/dev/null || true
done
cp "$meshes"/* "$stage/vx/meshes/"
echo "$meshes" >"$stage/vx/meshdir" # the tests' compiled-in VX_MESH_DIR
git -C "$root" rev-parse --short HEAD >"$stage/vx/commit" 2>/dev/null || echo unknown >"$stage/vx/commit"

rm -rf "$dest"
mkdir -p "$dest"
tar -C "$stage" -cf - vx | xz -T0 -6 >"$dest/vx.tar.xz"
ex=$root/.git/info/exclude
if [[ -d $root/.git ]] && ! grep -qx '/.gpu/' "$ex" 2>/dev/null; then
    mkdir -p "$(dirname "$ex")"
    echo '/.gpu/' >>"$ex"
fi
size=$(stat -c %s "$dest/vx.tar.xz")
echo "pack: $dest/vx.tar.xz $((size / 1048576)) MiB ($(ls "$stage/vx/bin" | wc -l) programs, $(ls "$stage/vx/lib" | wc -l) libraries)"
if ((size > 56 * 1048576)); then
    echo "pack: over 56 MiB: with the working tree it would not travel (64 MiB)" >&2
    exit 1
fi
