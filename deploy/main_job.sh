#!/usr/bin/env bash
# The main job on the embedded default configuration (see README). Called by
# `bash deploy/setup.sh run` with the build directory as its argument.
#
# Today it shows the driving environment end to end: both built-in towns drawn with their
# routes, the scripted waypoint follower driving a route of each town, and a random policy for
# contrast, with MP4 videos (semantic camera + bird's-eye view). It grows into the full
# learner + actors + evaluator launch as the service lands; this command stays the same.
set -euo pipefail
build_dir=${1:?usage: main_job.sh BUILD_DIR}
root=$(cd "$(dirname "${BASH_SOURCE[0]}")/.." && pwd)
bin="$build_dir/bin"
out="$root/runs/main-demo"
mkdir -p "$out/plots" "$out/videos"

say() { printf '\033[1m[main]\033[0m %s\n' "$*"; }

for town in town01 town02; do
  say "drawing $town with its routes -> $out/plots/$town.png"
  "$bin/indrive-env" routes --town "$town" --out "$out/plots/$town.png"
done

say "follower on town01/straight, 10 vehicles"
"$bin/indrive-env" episode --town town01 --route straight --density 10 --policy follower \
  --seed 1 --video "$out/videos/town01_straight_follower.mp4" --quiet
say "follower on town02/two_turn, 10 vehicles"
"$bin/indrive-env" episode --town town02 --route two_turn --density 10 --policy follower \
  --seed 2 --video "$out/videos/town02_two_turn_follower.mp4" --quiet
say "random policy on town01/straight, 10 vehicles"
"$bin/indrive-env" episode --town town01 --route straight --density 10 --policy random \
  --seed 3 --video "$out/videos/town01_straight_random.mp4" --quiet

say "done. Outputs in $out:"
find "$out" -type f | sort | sed 's/^/  /'
