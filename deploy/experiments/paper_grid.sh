#!/usr/bin/env bash
# The paper's experiment at a CPU budget, one (seed, method) chain per call, resumable, so that
# a grid too long for one sitting is split by seed and merged by the report:
#   pretrain  reward-free pretraining on town01 (indrive-train-local), then the run's final
#             snapshot file;
#   zeroshot  that snapshot, every parameter frozen, on town01 and town02: all four routes,
#             densities 5/10/20, --episodes per cell (indrive-actor --evaluate --snapshot);
#   fewshot   lane following and collision avoidance fine-tuned from the pretraining for
#             --task-steps on town01's routes at replay ratio --fewshot-ratio (512, the public
#             InDRiVE code's, chosen by docs/results/ablation-fewshot-ratio/'s rule; the
#             method page's few-shot rows were made at 32), each evaluated like the zero-shot;
#   dreamer   DreamerV3 from scratch on a task for the same total budget (pretrain + task
#             steps), evaluated the same way;
#   report    `indrive report` over every evaluation under --out (Tables III-VI, 95% CIs;
#             the layout bound on --route-set's routes);
#   publish   what must outlast the machine, into a committed results page (--page DIR):
#             metrics, configs, evaluation CSVs, the report, and the acting snapshots of the
#             seeds in --snapshot-seeds ("0").
# Every stage leaves a DONE file in its run directory and is skipped when it is there, so a
# chain stopped midway resumes at its stage (a training run resumes from its checkpoints, an
# evaluation of the same snapshot with the same settings from the rows its CSVs hold).
#
#   deploy/experiments/paper_grid.sh chain --seed 0 --method disag     # pretrain, zero/few-shot
#   deploy/experiments/paper_grid.sh chain --seed 0 --method random    # its episodes, zero-shot
#   deploy/experiments/paper_grid.sh dreamer --seed 0 --task lane_following
#   deploy/experiments/paper_grid.sh grid --seeds "0 1 2" --methods "disag icm rnd random" \
#       --dreamer-tasks "lane_following collision_avoidance" [--slurm [--sbatch OPTION ...]]
#             # every chain's stages and the report: here in order, or as Slurm jobs that
#             # follow one another (docs/operations.md, "On a Slurm cluster")
#   deploy/experiments/paper_grid.sh summary   # the pretraining measures, a markdown table
#   deploy/experiments/paper_grid.sh report
#   deploy/experiments/paper_grid.sh publish --page docs/results/method-fewshot512
# Two chains side by side on 2 cores: give each OMP_NUM_THREADS=1 (the script sets it and
# OMP_WAIT_POLICY=passive unless they are set), and start them from one session (one shell,
# `&`): with the kernel's autogroup scheduling each session gets an equal CPU share, so a chain
# started alone under setsid ran at 0.9 core beside three that shared the other.
# --towns carla runs the chain on CARLA's towns instead of ours: pretraining on carla_town01,
# few-shot on its routes, every evaluation on carla_town01 and carla_town02 twice, under the
# strict protocol (<stage>/) and under the public InDRiVE code's (<stage>-code/, budget
# --code-budget steps); the report then holds both protocols' tables.
# Options: --out DIR (runs/paper-grid), --preset P (tiny), --pretrain-steps N (100000),
# --task-steps N (10000), --episodes N per town x route x density (5), --stages "pretrain
# zeroshot fewshot" (a chain's stages), --task T (dreamer's task; a chain's fewshot then does
# only T), --fewshot-ratio N (512), --route-set right|left (env.route_set of every run and
# evaluation: the built-in towns' route set, right by default), --set KEY=VALUE for every
# training run (repeatable), --page DIR and --snapshot-seeds "S ..." (publish), --trained-in
# DIR: take every training run (pretrain, few-shot, dreamer) from another --out instead of
# training, linked into this one, to evaluate the same policies on another --route-set:
#   paper_grid.sh chain --out runs/grid-left --trained-in runs/grid --route-set left \
#       --seed 0 --method disag --stages "zeroshot fewshot"
# grid: --seeds "S ..." and --methods "M ..." (the cells; --seed and --method by default),
# --dreamer-tasks "T ..." (none by default), --stages as a chain's, --slurm (submit with sbatch),
# --sbatch OPTION (repeatable, e.g. --sbatch --partition=cpu); the other options go to every stage.
# INDRIVE_GRID_BIN=DIR runs the programs from DIR instead of build/bin: a copy of the binaries
# keeps a grid of several hours on one build while the tree is rebuilt beside it.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="${INDRIVE_GRID_BIN:-$root/build/bin}"
out="$root/runs/paper-grid"
preset=tiny
pretrain_steps=100000
task_steps=10000
fewshot_ratio=512
episodes=5
seed=0
method=disag
task=lane_following
tasks="lane_following collision_avoidance"  # of a chain's fewshot stage; --task picks one
stages="pretrain zeroshot fewshot"
route_set=right
extra=()
page=""
snapshot_seeds=0
trained_in=""
towns=ours
code_budget=30000
seeds=""
methods=""
dreamer_tasks=""
scheduler=local
sbatch_args=()
forward=()  # the options every stage of a grid passes on to its chain, dreamer or report call

