#!/usr/bin/env bash
# The service and the paper grid under a real Slurm: a two-node cluster in network namespaces
# (cluster.sh), through which this test
#   1. submits deploy/slurm/service.sbatch with a small budget on both nodes (learner on nodea,
#      an actor on each, the evaluator on nodeb) and checks that the job ends at its budget with
#      a final snapshot, an evaluation of it and a report, and leaves no process;
#   2. stops one run twice: the signal Slurm sends before the time limit (the script requeues
#      the job, which resumes), then scancel (checkpoint, no process left on either node) and a
#      resubmission, which resumes again and ends at the run's budget;
#   3. submits a two-cell grid (disag, seeds 0 and 1, pretrain and zero-shot, `tiny`, small
#      budgets) with paper_grid.sh grid --slurm, checks the report, and checks that a second
#      submission submits nothing;
#   4. submits the service with DDS Security (--dds-security) and checks that it authenticates
#      across the nodes and ends with its report.
# Prints each step's seconds and the processes each node ran. Needs root, iproute2, slurm-wlm
# and munge; exits 77 (skipped) without them.
#
#   tests/deploy/slurm/slurm_test.sh SOURCE_DIR BIN_DIR
set -euo pipefail

source_dir=$(cd "${1:?usage: slurm_test.sh SOURCE_DIR BIN_DIR}" && pwd)
bin=$(cd "${2:?usage: slurm_test.sh SOURCE_DIR BIN_DIR}" && pwd)
work=$(mktemp -d /tmp/indrive-slurm-test.XXXXXX)
cluster="$work/cluster"
cluster_sh="$source_dir/tests/deploy/slurm/cluster.sh"
export CLUSTER_DIR=$cluster INDRIVE_ROOT=$source_dir INDRIVE_BIN=$bin
failures=0

cleanup() {
  bash "$cluster_sh" down "$cluster" || true
  if [[ $failures == 0 ]]; then rm -rf "$work"; else echo "kept for inspection: $work"; fi
}
trap cleanup EXIT

say() { echo "[slurm test $(date +%H:%M:%S)] $*"; }
fail() { echo "FAILED: $*"; failures=$((failures + 1)); }
check() { # description command...
  local what=$1
  shift
  if "$@"; then echo "ok: $what"; else fail "$what"; fi
}
on_a() { bash "$cluster_sh" on nodea "$@"; }

status=0
bash "$cluster_sh" up "$cluster" || status=$?
[[ $status == 0 ]] || exit "$status"  # 77: skipped, with the reason above

# The processes of a job, one line per node: "nodea: discovery-server indrive-learner ...".
processes_of() { # job id
  local dir environ node args name
  for dir in /proc/[0-9]*; do
    environ=$(tr '\0' '\n' 2> /dev/null < "$dir/environ") || continue
    grep -qx "SLURM_JOB_ID=$1" <<< "$environ" || continue
    node=$(sed -n 's/^SLURMD_NODENAME=//p' <<< "$environ")
    args=$(tr '\0' ' ' 2> /dev/null < "$dir/cmdline") || continue
    name=$(basename "${args%% *}")
    case $name in
      indrive-actor) [[ $args == *--evaluate* ]] && name=indrive-actor--evaluate ;;
      indrive) name="indrive-${args#* }" && name=${name%% *} ;;
      fast-discovery-server | indrive-learner) ;;
      *) continue ;;
    esac
    echo "$node $name"
  done | sort | uniq -c | awk '{ line[$2] = line[$2] " " $3 ($1 > 1 ? " x" $1 : "") }
    END { for (n in line) print n ":" line[n] }' | sort
}
job_state() { on_a scontrol show job "$1" 2> /dev/null | sed -n 's/.*JobState=\([A-Z_]*\).*/\1/p'; }
job_exit() { on_a scontrol show job "$1" 2> /dev/null | sed -n 's/.* ExitCode=\([0-9:]*\).*/\1/p'; }
# Waits until the job has ended (at most $2 seconds), printing the per-node processes it saw
# with the most processes at once.
wait_job() { # id timeout_s
  local id=$1 timeout=$2 start=$SECONDS seen="" now
  while [[ -n $(on_a squeue -h -j "$id" -o %i 2> /dev/null) ]]; do
    now=$(processes_of "$id")
    [[ $(wc -w <<< "$now") -gt $(wc -w <<< "$seen") ]] && seen=$now
    if ((SECONDS - start > timeout)); then
      fail "job $id still running after $timeout s"
      on_a scancel "$id"
      return 1
    fi
    sleep 2
  done
  [[ -n $seen ]] && { echo "processes of job $id, per node:"; sed 's/^/  /' <<< "$seen"; }
  say "job $id ended after $((SECONDS - start)) s: $(job_state "$id"), exit $(job_exit "$id")"
}
no_process_left() { [[ -z $(processes_of "$1") ]]; }
metrics_steps() { tail -n 1 "$1/metrics.jsonl" | sed -n 's/.*"env_steps":\([0-9]*\).*/\1/p'; }

