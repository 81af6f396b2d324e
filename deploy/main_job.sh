#!/usr/bin/env bash
# The main job on the embedded default configuration (see README). Called by
# `bash deploy/setup.sh run` with the build directory as its argument.
#
# Runs the whole system on the `tiny` preset for a few minutes: the learner and 2 actors
# pretrain with latent disagreement on town01, then 1 evaluator runs a zero-shot evaluation of
# the last snapshot on town02 (deploy/configs/smoke.yaml). Then it writes the report tables and
# learning curves, draws both towns and records a follower episode video.
set -euo pipefail
build_dir=${1:?usage: main_job.sh BUILD_DIR}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin="$build_dir/bin"
runs="$root/runs"
run_id=${INDRIVE_RUN_ID:-smoke-$(date +%Y%m%d-%H%M%S)}
run="$runs/$run_id"

say() { printf '\033[1m[main]\033[0m %s\n' "$*"; }

say "training + zero-shot evaluation: run $run_id (learner, 2 actors, 1 evaluator; tiny preset)"
"$bin/indrive" launch --config "$root/deploy/configs/smoke.yaml" --runs-dir "$runs" \
  --run-id "$run_id" --actors 2 --evaluators 1 --status-interval 30

say "report and learning curves"
"$bin/indrive" report "$run" --out "$run"
"$bin/indrive" plot "$run" > /dev/null

say "town maps and a follower episode on town02/two_turn"
for town in town01 town02; do
  "$bin/indrive-env" routes --town "$town" --out "$run/plots/$town.png" > /dev/null
done
"$bin/indrive-env" episode --town town02 --route two_turn --density 10 --policy follower \
  --seed 2 --video "$run/videos/town02_two_turn_follower.mp4" --quiet
# The run's page again, now with the town maps and the video.
"$bin/indrive" dashboard "$run" > /dev/null

say "done. Run directory: $run"
say "  page:        $run/index.html (open it in a browser: curves, tables, maps, video, config)"
say "  report:      $run/report.md (also .csv, .tex)"
say "  curves:      $run/plots/*.png ($(ls "$run/plots" | wc -l) files)"
say "  metrics:     $run/metrics.jsonl; evaluation rows: $run/eval/*.csv"
say "  checkpoints: $run/checkpoints; logs: $run/logs"
echo
sed -n '/^## /,$p' "$run/report.md" | head -20