usage() { sed -n '2,/^set -euo/p' "$0" | sed '$d' | sed 's/^# \{0,1\}//'; }
[[ $# -ge 1 ]] || { usage; exit 2; }
[[ $1 == -h || $1 == --help ]] && { usage; exit 0; }
command=$1
shift
while [[ $# -gt 0 ]]; do
  case "$1" in
    --bin | --out | --preset | --pretrain-steps | --task-steps | --fewshot-ratio | --episodes | \
      --route-set | --set | --towns | --code-budget) forward+=("$1" "$2") ;;&
    --bin) bin=$2; shift 2 ;;
    --out) out=$2; shift 2 ;;
    --preset) preset=$2; shift 2 ;;
    --pretrain-steps) pretrain_steps=$2; shift 2 ;;
    --task-steps) task_steps=$2; shift 2 ;;
    --fewshot-ratio) fewshot_ratio=$2; shift 2 ;;
    --episodes) episodes=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --method) method=$2; shift 2 ;;
    --task) task=$2; tasks=$2; shift 2 ;;
    --stages) stages=$2; shift 2 ;;
    --route-set) route_set=$2; shift 2 ;;
    --set) extra+=(--set "$2"); shift 2 ;;
    --page) page=$2; shift 2 ;;
    --snapshot-seeds) snapshot_seeds=$2; shift 2 ;;
    --trained-in) trained_in=$2; shift 2 ;;
    --towns) towns=$2; shift 2 ;;
    --code-budget) code_budget=$2; shift 2 ;;
    --seeds) seeds=$2; shift 2 ;;
    --methods) methods=$2; shift 2 ;;
    --dreamer-tasks) dreamer_tasks=$2; shift 2 ;;
    --slurm) scheduler=slurm; shift ;;
    --sbatch) sbatch_args+=("$2"); shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
case $method in disag|icm|rnd|random) ;; *)
  echo "--method must be disag, icm, rnd or random, got '$method'" >&2; exit 2 ;;
esac
case $route_set in right|left) ;; *)
  echo "--route-set must be right or left, got '$route_set'" >&2; exit 2 ;;
esac
case $towns in ours|carla) ;; *)
  echo "--towns must be ours (town01, town02) or carla (carla_town01, carla_town02), got '$towns'" >&2; exit 2 ;;
esac
[[ $code_budget =~ ^[1-9][0-9]*$ ]] || { echo "--code-budget must be a positive step count, got '$code_budget'" >&2; exit 2; }
case $task in lane_following|collision_avoidance) ;; *)
  echo "--task must be lane_following or collision_avoidance, got '$task'" >&2; exit 2 ;;
esac
for program in indrive indrive-actor indrive-train-local; do
  [[ -x $bin/$program ]] || { echo "no $bin/$program: build first (bash deploy/setup.sh build)" >&2; exit 1; }
done
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} \
  GOMP_SPINCOUNT=${GOMP_SPINCOUNT:-100000}  # a short spin before sleeping, as indrive launch sets

say() { printf '\033[1m[grid %s]\033[0m %s\n' "$(date +%H:%M:%S)" "$*"; }
seed_dir="$out/s$seed"
mkdir -p "$seed_dir"
common=(--set "preset=$preset" --set "run.seed=$seed" --set "env.route_set=$route_set")
eval_towns=town01,town02
task_routes=()  # the configs' own: town01's four
if [[ $towns == carla ]]; then
  eval_towns=carla_town01,carla_town02
  common+=(--set "env.town=carla_town01")
  # Few-shot and DreamerV3 train on every route of the training town, as on ours.
  task_routes=(--set "env.route=$(sed -n 's/^\([a-z_0-9]*\):$/\1/p' \
    "$root/envserver/data/routes/carla_town01.routes.yaml" | paste -sd, -)")
