#!/usr/bin/env bash
# Installs voxeld's dependencies from Debian 12 packages. Used by the README
# and by .ci/run; safe to run again.
#   (no option)  everything to build, run and test (--run and --test)
#   --run        only what building and running voxeld and voxelctl needs
#                (the README's first command: no tests, no benchmarks)
#   --test       --run, plus what the test suite needs (scripts/check.sh)
#   --bench      --test, plus what bench/ compares against (wrk, nginx)
# apt waits up to 10 minutes for the dpkg lock (another apt running, e.g.
# unattended-upgrades on a fresh machine) instead of failing at once.
set -euo pipefail

mode=${1:---test}
case "$mode" in
--run | --test | --bench) ;;
*)
    echo "usage: $0 [--run | --test | --bench]" >&2
    exit 2
    ;;
esac

run_pkgs=(
  # toolchain
  build-essential cmake pkg-config git ca-certificates
  # GL through EGL: glvnd loaders + headers, Mesa's EGL and DRI drivers (llvmpipe)
  libegl-dev libgl-dev libopengl-dev libegl1 libegl-mesa0 libgl1-mesa-dri
  # HTTP, JSON, meshes (tinygltf on nlohmann's JSON: glTF); libcurl: voxelctl
  libmicrohttpd-dev libcjson-dev libdraco-dev libtinygltf-dev nlohmann-json3-dev libcurl4-openssl-dev
  # libdraco's glTF encoder header (the glb writer) includes Eigen
  libeigen3-dev
  # compressed result downloads (Content-Encoding zstd; gzip is zlib)
  libzstd-dev
  # the README's example requests (curl, jq)
  curl jq
  # OpenVDB and what its headers need
  libopenvdb-dev libboost-dev libboost-iostreams-dev libtbb-dev libimath-dev libblosc-dev
  zlib1g-dev
  # FFT, images, systemd notify, SHA-256
  libfftw3-dev libosd-dev libpng-dev libsystemd-dev nettle-dev
  # --database: the PostgreSQL job queue's client (src/jobs/pg.c)
  libpq-dev
)
test_pkgs=(
  # clang + its runtime for the libFuzzer targets (tests/fuzz); scripts/check.sh
  # checks the formatting of every C/C++ file (.clang-format)
  clang libclang-rt-14-dev clang-format
  # unit tests; reference tools (draco_decoder, vdb_print)
  libcmocka-dev draco libopenvdb-tools systemd
  # the tests read compressed downloads back
  zstd
  # test_voxel_formats.sh reads the npy and vox outputs with NumPy
  python3-numpy
  # integration tests
  curl jq procps psmisc python3 python3-yaml python3-jsonschema man-db
  # unit.test_pg_queue and bench/cluster: a throw-away server (tests/support/pg.sh)
  postgresql-15
  # tests/deploy/test_systemd.sh: the system calls voxeld makes vs the unit's filter
  strace
  # the container image test (tests/deploy): podman builds the Dockerfile
  podman buildah debootstrap
  # tests/integration/test_viewer.sh: the viewer in a real browser
  chromium
)
pkgs=("${run_pkgs[@]}")
# The viewer's libraries come from npm at build time (and the test suite's
# linter and browser driver): Debian's nodejs + npm unless a Node (CI: Node
# 20, with its own npm) is installed already.
if ! command -v npm >/dev/null; then
  pkgs+=(nodejs npm)
fi
if [[ "$mode" != --run ]]; then
  pkgs+=("${test_pkgs[@]}")
fi
if [[ "$mode" == --bench ]]; then
  pkgs+=(wrk nginx-light)
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
APT=(apt-get -o DPkg::Lock::Timeout=600)
$SUDO "${APT[@]}" update -qq
$SUDO "${APT[@]}" install -y -qq --no-install-recommends "${pkgs[@]}"

# The viewer's browser libraries (three.js, js-yaml: embedded into voxeld at
# build time) and its test's browser driver (playwright-core), at the
# versions tools/viewer/package-lock.json pins, into tools/viewer/node_modules.
npm ci --prefix "$(dirname "$0")/../tools/viewer" --no-audit --no-fund --loglevel=error
if [[ "$mode" != --run ]]; then
  # The OpenAPI linter at the version package-lock.json pins, into
  # tools/redocly/node_modules (git-ignored), not globally.
  npm ci --prefix "$(dirname "$0")/../tools/redocly" --no-audit --no-fund --loglevel=error
  # tests/deploy/test_kubernetes.sh: the Kubernetes and KEDA schemas the
  # rendered deploy/kubernetes overlays are checked against, offline. The
  # rendering needs kubectl with Kustomize v4+ (or a standalone kustomize),
  # which Debian 12 does not package (its kubernetes-client 1.20 has
  # Kustomize v2): without one the test is skipped.
  npm ci --prefix "$(dirname "$0")/../tools/k8s-validate" --no-audit --no-fund --loglevel=error
  # The S3 server tests/integration/test_blob_s3.sh starts (s3rver), pinned
  # by tools/s3rver/package-lock.json, into tools/s3rver/node_modules.
  npm ci --prefix "$(dirname "$0")/../tools/s3rver" --no-audit --no-fund --loglevel=error
fi
