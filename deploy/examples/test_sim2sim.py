#!/usr/bin/env python3
"""Tests of sim2sim.py: `python3 deploy/examples/test_sim2sim.py` (unittest, about 10 s on 2 cores).

The menagerie test reads `$L3P_SHARED_DIR/mjcf/unitree_a1/a1.xml` and prints `skipped: ...`
without that variable (like the Rust tests that read vendor files).
"""
import contextlib
import io
import json
import math
import os
import shutil
import struct
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent.parent
sys.path.insert(0, str(HERE))
import sim2sim  # noqa: E402

EXPORT = ROOT / "docs/a1-flat-session31/policy"
A1_URDF = ROOT / "robot/assets/a1.urdf"


def run(*argv):
    """sim2sim's main in-process: (exit code, JSON result or None, stderr text)."""
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.json"
        err = io.StringIO()
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(err):
            code = sim2sim.main([str(a) for a in argv] + ["--json", str(out)])
        result = json.loads(out.read_text()) if out.exists() else None
    return code, result, err.getvalue()


def zero_action_export(directory):
    """A copy of the A1 export whose last layer's weights and bias are 0: the action is always
    0, so the targets stay at the default pose (safetensors edited in place, numpy only)."""
    shutil.copy(EXPORT / "policy.json", directory / "policy.json")
    raw = bytearray((EXPORT / "policy.safetensors").read_bytes())
    (n,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8:8 + n])
    last = json.loads(header["__metadata__"]["l3p_export"])["layers"][-1]["name"]
    for suffix in (".weight", ".bias"):
        begin, end = header[last + suffix]["data_offsets"]
        raw[8 + n + begin:8 + n + end] = bytes(end - begin)
    (directory / "policy.safetensors").write_bytes(bytes(raw))
    return directory


def flipped_urdf(path, joint, limits=None):
    """A copy of the A1 URDF with `joint`'s axis negated (and its limits mirrored, as a vendor
    with the other sign convention would write them)."""
    text = A1_URDF.read_text()
    start = text.index(f'<joint name="{joint}"')
    end = text.index("</joint>", start)
    block = text[start:end]
    axis = block[block.index('<axis xyz="') + 11:].split('"')[0]
    flipped = " ".join(str(-float(x) + 0.0) for x in axis.split())
    block = block.replace(f'<axis xyz="{axis}"/>', f'<axis xyz="{flipped}"/>')
    if limits:
        lo = block[block.index('lower="') + 7:].split('"')[0]
        hi = block[block.index('upper="') + 7:].split('"')[0]
        mirrored = f'lower="{-float(hi)}" upper="{-float(lo)}"'
        block = block.replace(f'lower="{lo}" upper="{hi}"', mirrored)
    path.write_text(text[:start] + block + text[end:])
    return path


