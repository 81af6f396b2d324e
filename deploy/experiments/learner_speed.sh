#!/usr/bin/env bash
# How fast does the learner train on this machine? One command for every figure of the learner's
# speed targets (docs/performance.md): the full agent update on `tiny` (1 and 2 threads)
# and `cpu` (2 threads) in fp32 and, where the CPU multiplies bf16 natively, in bf16 and under
# `precision: auto` (what it chose, and its ratio to the faster forced precision); the PyTorch
# reference of the same update (with --torch); and the service at replay ratio 32 (learner and
# 1 or 2 actors as real processes) with the hours the paper's 5e5 env steps take. It writes
# report.md (each figure against its target, and the bound the machine's measured product peak
# sets), figures.csv and every program's output into the folder.
#
#   deploy/experiments/learner_speed.sh [--out DIR] [--bin DIR] [--repeats N] [--torch FILE]
#                                       [--no-service] [--no-small] [--report-only]
#
# Defaults: runs/learner-speed, build/bin, 3 runs of each agent update (medians reported), no
# PyTorch reference, the `small` preset (the paper's model: update, bound, memory and hours; one
# run per precision). Run it on an idle machine: it takes about 15 minutes on 2 cores (a few
# more with --torch; 5 fewer with --no-small). --report-only writes the report again from the
# logs of an earlier run in DIR.
set -euo pipefail

root=$(cd "$(dirname "${BASH_SOURCE[0]}")/../.." && pwd)
bin="$root/build/bin"
out="$root/runs/learner-speed"
repeats=3
torch=""
service=1
small=1
report_only=0
while [[ $# -gt 0 ]]; do
  case "$1" in
    --out) out=$2; shift 2 ;;
    --bin) bin=$2; shift 2 ;;
    --repeats) repeats=$2; shift 2 ;;
    --torch) torch=$2; shift 2 ;;
    --no-service) service=0; shift ;;
    --no-small) small=0; shift ;;
    --report-only) report_only=1; shift ;;
    -h|--help) sed -n '2,18p' "$0" | sed 's/^# \{0,1\}//'; exit 0 ;;
    *) echo "unknown option $1 (see --help)" >&2; exit 2 ;;
  esac
done
for program in common_agent_bench learner_service_bench; do
  ((report_only)) || [[ -x $bin/$program ]] || {
    echo "no $bin/$program: build with the benchmarks first (bash deploy/setup.sh build)" >&2
    exit 1
  }
done
[[ $repeats =~ ^[1-9][0-9]*$ ]] || { echo "--repeats wants a positive count, got '$repeats'" >&2; exit 2; }
[[ -z $torch || -f $torch ]] || { echo "--torch: no file $torch (torch_agent_step.py)" >&2; exit 2; }
mkdir -p "$out/logs"
logs="$out/logs"
[[ $report_only == 0 || -f $logs/probe.txt ]] || { echo "--report-only: no earlier run in $out" >&2; exit 2; }

# Targets of the learner's speed (docs/performance.md states them).
target_cpu_s=0.8 target_tiny_s=0.04 target_torch_x=15 target_steps=90 target_tiny_h=1.5 target_cpu_h=4

if ((!report_only)); then
  load=$(cut -d' ' -f1 /proc/loadavg)
  echo "learner speed on $(nproc) hardware threads, load average $load; output in $out"
  if awk -v l="$load" 'BEGIN { exit !(l > 0.5) }'; then
    echo "warning: the load average is $load (the last minute's); other work slows every figure" >&2
  fi
  {
    echo "cpu: $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')"
    echo "threads: $(nproc)"
    echo "load: $load"
    echo "features: $(grep -m1 '^flags' /proc/cpuinfo | tr ' ' '\n' |
      grep -E '^(avx2|avx512f|avx512_bf16|amx_bf16|amx_tile)$' | tr '\n' ' ')"
    echo "started: $(date -u '+%Y-%m-%d %H:%M UTC')"
  } > "$logs/machine.txt"
fi
machine() { sed -n "s/^$1: //p" "$logs/machine.txt"; }

