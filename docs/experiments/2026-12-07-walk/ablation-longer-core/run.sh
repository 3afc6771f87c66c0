#!/usr/bin/env bash
# Longer-pretrained core (issue 40 item 2): A1 l3p seed 1 continued to 400 iterations, then Go1 fresh-head transfer.
set -u
cd "$(dirname "$0")"
BIN=/work/data/bin/l3p
if [ ! -f core400.done ]; then
  nice -n 5 $BIN train pretrain-l3p-s1-400.toml --quiet > pretrain-400.log 2>&1 && touch core400.done
fi
for s in 1 2 3; do
  if [ -f l3p-data/go1-longcore-s$s/go1-longcore-s$s/walk.json ]; then continue; fi
  nice -n 5 $BIN train go1-longcore-s$s.toml --quiet --until-walks > go1-longcore-s$s.log 2>&1
done
echo done > finished