config="$source_dir/deploy/configs/smoke.yaml"
service=("$source_dir/deploy/slurm/service.sbatch" --config "$config"
  --set agent.replay.prefill=200 --set learner.checkpoint_minutes=60)
cd "$work"

# 1. The service to its budget.
say "1. the service on both nodes, budget 600 env steps"
run1="$work/runs/service"
id=$(on_a sbatch --parsable --nodes=2 --output="$work/service-%j.out" "${service[@]}" \
  --run-dir "$run1" --set run.budget_env_steps=600)
wait_job "$id" 300 || true
cat "$work/service-$id.out"
check "the job completed with exit 0" test "$(job_state "$id")" = COMPLETED -a "$(job_exit "$id")" = 0:0
check "the learner reached its budget" grep -q "budget reached" "$run1/logs/learner.log"
steps=$(metrics_steps "$run1")
check "600 <= env steps ($steps) <= 600 + 2 chunks of 2 actors" test "${steps:-0}" -ge 600 -a "${steps:-0}" -le 728
check "a final snapshot" test -s "$run1/final-snapshot.params"
check "one actor log per node" test -s "$run1/logs/actor-0.log" -a -s "$run1/logs/actor-1.log"
check "the evaluator's episodes" test "$(wc -l < "$run1/eval/evaluator-0.csv")" -ge 5
check "the report" grep -q "^## Zero-shot" "$run1/report.md"
check "no process of job $id left" no_process_left "$id"

# 2. One run stopped twice: requeued near its time limit, then cancelled and resubmitted.
say "2. a service requeued at its time limit's signal, then cancelled, then resubmitted"
run2="$work/runs/stopped"
submit2() {
  on_a sbatch --parsable --nodes=2 --output="$work/service-%j.out" "${service[@]}" \
    --run-dir "$run2" --set run.budget_env_steps=1500
}
wait_updates() { # until the learner has trained past $1 updates (at most 240 s)
  local start=$SECONDS
  until [[ $(tail -n 1 "$run2/metrics.jsonl" 2> /dev/null | sed -n 's/.*"updates":\([0-9]*\).*/\1/p') -gt $1 ]]; do
    ((SECONDS - start < 240)) || { fail "no update past $1 in 240 s"; return 1; }
    sleep 2
  done
}
updates_now() { tail -n 1 "$run2/metrics.jsonl" | sed -n 's/.*"updates":\([0-9]*\).*/\1/p'; }
id=$(submit2)
wait_updates 0 || true
# What Slurm sends the script 300 s before the time limit (--signal=B:USR1@300).
on_a scancel --batch --signal=USR1 "$id"
start=$SECONDS
until [[ $(on_a scontrol show job "$id" | grep -o 'Restarts=[0-9]*') == Restarts=1 ]]; do
  ((SECONDS - start < 120)) || { fail "job $id not requeued 120 s after USR1"; break; }
  sleep 2
done
say "job $id requeued after $((SECONDS - start)) s ($(job_state "$id"))"
check "the requeue stopped every process first" no_process_left "$id"
on_a scontrol update JobId="$id" StartTime=now  # Slurm holds a requeued job 2 minutes
check "the learner checkpointed before the requeue" grep -q "checkpoint ckpt-" "$run2/logs/learner.log"
start=$SECONDS
until [[ $(grep -c "resumed from .*ckpt-" "$run2/logs/learner.log") -ge 1 ]]; do
  ((SECONDS - start < 180)) || { fail "the requeued job did not resume in 180 s"; break; }
  sleep 2
