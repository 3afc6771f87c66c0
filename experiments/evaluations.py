# Every finished arm's evaluations (done.json) as text: `python3 experiments/evaluations.py <data_dir>/<name>`
# (docs/experiments/<date>-<name>/evaluations.txt).
import json, glob, os, sys
root = sys.argv[1]
for done in sorted(glob.glob(os.path.join(root, '*', 'done.json'))):
    d = json.load(open(done))
    print(f"{d['arm']} {d['iterations']} wall {round(d['wall_seconds'])}")
    groups = list(d['evaluations'].items()) + ([('zero-shot', d['zero_shot'])] if d.get('zero_shot') else [])
    for robot, rows in groups:
        for r in rows:
            g = r['gait']
            print(f"   {robot} {r['forward']} ret {r['episode_return']:.2f} err {r['lin_vel_error']:.3f} yaw {r['yaw_rate_error']:.3f} falls {r['fall_fraction']:.2f} h% {round(g['base_height_pct'])} swing {[round(x, 2) for x in g['swing_share']]} nf {g['non_foot_contact_share']:.3f} chatter {g['target_change_rms']:.3f} {r['walk_failures']}")
