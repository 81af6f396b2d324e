#!/usr/bin/env bash
# clang-tidy with the project's checks (.clang-tidy) on C++ sources, using the compile commands
# of a build folder (bash deploy/setup.sh build makes build/compile_commands.json):
#   deploy/lint.sh                     the .cc files changed since the merge base with main
#   deploy/lint.sh --base REV          ... changed since REV
#   deploy/lint.sh FILE.cc...          the files named
# Headers are checked through the sources that include them (project headers only). Prints
# every finding and exits 1 when there is one, 0 when the files are clean. Not part of the test
# command: clang-tidy takes 10-20 s a file; run it on what you change before committing.
set -euo pipefail
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
build=${INDRIVE_BUILD_DIR:-$root/build}
base=""
files=()
while [[ $# -gt 0 ]]; do
  case "$1" in
    --base) base=$2; shift 2 ;;
    -h|--help) sed -n '2,9p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) files+=("$1"); shift ;;
  esac
done
command -v clang-tidy > /dev/null || { echo "clang-tidy is missing: apt-get install clang-tidy" >&2; exit 2; }
[[ -f $build/compile_commands.json ]] || { echo "no $build/compile_commands.json: build first (bash deploy/setup.sh build)" >&2; exit 2; }
cd "$root"
if [[ ${#files[@]} -eq 0 ]]; then
  [[ -n $base ]] || base=$(git merge-base HEAD main 2>/dev/null || echo HEAD)
  mapfile -t files < <(git diff --name-only --diff-filter=AMR "$base" -- '*.cc' | grep -v '^tests/fuzz/')
fi
[[ ${#files[@]} -gt 0 ]] || { echo "lint: no C++ source changed since ${base:-?}"; exit 0; }
echo "lint: clang-tidy on ${#files[@]} file(s)"
out=$(mktemp)
trap 'rm -f "$out"' EXIT
printf '%s\n' "${files[@]}" |
  xargs -P "$(nproc)" -I{} clang-tidy -p "$build" --quiet \
    --header-filter="^$root/(common|actor|learner|envserver|deploy)/" {} 2> /dev/null >> "$out" || true
if grep -q 'warning:\|error:' "$out"; then
  grep -A3 'warning:\|error:' "$out"
  echo "lint: $(grep -c 'warning:\|error:' "$out") finding(s)" >&2
  exit 1
fi
echo "lint: clean"
