#!/usr/bin/env bash
# Random-core ablation (issue 40 "why"): Go1 fresh-head l3p-transfer around an A1 core trained 1 iteration.
set -u
cd "$(dirname "$0")"
BIN=/work/data/bin/l3p
if [ ! -f l3p-data/a1-core-1it/a1-core-1it/checkpoints/latest.ckpt ]; then
  nice -n 5 $BIN train a1-core-1it.toml --quiet > a1-core-1it.log 2>&1
fi
for s in 1 2 3; do
  if [ -f l3p-data/go1-randcore-s$s/go1-randcore-s$s/walk.json ]; then continue; fi
  nice -n 5 $BIN train go1-randcore-s$s.toml --quiet --until-walks > go1-randcore-s$s.log 2>&1
done
echo done > finished
