#!/usr/bin/env bash
# Installs every build, test and benchmark dependency of voxeld from Debian 12
# packages. Used by the README and by .ci/run; safe to run again.
#   --bench   also what bench/ compares against (wrk, nginx as the HTTP peer)
set -euo pipefail

pkgs=(
  # toolchain; clang + its runtime for the libFuzzer targets (tests/fuzz)
  build-essential cmake pkg-config git ca-certificates clang libclang-rt-14-dev
  # scripts/check.sh checks the formatting of every C/C++ file (.clang-format)
  clang-format
  # GL through EGL: glvnd loaders + headers, Mesa's EGL and DRI drivers (llvmpipe)
  libegl-dev libgl-dev libopengl-dev libegl1 libegl-mesa0 libgl1-mesa-dri
  # HTTP, JSON, meshes
  libmicrohttpd-dev libcjson-dev libdraco-dev draco libassimp-dev
  # libdraco's glTF encoder header (the glb writer) includes Eigen
  libeigen3-dev
  # OpenVDB and what its headers need
  libopenvdb-dev libopenvdb-tools libboost-dev libboost-iostreams-dev
  libtbb-dev libimath-dev libblosc-dev zlib1g-dev
  # FFT, images, tests, service
  libfftw3-dev libosd-dev libpng-dev libcmocka-dev libsystemd-dev systemd nettle-dev
  # integration tests and benchmarks
  curl jq procps psmisc python3 python3-yaml python3-jsonschema
  # tests/deploy/test_systemd.sh: the system calls voxeld makes vs the unit's filter
  strace
  # the container image test (tests/deploy): podman builds the Dockerfile
  podman buildah debootstrap
)
# unit.openapi_redocly_lint runs Node: Debian's nodejs + npm unless a Node
# (CI: Node 20, with its own npm) is installed already.
if ! command -v npm >/dev/null; then
  pkgs+=(nodejs npm)
fi
if [[ "${1:-}" == "--bench" ]]; then
  pkgs+=(wrk nginx-light)
fi

SUDO=""
if [[ $(id -u) -ne 0 ]]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends "${pkgs[@]}"

# The OpenAPI linter at the version package-lock.json pins, into
# tools/redocly/node_modules (git-ignored), not globally.
npm ci --prefix "$(dirname "$0")/../tools/redocly" --no-audit --no-fund --loglevel=error
