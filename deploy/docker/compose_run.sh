#!/bin/bash
# The service in containers, end to end: base image (when missing) -> image -> compose up
# (discovery server, learner, 2 actors, evaluator) -> wait for the learner's budget and the
# evaluation of its last snapshot -> stop -> report -> down. From the repository root:
#
#   bash deploy/docker/compose_run.sh [--run-id ID] [--runs-dir DIR] [--build] [--pull-base]
#                                     [--timeout SECONDS] [--keep]
#
# Prints progress and, at the end, lines the container test reads:
#   compose_run: image build seconds N | compose run seconds N | report PATH | exit codes ...
set -euo pipefail

root=$(cd "$(dirname "$0")/../.." && pwd)
compose_file="$root/deploy/docker/docker-compose.yml"
image=indrive-on-sumo:latest
project=indrive
run_id=compose-$(date +%Y%m%d-%H%M%S)
runs_dir="$root/runs"
build=0
pull_base=0
timeout_s=3600
keep=0

usage() {
  cat <<'EOF'
Usage: compose_run.sh [--run-id ID] [--runs-dir DIR] [--build] [--pull-base] [--timeout S] [--keep]

Runs deploy/docker/docker-compose.yml to the end of its smoke run and writes the report:
  1. the Debian 12 base image, when missing: deploy/docker/make_base_image.sh (mmdebstrap from
     this host's apt sources; --pull-base leaves it to the engine's registry instead);
  2. the image indrive-on-sumo, when missing or with --build (compiles the project: minutes);
  3. compose up: discovery, learner, actor-0, actor-1, evaluator, on DIR/ID (default
     runs/compose-<time>);
  4. waits until the learner and the evaluator have exited with 0 (at most S seconds,
     default 3600), then stops the actors and the discovery server and prints every exit code;
  5. indrive report DIR/ID --out DIR/ID in a container: DIR/ID/report.md;
  6. compose down (--keep leaves the stopped containers for inspection).

Engine: podman with podman-compose (or `podman compose`), else docker with `docker compose`;
INDRIVE_CONTAINER_ENGINE=podman|docker chooses. With podman, CONTAINERS_CONF defaults to
deploy/docker/containers.conf (runc, ulimits a sandboxed kernel accepts).
Exit status: 0 when the run finished and the report exists; 1 otherwise; 3 when no container
engine is installed or it does not answer.
EOF
}
while [ $# -gt 0 ]; do
  case "$1" in
    --run-id) run_id=$2; shift ;;
    --runs-dir) runs_dir=$2; shift ;;
    --build) build=1 ;;
    --pull-base) pull_base=1 ;;
    --timeout) timeout_s=$2; shift ;;
    --keep) keep=1 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "compose_run.sh: unknown argument '$1' (see --help)" >&2; exit 2 ;;
  esac
  shift
done

say() { echo "compose_run: $*"; }
die() { echo "compose_run: $*" >&2; exit 1; }

engine=${INDRIVE_CONTAINER_ENGINE:-}
if [ -z "$engine" ]; then
  if command -v podman >/dev/null; then engine=podman
  elif command -v docker >/dev/null; then engine=docker
  else
    echo "compose_run: no container engine: apt-get install podman runc podman-compose" \
         "(or docker.io docker-compose)" >&2
    exit 3
  fi
fi
command -v "$engine" >/dev/null || { echo "compose_run: $engine is not installed" >&2; exit 3; }
if ! "$engine" info >/dev/null 2>&1; then
  echo "compose_run: '$engine info' fails: is its service running (docker) or its set-up" \
       "complete?" >&2
  exit 3
fi
if [ "$engine" = podman ]; then
  export CONTAINERS_CONF=${CONTAINERS_CONF:-$root/deploy/docker/containers.conf}
  if command -v podman-compose >/dev/null; then compose=(podman-compose)
  elif podman compose version >/dev/null 2>&1; then compose=(podman compose)
  else
    echo "compose_run: podman has no compose: apt-get install podman-compose" >&2
    exit 3
  fi
else
  if docker compose version >/dev/null 2>&1; then compose=(docker compose)
  elif command -v docker-compose >/dev/null; then compose=(docker-compose)
  else
    echo "compose_run: docker has no compose: install docker-compose" >&2
    exit 3
  fi