# median of the numbers on stdin ("" when none)
median() { sort -g | awk '{ v[NR] = $1 } END { if (NR) print (NR % 2 ? v[(NR + 1) / 2] + 0 : (v[NR / 2] + v[NR / 2 + 1]) / 2) }'; }
# value of KEY=... on the first line of FILE that starts with PREFIX
field() { grep -m1 "^$2" "$1" | tr ' ' '\n' | sed -n "s/^$3=\([0-9.]*\).*/\1/p" | head -1; }

# The update runs: preset, threads, precision, repeats; logs/<preset>-<precision>-t<threads>-<i>.txt
# (a fifth argument: the number of runs instead of --repeats). Each log ends with the run's
# peak resident memory (max_rss_kb=, GNU time).
bench() {
  local preset=$1 threads=$2 precision=$3 iters=$4 runs=${5:-$repeats} i
  for ((i = 1; i <= runs; ++i)); do
    local log="$logs/$preset-$precision-t$threads-$i.txt"
    echo "  common_agent_bench --preset $preset --threads $threads --precision $precision ($i of $runs)"
    /usr/bin/time -a -o "$log.rss" -f 'max_rss_kb=%M' "$bin/common_agent_bench" --preset "$preset" \
      --threads "$threads" --iters "$iters" --precision "$precision" > "$log" 2>&1 ||
      { echo "failed, see $log" >&2; exit 1; }
    cat "$log.rss" >> "$log" && rm -f "$log.rss"
  done
}
first_log=$logs/probe.txt
((report_only)) || "$bin/common_agent_bench" --preset tiny --threads 1 --iters 1 > "$first_log" 2>&1
kernels=$(grep -m1 '^kernels:' "$first_log" || true)
precisions="fp32"
# auto: what precision auto chooses by measuring the model's products at the agent's start.
grep -q 'no native bf16' "$first_log" || precisions="fp32 bf16 auto"
best=$(echo "$precisions" | awk '{ print $NF }')
echo "$kernels"

if ((!report_only)); then
  echo "agent updates ($repeats runs each):"
  for precision in $precisions; do
    bench tiny 2 "$precision" 60
    bench tiny 1 "$precision" 60
    bench cpu 2 "$precision" 4
  done
  # The paper's model (DreamerV3 v1 "small", 128x128 camera): about 12 s an update on 2 cores
  # and 13 GB, so one run of 2 updates each (--no-small leaves it out).
  if ((small)); then
    for precision in $precisions; do bench small 2 "$precision" 2 1; done
  fi

  if [[ -n $torch ]]; then
    echo "PyTorch reference (the same update), tiny and cpu, 2 threads:"
    "$bin/common_agent_bench" --preset tiny --threads 2 --iters 20 --precision "$best" --torch "$torch" \
      > "$logs/torch-tiny.txt" 2>&1 || echo "  the tiny reference failed, see $logs/torch-tiny.txt" >&2
    "$bin/common_agent_bench" --preset cpu --threads 2 --iters 3 --precision "$best" --torch "$torch" \
      > "$logs/torch-cpu.txt" 2>&1 || echo "  the cpu reference failed, see $logs/torch-cpu.txt" >&2
  fi

  if ((service)); then
    echo "service at replay ratio 32 (tiny: 1 and 2 actors, 30 s windows; cpu: 1 actor, 90 s):"
    "$bin/learner_service_bench" --presets tiny cpu --modes limited --cpu-modes limited \
      --actors 1 2 --window-s 30 --cpu-window-s 90 > "$logs/service.txt" 2>&1 ||
      echo "  the service bench failed, see $logs/service.txt" >&2
  fi
  # The logs name this checkout's files relative to it, so that a report can be committed.
  sed -i "s#$root/##g" "$logs"/*.txt
fi

# ---- report ----
csv="$out/figures.csv"
echo "figure,run,value,unit,target,verdict" > "$csv"
report="$out/report.md"
# verdict of VALUE against TARGET, DIRECTION le (at most) or ge (at least)
verdict() {
  awk -v v="$1" -v t="$2" -v d="$3" 'BEGIN {
    if (v == "") print "not measured"; else if (t == "") print "no target"
    else if ((d == "le" && v + 0 <= t + 0) || (d == "ge" && v + 0 >= t + 0)) print "met"
    else print "not met" }'
}
row() {  # figure run value unit target direction
  local v bound=""
  v=$(verdict "$3" "$5" "$6")
  echo "$1,\"$2\",$3,$4,$5,$v" >> "$csv"
  [[ -n $5 ]] && bound="$([[ $6 == le ]] && echo '<=' || echo '>=') $5 $4"
  printf '| %s | %s | %s %s | %s | %s |\n' "$1" "$2" "${3:--}" "$4" "$bound" "$v" >> "$report"
}
{
  echo "# Learner speed on $(machine cpu) ($(machine features | sed 's/ *$//'))"
  echo
  echo "$(machine started), $(machine threads) hardware threads, load average $(machine load) at the start"
  echo "(\`deploy/experiments/learner_speed.sh\`). ${kernels^}."
  echo
  echo "Medians of $(find "$logs" -name 'tiny-fp32-t2-*.txt' | wc -l) runs (\`common_agent_bench\`, logs in \`logs/\`). The bound is the update's"
  echo "product FLOPs over the product peak measured in the same run: no update of this size can"
  echo "take less on this machine, whatever the engine does around its products."
  echo
  echo "| figure | run | measured | target | verdict |"
  echo "|---|---|---|---|---|"
} > "$report"
for precision in $precisions; do
  for spec in "tiny 2" "tiny 1" "cpu 2"; do
    read -r preset threads <<< "$spec"
    s=$(for f in "$logs/$preset-$precision-t$threads"-*.txt; do field "$f" "agent_update " sec; done | median)
    target=$target_cpu_s
    [[ $preset == tiny ]] && target=$target_tiny_s
    [[ $threads == 1 ]] && target=""  # the targets are for 2 threads
    label=$precision
    if [[ $precision == auto ]]; then
      label="auto ($(for f in "$logs/$preset-auto-t$threads"-*.txt; do
        sed -n 's/^precision_choice chosen=\([a-z0-9]*\).*/\1/p' "$f"; done | sort | uniq -c |
        awk '{ printf "%s%s %sx", (NR > 1 ? ", " : "chose "), $2, $1 }'))"
    fi
    row "full agent update" "$preset, $label, $threads thread$( ((threads > 1)) && echo s)" \
      "$s" s "$target" le
  done
