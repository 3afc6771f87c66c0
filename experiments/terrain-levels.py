#!/usr/bin/env python3
"""Mean terrain level of finished episodes per block of iterations, overall and per terrain type,
from a run's metrics.jsonl (learner records).

    experiments/terrain-levels.py <data_dir>/<run>/metrics.jsonl [block=25]
"""
import json
import sys

TYPES = ["flat", "pyramid_stairs", "inverted_pyramid_stairs", "boxes", "random_rough",
         "pyramid_slope", "inverted_pyramid_slope"]


def main():
    rows = [json.loads(line) for line in open(sys.argv[1])]
    rows = [r for r in rows if r.get("source") == "learner"]
    block = int(sys.argv[2]) if len(sys.argv) > 2 else 25
    present = sorted({k for r in rows for k in r["values"] if k.startswith("terrain_level/type")})
    names = {k: TYPES[int(k.removeprefix("terrain_level/type"))] for k in present}
    print("iterations  minutes  level  " + "  ".join(names[k] for k in present)
          + "  xy_error  episode_length")
    t0 = rows[0]["unix_ms"]
    for i in range(0, len(rows), block):
        chunk = rows[i:i + block]

        def mean(key):
            v = [r["values"][key] for r in chunk if key in r["values"]]
            return sum(v) / len(v) if v else float("nan")

        cells = [f"{mean(k):.2f}" for k in present]
        print(f"{chunk[0]['iteration']}-{chunk[-1]['iteration']}  "
              f"{(chunk[-1]['unix_ms'] - t0) / 60000:.1f}  {mean('terrain_level'):.2f}  "
              + "  ".join(cells)
              + f"  {mean('lin_vel_error'):.2f}  {mean('episode_length'):.0f}")


if __name__ == "__main__":
    main()