fi
compose+=(-p "$project" -f "$compose_file")
say "engine $engine, compose: ${compose[*]}"

mkdir -p "$runs_dir"
runs_dir=$(cd "$runs_dir" && pwd)
run="$runs_dir/$run_id"
[ -e "$run" ] && die "$run exists: a learner would resume there; choose another --run-id"
export INDRIVE_RUN_ID=$run_id INDRIVE_RUNS_DIR=$runs_dir

# 1. Base image.
base=$(sed -n 's/^FROM \([^ ]*\).*/\1/p' "$root/deploy/docker/Dockerfile" | head -1)
if ! "$engine" image inspect "$base" >/dev/null 2>&1; then
  if [ "$pull_base" = 1 ]; then
    say "base image $base missing: the build pulls it"
  else
    say "base image $base missing: making it (deploy/docker/make_base_image.sh)"
    INDRIVE_CONTAINER_ENGINE=$engine bash "$root/deploy/docker/make_base_image.sh" --name "$base"
  fi
fi

# 2. The image.
build_s=0
if [ "$build" = 1 ] || ! "$engine" image inspect "$image" >/dev/null 2>&1; then
  say "building $image (compiles the project; minutes)"
  start=$(date +%s)
  (cd "$root" && "$engine" build -f deploy/docker/Dockerfile -t "$image" .)
  build_s=$(($(date +%s) - start))
  say "image built in $build_s s"
else
  say "image $image exists (--build rebuilds it)"
fi
size=$("$engine" image inspect --format '{{.Size}}' "$image")
say "image size $((size / 1000000)) MB"

# 3. Up.
containers() {  # container names of one service of this project
  "$engine" ps -a --filter "label=com.docker.compose.project=$project" \
    --filter "label=com.docker.compose.service=$1" --format '{{.Names}}'
}
state() { "$engine" inspect --format '{{.State.Status}} {{.State.ExitCode}}' "$1" 2>/dev/null; }
services=(discovery learner actor-0 actor-1 evaluator)
cleanup() {
  if [ "$keep" = 0 ]; then "${compose[@]}" down >/dev/null 2>&1 || true; fi
}
trap cleanup EXIT
"${compose[@]}" down >/dev/null 2>&1 || true  # leftovers of an earlier run of this project
say "up: ${services[*]} on $run"
start=$(date +%s)
"${compose[@]}" up -d --no-build >/dev/null

# 4. Wait for the learner's budget and the evaluation of the last snapshot.
learner=$(containers learner)
evaluator=$(containers evaluator)
[ -n "$learner" ] && [ -n "$evaluator" ] || die "the learner or the evaluator did not start"
last=0
while :; do
  now=$(date +%s)
  ls=$(state "$learner")
  es=$(state "$evaluator")
  [ "$ls" = "exited 0" ] && [ "$es" = "exited 0" ] && break
  if [ $((now - start)) -ge "$timeout_s" ]; then
    for s in "${services[@]}"; do "$engine" logs --tail 20 "$(containers "$s")" 2>&1 | sed "s/^/  $s: /"; done
    die "not finished after $timeout_s s (learner: $ls, evaluator: $es)"
  fi
  if [ $((now - last)) -ge 30 ]; then
    steps=$(tail -n 1 "$run/metrics.jsonl" 2>/dev/null | grep -o '"env_steps":[0-9]*' | cut -d: -f2)
    say "$((now - start)) s: learner ${ls:-?} (env_steps ${steps:-0}), evaluator ${es:-?}"
    last=$now
  fi
  sleep 5
done
"${compose[@]}" stop >/dev/null 2>&1 || true
run_s=$(($(date +%s) - start))
codes=""
for s in "${services[@]}"; do codes+=" $s=$(state "$(containers "$s")" | cut -d' ' -f2)"; done
say "run finished in $run_s s; exit codes:$codes"

# 5. Report, in a container of the same image (the run's files belong to its root).
report_log=$("$engine" run --rm -v "$runs_dir:/runs" "$image" \
  indrive report "/runs/$run_id" --out "/runs/$run_id" 2>&1) || die "indrive report failed: $report_log"
[ -f "$run/report.md" ] || die "no report at $run/report.md"
sed -n "/^## /,\$p" "$run/report.md" | head -40
say "image build seconds $build_s"
say "compose run seconds $run_s"
say "report $run/report.md"
say "exit codes$codes"
