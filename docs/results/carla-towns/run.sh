#!/usr/bin/env bash
# The evaluations behind this page, from the repository root after `bash deploy/setup.sh build`.
# Each writes runs/carla-*/<name>/eval/evaluator-0.csv; the page's eval/ holds copies.
set -euo pipefail
bin=build/bin
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1}
evaluate() { # out_dir protocol episodes_per_cell [indrive-actor options ...]
  local dir=$1 protocol=$2 episodes=$3
  shift 3
  rm -rf "$dir"
  mkdir -p "$dir"
  "$bin/indrive-actor" --evaluate --run-dir "$dir" --set preset=tiny --set run.seed=0 \
    --set eval.towns=carla_town01,carla_town02 --set "eval.episodes_per_cell=$episodes" \
    --set "eval.protocol=$protocol" "$@" --log-level warn
}

# 1. Sanity bounds: the scripted route follower and uniform random actions, 50 episodes per cell.
for p in strict indrive_code; do
  for policy in oracle random; do evaluate "runs/carla-sanity/$policy-$p" "$p" 50 --policy "$policy"; done
done

# 2. The seed-0 policies of docs/results/route-sets/ (trained on our town01) on the CARLA towns,
#    20 episodes per cell.
snap=docs/results/route-sets/snapshots
for p in strict indrive_code; do
  for m in disag icm rnd; do
    evaluate "runs/carla-shipped/zeroshot-$m-$p" "$p" 20 --snapshot "$snap/s0-pretrain-$m.params" \
      --set eval.kind=zero_shot --set "agent.intrinsic.method=$m"
  done
  for t in lf ca; do
    task=$([[ $t == lf ]] && echo lane_following || echo collision_avoidance)
    evaluate "runs/carla-shipped/fewshot-$t-disag-$p" "$p" 20 --snapshot "$snap/s0-finetune-$t-disag.params" \
      --set eval.kind=few_shot --set agent.intrinsic.method=disag --set "agent.task=$task"
    evaluate "runs/carla-shipped/fewshot-$t-dreamer-$p" "$p" 20 --snapshot "$snap/s0-dreamer-$t.params" \
      --set eval.kind=few_shot --set agent.phase=dreamer --set "agent.task=$task"
  done
done

# 3. The grid on the CARLA towns (pretraining on carla_town01, evaluation under both
#    protocols, 50 episodes per cell): one chain per seed and method, resumable. On
#    2026-12-06 and 2026-12-07: seed 0 of disag, icm, rnd and random; on 2026-12-07 seeds 1 and 2
#    of disag, icm and rnd (icm and rnd side by side, one core each, beside other work; seed 2
#    with INDRIVE_GRID_BIN naming a copy of the binaries of commit b03573b).
for s in 0 1 2; do
  for m in disag icm rnd; do
    deploy/experiments/paper_grid.sh chain --out runs/carla-grid --towns carla --seed "$s" --method "$m" \
      --stages "pretrain zeroshot" --episodes 50
  done
done
deploy/experiments/paper_grid.sh chain --out runs/carla-grid --towns carla --seed 0 --method random \
  --stages "pretrain zeroshot" --episodes 50
# Few-shot LF and CA from LD's seed-0 pretraining (10,000 task steps on carla_town01's routes at
# replay ratio 512, then evaluated like the zero-shot), side by side, one core each; on
# 2026-12-07, about 70 minutes of training each beside other work. Their `indrive_code`
# evaluations were run later the same day by the chain command (stage fewshot, which skips what
# is done): 25 minutes each on two cores. Seeds 1 and 2 the same way, later that day, side by
# side beside other work: training and both protocols' evaluations took 40-43 minutes (seed 1)
# and 31-37 (seed 2).
for s in 0 1 2; do
  for t in lane_following collision_avoidance; do
    deploy/experiments/paper_grid.sh grid --towns carla --out runs/carla-grid --seeds "$s" --methods disag \
      --stages "pretrain fewshot" --task "$t" --episodes 50 &
  done
  wait
done
# DreamerV3 from scratch on carla_town01's routes at the same total budget (110,000 task
# steps), LF and CA side by side, one core each: seed 0 on 2026-12-07 (23-27 minutes of
# training each, then both protocols' evaluations); seeds 1 and 2 on 2026-12-08 with
# INDRIVE_GRID_BIN naming a copy of the binaries of commit b703976 (43-49 minutes per seed,
# training and evaluations, beside builds and tests).
for s in 0 1 2; do
  for t in lane_following collision_avoidance; do
    deploy/experiments/paper_grid.sh dreamer --towns carla --out runs/carla-grid --seed "$s" --task "$t" \
      --episodes 50 &
  done
  wait
done

# The page: each evaluation's CSV under sanity/eval/ and shipped/eval/ with their reports, and
# the grid's runs, CSVs, the snapshots of seeds 0-2, pretraining summary and report.
page=docs/results/carla-towns
for part in sanity shipped; do
  mkdir -p "$page/$part/eval"
  for d in runs/carla-$part/*/; do
    [[ -f $d/eval/evaluator-0.csv ]] && cp "$d/eval/evaluator-0.csv" "$page/$part/eval/$(basename "$d").csv"
  done
  $bin/indrive report "$page/$part/eval" --out "$page/$part"
done
deploy/experiments/paper_grid.sh publish --out runs/carla-grid --page docs/results/carla-towns \
  --snapshot-seeds "0 1 2"
