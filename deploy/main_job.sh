#!/usr/bin/env bash
# The main job on the embedded default configuration (see README). Called by
# `bash deploy/setup.sh run` with the build directory as its argument.
set -euo pipefail
build_dir=${1:?usage: main_job.sh BUILD_DIR}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
echo "main job: nothing runnable is built yet (see README, status)"