done
check "the requeued job resumed from the checkpoint" grep -q "resumed from .*ckpt-" "$run2/logs/learner.log"
wait_updates "$(updates_now)" || true
echo "processes of job $id before scancel, per node:"
processes_of "$id" | sed 's/^/  /'
on_a scancel "$id"
wait_job "$id" 120 || true
check "no process of job $id left on either node after scancel" no_process_left "$id"
check "a checkpoint at each stop" test "$(grep -c "checkpoint ckpt-" "$run2/logs/learner.log")" -ge 2
before=$(metrics_steps "$run2")
id=$(submit2)
wait_job "$id" 300 || true
cat "$work/service-$id.out"
check "the resubmitted job resumed too" test "$(grep -c "resumed from .*ckpt-" "$run2/logs/learner.log")" = 2
steps=$(metrics_steps "$run2")
check "it resumed at $before env steps and ended at its budget: 1500 <= $steps <= 1628" \
  test "${steps:-0}" -ge 1500 -a "${steps:-0}" -le 1628
check "the job completed with exit 0" test "$(job_state "$id")" = COMPLETED -a "$(job_exit "$id")" = 0:0
check "the stopped-and-resumed run's report" grep -q "^## Zero-shot" "$run2/report.md"
check "no process of job $id left" no_process_left "$id"

# 3. A two-cell grid as Slurm jobs.
say "3. paper_grid.sh grid --slurm: disag, seeds 0 and 1, pretrain and zero-shot"
grid=(bash "$source_dir/deploy/experiments/paper_grid.sh" grid --slurm --bin "$bin"
  --out "$work/grid" --seeds "0 1" --methods disag --stages "pretrain zeroshot"
  --pretrain-steps 300 --episodes 1 --set agent.replay.prefill=100 --set env.densities=[5])
on_a "${grid[@]}" | tee "$work/grid-submit.log"
report_job=$(sed -n 's/.*report: job \([0-9]*\).*/\1/p' "$work/grid-submit.log")
check "five jobs submitted (2 pretrain, 2 zero-shot, the report)" \
  test "$(grep -c ': job [0-9]' "$work/grid-submit.log")" = 5
if [[ -n $report_job ]]; then
  start=$SECONDS
  while [[ -n $(on_a squeue -h -o %i 2> /dev/null) ]]; do
    ((SECONDS - start < 600)) || { fail "the grid's jobs still run after 600 s"; break; }
    sleep 3
  done
  say "the grid's jobs ended after $((SECONDS - start)) s"
  cat "$work/grid/slurm/report-$report_job.out" | tail -n 5
fi
for s in 0 1; do
  check "seed $s: pretraining and zero-shot done" test -f "$work/grid/s$s/pretrain-disag/DONE" \
    -a -f "$work/grid/s$s/zeroshot-disag/DONE"
done
seeds=$(awk -F, 'NR > 1 && $4 == "disag" { print $7 }' "$work/grid/report/report.csv" | sort -u | paste -sd,)
check "the grid's report: disag's cells over 2 seeds (seeds: $seeds)" test "$seeds" = 2
check "the report's tables" grep -q "^| disag" "$work/grid/report/report.md"
on_a "${grid[@]}" > "$work/grid-again.log"
check "a second submission submits nothing" grep -q "every stage is done" "$work/grid-again.log"

# 4. The service with DDS Security across the nodes (multicast discovery: no discovery server).
say "4. the service with DDS Security on both nodes, budget 400 env steps"
run4="$work/runs/secure"
bash "$source_dir/deploy/dds/make_security.sh" "$work/security" > /dev/null
id=$(on_a sbatch --parsable --nodes=2 --output="$work/service-%j.out" "${service[@]}" \
  --run-dir "$run4" --set run.budget_env_steps=400 --dds-security "$work/security")
wait_job "$id" 300 || true
grep "service" "$work/service-$id.out"
check "the secure job completed with exit 0" test "$(job_state "$id")" = COMPLETED -a "$(job_exit "$id")" = 0:0
check "the learner authenticated the other participants" grep -q "DDS Security authenticated" "$run4/logs/learner.log"
check "the secure run's report" grep -q "^## Zero-shot" "$run4/report.md"
check "no process of job $id left" no_process_left "$id"

say "$failures failure(s)"
[[ $failures == 0 ]]
