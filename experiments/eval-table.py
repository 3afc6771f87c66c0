#!/usr/bin/env python3
"""`l3p eval --json` results as one Markdown table row per evaluated row (file, command): terrain
level, falls, tracking, height, swing, non-foot contact and chatter.

    experiments/eval-table.py <eval.json> ...
"""
import json
import sys


def main():
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    print("| file | forward | level (last) | falls | xy err | yaw err | height | swing | non-foot | chatter |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for path in sys.argv[1:]:
        for row in json.load(open(path))["rows"]:
            gait = row["gait"]
            level = row.get("terrain_level")
            last = row.get("final_terrain_level")
            levels = "-" if level is None else f"{level:.2f} ({last:.2f})"
            swing = gait["swing_share"]
            print(f"| {path} | {row.get('forward') or '-'} | {levels} | {100 * row['fall_fraction']:.0f}% "
                  f"| {row['lin_vel_error']:.3f} | {row['yaw_rate_error']:.3f} "
                  f"| {gait['base_height_pct']:.0f}% | {100 * min(swing):.0f}-{100 * max(swing):.0f}% "
                  f"| {100 * gait['non_foot_contact_share']:.1f}% | {gait['target_change_rms']:.3f} |")


if __name__ == "__main__":
    main()