done
# auto against the faster of the two forced precisions, in the same run: at most 5% slower.
if [[ $precisions == *auto* ]]; then
  for spec in "tiny 2" "tiny 1" "cpu 2"; do
    read -r preset threads <<< "$spec"
    m() { for f in "$logs/$preset-$1-t$threads"-*.txt; do field "$f" "agent_update " sec; done | median; }
    ratio=$(awk -v a="$(m auto)" -v f="$(m fp32)" -v b="$(m bf16)" 'BEGIN {
      best = (f < b ? f : b); if (a > 0 && best > 0) printf "%.3f", a / best }')
    row "auto over the faster forced precision" "$preset, $threads thread$( ((threads > 1)) && echo s)" \
      "$ratio" x 1.05 le
  done
fi
{
  echo
  echo "| bound at the measured peak | GFLOP of products | product peak, GFLOP/s | bound, s |"
  echo "|---|---|---|---|"
} >> "$report"
for precision in ${precisions/ auto/}; do
  for preset in tiny cpu; do
    f="$logs/$preset-$precision-t2-1.txt"
    [[ -f $f ]] || continue
    gflop=$(field "$f" agent_update_total gflop)
    peak=$(field "$f" product_peak "${precision}_gflops")
    bound=$(awk -v g="$gflop" -v p="$peak" 'BEGIN { if (p > 0) printf "%.3f", g / p }')
    echo "| $preset $precision, 2 threads | $gflop | $peak | $bound |" >> "$report"
  done