fi
common+=(${extra[@]+"${extra[@]}"})
short() { [[ $1 == lane_following ]] && echo lf || echo ca; }
config_of() { # phase task -> config file
  case $1 in
    pretrain) echo "$root/deploy/configs/pretrain_$2.yaml" ;;
    finetune) echo "$root/deploy/configs/finetune_$(short "$2").yaml" ;;
    dreamer) echo "$root/deploy/configs/dreamer_$(short "$2").yaml" ;;
  esac
}
done_mark() { [[ -f $1/DONE ]]; }

# Trains one run to its budget (resuming when stopped) and checks its snapshot file; with
# --trained-in, links the finished run of the same name there instead.
link_trained() { # run_dir: with --trained-in, links the finished run of the same name there
  [[ -n $trained_in && ! -e $1 ]] || return 0
  local from
  from="$(cd "$trained_in" 2> /dev/null && pwd)/s$seed/$(basename "$1")"
  done_mark "$from" || { echo "--trained-in: $from is not a finished run; train it there first (the same chain without --trained-in, --out $trained_in)" >&2; exit 1; }
  ln -s "$from" "$1"
  say "$1: linked to the run trained in $from"
}
train() { # run_dir config steps [--set ...]
  local dir=$1 config=$2 steps=$3
  shift 3
  link_trained "$dir"
  if done_mark "$dir"; then say "$dir done already"; return; fi
  [[ -z $trained_in ]] || { echo "--trained-in: $dir exists but is not a finished run; remove it and run again" >&2; exit 1; }
  mkdir -p "$dir"
  "$bin/indrive-train-local" --config "$config" --run-dir "$dir" "${common[@]}" \
    --set "run.budget_env_steps=$steps" "$@" --log-level warn 2>&1 | tee -a "$dir/train.log" |
    awk '/^done/ || /failed/ || NR % 12 == 1 { print; fflush() }'  # about one line a minute
  [[ -f $dir/snapshot.params ]] || { echo "$dir has no snapshot.params: training failed (see $dir/train.log)" >&2; exit 1; }
  "$bin/indrive" plot "$dir" > /dev/null 2>&1 || echo "(no plots for $dir)"
  touch "$dir/DONE"
}

# Evaluates a snapshot file (or the random policy) on the grid with two evaluators; on the
# CARLA towns once per protocol (strict into eval_dir, indrive_code into eval_dir-code).
evaluate() { # eval_dir kind snapshot|random [--set ...]: the method and task the rows carry
  if [[ $towns == carla ]]; then
    local dir=$1
    shift
    evaluate_once "$dir" "$@" --set eval.protocol=strict
    evaluate_once "$dir-code" "$@" --set eval.protocol=indrive_code \
      --set "eval.indrive_code_budget_steps=$code_budget"
  else
    evaluate_once "$@"
  fi
}
evaluate_once() { # as evaluate
  local dir=$1 kind=$2 source=$3
  shift 3
  if done_mark "$dir"; then say "$dir done already"; return; fi
  # What is evaluated: the policy's bytes and every setting. An evaluation of the same stopped
  # part-way goes on with the episodes its CSVs lack (eval.resume); anything else starts afresh.
  local id
  id=$({ if [[ $source == random ]]; then echo random; else sha256sum < "$source"; fi
         printf '%s\n' "$kind" "$preset" "$seed" "$episodes" "$eval_towns" "$route_set" "$@"; } |
       sha256sum | cut -d' ' -f1)
  if [[ -d $dir/eval && -f $dir/evaluation.id && $(< "$dir/evaluation.id") == "$id" ]]; then
    say "$dir: going on with the episodes not yet in its eval/"
  else
    rm -rf "$dir/eval"
  fi
  mkdir -p "$dir"
  echo "$id" > "$dir/evaluation.id"
  local policy=(--snapshot "$source")
  [[ $source == random ]] && policy=(--policy random)
  local pids=()
  for j in 0 1; do
    "$bin/indrive-actor" --evaluate "${policy[@]}" --run-dir "$dir" --id "$j" --of 2 \
      --set "preset=$preset" --set "run.seed=$seed" --set "eval.kind=$kind" \
      --set "eval.episodes_per_cell=$episodes" --set "eval.towns=$eval_towns" \
      --set "env.route_set=$route_set" --set eval.resume=true \
      "$@" --log-level warn >> "$dir/evaluator-$j.log" 2>&1 &
    pids+=($!)
  done
  for pid in "${pids[@]}"; do wait "$pid" || { echo "an evaluator of $dir failed (see $dir/evaluator-*.log)" >&2; exit 1; }; done
  touch "$dir/DONE"
}

