#!/usr/bin/env bash
# Keep an experiment's results across machines: pack what `l3p experiment report` and a resumed
# `l3p experiment run` need from finished arms (done.json, the learner's metrics, the arm configs,
# an until_walks arm's walk.json and walk_checks.jsonl, and the pretraining arms' final checkpoints, which the transfer arms start from) into one tarball,
# or unpack it back. Unfinished arms are left out: a resumed run starts them again.
#
#   experiments/archive.sh pack   l3p-data/experiments/laptop docs/experiments/<date>-laptop/arms.tar.gz
#   experiments/archive.sh unpack docs/experiments/<date>-laptop/arms.tar.gz l3p-data/experiments/laptop
#
# ARCHIVE_CHECKPOINTS=0 leaves the checkpoints out (≈ 1.3 MB per arm): for an experiment with no
# transfer arms (the ablation) nothing resumes from them, and the report needs only the metrics.
set -euo pipefail
mode=${1:?pack|unpack}; from=${2:?source}; to=${3:?destination}
case "$mode" in
  pack)
    list=$(mktemp)
    (
      cd "$from"
      ls arms/*.toml
      for done in */done.json; do
        arm=${done%/done.json}
        echo "$done"
        echo "$arm/$arm/metrics.jsonl"
        # until_walks arms: the check history and the verdict (small), beside done.json's summary.
        for f in walk.json walk_checks.jsonl; do
          if [ -f "$arm/$arm/$f" ]; then echo "$arm/$arm/$f"; fi
        done
        if [ "${ARCHIVE_CHECKPOINTS:-1}" != 0 ]; then
          case "$arm" in pretrain-*) echo "$arm/$arm/checkpoints/latest.ckpt" ;; esac
        fi
      done
    ) > "$list"
    mkdir -p "$(dirname "$to")"
    tar -C "$from" -czf "$to" -T "$list"
    echo "packed $(grep -c done.json "$list") finished arms into $to ($(du -h "$to" | cut -f1))"
    rm -f "$list"
    ;;
  unpack)
    mkdir -p "$to"
    tar -C "$to" -xzf "$from"
    echo "unpacked into $to; \`l3p experiment status\` shows what is done"
    ;;
  *) echo "usage: $0 pack|unpack <from> <to>" >&2; exit 2 ;;
esac
