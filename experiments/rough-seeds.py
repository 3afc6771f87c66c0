#!/usr/bin/env python3
"""Terrain-curriculum runs side by side: when each one's mean terrain level reached 3, and where it
stood at fixed wall-clock times, with the mean and spread over the runs (BENCHMARKS.md, "A1 over
the terrain curriculum").

    experiments/rough-seeds.py <metrics.jsonl>[@<start unix s>] ...

The level is the learner's `terrain_level` (mean level of the episodes that finished in an
iteration), averaged over the last 25 iterations. Wall-clock counts from `@<start>` (when `l3p
train` was launched; `date +%s` before it) or else from the first iteration's start, so it
includes the first model set-up and excludes nothing after.
"""
import json
import statistics
import sys

WINDOW = 25
MARKS_MIN = [15, 30, 45, 60]
TARGET = 3.0


def load(arg):
    path, _, start = arg.partition("@")
    rows = [json.loads(line) for line in open(path)]
    rows = [r for r in rows if r.get("source") == "learner"]
    if start:
        t0 = float(start)
    else:
        t0 = rows[0]["unix_ms"] / 1000 - rows[0]["values"].get("iteration_seconds", 0.0)
    out, window = [], []
    for r in rows:
        level = r["values"].get("terrain_level")
        if level is not None and level == level:  # NaN until the first episodes end
            window.append(level)
            window = window[-WINDOW:]
        out.append({
            "iteration": r["iteration"],
            "minutes": (r["unix_ms"] / 1000 - t0) / 60,
            "level": sum(window) / len(window) if len(window) == WINDOW else float("nan"),
            "seconds": r["values"].get("iteration_seconds", float("nan")),
        })
    return path, out


def at_minutes(rows, minutes):
    before = [r for r in rows if r["minutes"] <= minutes]
    if not before or rows[-1]["minutes"] < minutes:
        return None
    return before[-1]


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    runs = [load(a) for a in sys.argv[1:]]
    header = ["run", "s/it (median)", "level >= 3 at"] + [f"level at {m} min" for m in MARKS_MIN]
    header += ["last iteration", "last level"]
    print("| " + " | ".join(header) + " |")
    print("|" + "---|" * len(header))
    reached, marks = [], {m: [] for m in MARKS_MIN}
    for path, rows in runs:
        first = next((r for r in rows if r["level"] >= TARGET), None)
        cells = [path, f"{statistics.median(r['seconds'] for r in rows):.2f}"]
        if first:
            cells.append(f"{first['minutes']:.1f} min (it {first['iteration']})")
            reached.append(first["minutes"])
        else:
            cells.append("not reached")
        for m in MARKS_MIN:
            r = at_minutes(rows, m)
            cells.append(f"{r['level']:.2f} (it {r['iteration']})" if r else "-")
            if r:
                marks[m].append(r["level"])
        cells += [str(rows[-1]["iteration"]), f"{rows[-1]['level']:.2f}"]
        print("| " + " | ".join(cells) + " |")

    def spread(values):
        if not values:
            return "-"
        if len(values) == 1:
            return f"{values[0]:.2f} (n=1)"
        return f"{statistics.mean(values):.2f} ± {statistics.stdev(values):.2f} (n={len(values)})"

    print()
    print(f"level >= {TARGET} reached by {len(reached)}/{len(runs)} runs; minutes: {spread(reached)}")
    for m in MARKS_MIN:
        print(f"level at {m} min: {spread(marks[m])}")


if __name__ == "__main__":
    main()
