#!/usr/bin/env bash
# Fuzzes every decoder of outside bytes with libFuzzer (tests/fuzz/README.md).
#
#   deploy/fuzz.sh build                         # clang build with ASan + UBSan into build-fuzz/
#   deploy/fuzz.sh run --seed 1                  # every target 5 s, fixed mutations (the tests)
#   deploy/fuzz.sh run --seconds 600             # the long run: 10 minutes per target
#   deploy/fuzz.sh run --seconds 60 chunk net    # some targets
#   deploy/fuzz.sh list
#
# Per target, inputs come from three folders: seeds the target writes from the project's own
# writers (fresh each run), the corpus libFuzzer grew in earlier runs (build-fuzz/fuzz-corpus,
# kept between runs, never committed) and tests/fuzz/regressions/<target>/ (committed: every
# input that once found a bug, so each brief run replays them all). A finding is saved under
# build-fuzz/fuzz-findings/<target>/ and makes the script exit 1 after the summary.
# Environment: INDRIVE_FUZZ_BUILD_DIR (build-fuzz), INDRIVE_FUZZ_JOBS (nproc).
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build_dir=${INDRIVE_FUZZ_BUILD_DIR:-$root/build-fuzz}
mode=${1:-}
shift || true

say() { printf '\033[1m[fuzz]\033[0m %s\n' "$*"; }

targets_built() {
  local t
  for t in "$build_dir"/fuzz/fuzz_*; do
    [[ -x $t ]] && basename "$t" | sed 's/^fuzz_//'
  done
}

build() {
  command -v clang++ >/dev/null || {
    echo "fuzz: clang++ not found; install clang, libclang-rt-14-dev and libomp-14-dev" \
         "(bash deploy/setup.sh test installs them)" >&2
    exit 1
  }
  if [[ ! -f $build_dir/build.ninja ]]; then
    say "configuring into $build_dir (clang, ASan + UBSan, libFuzzer)"
    # Without oneDNN: Debian's libdnnl runs on GCC's OpenMP runtime, which must not share a
    # process with clang's; the fuzzed decoders do not reach the products anyway.
    CC=clang CXX=clang++ cmake -S "$root" -B "$build_dir" -G Ninja \
      -DCMAKE_BUILD_TYPE=RelWithDebInfo -DINDRIVE_FUZZ=ON -DINDRIVE_ONEDNN=OFF \
      -DINDRIVE_BUILD_TESTS=OFF -DINDRIVE_BUILD_BENCH=OFF >/dev/null
  fi
  say "building the fuzz targets with ${INDRIVE_FUZZ_JOBS:-$(nproc)} jobs"
  cmake --build "$build_dir" --target fuzz -j "${INDRIVE_FUZZ_JOBS:-$(nproc)}"
}

run() {
  local seconds=5 seed=0 chosen=()
  while [[ $# -gt 0 ]]; do
    case $1 in
      --seconds) seconds=$2; shift 2 ;;
      --seed) seed=$2; shift 2 ;;  # libFuzzer's -seed; 0 (default): a new one each run
      -h|--help) sed -n 2,17p "${BASH_SOURCE[0]}"; exit 0 ;;
      *) chosen+=("$1"); shift ;;
    esac
  done
  [[ -d $build_dir/fuzz ]] || { echo "fuzz: no targets in $build_dir/fuzz; run: deploy/fuzz.sh build" >&2; exit 1; }
  [[ ${#chosen[@]} -gt 0 ]] || mapfile -t chosen < <(targets_built)
  local failed=() rows=() t
  for t in "${chosen[@]}"; do
    local exe=$build_dir/fuzz/fuzz_$t
    [[ -x $exe ]] || { echo "fuzz: no target '$t' (have: $(targets_built | tr '\n' ' '))" >&2; exit 2; }
    local work=$build_dir/fuzz-corpus/$t findings=$build_dir/fuzz-findings/$t
    local regressions=$root/tests/fuzz/regressions/$t
    rm -rf "$work/seeds"
    mkdir -p "$work/corpus" "$work/seeds" "$findings" "$regressions"
    INDRIVE_FUZZ_WRITE_SEEDS=$work/seeds "$exe" >"$work/seeds.log" 2>&1 || {
      echo "fuzz: $t could not write its seeds:" >&2; cat "$work/seeds.log" >&2; exit 1; }
    local log=$work/last-run.log rc=0
    # One allocation above 512 MB from one input, 2 GB of memory in all, or 10 s on one input
    # is a finding, as is any sanitizer report or an exception the decoder does not document.
    ASAN_OPTIONS=${ASAN_OPTIONS:-detect_leaks=1} UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1} \
      "$exe" -max_total_time="$seconds" -seed="$seed" -rss_limit_mb=2048 -malloc_limit_mb=512 -timeout=10 \
      -print_final_stats=1 -artifact_prefix="$findings/" \
      "$work/corpus" "$work/seeds" "$regressions" >"$log" 2>&1 || rc=$?
    local execs cov corpus
    execs=$(sed -n 's/^stat::number_of_executed_units: *//p' "$log" | tail -n 1)
    cov=$(grep -o 'cov: [0-9]*' "$log" | tail -n 1 | sed 's/cov: //')
    corpus=$(find "$work/corpus" -type f | wc -l)
    local verdict=ok
    if [[ $rc -ne 0 ]]; then
      verdict="FINDING (exit $rc): $(grep -m1 -E 'ERROR|runtime error|terminate|out-of-memory|timeout' "$log" || echo "see $log")"
      failed+=("$t")
    fi
    rows+=("$(printf '%-20s %6ss %10s execs %7s edges %6s corpus  %s' "$t" "$seconds" "${execs:-?}" "${cov:-?}" "$corpus" "$verdict")")
    say "${rows[-1]}"
  done
  printf '\n%-20s %7s %16s %13s %13s\n' target time executions coverage corpus
  printf '%s\n' "${rows[@]}"
  if [[ ${#failed[@]} -gt 0 ]]; then
    echo "fuzz: findings in: ${failed[*]}; inputs under $build_dir/fuzz-findings/, logs in $build_dir/fuzz-corpus/<target>/last-run.log." >&2
    echo "fuzz: reproduce with: $build_dir/fuzz/fuzz_<target> <input>; after the fix, copy the input into tests/fuzz/regressions/<target>/." >&2
    exit 1
  fi
}

case $mode in
  build) build ;;
  run) run "$@" ;;
  list) targets_built ;;
  *) sed -n 2,17p "${BASH_SOURCE[0]}"; exit 2 ;;
esac
