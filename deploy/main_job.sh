#!/usr/bin/env bash
# The main job on the embedded default configuration (see README). Called by
# `bash deploy/setup.sh run` with the build directory as its argument.
#
# 1. The service: the learner and 2 actors pretrain with latent disagreement on town01 for
#    3,000 env steps (tiny preset), then 1 evaluator runs a zero-shot evaluation of the last
#    snapshot on town02 (deploy/configs/smoke.yaml). It shows the processes working together;
#    3,000 steps are far too few to drive.
# 2. The method: the shipped LD policy (seed 0, 100,000 pretraining steps on town01;
#    docs/results/route-sets/) evaluated zero-shot on the held-out town02, a few episodes per
#    route at one density, with a video of each route's first episode.
# Then it prints both tables, one above the other, and writes the run's page with the videos.
set -euo pipefail
build_dir=${1:?usage: main_job.sh BUILD_DIR}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin="$build_dir/bin"
runs="$root/runs"
run_id=${INDRIVE_RUN_ID:-smoke-$(date +%Y%m%d-%H%M%S)}
run="$runs/$run_id"
shipped_snapshot="$root/docs/results/route-sets/snapshots/s0-pretrain-disag.params"
shipped="$run/shipped-policy"
shipped_episodes=${INDRIVE_SHIPPED_EPISODES:-10}

say() { printf '\033[1m[main]\033[0m %s\n' "$*"; }
started=$(date +%s)
since() { echo "$(($(date +%s) - $1)) s"; }

say "1/3 the service: run $run_id (learner, 2 actors, 1 evaluator; tiny preset, 3,000 steps)"
"$bin/indrive" launch --config "$root/deploy/configs/smoke.yaml" --runs-dir "$runs" \
  --run-id "$run_id" --actors 2 --evaluators 1 --status-interval 30
"$bin/indrive" report "$run" --out "$run" > /dev/null
"$bin/indrive" plot "$run" > /dev/null
say "    the service took $(since "$started")"

stage=$(date +%s)
say "2/3 the method: the shipped LD policy (100,000 steps) zero-shot on town02," \
  "$shipped_episodes episodes per route at density 5, with videos"
"$bin/indrive-actor" --evaluate --run-dir "$shipped" --snapshot "$shipped_snapshot" \
  --set preset=tiny --set eval.kind=zero_shot --set agent.intrinsic.method=disag \
  --set eval.towns=town02 --set eval.densities=[5] \
  --set "eval.episodes_per_cell=$shipped_episodes" --set eval.video_episodes=1 --log-level warn
"$bin/indrive" report "$shipped" --out "$shipped" > /dev/null
# The run's page shows the videos of <run>/videos: the shipped policy's first episode of each
# route, named in the grid's order with how it ended (e.g. shipped-ld-100k-1-town02-straight-success).
mkdir -p "$run/videos"
awk -F, 'NR == 1 { for (i = 1; i <= NF; ++i) col[$i] = i; next }
  $col["episode"] == 0 {
    outcome = $col["success"] == 1 ? "success" : $col["failure_reason"]
    print $col["town"], $col["route"], $col["density"], ++n, outcome }' \
  "$shipped/eval/evaluator-0.csv" |
  while read -r town route density index outcome; do
    video="$shipped/videos/eval-$town-$route-$density-0.mp4"
    if [[ -f $video ]]; then cp "$video" "$run/videos/shipped-ld-100k-$index-$town-$route-$outcome.mp4"; fi
  done
say "    the shipped policy's evaluation took $(since "$stage")"

stage=$(date +%s)
say "3/3 town maps and the run's page"
for town in town01 town02; do
  "$bin/indrive-env" routes --town "$town" --out "$run/plots/$town.png" > /dev/null
done
title="$run_id: the shipped LD policy driving town02, then your 3,000-step run"
"$bin/indrive" dashboard "$run" --videos-first --title "$title" > /dev/null
say "    maps and page took $(since "$stage")"

# A report's success table: its first section down to the average over routes.
success_table() { awk '/^## /{on=1} /^### Mean route completion/{exit} on' "$1"; }
echo
say "your 3,000-step run (zero-shot on town02; expect SR 0: 3,000 steps are far too few to drive)"
success_table "$run/report.md"
echo
say "the shipped policy, 100,000 steps (LD seed 0, zero-shot on town02; $shipped_episodes episodes" \
  "per route; docs/results/route-sets/ has the 50-episode grid)"
success_table "$shipped/report.md"
echo
say "done in $(since "$started"). Run directory: $run"
say "  page:        $run/index.html (open it in a browser: the shipped policy's videos, curves,"
say "               tables, maps, config)"
say "  reports:     $run/report.md and $shipped/report.md (also .csv, .tex)"
say "  metrics:     $run/metrics.jsonl; evaluation rows: $run/eval/*.csv, $shipped/eval/*.csv"
say "  checkpoints: $run/checkpoints; logs: $run/logs"
