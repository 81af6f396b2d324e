#!/usr/bin/env bash
# Is the few-shot stage limited by its number of updates? Few-shot fine-tuning from the paper
# grid's pretrainings at another replay ratio (the grid's was 32, 2,500 updates in 10,000 task
# steps, until 2026-12-03), evaluated with the grid's protocol, then a table of the ratios side
# by side.
#
#   deploy/experiments/fewshot_ratio.sh run --ratio 128 --seed 2 [--method disag] [--task T]
#   deploy/experiments/fewshot_ratio.sh table        # every ratio under --out against the grid's
#
# `run` links the grid's pretraining (--grid, runs/paper-grid/s<seed>/pretrain-<method>, which
# must be finished) into --out/r<ratio>/s<seed>/ and runs paper_grid.sh's fewshot stage there with
# --fewshot-ratio set; both tasks unless --task is given. Resumable like the grid.
# `table` prints, per seed, task and ratio (each run's learner.replay_ratio, read from its
# config.yaml; the grid's own few-shot runs trained at 32 before 2026-12-03, at 512 since):
# updates, the training measures over the last 10% of task steps (episode return, steps per
# episode; town01's routes are the training routes), and the average SR over routes and mean
# route completion on town01 and town02.
# Options: --out DIR (runs/ablation-fewshot-ratio), --grid DIR (runs/paper-grid), --bin DIR.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="$root/build/bin"
out="$root/runs/ablation-fewshot-ratio"
grid="$root/runs/paper-grid"
ratio=""
seed=""
method=disag
task_args=()
usage() { sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; }
[[ $# -ge 1 ]] || { usage; exit 2; }
[[ $1 == -h || $1 == --help ]] && { usage; exit 0; }
command=$1
shift
while [[ $# -gt 0 ]]; do
  case "$1" in
    --ratio) ratio=$2; shift 2 ;;
    --seed) seed=$2; shift 2 ;;
    --method) method=$2; shift 2 ;;
    --task) task_args=(--task "$2"); shift 2 ;;
    --out) out=$2; shift 2 ;;
    --grid) grid=$2; shift 2 ;;
    --bin) bin=$2; shift 2 ;;
    -h|--help) usage; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done

case $command in
  run)
    [[ $ratio =~ ^[0-9]+$ && $ratio -gt 0 ]] || { echo "--ratio must be a positive whole number, got '$ratio'" >&2; exit 2; }
    [[ $seed =~ ^[0-9]+$ ]] || { echo "--seed must be given (a whole number), got '$seed'" >&2; exit 2; }
    pre="$grid/s$seed/pretrain-$method"
    [[ -f $pre/DONE ]] || { echo "$pre is not a finished pretraining: run paper_grid.sh chain --seed $seed --method $method --stages pretrain first" >&2; exit 1; }
    here="$out/r$ratio/s$seed"
    mkdir -p "$here"
    ln -sfn "$(cd "$pre" && pwd)" "$here/pretrain-$method"
    "$root/deploy/experiments/paper_grid.sh" chain --bin "$bin" --out "$out/r$ratio" --seed "$seed" \
      --method "$method" --stages fewshot ${task_args[@]+"${task_args[@]}"} \
      --fewshot-ratio "$ratio"
    ;;
  table)
    python3 - "$out" "$grid" <<'PY'
import csv, json, pathlib, re, sys
out, grid = map(pathlib.Path, sys.argv[1:3])

def runs():
    # the grid's seed dirs, then those of every ratio run here
    yield from (d for d in sorted(grid.glob("s*")) if d.is_dir())
    for r in sorted(out.glob("r*")):
        if re.fullmatch(r"r\d+", r.name):
            yield from sorted(r.glob("s*"))

def ratio_of(run):
    # the replay ratio the run trained at, from its resolved config (learner.replay_ratio)
    found = re.search(r"^\s*replay_ratio:\s*([0-9.]+)", (run / "config.yaml").read_text(), re.M)
    return int(float(found.group(1))) if found else -1

rows = []
for sdir in runs():
    for ft in sorted(sdir.glob("finetune-*-*")):
        ev = sdir / ft.name.replace("finetune-", "fewshot-", 1) / "eval"
        metrics = ft / "metrics.jsonl"
        if not (ft / "DONE").exists() or not ev.is_dir() or not metrics.exists():
            continue
        lines = [json.loads(l) for l in open(metrics) if l.strip()]
        last = lines[-1]
        tail = [l for l in lines if l["env_steps"] > 0.9 * last["env_steps"]]
        ret = [l["episode_return"] for l in tail if "episode_return" in l]
        per = {}
        for f in ev.glob("*.csv"):
            for e in csv.DictReader(open(f)):
                per.setdefault(e["town"], {}).setdefault(e["route"], []).append(e)
        def town(t):
            routes = per.get(t, {})
            if not routes:
                return float("nan"), float("nan")
            sr = sum(100 * sum(int(e["success"]) for e in eps) / len(eps) for eps in routes.values()) / len(routes)
            done = [float(e["route_completion"]) for eps in routes.values() for e in eps]
            return sr, sum(done) / len(done)
        _, task, method = ft.name.split("-", 2)
        rows.append((sdir.name[1:], task, method, ratio_of(ft), last["updates"],
                     sum(ret) / len(ret) if ret else float("nan"),
                     last.get("episode_length_last20", float("nan")), *town("town01"), *town("town02")))
print("| seed | task | method | ratio | updates | episode return (last 10%) | steps per episode (last 20) |"
      " town01 SR | town01 completion | town02 SR | town02 completion |")
print("|---|---|---|---|---|---|---|---|---|---|---|")
for r in sorted(rows, key=lambda r: (r[2], r[1], r[0], r[3])):
    print("| %s | %s | %s | %d | %d | %.1f | %.0f | %.1f | %.2f | %.1f | %.2f |" % r)
PY
    ;;
  *) echo "unknown command '$command': run or table (see --help)" >&2; exit 2 ;;
esac
