#!/usr/bin/env bash
# The two claims of the method on one host, with indrive-train-local (one process per run):
#   1. exploration: coverage of a random policy vs disag pretraining over the same env steps
#      (distinct 10 m lane segments per 1,000 env steps, the fraction of the town's segments
#      ever visited, and the segments one episode reaches from its spawn point by driving; see
#      envserver/include/indrive/envserver/coverage.h);
#   2. few-shot transfer: lane following on the straight route, finetuned from the disag
#      pretraining vs DreamerV3 from scratch with the same task budget, scored by the success
#      rate over a fixed number of evaluation episodes (sampled actions, the protocol's traffic and
#      spawn seeds from actor/eval_protocol.h).
# It prints a table at the end and leaves every run directory (metrics.jsonl, checkpoints,
# coverage.csv, eval/*.csv, plots/) under --out.
#
# The long run (cpu preset; hours on a laptop-class CPU):
#   deploy/experiments/exploration_and_fewshot.sh --out runs/explore-fewshot-cpu
# The tiny preset at 20k exploration steps (about 20 minutes per seed on 2 cores;
# docs/results/explore-fewshot-tiny/):
#   deploy/experiments/exploration_and_fewshot.sh --preset tiny --explore-steps 20000 \
#       --task-steps 5000 --prefill 1000 --eval-episodes 10 --eval-densities 5,10,20 --seed 0
# Extra configuration for every run (repeatable), e.g. shorter replay windows so that the cpu
# preset makes four times as many updates for the same compute:
#   deploy/experiments/exploration_and_fewshot.sh --explore-steps 20000 --task-steps 5000 \
#       --eval-densities 5,10,20 --set agent.replay.length=16
# --video-episodes N records the first N evaluation episodes of each density as MP4 under
# <run>/videos/ (camera, bird's-eye view, events), to see how the policies fail.
# A tiny run that only shows the pipeline works (minutes):
#   deploy/experiments/exploration_and_fewshot.sh --preset tiny --explore-steps 600 \
#       --task-steps 300 --prefill 100 --eval-episodes 1 --out /tmp/explore-fewshot-tiny
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="$root/build/bin"
out="$root/runs/explore-fewshot"
preset=cpu
explore_steps=50000   # env steps of the random run and of the disag pretraining, each
task_steps=10000      # env steps of the finetune and of the from-scratch dreamer run, each
prefill=1000          # random steps before training in every trained run
eval_episodes=10      # evaluation episodes per density
eval_densities=10     # densities of the evaluation, comma-separated (5, 10, 20)
route=straight
town=town01
seed=0
extra=()              # --set KEY=VALUE for every run
video_episodes=0      # evaluation episodes per density recorded as video

usage() { sed -n '2,26p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --explore-steps) explore_steps=$2; shift 2 ;;
    --task-steps) task_steps=$2; shift 2 ;;
    --prefill) prefill=$2; shift 2 ;;
    --eval-episodes) eval_episodes=$2; shift 2 ;;
    --eval-densities) eval_densities=$2; shift 2 ;;
    --route) route=$2; shift 2 ;;
    --town) town=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --set) extra+=(--set "$2"); shift 2 ;;
    --video-episodes) video_episodes=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

train=$bin/indrive-train-local
[[ -x $train ]] || { echo "no $train: build the indrive-train-local target first" >&2; exit 1; }
if [[ -e $out ]]; then
  echo "$out exists: pick a new --out (runs in it would resume rather than start fresh)" >&2
  exit 1
fi
mkdir -p "$out"
say() { printf '\033[1m[experiment]\033[0m %s\n' "$*"; }
common=(--set "preset=$preset" --set "run.seed=$seed" --set "env.town=$town"
        --set "agent.replay.prefill=$prefill" ${extra[@]+"${extra[@]}"})

# Last value of a key in a run's metrics.jsonl.
last_metric() {
  python3 -c 'import json,sys
v=None
for line in open(sys.argv[1]):
    line=line.strip()
    if line:
        d=json.loads(line)
        if sys.argv[2] in d: v=d[sys.argv[2]]
scale=float(sys.argv[3]) if len(sys.argv) > 3 else 1.0
print("n/a" if v is None else ("%.4g" % (v * scale)))' "$1/metrics.jsonl" "$2" "${3:-1}"
}
newest_checkpoint() { ls "$1"/checkpoints/ckpt-*.bin | sort | tail -n 1; }

