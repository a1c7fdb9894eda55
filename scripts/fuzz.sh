#!/usr/bin/env bash
# Builds the libFuzzer targets (tests/fuzz, clang + ASan + UBSan) in
# build-fuzz/ and runs each one for FUZZ_SECONDS (default 60) on a copy of
# its seed corpus, with its dictionary. Any crash, leak, timeout or
# out-of-memory fails the run; the input that did it is kept under
# build-fuzz/fuzz-out/<target>/. Part of scripts/check.sh.
#   scripts/fuzz.sh [TARGET...]      default: every tests/fuzz/fuzz_* target
#   FUZZ_SECONDS=600 FUZZ_JOBS=1 scripts/fuzz.sh fuzz_obj
#   FUZZ_RUNS=10000000 scripts/fuzz.sh   stop each target after N runs instead
#                                        (FUZZ_SECONDS still caps the time)
set -euo pipefail
cd "$(dirname "$0")/.."
secs=${FUZZ_SECONDS:-60}
runs=${FUZZ_RUNS:--1}
par=${FUZZ_JOBS:-$(nproc)}
launcher=()
if command -v ccache >/dev/null; then launcher=(-DCMAKE_C_COMPILER_LAUNCHER=ccache -DCMAKE_CXX_COMPILER_LAUNCHER=ccache); fi
CC=clang CXX=clang++ cmake -S . -B build-fuzz -DVX_FUZZ=ON -DVX_TESTS=OFF -DVX_BENCH=OFF \
    -DCMAKE_BUILD_TYPE=RelWithDebInfo "${launcher[@]}" >/dev/null
cmake --build build-fuzz -j"$(nproc)" --target fuzz_all

targets=("$@")
if [[ ${#targets[@]} -eq 0 ]]; then
  for src in tests/fuzz/fuzz_*.c tests/fuzz/fuzz_*.cc; do
    [[ -e $src ]] || continue
    n=$(basename "$src"); targets+=("${n%.*}")
  done
fi

out=build-fuzz/fuzz-out
rm -rf "$out"; mkdir -p "$out"
run_one() {
  local t=$1 dir=$out/$1
  mkdir -p "$dir/corpus"
  cp -r tests/fuzz/corpus/"$t"/. "$dir/corpus/" 2>/dev/null || true
  local dict=() ; [[ -f tests/fuzz/dict/$t.dict ]] && dict=(-dict=tests/fuzz/dict/"$t".dict)
  # 2 GiB RSS and 1 GiB per allocation: a reader that believes a declared
  # count reaches them on a few bytes of input.
  ASAN_OPTIONS=detect_leaks=1:allocator_may_return_null=0 \
  LSAN_OPTIONS=suppressions=$PWD/tests/lsan.supp \
  build-fuzz/fuzz/"$t" "${dict[@]}" -max_total_time="$secs" -runs="$runs" -rss_limit_mb=2048 -malloc_limit_mb=1024 \
      -timeout=10 -print_final_stats=1 -artifact_prefix="$dir/" "$dir/corpus" >"$dir/log" 2>&1
  local rc=$?
  local execs; execs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$dir/log" | grep -o '[0-9]*$' || echo 0)
  local cov; cov=$(grep -o 'cov: [0-9]*' "$dir/log" | tail -1 | grep -o '[0-9]*' || echo 0)
  if [[ $rc -ne 0 ]]; then
    echo fail >"$dir/status"
    echo "fuzz: $t FAILED (exit $rc) after $execs runs; log and reproducer in $dir/" >&2
    tail -n 40 "$dir/log" >&2
    return 1
  fi
  echo ok >"$dir/status"
  echo "fuzz: $t ok: $execs runs, coverage $cov edges, peak RSS $(grep -o 'stat::peak_rss_mb: *[0-9]*' "$dir/log" | grep -o '[0-9]*$') MB"
}
export -f run_one; export out secs runs
printf '%s\n' "${targets[@]}" | xargs -P "$par" -I{} bash -c 'run_one {}' || true
npass=0; nfail=0
for t in "${targets[@]}"; do
  if [[ $(cat "$out/$t/status" 2>/dev/null) == ok ]]; then npass=$((npass+1)); else nfail=$((nfail+1)); fi
done
echo "fuzz: $npass passed, $nfail failed"
[[ $nfail -eq 0 ]]
