#!/usr/bin/env bash
# The paper's pipeline end to end through the distributed system, on a short budget:
#   1. reward-free pretraining on town01 with each intrinsic method (disag, icm, rnd): learner,
#      actors and evaluators started by `indrive launch`; the evaluators run a zero-shot
#      evaluation of each run's last snapshot (exploration policy) on town01 and town02;
#   2. few-shot finetuning for lane following from the disag pretraining (world model, intrinsic
#      module and exploration policy frozen), evaluated on both towns with its task policy;
#   3. `indrive report` over all runs (the paper's Tables III-VI layout) and `indrive plot` for
#      each run (learning curves and the coverage map of the training town).
# Every run directory stays under --out; the combined report is in --out/report.
#
#   deploy/experiments/paper_tables.sh --out runs/paper-tables            # cpu preset, short budget
#   deploy/experiments/paper_tables.sh --preset tiny --pretrain-steps 1500 --task-steps 600 \
#       --out /tmp/paper-tables-tiny                                       # a few minutes
#
# The paper's budgets are 5e5 pretraining and 1e4 task steps; the defaults here are a short
# budget that shows the pipeline and its outputs, not the paper's numbers.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="$root/build/bin"
out="$root/runs/paper-tables"
preset=cpu
pretrain_steps=3000
task_steps=1500
prefill=500
episodes=1          # evaluation episodes per town x route x density
densities="[5,10,20]"
actors=2
snapshot_every=10   # updates between snapshots: short runs need the actors to act with them
evaluators=2
seed=0
methods="disag icm rnd"

usage() { sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; }
while [[ $# -gt 0 ]]; do
  case "$1" in
    --bin) bin=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --pretrain-steps) pretrain_steps=$2; shift 2 ;;
    --task-steps) task_steps=$2; shift 2 ;;
    --prefill) prefill=$2; shift 2 ;;
    --episodes) episodes=$2; shift 2 ;;
    --densities) densities=$2; shift 2 ;;
    --actors) actors=$2; shift 2 ;;
    --snapshot-every) snapshot_every=$2; shift 2 ;;
    --evaluators) evaluators=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --methods) methods=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

[[ -x $bin/indrive ]] || { echo "no $bin/indrive: build first (bash deploy/setup.sh build)" >&2; exit 1; }
if [[ -e $out ]]; then
  echo "$out exists: pick a new --out (a launch into an existing run resumes it)" >&2
  exit 1
fi
mkdir -p "$out"
say() { printf '\033[1m[paper-tables]\033[0m %s\n' "$*"; }
common=(--runs-dir "$out" --actors "$actors" --evaluators "$evaluators" --status-interval 30
        --set "preset=$preset" --set "run.seed=$seed" --set "agent.replay.prefill=$prefill"
        --set "eval.towns=town01,town02" --set "eval.densities=$densities"
        --set "eval.episodes_per_cell=$episodes" --set "eval.wait_for_done=true"
        --set "learner.snapshot_every=$snapshot_every")

runs=()
for method in $methods; do
  say "pretrain $method: $pretrain_steps env steps ($preset preset, town01), then zero-shot evaluation"
  "$bin/indrive" launch --config "$root/deploy/configs/pretrain_$method.yaml" \
    --run-id "pretrain-$method-s$seed" "${common[@]}" \
    --set "run.budget_env_steps=$pretrain_steps"
  runs+=("$out/pretrain-$method-s$seed")
done

if [[ " $methods " == *" disag "* ]]; then
  ckpt=$(ls "$out/pretrain-disag-s$seed"/checkpoints/ckpt-*.bin | sort | tail -n 1)
  say "finetune lane following from $(basename "$ckpt"): $task_steps env steps, then few-shot evaluation"
  "$bin/indrive" launch --config "$root/deploy/configs/finetune_lf.yaml" \
    --run-id "finetune-lf-disag-s$seed" "${common[@]}" \
    --set "run.budget_env_steps=$task_steps" --set "learner.init_checkpoint=$ckpt"
  runs+=("$out/finetune-lf-disag-s$seed")
fi

say "report and plots"
"$bin/indrive" report "${runs[@]}" --out "$out/report"
for run in "${runs[@]}"; do "$bin/indrive" plot "$run" > /dev/null; done

say "done: $out/report/report.md"
sed -n '/^## /,$p' "$out/report/report.md"