has_stage() { [[ " $stages " == *" $1 "* ]]; }
case $command in
  chain)
    pre="$seed_dir/pretrain-$method"
    if [[ $method == random ]]; then
      # The baseline's training-town episodes (length, reach, coverage) over the same env steps;
      # it acts uniformly at random and never trains.
      has_stage pretrain && { say "random policy, seed $seed, $pretrain_steps env steps"; train "$pre" "$(config_of pretrain disag)" "$pretrain_steps" --random; }
      has_stage zeroshot && { say "zero-shot random policy, seed $seed"; evaluate "$seed_dir/zeroshot-random" zero_shot random; }
      exit 0
    fi
    # Evaluating another route set's routes: the pretraining every later stage starts from.
    if has_stage zeroshot || has_stage fewshot; then link_trained "$pre"; fi
    has_stage pretrain && { say "pretrain $method seed $seed, $pretrain_steps env steps ($preset)"; train "$pre" "$(config_of pretrain "$method")" "$pretrain_steps"; }
    has_stage zeroshot && { say "zero-shot $method seed $seed"; evaluate "$seed_dir/zeroshot-$method" zero_shot "$pre/snapshot.params" --set "agent.intrinsic.method=$method"; }
    if has_stage fewshot; then
      for t in $tasks; do
        ft="$seed_dir/finetune-$(short "$t")-$method"
        say "few-shot $t from $method seed $seed, $task_steps env steps"
        ckpt=$(ls "$pre"/checkpoints/ckpt-*.bin | sort -V | tail -n 1)
        # agent.intrinsic.method: the checkpoint's module, not the config's.
        train "$ft" "$(config_of finetune "$t")" "$task_steps" --set "learner.init_checkpoint=$ckpt" \
          --set "agent.intrinsic.method=$method" --set "learner.replay_ratio=$fewshot_ratio" \
          ${task_routes[@]+"${task_routes[@]}"}
        evaluate "$seed_dir/fewshot-$(short "$t")-$method" few_shot "$ft/snapshot.params" \
          --set "agent.intrinsic.method=$method" --set "agent.task=$t"
      done
    fi
    ;;
  dreamer)
    total=$((pretrain_steps + task_steps))
    d="$seed_dir/dreamer-$(short "$task")"
    say "DreamerV3 from scratch on $task seed $seed, $total env steps"
    train "$d" "$(config_of dreamer "$task")" "$total" ${task_routes[@]+"${task_routes[@]}"}
    evaluate "$seed_dir/fewshot-$(short "$task")-dreamer" few_shot "$d/snapshot.params" \
      --set "agent.phase=dreamer" --set "agent.task=$task"
    ;;
  grid)
    # Every stage of every (seed, method) chain, DreamerV3 on each of --dreamer-tasks, then the
    # report: here, one after another (a failed stage stops the grid; run it again to go on), or
    # with --slurm each as its own Slurm job, a stage after the one it starts from
    # (--dependency=afterok) and the report after all (afterany). A stage whose DONE files
    # exist is not run or submitted, so a second call completes a partial grid.
    self="$root/deploy/experiments/paper_grid.sh"
    seeds=${seeds:-$seed}
    methods=${methods:-$method}
    for m in $methods; do
      case $m in disag|icm|rnd|random) ;; *)
        echo "--methods takes disag, icm, rnd and random, got '$m'" >&2; exit 2 ;;
      esac
    done
    for s in $seeds; do
      [[ $s =~ ^[0-9]+$ ]] || { echo "--seeds takes seed numbers, got '$s'" >&2; exit 2; }
    done
    for t in $dreamer_tasks; do
      case $t in lane_following|collision_avoidance) ;; *)
        echo "--dreamer-tasks takes lane_following and collision_avoidance, got '$t'" >&2; exit 2 ;;
      esac
    done
    if [[ $scheduler == slurm ]]; then
      command -v sbatch > /dev/null || { echo "--slurm: no sbatch here; submit from a node of the cluster (or leave --slurm out to run the grid here)" >&2; exit 1; }
      mkdir -p "$out/slurm"
    fi
    finished() { # evaluation or run directories, all with their DONE (evaluations on the CARLA towns: both protocols')
      local d
      for d in "$@"; do
        done_mark "$d" || return 1
        if [[ $towns == carla && $(basename "$d") == @(zeroshot|fewshot)-* ]]; then done_mark "$d-code" || return 1; fi
      done
    }
    job_ids=()
    job=""  # the id of the stage run() last submitted, empty when it ran here or was done
    run() { # name cpus after-job marker-dirs -- this script's arguments
      local name=$1 cpus=$2 after=$3
      shift 3
      local markers=()
      while [[ $1 != -- ]]; do markers+=("$1"); shift; done
      shift
      job=""
      if finished "${markers[@]}"; then say "$name: done already"; return; fi
      if [[ $scheduler == local ]]; then
        bash "$self" "$@" "${forward[@]}"
        return
      fi
      local dependency=()
      [[ -n $after ]] && dependency=(--dependency="afterok:$after" --kill-on-invalid-dep=yes)
      job=$(sbatch --parsable --job-name="indrive-$name" --output="$out/slurm/$name-%j.out" \
        --ntasks=1 --cpus-per-task="$cpus" ${dependency[@]+"${dependency[@]}"} \
        ${sbatch_args[@]+"${sbatch_args[@]}"} --wrap="$(printf '%q ' bash "$self" "$@" "${forward[@]}")")
      job=${job%%;*}
      job_ids+=("$job")
      say "$name: job $job${after:+ after $after}"
    }
    # Training runs one process (OMP_NUM_THREADS, 1 unless set); an evaluation runs two.
    for s in $seeds; do
      for m in $methods; do
        sd="$out/s$s"
        run "s$s-$m-pretrain" 1 "" "$sd/pretrain-$m" -- chain --seed "$s" --method "$m" --stages pretrain
        pretrain_job=$job
        if has_stage zeroshot; then
          run "s$s-$m-zeroshot" 2 "$pretrain_job" "$sd/zeroshot-$m" -- \
            chain --seed "$s" --method "$m" --stages zeroshot
        fi
        if has_stage fewshot && [[ $m != random ]]; then
          for t in $tasks; do
            run "s$s-$m-fewshot-$(short "$t")" 2 "$pretrain_job" "$sd/finetune-$(short "$t")-$m" \
              "$sd/fewshot-$(short "$t")-$m" -- chain --seed "$s" --method "$m" --stages fewshot --task "$t"
          done
        fi
      done
      for t in $dreamer_tasks; do
        run "s$s-dreamer-$(short "$t")" 2 "" "$out/s$s/fewshot-$(short "$t")-dreamer" -- \
          dreamer --seed "$s" --task "$t"
      done
    done
    if [[ $scheduler == local ]]; then
      bash "$self" report "${forward[@]}"
    elif [[ ${#job_ids[@]} -gt 0 ]]; then
      report=$(sbatch --parsable --job-name=indrive-grid-report --output="$out/slurm/report-%j.out" \
        --ntasks=1 --dependency="afterany:$(IFS=:; echo "${job_ids[*]}")" \
        ${sbatch_args[@]+"${sbatch_args[@]}"} --wrap="$(printf '%q ' bash "$self" report "${forward[@]}")")
      say "report: job ${report%%;*} after all ${#job_ids[@]}; logs in $out/slurm/, the report in $out/report/"
    else
      say "every stage is done; the report: $out/report/report.md (paper_grid.sh report to rewrite it)"
    fi
    ;;
  summary)
    # The pretraining measures of every pretrain-* run under --out, one markdown row each: the
    # exploration actor's entropy and the length and reach of the last 20 training episodes at
    # the end, the share of town01 visited, the return scale and the intrinsic reward.
    python3 - "$out" <<'PY'
import json, pathlib, sys
rows = []
for run in sorted(pathlib.Path(sys.argv[1]).glob("s*/pretrain-*")):
    lines = [json.loads(l) for l in open(run / "metrics.jsonl") if l.strip()]
    if not lines:
        continue
    last = lines[-1]
    tail = [l for l in lines if l["env_steps"] > 0.9 * last["env_steps"] and "expl/entropy" in l]
    mean = lambda key: sum(l[key] for l in tail) / len(tail) if tail else float("nan")
    rows.append((run.parent.name, run.name.removeprefix("pretrain-"), last["env_steps"],
                 mean("expl/entropy"), last.get("episode_length_last20", float("nan")),
                 last.get("episode_reach_last20", float("nan")),
                 100 * last.get("coverage_fraction_visited", float("nan")),
                 mean("expl/return_scale"), mean("intrinsic/raw_reward"), mean("expl/reward")))
print("| seed | method | env steps | entropy (last 10%) | steps per episode (last 20) |"
      " segments per episode (last 20) | % of town visited | return scale (last 10%) |"
      " raw intrinsic reward (last 10%) | reward reaching the actor-critic (last 10%) |")
print("|---|---|---|---|---|---|---|---|---|---|")
for r in rows:
    print("| %s | %s | %d | %.2f | %.0f | %.1f | %.1f | %.2f | %.3g | %.3g |" % r)
PY
    ;;
  publish)
    # Copies what must outlast the machine into a results page (--page DIR, committed): each
    # finished training run's metrics.jsonl, config.yaml (paths made relative to the
    # repository) and train-episodes.csv (where its build wrote one) under runs/s<seed>-<run>/, each finished evaluation's CSVs under
    # eval/s<seed>-<evaluation>-evaluator-<j>.csv, the acting part of the final snapshot of every
    # run of the seeds in --snapshot-seeds under snapshots/ (1.5 MB each on tiny), the pretraining
    # summary, and `indrive report` over eval/. Runs and evaluations not finished (no DONE) are
    # left out and named.
    [[ -n $page ]] || { echo "publish needs --page DIR (a folder under docs/results/)" >&2; exit 2; }
    mkdir -p "$page/runs" "$page/eval" "$page/snapshots"
    for run in "$out"/s*/{pretrain,finetune,dreamer}-*; do
      [[ -d $run ]] || continue
      s=$(basename "$(dirname "$run")")
      name="$s-$(basename "$run")"
      if ! done_mark "$run"; then say "not finished, left out: $run"; continue; fi
      mkdir -p "$page/runs/$name"
      cp "$run/metrics.jsonl" "$page/runs/$name/"
      [[ -f $run/train-episodes.csv ]] && cp "$run/train-episodes.csv" "$page/runs/$name/"
      # machine paths made relative: the root as a literal string, whatever characters it holds
      ROOT="$root/" perl -pe 's/\Q$ENV{ROOT}\E//g' "$run/config.yaml" > "$page/runs/$name/config.yaml"
      # (a random-action run's snapshot is an untrained model: the random policy is no file)
      if [[ " $snapshot_seeds " == *" ${s#s} "* && -f $run/snapshot.params && $run != *-random ]]; then
        "$bin/indrive" snapshot "$run/snapshot.params" --acting-only "$page/snapshots/$name.params" > /dev/null
      fi
    done
    for ev in "$out"/s*/{zeroshot,fewshot}-*; do
      [[ -d $ev ]] || continue
      s=$(basename "$(dirname "$ev")")
      if ! done_mark "$ev"; then say "not finished, left out: $ev"; continue; fi
      for csv in "$ev"/eval/evaluator-*.csv; do
        cp "$csv" "$page/eval/$s-$(basename "$ev")-$(basename "$csv")"
      done
    done
    rmdir "$page/snapshots" 2> /dev/null || true
    "$0" summary --out "$out" --bin "$bin" > "$page/pretrain-summary.md"
    "$bin/indrive" report "$page/eval" --out "$page" --route-set "$route_set" > /dev/null
    say "published $out into $page: $(find "$page/runs" -mindepth 1 -maxdepth 1 | wc -l) runs, $(find "$page/eval" -name '*.csv' | wc -l) evaluation files"
    ;;
  report)
    mapfile -t dirs < <(find "$out" -mindepth 2 -maxdepth 2 -type d \( -name 'zeroshot-*' -o -name 'fewshot-*' \) | sort)
    [[ ${#dirs[@]} -gt 0 ]] || { echo "no evaluations under $out yet" >&2; exit 1; }
    "$bin/indrive" report "${dirs[@]}" --out "$out/report" --route-set "$route_set"
    ;;
  *) echo "unknown command '$command': chain, dreamer, summary, publish or report (see --help)" >&2; exit 2 ;;
esac