class Sim2Sim(unittest.TestCase):
    def setUp(self):
        self.tmp = Path(tempfile.mkdtemp())

    def tearDown(self):
        shutil.rmtree(self.tmp)

    def test_zero_action_export_stands_on_the_catalog_urdf(self):
        export = zero_action_export(self.tmp)
        code, r, _ = run(export, "--model", A1_URDF, "--stand", "--seeds", "1", "--seconds", "3")
        self.assertEqual(code, 0)
        stand = r["commands"][0]["seeds"][0]
        self.assertFalse(stand["fell"])
        self.assertGreaterEqual(stand["base_height_pct"], 85.0)
        # The catalog A1 stands 0.30 m tall on its feet (robots' nominal standing height 0.302).
        self.assertAlmostEqual(r["nominal_standing_height_m"], 0.302, delta=0.003)
        self.assertTrue(0.25 < r["standing_height_m"] <= r["nominal_standing_height_m"])
        self.assertEqual(sorted(r["feet"]), ["FL", "FR", "RL", "RR"])
        # A policy that never moves does not walk: --require-pass turns the verdict into exit 1.
        code, r, _ = run(export, "--model", A1_URDF, "--forward", "0.5", "--seeds", "1",
                         "--seconds", "2", "--stand-seconds", "0", "--require-pass")
        self.assertEqual(code, 1)
        self.assertTrue(any("xy tracking error" in f for f in r["verdict"]["failures"]))

    def test_shipped_export_walks_on_the_catalog_urdf(self):
        # Joint damping 2 N·m·s/rad: the walk criterion's pin (the top of the training range).
        code, r, _ = run(EXPORT, "--model", A1_URDF, "--forward", "0.5", "--seeds", "1",
                         "--seconds", "6", "--joint-damping", "2")
        self.assertEqual(code, 0)
        self.assertTrue(r["contract"]["ok"])
        self.assertFalse(r["stand"]["fell"])
        self.assertGreaterEqual(r["stand"]["base_height_pct"], 80.0)
        walk = r["commands"][0]["seeds"][0]
        self.assertFalse(walk["fell"])
        self.assertLess(walk["xy_error"], 0.2)
        self.assertGreaterEqual(walk["base_height_pct"], 80.0)
        self.assertGreater(walk["forward_speed"], 0.35)
        for foot in ("FL", "FR", "RL", "RR"):
            self.assertGreater(walk["swing_share"][foot], 0.2, foot)
            self.assertGreaterEqual(walk["touchdown_hz"][foot], 1.0, foot)
        self.assertLess(walk["non_foot_contact_share"], 0.02)
        self.assertLess(walk["chatter_rad"], 0.08)

    def test_urdf_feet_get_soft_rubber_contact_unless_rigid_is_asked(self):
        args = sim2sim.parse_args([str(EXPORT), "--model", str(A1_URDF)])
        config, _ = sim2sim.load_export(EXPORT)
        robot = sim2sim.load_model(A1_URDF, config["io"], args)
        feet = [g for leg in robot.legs for g in leg["feet"]]
        self.assertEqual(len(feet), 4)
        np.testing.assert_allclose(robot.m.geom_solimp[feet], [sim2sim.SOFT_FOOT_SOLIMP] * 4)
        self.assertTrue((robot.m.geom_condim[feet] == 6).all())
        shins = [g for leg in robot.legs for g in leg["geoms"] if g not in leg["feet"]]
        self.assertTrue((robot.m.geom_condim[shins] == 3).all())  # only the feet are rubber
        rigid = sim2sim.parse_args([str(EXPORT), "--model", str(A1_URDF), "--foot-contact", "rigid"])
        robot = sim2sim.load_model(A1_URDF, config["io"], rigid)
        self.assertTrue((robot.m.geom_condim[feet] == 3).all())
        self.assertFalse(np.allclose(robot.m.geom_solimp[feet], [sim2sim.SOFT_FOOT_SOLIMP] * 4))

    def test_flipped_joint_is_caught_by_the_contract_check(self):
        thigh = flipped_urdf(self.tmp / "thigh.urdf", "FL_thigh_joint", limits=True)
        code, r, err = run(EXPORT, "--model", thigh)
        self.assertEqual(code, 2)
        self.assertFalse(r["contract"]["ok"])
        self.assertIn("negating FL_thigh_joint makes the pose right", err)
        # The smallest default angle (abduction 0.1 rad) still moves the foot 5 cm sideways.
        hip = flipped_urdf(self.tmp / "hip.urdf", "FL_hip_joint")
        code, _, err = run(EXPORT, "--model", hip)
        self.assertEqual(code, 2)
        self.assertIn("legs FL and FR are not mirror images", err)
        self.assertIn("negating FL_hip_joint (or FR_hip_joint)", err)
        # A flipped knee with mirrored limits: the default pose lies outside the range.
        knee = flipped_urdf(self.tmp / "knee.urdf", "FL_calf_joint", limits=True)
        code, _, err = run(EXPORT, "--model", knee)
        self.assertEqual(code, 2)
        self.assertIn("FL_calf_joint: default position -1.500 rad is outside", err)

    def test_flipped_thigh_also_fails_the_walk(self):
        thigh = flipped_urdf(self.tmp / "thigh.urdf", "FL_thigh_joint", limits=True)
        code, r, _ = run(EXPORT, "--model", thigh, "--skip-contract-check", "--forward", "0.5",
                         "--seeds", "1", "--seconds", "4", "--stand-seconds", "0",
                         "--joint-damping", "2")
        self.assertEqual(code, 0)
        walk = r["commands"][0]["seeds"][0]
        self.assertFalse(r["verdict"]["pass"])
        self.assertGreater(walk["xy_error"], 0.3)
        self.assertGreater(walk["swing_share"]["FL"], 0.9)  # the leg points forward, in the air

    def test_missing_joint_names_both_sets(self):
        urdf = self.tmp / "renamed.urdf"
        urdf.write_text(A1_URDF.read_text().replace('"RR_calf_joint"', '"RR_knee"'))
        code, _, err = run(EXPORT, "--model", urdf)
        self.assertEqual(code, 2)
        self.assertIn("missing from the model (or not hinges): RR_calf_joint", err)
        self.assertIn("RR_knee", err)
        code, _, err = run(self.tmp, "--model", A1_URDF)
        self.assertEqual(code, 2)
        self.assertIn("no policy.safetensors", err)

    def test_observation_frames_match_the_rust_builder(self):
        args = sim2sim.parse_args([str(EXPORT), "--model", str(A1_URDF)])
        config, _ = sim2sim.load_export(EXPORT)
        robot = sim2sim.load_model(A1_URDF, config["io"], args)
        # Base yawed 90° and pitched 0.2 rad; world velocity +x, world angular velocity +z.
        yaw, pitch = math.pi / 2, 0.2
        qz = np.array([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])
        qy = np.array([math.cos(pitch / 2), 0, math.sin(pitch / 2), 0])
        quat = quat_mul(qz, qy)
        robot.place(np.zeros(2), 0.0, robot.default, height=1.0)
        d = robot.d
        d.qpos[robot.free_q + 3:robot.free_q + 7] = quat
        d.qvel[robot.free_v:robot.free_v + 3] = [1.0, 0.0, 0.0]
        d.qvel[robot.free_v + 3:robot.free_v + 6] = rotate_inverse(quat, [0, 0, 0.5])  # body axes
        sim2sim.mujoco.mj_forward(robot.m, d)
        (lin, gyro, gravity), q, _ = robot.base_state()
        np.testing.assert_allclose(lin, rotate_inverse(quat, [1, 0, 0]), atol=1e-9)
        np.testing.assert_allclose(gyro, rotate_inverse(quat, [0, 0, 0.5]), atol=1e-9)
        np.testing.assert_allclose(gravity, rotate_inverse(quat, [0, 0, -1]), atol=1e-9)
        self.assertAlmostEqual(gravity[0], math.sin(pitch))  # nose down: gravity points forward
        self.assertAlmostEqual(sim2sim.yaw_of(q), yaw)
        # The observation: layout order, joint_pos relative to default, clock [sin, cos] at tick 0.
        obs = sim2sim.observation(config["io"], (lin, gyro, gravity), np.array([0.5, 0, 0]),
                                  robot.default + 0.1, np.zeros(12), np.ones(12), 0)
        self.assertEqual(obs.shape, (config["obs_dim"],))
        np.testing.assert_allclose(obs[6:9], gravity, atol=1e-6)
        np.testing.assert_allclose(obs[9:12], [0.5, 0, 0])
        np.testing.assert_allclose(obs[12:24], 0.1, atol=1e-6)
        np.testing.assert_allclose(obs[36:48], 1.0)
        np.testing.assert_allclose(obs[48:50], [0.0, 1.0], atol=1e-7)
        # Tick 6 of the 2 Hz clock at 50 Hz: φ = frac(6 · 2 · 0.02) = 0.24.
        obs = sim2sim.observation(config["io"], (lin, gyro, gravity), np.zeros(3), robot.default,
                                  np.zeros(12), np.zeros(12), 6)
        phase = 6 * 2.0 * 0.02
        np.testing.assert_allclose(obs[48:50], [math.sin(2 * math.pi * phase),
                                                math.cos(2 * math.pi * phase)], atol=1e-6)

    def test_menagerie_mjcf_loads_with_its_own_passive_terms(self):
        shared = os.environ.get("L3P_SHARED_DIR")
        model = Path(shared or "/nonexistent") / "mjcf/unitree_a1/a1.xml"
        if not model.is_file():
            print("skipped: menagerie A1 (set L3P_SHARED_DIR to a folder with mjcf/unitree_a1/a1.xml)")
            return
        # a1.xml has no floor (one is added) and position actuators (removed: PD goes to qfrc_applied).
        code, r, _ = run(EXPORT, "--model", model, "--stand", "--seeds", "1", "--seconds", "2")
        self.assertEqual(code, 0)
        self.assertTrue(r["contract"]["ok"])
        self.assertEqual([len(g) for g in r["feet"].values()], [1, 1, 1, 1])  # the foot spheres
        self.assertEqual(r["passive"]["FL_calf_joint"],
                         {"damping": 2.0, "friction": 0.2, "armature": 0.01})
        self.assertFalse(r["commands"][0]["seeds"][0]["fell"])
        self.assertGreater(r["commands"][0]["seeds"][0]["base_height_pct"], 85.0)
        code, r, _ = run(EXPORT, "--model", model, "--stand", "--seeds", "1", "--seconds", "1",
                         "--no-passive", "--joint-damping", "0.5")
        self.assertEqual(r["passive"]["FR_hip_joint"],
                         {"damping": 0.5, "friction": 0.0, "armature": 0.0})

    def test_vendor_urdfs_get_one_foot_group_per_leg(self):
        # Vendor URDFs hang the trunk below a root link by a fixed joint (`base` → `trunk`): the
        # legs branch from the trunk, not from the root (all four feet were grouped as one leg).
        shared = os.environ.get("L3P_SHARED_DIR")
        models = [Path(shared or "/nonexistent") / f for f in ("urdf/a1/a1.urdf", "urdf/go1/go1.urdf")]
        if not all(m.is_file() for m in models):
            print("skipped: vendor URDFs (set L3P_SHARED_DIR to a folder with urdf/a1, urdf/go1)")
            return
        for model in models:
            code, r, err = run(EXPORT, "--model", model, "--stand", "--seeds", "1", "--seconds", "1")
            self.assertEqual(code, 0, f"{model}: {err}")
            self.assertEqual(sorted(r["feet"]), ["FL", "FR", "RL", "RR"], model)
            self.assertTrue(all(len(g) >= 1 for g in r["feet"].values()), (model, r["feet"]))

    def test_missing_mujoco_exits_3_with_one_line(self):
        code = ("import sys, runpy; sys.modules['mujoco'] = None; "
                f"sys.argv = ['sim2sim.py', '--help']; runpy.run_path({str(HERE / 'sim2sim.py')!r}, "
                "run_name='__main__')")
        p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        self.assertEqual(p.returncode, 3)
        self.assertEqual(p.stderr.strip(),
                         "sim2sim needs the Python package mujoco: pip install mujoco")


def quat_mul(a, b):
    w1, x1, y1, z1 = a
    w2, x2, y2, z2 = b
    return np.array([w1 * w2 - x1 * x2 - y1 * y2 - z1 * z2, w1 * x2 + x1 * w2 + y1 * z2 - z1 * y2,
                     w1 * y2 - x1 * z2 + y1 * w2 + z1 * x2, w1 * z2 + x1 * y2 - y1 * x2 + z1 * w2])


def rotate_inverse(q, v):
    """task/src/task/frames.rs `quat_rotate_inverse`, transcribed: R(q)ᵀ v."""
    w, x, y, z = q[0], -q[1], -q[2], -q[3]
    t = [2 * (y * v[2] - z * v[1]), 2 * (z * v[0] - x * v[2]), 2 * (x * v[1] - y * v[0])]
    return np.array([v[0] + w * t[0] + (y * t[2] - z * t[1]),
                     v[1] + w * t[1] + (z * t[0] - x * t[2]),
                     v[2] + w * t[2] + (x * t[1] - y * t[0])])


if __name__ == "__main__":
    unittest.main(verbosity=2)