say "1/6 random policy, $explore_steps env steps ($preset preset, $town)"
"$train" --config "$root/deploy/configs/pretrain_disag.yaml" --run-dir "$out/random" --random \
  "${common[@]}" --set "run.budget_env_steps=$explore_steps"

say "2/6 disag pretraining, $explore_steps env steps"
"$train" --config "$root/deploy/configs/pretrain_disag.yaml" --run-dir "$out/disag" \
  "${common[@]}" --set "run.budget_env_steps=$explore_steps"

say "3/6 finetune lane following on $route from the disag pretraining, $task_steps env steps"
"$train" --config "$root/deploy/configs/finetune_lf.yaml" --run-dir "$out/finetune-lf" \
  "${common[@]}" --set "run.budget_env_steps=$task_steps" --set "env.route=$route" \
  --set "learner.init_checkpoint=$(newest_checkpoint "$out/disag")"

say "4/6 dreamer from scratch on lane following, $task_steps env steps"
"$train" --config "$root/deploy/configs/dreamer_lf.yaml" --run-dir "$out/dreamer-lf" \
  "${common[@]}" --set "run.budget_env_steps=$task_steps" --set "env.route=$route"

say "5/6 evaluation on $route: $eval_episodes episode(s) per density of [$eval_densities]"
evaluate() {
  "$train" --config "$2" --run-dir "$out/$1" "${common[@]}" --set "eval.densities=$eval_densities" \
    --set "eval.video_episodes=$video_episodes" \
    --evaluate-episodes "$eval_episodes" --route "$route" "${@:3}" --log-level warn |
    tee "$out/$1/evaluation.txt"
}
evaluate finetune-lf "$root/deploy/configs/finetune_lf.yaml"
evaluate dreamer-lf "$root/deploy/configs/dreamer_lf.yaml"
evaluate random "$root/deploy/configs/finetune_lf.yaml" --random

say "6/6 plots (learning curves and coverage maps)"
for run in random disag finetune-lf dreamer-lf; do
  "$bin/indrive" plot "$out/$run" > /dev/null || echo "(no plots for $run)"
done
for metric in coverage_fraction_visited coverage_distinct_per_1k episode_reach_last20; do
  "$bin/indrive" compare "$out/random" "$out/disag" --metric "$metric" \
    --out "$out/compare-$metric.png" > /dev/null
done

sr() { sed -n 's/^evaluation [^ ]* [^ ]*: //p' "$out/$1/evaluation.txt"; }
{
  echo
  echo "exploration on $town, $explore_steps env steps each ($preset preset, seed $seed)"
  [[ ${#extra[@]} -eq 0 ]] || echo "every run with: ${extra[*]}"
  printf '  %-40s %12s %12s\n' "measure" "random" "disag"
  printf '  %-40s %12s %12s\n' "distinct lane segments per 1k env steps" \
    "$(last_metric "$out/random" coverage_distinct_per_1k)" \
    "$(last_metric "$out/disag" coverage_distinct_per_1k)"
  printf '  %-40s %12s %12s\n' "% of the town's segments visited" \
    "$(last_metric "$out/random" coverage_fraction_visited 100)" \
    "$(last_metric "$out/disag" coverage_fraction_visited 100)"
  printf '  %-40s %12s %12s\n' "lane segments reached per episode (*)" \
    "$(last_metric "$out/random" episode_reach_last20)" \
    "$(last_metric "$out/disag" episode_reach_last20)"
  printf '  %-40s %12s %12s\n' "env steps per episode (*)" \
    "$(last_metric "$out/random" episode_length_last20)" \
    "$(last_metric "$out/disag" episode_length_last20)"
  echo "  (*) mean over the last 20 episodes of the run"
  echo
  echo "lane following on $route, $task_steps task env steps, $eval_episodes episode(s) per density [$eval_densities]"
  printf '  %-34s %s\n' "finetune from disag pretraining" "$(sr finetune-lf)"
  printf '  %-34s %s\n' "dreamer from scratch" "$(sr dreamer-lf)"
  printf '  %-34s %s\n' "random policy (reference)" "$(sr random)"
  echo
  echo "coverage maps: $out/{random,disag}/plots/coverage_map.png; over time: $out/compare-*.png"
  [[ $video_episodes -eq 0 ]] || echo "evaluation videos: $out/{finetune-lf,dreamer-lf,random}/videos/"
} | tee "$out/summary.txt"
