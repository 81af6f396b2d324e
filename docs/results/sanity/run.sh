#!/usr/bin/env bash
# The protocol's sanity bounds: the oracle (route follower, coasting behind a leader), the
# oracle without that, and uniformly random actions, each through the evaluator on every route
# of both built-in towns at densities 5, 10 and 20 (3 episodes per cell), then `indrive report`.
# Usage: bash docs/results/sanity/run.sh [build/bin] [runs/sanity]   (from the repository root)
set -euo pipefail
bin=${1:-build/bin}
runs=${2:-runs/sanity}
episodes=${EPISODES:-3}
common=(--evaluate --set eval.towns=town01,town02
        --set eval.routes=straight,right_loop,left_loop,two_turn
        --set "eval.densities=[5, 10, 20]" --set eval.episodes_per_cell="$episodes")
rm -rf "$runs/oracle" "$runs/oracle_nobrake" "$runs/random"
"$bin/indrive-actor" "${common[@]}" --policy oracle --run-dir "$runs/oracle" \
    --set eval.video_episodes=1 --log-level warn
"$bin/indrive-actor" "${common[@]}" --policy oracle --run-dir "$runs/oracle_nobrake" \
    --set eval.oracle_brake=false --log-level warn
"$bin/indrive-actor" "${common[@]}" --policy random --run-dir "$runs/random" --log-level warn
"$bin/indrive" report "$runs/oracle" "$runs/oracle_nobrake" "$runs/random" \
    --out docs/results/sanity
