#!/usr/bin/env bash
# Sets up InDRiVE-on-SUMO on a Debian 12 machine, builds it, and runs the main job or the tests.
#
#   bash deploy/setup.sh run    # install what is missing, build the programs, run the main job
#   bash deploy/setup.sh test   # install what is missing, build everything, run the tests and a
#                               # brief fuzz
#   bash deploy/setup.sh build  # install what is missing and build only
#   bash deploy/setup.sh deps   # install what is missing only (the Docker image's first layer)
#
# INDRIVE_CMAKE_ARGS adds configure options, e.g. "-DINDRIVE_NATIVE=OFF" for binaries that must
# run on other CPUs (deploy/docker/Dockerfile sets it).
#
# Idempotent: installs only missing packages (as root directly, otherwise through sudo) and
# rebuilds only what changed. The build goes to build/ (Release).
set -euo pipefail

here=$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)
root=$(cd "$here/.." && pwd)
build_dir=${INDRIVE_BUILD_DIR:-$root/build}
mode=${1:-build}

# Debian 12 packages the build and the tests need (the README's dependency table says why).
packages=(
  build-essential cmake ninja-build pkg-config
  libfastrtps-dev libfastcdr-dev fastddsgen fastdds-tools
  sumo
  libeigen3-dev libdnnl-dev ocl-icd-opencl-dev libopencv-dev
  libyaml-cpp-dev nlohmann-json3-dev libcli11-dev libpugixml-dev zlib1g-dev libzstd-dev
  libssl-dev openssl
  libgtest-dev libgmock-dev
  ffmpeg
  libjs-chart.js
  libplplot-dev plplot-driver-cairo
)
# The test command also builds and briefly runs the fuzz targets (tests/fuzz/README.md):
# clang's libFuzzer and sanitizer runtimes, and its OpenMP.
# The dashboard's browser test opens a real page in headless Chromium.
# The cluster test runs a real two-node Slurm (tests/deploy/slurm/).
test_packages=(clang libclang-rt-14-dev libomp-14-dev chromium slurm-wlm munge)

say() { printf '\033[1m[setup]\033[0m %s\n' "$*"; }

install_missing() {
  local missing=()
  local wanted=("${packages[@]}")
  if [[ $mode == test ]]; then wanted+=("${test_packages[@]}"); fi
  for p in "${wanted[@]}"; do
    dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed" ||
      missing+=("$p")
  done
  if [ ${#missing[@]} -eq 0 ]; then
    say "all ${#wanted[@]} packages present"
    return
  fi
  local sudo=()
  if [ "$(id -u)" -ne 0 ]; then
    command -v sudo >/dev/null || {
      echo "setup: missing packages (${missing[*]}) and not root, and sudo is not installed;" \
           "install them as root: apt-get install ${missing[*]}" >&2
      exit 1
    }
    sudo=(sudo)
  fi
  say "installing: ${missing[*]}"
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get update -q
  "${sudo[@]}" env DEBIAN_FRONTEND=noninteractive apt-get install -y -q --no-install-recommends \
    "${missing[@]}"
}

# build [TARGET]: everything, or one target (`programs`: what the main job runs, no tests).
build() {
  local jobs target=()
  jobs=$(nproc)
  [[ $# -gt 0 ]] && target=(--target "$1")
  if [ ! -f "$build_dir/build.ninja" ]; then
    say "configuring into $build_dir"
    # shellcheck disable=SC2086  # INDRIVE_CMAKE_ARGS is a list of options
    cmake -S "$root" -B "$build_dir" -G Ninja -DCMAKE_BUILD_TYPE=Release ${INDRIVE_CMAKE_ARGS:-}
  fi
  say "building ${1:-everything} with $jobs jobs"
  cmake --build "$build_dir" -j "$jobs" "${target[@]}"
}

run_tests() {
  # unit + integration + smoke; benchmarks (label bench), the long soak (soak) and the real
  # containers (container: podman or docker, minutes) run only on request: ctest -L bench
  say "running tests (unit, integration, smoke)"
  ctest --test-dir "$build_dir" -LE 'bench|soak|container' --output-on-failure -j "$(nproc)" --timeout 600
  # Every fuzz target for a few seconds, replaying its committed regression inputs first. The
  # seed is fixed so that a test run tries the same mutations each time; finding new bugs is
  # the long run's job (deploy/fuzz.sh run --seconds 600, a new seed each time).
  say "fuzzing every decoder briefly (deploy/fuzz.sh)"
  "$here/fuzz.sh" build
  "$here/fuzz.sh" run --seconds 5 --seed 1
}

run_main() {
  "$root/deploy/main_job.sh" "$build_dir"
}

case "$mode" in
  deps) install_missing ;;
  build) install_missing; build ;;
  test) install_missing; build; run_tests ;;
  run) install_missing; build programs; run_main ;;
  *) echo "usage: $0 run|test|build|deps" >&2; exit 2 ;;
esac
