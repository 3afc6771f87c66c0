#!/usr/bin/env python3
"""Samples to a common bar: for each target robot, the first iteration at which each arm's episode
reward reaches a share of what the from-scratch arm of its family ends at (L3P for l3p-transfer
and its variants, MLP for mlp-transfer; final = mean of the last 5% of iterations, mean over
seeds). The reward is smoothed over the last 10 iterations weighted by the episodes that ended in
each, and a window counts only once 20 episodes have ended in it: early in a run few episodes end
per iteration, and one lucky episode is not a level reached.

The report's 85% / 95% convergence measures each curve against its own final value, so an arm
that flattens early at a low reward "converges" fast. This asks the paper's question directly: how
many iterations does the transferred policy need to get where training from scratch gets?

    experiments/time-to-reward.py [--pretrain] <experiment data dir> [share=1.0 ...]
    # e.g. experiments/time-to-reward.py l3p-data/experiments/laptop 0.5 0.8 1.0

Resolution: an episode lasts 1,000 steps (20 s) and an iteration collects 24 steps per
environment, so the first episodes that did not end in a fall end at iteration ~42 and earlier
windows hold only falls. An arm that meets the bar at ~42 was there as soon as full episodes could
show it: differences below ~42 iterations are not resolved.

--pretrain compares the pretraining arms instead (the latent-size ablation: each `[[variants]]`
arm against the plain `pretrain-l3p` arms).

Output: a Markdown table per share; "—" = not reached within the arm's iterations (counted
as the arm's length in the mean, so a mean with "—" is a lower bound, marked ≥).
"""
import glob
import json
import os
import re
import statistics
import sys

SMOOTH = 10


MIN_EPISODES = 20


def rewards(metrics):
    """Per iteration: (mean episode reward or None, episodes that ended)."""
    rows = [json.loads(line) for line in open(metrics)]
    rows = [r for r in rows if r.get("source") == "learner"]
    return [(r["values"].get("episode_return"), r["values"].get("episodes", 0.0)) for r in rows]


def moving_average(values):
    out = []
    for i in range(len(values)):
        window = [(v, n) for v, n in values[max(0, i + 1 - SMOOTH):i + 1] if v is not None and n > 0]
        episodes = sum(n for _, n in window)
        out.append(sum(v * n for v, n in window) / episodes
                   if episodes >= MIN_EPISODES else float("-inf"))
    return out


def final(values):
    v = [x for x, _ in values if x is not None]
    n = max(1, round(len(v) * 0.05))
    return sum(v[-n:]) / n


def first_reaching(curve, bar):
    for i, v in enumerate(curve):
        if v >= bar:
            return i + 1
    return None


def main():
    args = sys.argv[1:]
    pretrain = "--pretrain" in args
    args = [a for a in args if a != "--pretrain"]
    data = args[0]
    shares = [float(s) for s in args[1:]] or [1.0]
    arms = {}
    for done in sorted(glob.glob(os.path.join(data, "*", "done.json"))):
        arm = os.path.basename(os.path.dirname(done))
        if arm.startswith("pretrain-") != pretrain:
            continue
        if pretrain:
            m = re.fullmatch(r"pretrain-(?:(\w+)-)?(mlp|l3p)-s(\d+)", arm)
            if not m:
                continue
            variant, family, seed = m.groups()
            robot, transfer = "pretraining", None
        else:
            m = re.fullmatch(r"(.+?)-(mlp|l3p)(-transfer)?(?:-(\w+))?-s(\d+)", arm)
            if not m:
                continue
            robot, family, transfer, variant, seed = m.groups()
        method = family + (transfer or "") + (f" [{variant}]" if variant else "")
        values = rewards(os.path.join(data, arm, arm, "metrics.jsonl"))
        arms.setdefault((robot, family, method), []).append(values)

    for share in shares:
        print(f"\n### Iterations to {share:.0%} of the from-scratch final reward\n")
        print("| robot | method | bar (reward) | iterations (mean over seeds) | per seed | vs scratch |")
        print("|---|---|---|---|---|---|")
        for robot in sorted({k[0] for k in arms}):
            for family in ("l3p", "mlp"):
                scratch = arms.get((robot, family, family))
                if not scratch:
                    continue
                bar = share * statistics.mean(final(v) for v in scratch)
                scratch_mean = None
                for (r, f, method), runs in sorted(arms.items()):
                    if r != robot or f != family:
                        continue
                    hits = [first_reaching(moving_average(v), bar) for v in runs]
                    counted = [h if h is not None else len(v) for h, v in zip(hits, runs)]
                    mean = statistics.mean(counted)
                    bound = "≥ " if None in hits else ""
                    if method == family:
                        scratch_mean = mean
                    ratio = (f"{scratch_mean / mean:.2f}×" if scratch_mean and method != family
                             else "")
                    seeds = ", ".join(str(h) if h is not None else "—" for h in hits)
                    print(f"| {robot} | {method} | {bar:.2f} | {bound}{mean:.0f} | {seeds} | {ratio} |")


if __name__ == "__main__":
    main()
