#!/usr/bin/env bash
# Does bf16 change what is learned? The same fixed-seed reward-free pretraining (disag, tiny,
# town01) once with agent.precision=fp32 and once with bf16, then the world model's
# reconstruction and KL and the exploration measures side by side: a table of the two runs over
# windows of env steps (means, and bf16's relative difference) and one PNG per metric.
#
#   deploy/experiments/precision_compare.sh [--out DIR] [--steps N] [--seed S] [--bin DIR]
#
# Defaults: runs/precision, 20,000 env steps, seed 0, build/bin. The two runs go side by side
# with one OpenMP thread each; a run already finished (DONE in its folder) is not run again.
# bf16 needs a CPU with native bf16 (AMX or avx512_bf16): elsewhere the bf16 run fails and says so.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="$root/build/bin"
out="$root/runs/precision"
steps=20000
seed=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --steps) steps=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --bin) bin=$2; shift 2 ;;
    -h|--help) sed -n '2,12p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
[[ -x $bin/indrive-train-local ]] || { echo "no $bin/indrive-train-local: build first (bash deploy/setup.sh build)" >&2; exit 1; }
export OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} OMP_WAIT_POLICY=${OMP_WAIT_POLICY:-passive} \
  GOMP_SPINCOUNT=${GOMP_SPINCOUNT:-100000}  # a short spin before sleeping, as indrive launch sets
mkdir -p "$out"

pids=()
for precision in fp32 bf16; do
  dir="$out/$precision"
  [[ -f $dir/DONE ]] && continue
  mkdir -p "$dir"
  ( "$bin/indrive-train-local" --config "$root/deploy/configs/pretrain_disag.yaml" --run-dir "$dir" \
      --set preset=tiny --set "run.seed=$seed" --set "run.budget_env_steps=$steps" \
      --set "agent.precision=$precision" --set learner.dashboard_s=0 --log-level warn \
      > "$dir/train.log" 2>&1 && touch "$dir/DONE" ) &
  pids+=($!)
done
for pid in ${pids[@]+"${pids[@]}"}; do wait "$pid" || { echo "a run failed: see $out/*/train.log" >&2; exit 1; }; done

for metric in wm/recon wm/kl expl/entropy episode_length_last20 coverage_fraction_visited; do
  name=${metric//\//_}
  "$bin/indrive" compare "$out/fp32" "$out/bf16" --metric "$metric" --out "$out/$name.png" > /dev/null
done
python3 - "$out" "$steps" <<'PY'
import json, sys
out, steps = sys.argv[1], int(sys.argv[2])
def lines(p):
    return [json.loads(l) for l in open(f"{out}/{p}/metrics.jsonl") if l.strip()]
runs = {p: lines(p) for p in ("fp32", "bf16")}
keys = ["wm/recon", "wm/kl", "expl/entropy", "episode_length_last20", "coverage_fraction_visited"]
windows = 5
print(f"| env steps | " + " | ".join(f"{k} fp32 / bf16 (diff)" for k in keys) + " |")
print("|---" * (len(keys) + 1) + "|")
for w in range(windows):
    lo, hi = steps * w / windows, steps * (w + 1) / windows
    cells = []
    for k in keys:
        means = []
        for p in ("fp32", "bf16"):
            v = [l[k] for l in runs[p] if lo < l["env_steps"] <= hi and k in l]
            means.append(sum(v) / len(v) if v else float("nan"))
        a, b = means
        diff = (b - a) / abs(a) * 100 if a == a and a != 0 else float("nan")
        cells.append(f"{a:.3g} / {b:.3g} ({diff:+.0f}%)")
    print(f"| {int(lo)}-{int(hi)} | " + " | ".join(cells) + " |")
for p in ("fp32", "bf16"):
    last = runs[p][-1]
    print(f"{p}: {last['env_steps']} env steps, {last['updates']} updates, "
          f"{last.get('time/update_s', float('nan')):.3g} s per update (last line)")
PY