done
if compgen -G "$logs/small-*-t2-1.txt" > /dev/null; then
  {
    echo
    echo "The paper's model, \`small\` (128x128 camera, deter 512; one run of 2 updates per precision,"
    echo "2 threads). Hours are the learner's alone at replay ratio 32 (updates x update time; the"
    echo "actors' time comes on top where they cannot keep up); no target yet."
    echo
    echo "| precision | update, s | GFLOP of products | bound at the peak, s | peak memory, GB | hours for 1e5 env steps | hours for 5e5 env steps |"
    echo "|---|---|---|---|---|---|---|"
  } >> "$report"
  for precision in $precisions; do
    f="$logs/small-$precision-t2-1.txt"
    [[ -f $f ]] || continue
    sec=$(field "$f" "agent_update " sec)
    gflop=$(field "$f" agent_update_total gflop)
    p=$precision
    [[ $p == auto ]] && p=$(sed -n 's/^precision_choice chosen=\([a-z0-9]*\).*/\1/p' "$f")
    peak=$(field "$f" product_peak "${p}_gflops")
    frames=$(grep -m1 '^preset=' "$f" | awk '{ for (i = 1; i <= NF; ++i) { split($i, kv, "=");
      if (kv[1] == "B") b = kv[2]; if (kv[1] == "T") t = kv[2] } } END { print b * t }')
    rss=$(sed -n 's/^max_rss_kb=\([0-9]*\)/\1/p' "$f" | tail -1)
    awk -v pr="$precision" -v p="$p" -v s="$sec" -v g="$gflop" -v pk="$peak" -v fr="$frames" \
      -v rss="$rss" 'BEGIN {
        label = (pr == "auto" ? "auto (chose " p ")" : pr)
        bound = (pk > 0 ? sprintf("%.2f", g / pk) : "-")
        mem = (rss > 0 ? sprintf("%.1f", rss / 1048576) : "-")
        h1 = (fr > 0 && s > 0 ? sprintf("%.1f", 1e5 * 32 / fr * s / 3600) : "-")
        h5 = (fr > 0 && s > 0 ? sprintf("%.1f", 5e5 * 32 / fr * s / 3600) : "-")
        printf "| %s | %s | %s | %s | %s | %s | %s |\n", label, s, g, bound, mem, h1, h5 }' >> "$report"
    echo "small,\"$precision, 2 threads\",$sec,s,,no target" >> "$csv"
  done
fi
if [[ -f $logs/torch-tiny.txt || -f $logs/torch-cpu.txt ]]; then
  {
    echo
    echo "PyTorch reference in the same runs (\`--torch\`, 2 threads):"
    echo
    echo "| figure | run | measured | target | verdict |"
    echo "|---|---|---|---|---|"
  } >> "$report"
  for preset in tiny cpu; do
    f="$logs/torch-$preset.txt"
    x=$(grep -m1 '^torch_ratio' "$f" 2>/dev/null | sed -n 's/.*speedup=\([0-9.]*\)x.*/\1/p' || true)
    target=""
    [[ $preset == cpu ]] && target=$target_torch_x  # the target is for the cpu update
    row "times faster than PyTorch" "$preset, $best, 2 threads" "$x" x "$target" ge
    grep -m1 '^torch_warning' "$f" 2>/dev/null | sed 's/^torch_warning: /\n> /' >> "$report" || true
  done
fi
if [[ -f $logs/service.txt ]]; then
  {
    echo
    echo "Service at replay ratio 32 (\`learner_service_bench\`, learner and actors as processes):"
    echo
    echo "| figure | run | measured | target | verdict |"
    echo "|---|---|---|---|---|"
  } >> "$report"
  for spec in "tiny 1" "tiny 2" "cpu 1"; do
    read -r preset actors <<< "$spec"
    noun=actor
    ((actors > 1)) && noun=actors
    rate=$(grep -m1 "^$preset rate-limited, $actors $noun " "$logs/service.txt" 2>/dev/null |
      sed "s/^$preset rate-limited, $actors $noun *//" | awk '{ print $2 }' || true)
    hours=$(awk -v r="$rate" 'BEGIN { if (r > 0) printf "%.2f", 5e5 / r / 3600 }')
    if [[ $preset == tiny ]]; then
      row "env steps/s at ratio 32" "$preset, $actors $noun" "$rate" "steps/s" "$target_steps" ge
      row "hours for 5e5 env steps" "$preset, $actors $noun" "$hours" h "$target_tiny_h" le
    else
      row "env steps/s at ratio 32" "$preset, $actors $noun" "$rate" "steps/s" "" ge
      row "hours for 5e5 env steps" "$preset, $actors $noun" "$hours" h "$target_cpu_h" le
    fi
  done
fi
echo
cat "$report"
