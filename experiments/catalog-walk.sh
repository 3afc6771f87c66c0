#!/usr/bin/env bash
# Every catalog robot from scratch with the shipped flat recipe: BENCHMARKS.md "Every catalog robot
# from scratch". For each robot, configs/a1-flat.toml with only `robot`, the run name, the seed and
# an iteration cap changed, trained with `--until-walks` (walk checks in 5 ms physics at joint
# damping 2). Each run gets a fresh data directory: the same data dir and run name would resume.
#
#   experiments/catalog-walk.sh <out-dir> <seed> <cap> robot...
#   experiments/catalog-walk.sh /work/data/catalog 1 300 spot anymal_d
#   (L3P=<binary> picks the l3p binary; BASE=<config> a variant of configs/a1-flat.toml)
#
# Per robot it leaves <out-dir>/<robot>-s<seed>/{config.toml,train.log,data/} and prints the run's
# walk.json (when the criterion held) or its last walk check.
set -euo pipefail
[ $# -ge 4 ] || { echo "usage: $0 <out-dir> <seed> <cap> robot..." >&2; exit 2; }
out=$1; seed=$2; cap=$3; shift 3
l3p=${L3P:-l3p}
here=$(cd "$(dirname "$0")/.." && pwd)
base=${BASE:-$here/configs/a1-flat.toml}   # BASE=<config> to try a variant of the recipe
for robot in "$@"; do
  dir="$out/$robot-s$seed"
  mkdir -p "$dir"
  sed -e "s/^robot = \"a1\"/robot = \"$robot\"/" \
      -e "s/^name = \"a1-flat\"/name = \"$robot-flat\"\nseed = $seed/" \
      -e "s/^max_iterations = .*/max_iterations = $cap/" \
      "$base" > "$dir/config.toml"
  grep -q "^robot = \"$robot\"" "$dir/config.toml" || { echo "robot not set in $dir/config.toml" >&2; exit 1; }
  start=$(date +%s)
  "$l3p" train "$dir/config.toml" --until-walks --data-dir "$dir/data" --quiet > "$dir/train.log" 2>&1 \
    || echo "$robot: l3p train exited with $? (see $dir/train.log)"
  echo "== $robot seed $seed: $(( $(date +%s) - start )) s wall-clock"
  run="$dir/data/$robot-flat"
  if [ -f "$run/walk.json" ]; then
    cat "$run/walk.json"
  else
    echo "did not walk within $cap iterations; last check:"
    tail -n 1 "$run/walk_checks.jsonl" 2>/dev/null || echo "(no walk check)"
  fi
  echo
done
