#!/usr/bin/env bash
# Checks the formatting (scripts/format.sh --check: every C/C++ file as
# .clang-format says), then builds voxeld three times and runs every test
# on each build:
#   build/       warnings as errors, all tests (unit, integration, deploy)
#   build-asan/  AddressSanitizer + UndefinedBehaviorSanitizer, unit + integration
#   build-fuzz/  clang + libFuzzer + ASan/UBSan: every tests/fuzz target for
#                FUZZ_SECONDS (default 60) each (scripts/fuzz.sh)
# This is the README's test command and what CI (.ci/run) runs.
set -euo pipefail
cd "$(dirname "$0")/.."
jobs=$(nproc)

scripts/format.sh --check

# Tests and benchmarks on, whatever the README's first command cached in build/.
cmake -S . -B build -DVX_WERROR=ON -DVX_TESTS=ON -DVX_BENCH=ON
cmake --build build -j"$jobs"
ctest --test-dir build --output-on-failure -j2

cmake -S . -B build-asan -DVX_WERROR=ON -DVX_SANITIZE=ON -DVX_BENCH=OFF -DCMAKE_BUILD_TYPE=Debug
cmake --build build-asan -j"$jobs"
ASAN_OPTIONS=abort_on_error=0:detect_leaks=1 \
    ctest --test-dir build-asan --output-on-failure -j2 -L 'unit|integration'

scripts/fuzz.sh
