#!/usr/bin/env python3
"""Play an l3p policy export in MuJoCo and report gait diagnostics (the Python half of `l3p sim2sim`).

    python3 sim2sim.py <export dir> --model robot/assets/a1.urdf --forward 0.5,1.0 \\
        [--seconds 20] [--seeds 3] [--json out.json | --json -] [--require-pass]

A second simulator, an independently made robot model and a controller written from the export's
`io` contract alone: a policy that walks here does not rely on quirks of the training simulator.
Needs `numpy_policy.py` beside this file (loading, inference, action filter, gait clock, targets).

What it does, in order:
  1. loads the export and the model (URDF or MJCF; see `load_model` for how each is prepared);
  2. checks the model against the contract (joints by name, default pose inside the joint ranges,
     feet below the hips, mirrored legs, fore feet ahead): a mismatch names the joint, exit 2;
  3. measures the standing height once: the robot at the default pose under PD, 1 s, no policy;
  4. the stand check: a zero-command policy run of `--stand-seconds`;
  5. per forward command and seed: settle `--settle-seconds` under PD at the default pose, then
     the policy for `--seconds`, control period io.control_dt, clipped PD every physics step;
  6. prints a table (one row per command: mean over seeds, worst in brackets) and a verdict.

Exit codes: 0 it ran (whatever the verdict), 1 the verdict failed and --require-pass was given,
2 bad input (export, model, arguments, contract), 3 the mujoco package is missing.
With `--json -` the JSON goes to stdout and the table to stderr.
"""
import argparse
import json
import math
import sys
import time
from collections import deque
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import numpy_policy  # noqa: E402  (lives beside this script)

try:
    import mujoco
except ImportError:
    print("sim2sim needs the Python package mujoco: pip install mujoco", file=sys.stderr)
    sys.exit(3)

# Robot-floor contact counts when its normal force exceeds this (N), as in the training meter.
CONTACT_FORCE = 1.0
# Falls: base lower than this share of the standing height, or tilted more than this.
FALL_HEIGHT_SHARE = 0.4
FALL_TILT_DEG = 60.0
# Per-seed perturbation of the initial state (uniform ±): joint offsets (rad) and yaw (rad) at
# placement, base velocity (m/s, rad/s) when the policy takes over (the settle would absorb it).
PERTURB_JOINT, PERTURB_YAW, PERTURB_VEL, PERTURB_YAW_RATE = 0.05, 0.1, 0.1, 0.1
HEADING_STIFFNESS = 0.5  # heading hold: yaw rate = clip(k · wrap(target − heading), ±1)
STANDING_SETTLE_S = 1.0
KNOWN_SEGMENTS = {
    "base_lin_vel", "base_ang_vel", "projected_gravity", "velocity_command",
    "joint_pos_rel", "joint_vel", "last_action", "gait_clock",
}


class BadInput(Exception):
    """Bad export, model or arguments: printed as one message, exit 2."""


# ---------------------------------------------------------------------------------------- export


def load_export(path):
    """The export's config and tensors, with the observation layout checked against what this
    script (like deploy's ObservationBuilder) can build."""
    p = Path(path)
    if not (p / "policy.safetensors").is_file() and not (p.is_file() and p.suffix == ".safetensors"):
        raise BadInput(f"{path}: no policy.safetensors (expected an l3p export directory)")
    try:
        config, tensors = numpy_policy.load(p)
    except (OSError, ValueError, KeyError, AssertionError) as e:
        raise BadInput(f"{path}: cannot read the export: {e}") from e
    io = config.get("io")
    if io is None:
        raise BadInput(f"{path}: the export has no `io` section (not deployable)")
    n = len(io["joint_names"])
    lengths = {"joint_pos_rel": n, "joint_vel": n, "last_action": n, "gait_clock": 2}
    for s in io["obs_layout"]:
        if s["name"] == "height_scan":
            raise BadInput("the policy observes a terrain height scan; sim2sim plays blind "
                           "(proprioceptive) policies only\nhint: train with [env] height_scan = false")
        if s["name"] not in KNOWN_SEGMENTS:
            raise BadInput(f"unknown observation segment {s['name']!r}")
        if s["len"] != lengths.get(s["name"], 3):
            raise BadInput(f"observation segment {s['name']} has length {s['len']}, "
                           f"expected {lengths.get(s['name'], 3)}")
    if sum(s["len"] for s in io["obs_layout"]) != config["obs_dim"]:
        raise BadInput("the observation layout does not add up to obs_dim")
    if config["action_dim"] != n:
        raise BadInput(f"action_dim {config['action_dim']} != {n} joints")
    return config, tensors


def observation(io, base, cmd, q, qd, last_action, ticks):
    """The observation vector, segment by segment as deploy's ObservationBuilder::build: scaled,
    NaN → 0, clipped to ±obs_clip. `base` = (lin_vel_b, ang_vel_b, projected_gravity)."""
    lin_vel, ang_vel, gravity = base
    default = np.asarray(io["default_joint_pos"])
    values = {
        "base_lin_vel": lin_vel, "base_ang_vel": ang_vel, "projected_gravity": gravity,
        "velocity_command": cmd, "joint_pos_rel": q - default, "joint_vel": qd,
        "last_action": last_action,
    }
    parts = []
    for s in io["obs_layout"]:
        if s["name"] == "gait_clock":
            x = numpy_policy.gait_clock({"io": io}, ticks)
        else:
            x = values[s["name"]]
        parts.append(s["scale"] * np.asarray(x, dtype=np.float64))
    obs = np.nan_to_num(np.concatenate(parts), nan=0.0)
    return np.clip(obs, -io["obs_clip"], io["obs_clip"]).astype(np.float32)


# ----------------------------------------------------------------------------------------- model


class Robot:
    """A compiled model plus what the controller and the meter need to know about it."""

    def __init__(self, model, io):
        self.m = model
        self.d = mujoco.MjData(model)
        self.names = io["joint_names"]
        m = model
        hinges = {m.joint(j).name: j for j in range(m.njnt)
                  if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE}
        missing = [n for n in self.names if n not in hinges]
        if missing:
            other = [m.joint(j).name for j in range(m.njnt)]
            raise BadInput(
                f"joints of the export missing from the model (or not hinges): {', '.join(missing)}\n"
                f"  export: {', '.join(self.names)}\n"
                f"  model:  {', '.join(n or '(unnamed)' for n in other)}")
        self.jnt = np.array([hinges[n] for n in self.names])
        self.qadr = m.jnt_qposadr[self.jnt]
        self.dadr = m.jnt_dofadr[self.jnt]
        self.extra_joints = sorted(set(hinges) - set(self.names))
        free = [j for j in range(m.njnt) if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_FREE]
        self.base = self.root = m.jnt_bodyid[free[0]]
        self.free_q, self.free_v = m.jnt_qposadr[free[0]], m.jnt_dofadr[free[0]]
        self.default = np.asarray(io["default_joint_pos"], dtype=np.float64)
        self.kp = np.asarray(io["kp"], dtype=np.float64)
        self.kd = np.asarray(io["kd"], dtype=np.float64)
        self.effort = np.asarray(io["effort_limit"], dtype=np.float64)
        self._find_legs()

    def _subtree(self, body):
        m = self.m
        out, todo = [], [body]
        while todo:
            b = todo.pop()
            out.append(b)
            todo.extend(c for c in range(1, m.nbody) if m.body_parentid[c] == b and c != b)
        return out

    def _find_legs(self):
        """Legs: the base's child subtrees that hold io joints, in io order. Foot geoms of a leg:
        those whose geom or body name contains "foot"; otherwise the leg's lowest geoms at the
        default pose (within 5 mm of its lowest point). Not simply "the last body's geoms": in an
        MJCF like menagerie's the foot sphere shares the calf body with the shin capsules, and a
        shin on the floor is a knee contact, not a step."""
        m = self.m
        self.place(np.zeros(3), 0.0, self.default, height=10.0)
        collide = (m.geom_contype != 0) | (m.geom_conaffinity != 0)
        while True:
            self.legs = []  # dicts: name, joints (io indices), geoms, feet, hip (first joint's body)
            for k, name in enumerate(self.names):
                b = m.jnt_bodyid[self.jnt[k]]
                while m.body_parentid[b] != self.base:
                    if b == 0 or m.body_parentid[b] == 0:
                        raise BadInput(
                            f"joint {name} is not below the base body {m.body(self.base).name}")
                    b = m.body_parentid[b]
                leg = next((l for l in self.legs if l["root"] == b), None)
                if leg is None:
                    leg = {"root": b, "joints": []}
                    self.legs.append(leg)
                leg["joints"].append(k)
            # A root link fixed to the trunk (vendor URDFs' `base` → `trunk`) holds every leg in
            # one subtree: the trunk, the body the legs branch from, is the base.
            root = self.legs[0]["root"] if len(self.legs) == 1 else None
            if root is None or any(m.jnt_bodyid[self.jnt[k]] == root for k in range(len(self.names))):
                break
            self.base = root
        floor = self.floor_geom
        for leg in self.legs:
            bodies = self._subtree(leg["root"])
            geoms = [g for g in range(m.ngeom) if m.geom_bodyid[g] in bodies and collide[g]]
            if not geoms:
                raise BadInput(f"leg {m.body(leg['root']).name} has no collision geoms")
            named = [g for g in geoms
                     if "foot" in (m.geom(g).name + m.body(m.geom_bodyid[g]).name).lower()]
            low = {g: mujoco.mj_geomDistance(m, self.d, g, floor, 100.0, None) for g in geoms}
            lowest = min(low.values())
            leg["bodies"] = bodies
            leg["geoms"] = geoms
            leg["feet"] = named or [g for g in geoms if low[g] < lowest + 0.005]
            leg["hip"] = m.jnt_bodyid[self.jnt[leg["joints"][0]]]
            leg["name"] = _leg_name([self.names[k] for k in leg["joints"]], m.body(leg["root"]).name)
        # geom → role: leg index for foot geoms, -1 other robot geoms, -2 base geoms, -3 world.
        self.role = np.full(m.ngeom, -1)
        robot_bodies = set(self._subtree(self.root))
        for g in range(m.ngeom):
            if m.geom_bodyid[g] not in robot_bodies:
                self.role[g] = -3
            elif m.geom_bodyid[g] in (self.base, self.root):
                self.role[g] = -2
        self.leg_of = np.full(m.ngeom, -1)
        for i, leg in enumerate(self.legs):
            self.leg_of[leg["geoms"]] = i
            self.role[leg["feet"]] = i

    @property
    def floor_geom(self):
        m = self.m
        return next(g for g in range(m.ngeom)
                    if m.geom_bodyid[g] == 0 and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_PLANE)

    def place(self, xy, yaw, q, height=None):
        """Puts the robot at rest with a level base, heading `yaw` and joints `q`; with no `height`
        the base is lowered until the lowest foot just touches the floor."""
        d = self.d
        mujoco.mj_resetData(self.m, d)
        d.qpos[self.free_q:self.free_q + 3] = [xy[0], xy[1], 1.0 if height is None else height]
        d.qpos[self.free_q + 3:self.free_q + 7] = [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)]
        d.qpos[self.qadr] = q
        mujoco.mj_forward(self.m, d)
        if height is None:
            feet = [g for leg in self.legs for g in leg["feet"]]
            gap = min(mujoco.mj_geomDistance(self.m, d, g, self.floor_geom, 100.0, None) for g in feet)
            d.qpos[self.free_q + 2] -= gap
            mujoco.mj_forward(self.m, d)

    def base_state(self):
        """(lin vel, gyro, projected gravity) in the base frame, the base quaternion and height."""
        d = self.d
        rot = d.xmat[self.base].reshape(3, 3)  # base → world
        v_world = d.qvel[self.free_v:self.free_v + 3]  # a free joint's linear velocity: world axes
        gyro = d.qvel[self.free_v + 3:self.free_v + 6].copy()  # its angular velocity: body axes
        quat = d.qpos[self.free_q + 3:self.free_q + 7].copy()
        return (rot.T @ v_world, gyro, -rot[2, :]), quat, d.xpos[self.base][2]

    def contacts(self):
        """(per-leg foot contact flags, any non-foot robot geom on the world, base on the world)."""
        d, m = self.d, self.m
        feet = np.zeros(len(self.legs), dtype=bool)
        other = base = False
        force = np.zeros(6)
        for i in range(d.ncon):
            g1, g2 = d.contact.geom[i]
            r1, r2 = self.role[g1], self.role[g2]
            if (r1 == -3) == (r2 == -3):
                continue  # self-contact or world-world
            mujoco.mj_contactForce(m, d, i, force)
            if force[0] <= CONTACT_FORCE:
                continue
            g, r = (g2, r2) if r1 == -3 else (g1, r1)
            if r == -1 and self.leg_of[g] >= 0:
                r = self._at_foot(self.leg_of[g], d.contact.pos[i])
            if r >= 0:
                feet[r] = True
            else:
                other = True
                base |= r == -2
        return feet, other, base

    def _at_foot(self, leg, point):
        """`leg` when `point` lies within a foot geom's bounding radius (+5 mm) of its centre, else
        -1. A shin geom that ends inside the foot sphere meets the floor wherever the foot sinks
        in (menagerie's soft feet sink 1-2 cm by design): that is the foot standing, not a knee."""
        for g in self.legs[leg]["feet"]:
            if np.linalg.norm(point - self.d.geom_xpos[g]) < self.m.geom_rbound[g] + 0.005:
                return leg
        return -1


def _leg_name(joints, fallback):
    """The joints' common prefix without separators (`FL_hip_joint`, `FL_thigh_joint` → FL)."""
    prefix = joints[0]
    for n in joints[1:]:
        while not n.startswith(prefix):
            prefix = prefix[:-1]
    prefix = prefix.rstrip("_-. ")
    return prefix or fallback


def load_model(path, io, args):
    """Compiles the model for play.

    URDF: MuJoCo's importer fixes the root to the world and fuses fixed-joint links into their
    parent; here fixed links stay bodies (feet keep their names), the root gets a free joint, the
    robot collides with the floor only (no self-collision: URDF has no collision filters, and the
    training simulator has none), and a floor plane (friction `--ground-friction`) is added.
    MJCF: the model's own bodies, contacts and passive joint terms; a free joint and a floor are
    added only if missing; actuators and keyframes are removed (the PD torques go into
    qfrc_applied, so a model's position actuators cannot fight them).
    URDF feet get soft rubber contact (`soften_feet`) unless --foot-contact rigid.
    Both: timestep = --physics-dt; passive terms per --no-passive / --joint-damping /
    --joint-friction / --armature."""
    path = Path(path)
    if not path.is_file():
        raise BadInput(f"{path}: no such model file")
    urdf = path.suffix.lower() == ".urdf"
    try:
        spec = mujoco.MjSpec.from_file(str(path))
    except Exception as e:  # mujoco raises ValueError, but any parse failure is bad input
        raise BadInput(f"{path}: MuJoCo cannot load the model: {e}") from e
    if urdf:
        spec.compiler.fusestatic = False
        spec.compiler.discardvisual = True
    for a in list(spec.actuators):
        spec.delete(a)
    for k in list(spec.keys):
        spec.delete(k)
    root = spec.worldbody.first_body()
    if root is None:
        raise BadInput(f"{path}: the model has no bodies")
    if not any(j.type == mujoco.mjtJoint.mjJNT_FREE for j in root.joints):
        if root.joints:
            raise BadInput(f"{path}: the root body {root.name} has joints but no free joint")
        root.add_freejoint()
    if urdf:
        for g in spec.geoms:
            g.contype, g.conaffinity = 1, 0  # collides with the floor (contype 1) only
    has_floor = any(g.type == mujoco.mjtGeom.mjGEOM_PLANE for g in spec.worldbody.geoms)
    if not has_floor:
        spec.worldbody.add_geom(name="sim2sim_floor", type=mujoco.mjtGeom.mjGEOM_PLANE,
                                size=[0, 0, 0.05], contype=1, conaffinity=1,
                                friction=[args.ground_friction, 0.005, 0.0001])
    try:
        model = spec.compile()
    except Exception as e:
        raise BadInput(f"{path}: MuJoCo cannot compile the model: {e}") from e
    model.opt.timestep = args.physics_dt
    robot = Robot(model, io)
    if urdf and args.foot_contact == "soft":
        soften_feet(robot)
    dofs = robot.dadr
    if args.no_passive:
        model.dof_damping[dofs] = 0.0
        model.dof_frictionloss[dofs] = 0.0
        model.dof_armature[dofs] = 0.0
        model.jnt_stiffness[robot.jnt] = 0.0
    for value, field in ((args.joint_damping, model.dof_damping),
                         (args.joint_friction, model.dof_frictionloss),
                         (args.armature, model.dof_armature)):
        if value is not None:
            field[dofs] = value
    return robot


# A rubber foot as MuJoCo Menagerie's Unitree and ANYbotics models write it: soft (impedance
# rising over 31 mm from 0.015), torsional and rolling friction (condim 6), and the foot's friction
# wins over the floor's (priority). A URDF carries no contact parameters; MuJoCo's defaults are
# those of rigid objects, on which the same policies' feet bounce at touchdown (2-6 counted
# touchdowns per foot per second instead of 2: BENCHMARKS.md "Session 31").
SOFT_FOOT_SOLIMP = [0.015, 1.0, 0.031, 0.5, 2.0]
SOFT_FOOT_FRICTION = [0.8, 0.02, 0.01]


def soften_feet(robot):
    """Gives every foot geom of `robot` the soft rubber contact above."""
    m = robot.m
    feet = [g for leg in robot.legs for g in leg["feet"]]
    m.geom_solimp[feet] = SOFT_FOOT_SOLIMP
    m.geom_condim[feet] = 6
    m.geom_friction[feet] = SOFT_FOOT_FRICTION
    m.geom_priority[feet] = 1


# -------------------------------------------------------------------------------------- contract


def contract_errors(robot):
    """Checks the model against the export at the default pose; [] when it holds. A joint whose
    axis sign differs from the training model's bends its leg the wrong way: its foot ends up
    beside or above the hip, or the leg stops mirroring its partner. The errors name the legs,
    and a hint names the joints whose negation would make every check pass (the likely flipped
    axis; most likely first: the one that also lines its foot up with the other legs' sideways).
    A flipped joint whose default angle is 0 leaves the pose unchanged and passes: the walk
    itself has to show it."""
    m = robot.m
    errors = []
    for k, name in enumerate(robot.names):
        j = robot.jnt[k]
        lo, hi = m.jnt_range[j]
        if m.jnt_limited[j] and not lo <= robot.default[k] <= hi:
            errors.append(f"{name}: default position {robot.default[k]:+.3f} rad is outside the "
                          f"model's range [{lo:+.3f}, {hi:+.3f}] (flipped axis or another zero?)")
    if errors:
        return errors
    problems, _ = _pose_problems(robot, robot.default)
    if not problems:
        return []
    fixes = []
    for k, name in enumerate(robot.names):
        q = robot.default.copy()
        q[k] = -q[k]
        if q[k] != robot.default[k]:
            left, spread = _pose_problems(robot, q)
            if not left:
                fixes.append((spread, name))
    if fixes:
        names = [n for _, n in sorted(fixes)]
        problems[-1] += (f"\nhint: negating {names[0]}"
                         + (f" (or {', '.join(names[1:])})" if names[1:] else "")
                         + " makes the pose right: is its axis flipped against the training model?")
    return problems


def _pose_problems(robot, q):
    """What is wrong with the standing pose `q` (level base): feet below their hips; mirrored legs
    mirror images (every body of the leg, knees included, relative to the hip: x and z agree, y
    opposite, within 10% of the leg length); fore feet ahead of hind feet. Also returns the
    spread of the feet's sideways offsets from their hips (|y|) over all legs."""
    d = robot.d
    robot.place(np.zeros(3), 0.0, q, height=10.0)
    hips = np.array([d.xpos[leg["hip"]] for leg in robot.legs])
    feet = np.array([d.geom_xpos[leg["feet"]].mean(axis=0) for leg in robot.legs])
    rel = feet - hips
    tol = 0.1 * np.linalg.norm(rel, axis=1).mean()
    out = []
    for leg, r in zip(robot.legs, rel):
        if -r[2] < 0.5 * np.linalg.norm(r):
            out.append(f"leg {leg['name']}: at the default pose its foot is not below its hip "
                       f"(foot - hip = {_fmt(r)} m in the base frame)")
    center = hips.mean(axis=0)
    for i, li in enumerate(robot.legs):
        if hips[i, 1] <= center[1]:
            continue
        mirror = hips[i] * [1, -1, 1] + [0, 2 * center[1], 0]
        j = int(np.argmin(np.linalg.norm(hips - mirror, axis=1)))
        lj = robot.legs[j]
        if np.linalg.norm(hips[j] - mirror) > tol:
            continue  # no mirrored partner (odd layouts): nothing to compare
        shape_i, shape_j = rel[i][None], rel[j][None]
        if len(li["bodies"]) == len(lj["bodies"]):
            shape_i, shape_j = d.xpos[li["bodies"]] - hips[i], d.xpos[lj["bodies"]] - hips[j]
        if np.abs(shape_i * [1, -1, 1] - shape_j).max() > tol:
            out.append(f"legs {li['name']} and {lj['name']} are not mirror images at the default "
                       f"pose: foot - hip = {_fmt(rel[i])} and {_fmt(rel[j])} m")
    fore = hips[:, 0] > center[0]
    if fore.any() and (~fore).any() and feet[fore, 0].min() <= feet[~fore, 0].max():
        out.append("at the default pose a fore foot is not ahead of every hind foot "
                   f"(fore x {_fmt(feet[fore, 0])}, hind x {_fmt(feet[~fore, 0])} m)")
    return out, float(np.ptp(np.abs(rel[:, 1])))


def _fmt(v):
    return "(" + ", ".join(f"{x:+.3f}" for x in v) + ")"


# ------------------------------------------------------------------------------------------ play


def wrap(a):
    return (a + math.pi) % (2 * math.pi) - math.pi


def yaw_of(q):
    w, x, y, z = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


class Controller:
    """The deploy controller's policy mode plus the robot-side PD: targets at control_dt, clipped
    PD torques every physics step through `--latency-ms` of delay."""

    def __init__(self, robot, config, tensors, args):
        self.robot, self.config, self.tensors, self.io = robot, config, tensors, config["io"]
        self.decimation = round(self.io["control_dt"] / args.physics_dt)
        if self.decimation < 1 or abs(self.decimation * args.physics_dt - self.io["control_dt"]) > 1e-9:
            raise BadInput(f"--physics-dt {args.physics_dt} does not divide control_dt "
                           f"{self.io['control_dt']}")
        self.latency = round(args.latency_ms / 1000 / args.physics_dt)
        self.strength = args.motor_strength
        self.implicit_kd = None
        if args.pd == "implicit-kd":
            m = robot.m
            if m.opt.integrator == mujoco.mjtIntegrator.mjINT_RK4:
                raise BadInput("--pd implicit-kd needs the Euler or an implicit integrator, the "
                               "model uses RK4\nhint: --pd explicit")
            if m.opt.integrator == mujoco.mjtIntegrator.mjINT_EULER and \
                    m.opt.disableflags & mujoco.mjtDisableBit.mjDSBL_EULERDAMP:
                raise BadInput("--pd implicit-kd needs implicit joint damping (the model disables "
                               "eulerdamp)\nhint: --pd explicit")
            self.implicit_kd = self.strength * robot.kd
            m.dof_damping[robot.dadr] += self.implicit_kd

    def hold(self, targets, steps):
        """Physics steps with fixed targets (no latency queue needed)."""
        r = self.robot
        for _ in range(steps):
            self._pd(targets)
            mujoco.mj_step(r.m, r.d)

    def _pd(self, targets):
        """τ = strength · clip(kp (q* − q) − kd q̇, ±effort) at the start of the step. With
        `implicit_kd` the step applies τ + kd' q̇ and MuJoCo's implicit joint damping (kd' added to
        dof_damping) takes kd' q̇ back, evaluated at the step's end: the same torque to first order,
        stable at any step (see `--pd`)."""
        r = self.robot
        q, qd = r.d.qpos[r.qadr], r.d.qvel[r.dadr]
        tau = self.strength * np.clip(r.kp * (targets - q) - r.kd * qd, -r.effort, r.effort)
        if self.implicit_kd is not None:
            tau = tau + self.implicit_kd * qd
        r.d.qfrc_applied[r.dadr] = tau

    def run(self, commands, seconds, meter):
        """Plays the policy for `seconds`; `commands(base_quat)` gives (vx, vy, wz) each step.
        Ticks start at 0 with the policy, last_action at 0 (deploy's switch to policy mode)."""
        r, io = self.robot, self.io
        last_action = np.zeros(len(r.names))
        queue = deque([r.default.copy()] * (self.latency + 1), maxlen=self.latency + 1)
        for tick in range(round(seconds / io["control_dt"])):
            base, quat, _ = r.base_state()
            cmd = np.asarray(commands(quat), dtype=np.float64)
            obs = observation(io, base, cmd, r.d.qpos[r.qadr], r.d.qvel[r.dadr], last_action, tick)
            raw = numpy_policy.act(self.config, self.tensors, obs[None])[0]
            last_action = numpy_policy.filtered_action(self.config, last_action, raw)
            targets = numpy_policy.joint_targets(self.config, last_action).astype(np.float64)
            for _ in range(self.decimation):
                queue.append(targets)
                self._pd(queue[0])
                mujoco.mj_step(r.m, r.d)
            if not np.isfinite(r.d.qpos).all():
                meter.fell("non-finite state")
                return
            if meter.record(cmd, targets):
                return


class Meter:
    """Per-episode sums over control steps (the measures of task/src/gait.rs)."""

    def __init__(self, robot, standing, dt):
        self.robot, self.standing, self.dt = robot, standing, dt
        n = len(robot.legs)
        self.steps = 0
        self.sums = dict(xy_error=0.0, forward_speed=0.0, yaw_rate_error=0.0, height=0.0,
                         non_foot=0, chatter_sq=0.0)
        self.swing = np.zeros(n)
        self.touchdowns = np.zeros(n)
        self.chatter_steps = 0
        self.prev_contact = self.prev_targets = self.prev_yaw = None
        self.heading_change = 0.0
        self.fall = None

    def fell(self, why):
        self.fall = why

    def record(self, cmd, targets):
        """Adds the state after one control period; True when the robot fell (episode ends)."""
        r = self.robot
        (v, gyro, gravity), quat, height = r.base_state()
        feet, other, base_contact = r.contacts()
        s = self.sums
        self.steps += 1
        s["xy_error"] += math.hypot(cmd[0] - v[0], cmd[1] - v[1])
        s["yaw_rate_error"] += abs(cmd[2] - gyro[2])
        yaw = yaw_of(quat)
        v_world = r.d.qvel[r.free_v:r.free_v + 2]
        s["forward_speed"] += math.cos(yaw) * v_world[0] + math.sin(yaw) * v_world[1]  # heading frame
        s["height"] += height
        s["non_foot"] += other
        self.swing += ~feet
        if self.prev_contact is not None:
            self.touchdowns += feet & ~self.prev_contact
        self.prev_contact = feet
        if self.prev_targets is not None:
            s["chatter_sq"] += np.mean((targets - self.prev_targets) ** 2)
            self.chatter_steps += 1
        self.prev_targets = targets
        if self.prev_yaw is not None:
            self.heading_change += wrap(yaw - self.prev_yaw)
        self.prev_yaw = yaw
        tilt = math.degrees(math.acos(max(-1.0, min(1.0, -gravity[2]))))
        if height < FALL_HEIGHT_SHARE * self.standing:
            self.fall = f"base at {height:.3f} m"
        elif tilt > FALL_TILT_DEG:
            self.fall = f"tilted {tilt:.0f} deg"
        elif base_contact:
            self.fall = "trunk on the floor"
        return self.fall is not None

    def result(self):
        n = max(self.steps, 1)
        s = self.sums
        secs = max(self.steps * self.dt, 1e-9)
        names = [leg["name"] for leg in self.robot.legs]
        return {
            "seconds": self.steps * self.dt,
            "xy_error": s["xy_error"] / n,
            "forward_speed": s["forward_speed"] / n,
            "yaw_rate_error": s["yaw_rate_error"] / n,
            "heading_change_deg": abs(math.degrees(self.heading_change)),
            "base_height_m": s["height"] / n,
            "base_height_pct": 100 * s["height"] / n / self.standing,
            "swing_share": dict(zip(names, (self.swing / n).tolist())),
            "touchdown_hz": dict(zip(names, (self.touchdowns / secs).tolist())),
            "non_foot_contact_share": s["non_foot"] / n,
            "chatter_rad": math.sqrt(s["chatter_sq"] / max(self.chatter_steps, 1)),
            "fell": self.fall is not None,
            "fall": self.fall,
        }


def standing_heights(robot, ctl):
    """(held, nominal): the base height of the robot held at the default pose by the PD for 1 s,
    measured once per model — the 100% of base height, with the sag under its own weight and the
    feet's sinking into a soft floor, so that a policy is not blamed for either — and the
    kinematic height at which the feet just touch (what `l3p eval` divides by)."""
    robot.place(np.zeros(2), 0.0, robot.default)
    nominal = float(robot.d.xpos[robot.base][2])
    ctl.hold(robot.default, round(STANDING_SETTLE_S / robot.m.opt.timestep))
    return float(robot.d.xpos[robot.base][2]), nominal


def episode(robot, ctl, standing, forward, seed, seconds, args):
    """One (command, seed) run: place, settle, play; the meter's result."""
    rng = np.random.default_rng(seed)
    yaw = rng.uniform(-PERTURB_YAW, PERTURB_YAW)
    q0 = robot.default + rng.uniform(-PERTURB_JOINT, PERTURB_JOINT, robot.default.shape)
    robot.place(np.zeros(2), yaw, q0)
    ctl.hold(robot.default, round(args.settle_seconds / robot.m.opt.timestep))
    d = robot.d
    v = robot.free_v
    d.qvel[v:v + 2] += rng.uniform(-PERTURB_VEL, PERTURB_VEL, 2)
    d.qvel[v + 5] += rng.uniform(-PERTURB_YAW_RATE, PERTURB_YAW_RATE)  # body z ≈ world z when level
    target = yaw_of(d.qpos[robot.free_q + 3:robot.free_q + 7])

    def command(quat):
        wz = 0.0
        if args.heading_hold:  # IsaacLab's heading command: yaw rate toward the initial heading
            wz = float(np.clip(HEADING_STIFFNESS * wrap(target - yaw_of(quat)), -1.0, 1.0))
        return (forward, 0.0, wz)

    meter = Meter(robot, standing, ctl.io["control_dt"])
    ctl.run(command, seconds, meter)
    out = meter.result()
    out["seed"] = seed
    return out


# -------------------------------------------------------------------------------------- results

# Per scalar measure: how seeds combine into "worst".
WORST = {"xy_error": max, "forward_speed": min, "yaw_rate_error": max, "heading_change_deg": max,
         "base_height_m": min, "base_height_pct": min, "non_foot_contact_share": max,
         "chatter_rad": max}


def aggregate(runs):
    mean = {k: float(np.mean([r[k] for r in runs])) for k in WORST}
    worst = {k: f(r[k] for r in runs) for k, f in WORST.items()}
    for k in ("swing_share", "touchdown_hz"):
        legs = runs[0][k].keys()
        mean[k] = {leg: float(np.mean([r[k][leg] for r in runs])) for leg in legs}
    worst["swing_share_min"] = {leg: min(r["swing_share"][leg] for r in runs) for leg in legs}
    worst["swing_share_max"] = {leg: max(r["swing_share"][leg] for r in runs) for leg in legs}
    worst["touchdown_hz_min"] = {leg: min(r["touchdown_hz"][leg] for r in runs) for leg in legs}
    mean["falls"] = worst["falls"] = sum(r["fell"] for r in runs)
    return mean, worst


def failures(rows, stand, args):
    """The bounds that fail, as readable lines; every seed must meet each bound (worst seed)."""
    out = []
    if stand is not None:
        if stand["fell"]:
            out.append(f"stand check: fell ({stand['fall']})")
        if stand["base_height_pct"] < args.min_stand_height:
            out.append(f"stand check: base height {stand['base_height_pct']:.0f}% < "
                       f"{args.min_stand_height:.0f}% of standing")
    lo, hi = args.swing_share
    for row in rows:
        w, c = row["worst"], f"{row['forward']:.2f} m/s: "
        if w["falls"] > args.max_falls:
            why = "; ".join(f"seed {r['seed']}: {r['fall']}" for r in row["seeds"] if r["fell"])
            out.append(c + f"{w['falls']} falls > {args.max_falls} ({why})")
        if w["xy_error"] > args.max_xy_error:
            out.append(c + f"xy tracking error {w['xy_error']:.3f} > {args.max_xy_error:.3f} m/s")
        if w["heading_change_deg"] > args.max_heading_change:
            out.append(c + f"heading change {w['heading_change_deg']:.0f} > "
                       f"{args.max_heading_change:.0f} deg")
        if w["base_height_pct"] < args.min_height:
            out.append(c + f"base height {w['base_height_pct']:.0f}% < {args.min_height:.0f}% "
                       "of standing")
        for leg, s_min in w["swing_share_min"].items():
            s_max = w["swing_share_max"][leg]
            if s_min < lo or s_max > hi:
                out.append(c + f"foot {leg} swings {100 * s_min:.0f}-{100 * s_max:.0f}% of steps "
                           f"(want {100 * lo:.0f}-{100 * hi:.0f}%)")
        if w["non_foot_contact_share"] >= args.max_non_foot_contact:
            out.append(c + f"non-foot floor contact in {100 * w['non_foot_contact_share']:.1f}% of "
                       f"steps (want < {100 * args.max_non_foot_contact:.1f}%)")
        if w["chatter_rad"] > args.max_chatter:
            out.append(c + f"joint-target change {w['chatter_rad']:.3f} rad RMS per step > "
                       f"{args.max_chatter:.3f}")
    return out


def table(rows, stand, legs, nominal):
    """One row per command: mean over seeds, worst seed in brackets where the verdict reads it."""
    head = ["cmd m/s", "xy err m/s", "fwd m/s", "yaw err", "heading deg", "height %",
            "of nominal", "swing % " + "/".join(legs), "touchdowns/s", "non-foot %",
            "chatter rad", "falls"]
    body = []
    for row in rows:
        m, w = row["mean"], row["worst"]
        body.append([
            f"{row['forward']:.2f}", f"{m['xy_error']:.3f} ({w['xy_error']:.3f})",
            f"{m['forward_speed']:.2f}", f"{m['yaw_rate_error']:.3f}",
            f"{m['heading_change_deg']:.0f} ({w['heading_change_deg']:.0f})",
            f"{m['base_height_pct']:.0f} ({w['base_height_pct']:.0f})",
            f"{100 * m['base_height_m'] / nominal:.0f}",
            "/".join(f"{100 * m['swing_share'][leg]:.0f}" for leg in legs),
            "/".join(f"{m['touchdown_hz'][leg]:.1f}" for leg in legs),
            f"{100 * m['non_foot_contact_share']:.1f}",
            f"{m['chatter_rad']:.3f} ({w['chatter_rad']:.3f})", f"{m['falls']}/{len(row['seeds'])}",
        ])
    widths = [max(len(r[i]) for r in [head] + body) for i in range(len(head))]
    lines = [" | ".join(c.rjust(n) for c, n in zip(r, widths)) for r in [head] + body]
    lines.insert(1, "-" * len(lines[0]))
    if stand is not None:
        lines.append(f"stand check (zero command, {stand['seconds']:.0f} s): base height "
                     f"{stand['base_height_pct']:.0f}% of standing, "
                     + (f"fell ({stand['fall']})" if stand["fell"] else "no fall"))
    return "\n".join(lines)


# ------------------------------------------------------------------------------------------- cli


def floats(text):
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected comma-separated numbers, got {text!r}") from None


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0],
                                formatter_class=argparse.ArgumentDefaultsHelpFormatter)
    p.add_argument("export", help="l3p export directory (policy.json + policy.safetensors)")
    p.add_argument("--model", required=True, help="robot model: .urdf or MuJoCo .xml")
    g = p.add_argument_group("play")
    g.add_argument("--forward", type=floats, default=[0.5, 1.0],
                   help="constant forward commands (m/s), vy = 0, yaw rate 0 (or heading hold)")
    g.add_argument("--stand", action="store_true", help="zero command only: the stand check, "
                   "--seeds × --seconds")
    g.add_argument("--seconds", type=float, default=20.0, help="policy time per episode")
    g.add_argument("--seeds", type=int, default=3, help="episodes per command (perturbed starts)")
    g.add_argument("--heading-hold", action="store_true",
                   help="yaw-rate command = clip(0.5 · wrap(initial heading − heading), ±1)")
    g.add_argument("--settle-seconds", type=float, default=0.5,
                   help="PD at the default pose before the policy takes over")
    g.add_argument("--stand-seconds", type=float, default=5.0, help="stand check length (0: skip)")
    g.add_argument("--skip-contract-check", action="store_true",
                   help="play even if the model fails the contract check (to see what happens)")
    g = p.add_argument_group("physics")
    g.add_argument("--physics-dt", type=float, default=0.005, help="physics step (s)")
    g.add_argument("--pd", choices=["implicit-kd", "explicit"], default="implicit-kd",
                   help="explicit: the clipped PD torque as a constant force over the physics step; "
                   "implicit-kd: the same torque, its kd part integrated implicitly by MuJoCo "
                   "(explicit kd is unstable at 5 ms on light shins without rotor armature)")
    g.add_argument("--motor-strength", type=float, default=1.0, help="scale of the clipped PD torque")
    g.add_argument("--latency-ms", type=float, default=0.0, help="delay of the joint targets")
    g.add_argument("--foot-contact", choices=["soft", "rigid"], default="soft",
                   help="a URDF's feet: soft rubber as MuJoCo Menagerie's models have them (default), "
                   "or MuJoCo's rigid defaults (an MJCF keeps its own)")
    g.add_argument("--ground-friction", type=float, default=1.0,
                   help="friction of the floor this script adds (a model's own floor is kept)")
    g.add_argument("--no-passive", action="store_true",
                   help="zero the model's damping, friction loss, armature and stiffness on the "
                   "policy's joints")
    g.add_argument("--joint-damping", type=float,
                   help="passive damping (N·m·s/rad), all policy joints")
    g.add_argument("--joint-friction", type=float,
                   help="Coulomb friction loss (N·m), all policy joints")
    g.add_argument("--armature", type=float, help="rotor inertia (kg·m²), all policy joints")
    g = p.add_argument_group("verdict bounds (every seed must meet each)")
    g.add_argument("--max-xy-error", type=float, default=0.2, help="m/s")
    g.add_argument("--max-heading-change", type=float, default=15.0, help="deg over an episode")
    g.add_argument("--min-height", type=float, default=80.0, help="base height, %% of standing")
    g.add_argument("--min-stand-height", type=float, default=80.0, help="stand check, %% of standing")
    g.add_argument("--swing-share", type=floats, default=[0.2, 0.6], help="MIN,MAX per foot")
    g.add_argument("--max-non-foot-contact", type=float, default=0.02, help="share of steps (strict)")
    g.add_argument("--max-chatter", type=float, default=0.08, help="joint-target change RMS, rad")
    g.add_argument("--max-falls", type=int, default=0, help="per command, over all seeds")
    g = p.add_argument_group("output")
    g.add_argument("--json", help="write everything as JSON to this file, or - for stdout "
                   "(the table then goes to stderr)")
    g.add_argument("--require-pass", action="store_true", help="exit 1 when the verdict fails")
    args = p.parse_args(argv)
    if args.physics_dt <= 0 or args.seconds <= 0 or args.seeds < 1 or min(
            args.settle_seconds, args.stand_seconds, args.latency_ms) < 0:
        p.error("--physics-dt and --seconds must be > 0, --seeds >= 1, --settle-seconds, "
                "--stand-seconds and --latency-ms >= 0")
    if len(args.swing_share) != 2 or not args.forward:
        p.error("--swing-share takes MIN,MAX; --forward at least one speed")
    if args.stand:
        args.forward = [0.0]
    return args


def main(argv=None):
    try:
        args = parse_args(argv)
    except SystemExit as e:  # argparse exits 2 on bad arguments, which is our "bad input" too
        return e.code if isinstance(e.code, int) else 2
    started = time.monotonic()
    report_out = sys.stderr if args.json == "-" else sys.stdout
    try:
        config, tensors = load_export(args.export)
        io = config["io"]
        robot = load_model(args.model, io, args)
        passive = {n: {"damping": float(robot.m.dof_damping[a]),
                       "friction": float(robot.m.dof_frictionloss[a]),
                       "armature": float(robot.m.dof_armature[a])}
                   for n, a in zip(robot.names, robot.dadr)}
        ctl = Controller(robot, config, tensors, args)
        problems = contract_errors(robot)
    except BadInput as e:
        print(f"sim2sim: {e}", file=sys.stderr)
        return 2
    result = {
        "export": str(args.export), "model": str(args.model), "robot": config.get("robot"),
        "settings": {k: v for k, v in vars(args).items() if k not in ("export", "model", "json")},
        "feet": {leg["name"]: [robot.m.geom(g).name or f"{robot.m.body(robot.m.geom_bodyid[g]).name} "
                               f"geom {g}" for g in leg["feet"]] for leg in robot.legs},
        "passive": passive,
        "foot_contact": (args.foot_contact if Path(args.model).suffix.lower() == ".urdf"
                         else "the model's"),
        "contract": {"ok": not problems, "errors": problems},
    }
    if robot.extra_joints:
        print(f"sim2sim: note: model joints the policy does not drive (left passive): "
              f"{', '.join(robot.extra_joints)}", file=sys.stderr)
    if problems and not args.skip_contract_check:
        print("sim2sim: the model does not match the export's contract:\n  "
              + "\n  ".join(problems), file=sys.stderr)
        _write_json(args.json, result)
        return 2
    standing, nominal = standing_heights(robot, ctl)
    result.update(standing_height_m=standing, nominal_standing_height_m=nominal)
    stand = None
    if args.stand_seconds > 0 and not args.stand:
        stand = episode(robot, ctl, standing, 0.0, 0, args.stand_seconds, args)
    rows = []
    for forward in args.forward:
        runs = [episode(robot, ctl, standing, forward, seed, args.seconds, args)
                for seed in range(args.seeds)]
        mean, worst = aggregate(runs)
        rows.append({"forward": forward, "seeds": runs, "mean": mean, "worst": worst})
    if args.stand:  # the stand check is the verdict: height and falls of each seed
        stand = min(rows[0]["seeds"], key=lambda r: (not r["fell"], r["base_height_pct"]))
        failed = failures([], stand, args)
    else:
        failed = failures(rows, stand, args)
    result.update(stand=stand, commands=rows, verdict={"pass": not failed, "failures": failed},
                  wall_seconds=time.monotonic() - started)
    legs = [leg["name"] for leg in robot.legs]
    print(f"sim2sim: {args.export} on {args.model} ({len(legs)} legs, standing height "
          f"{standing:.3f} m held by the PD, {nominal:.3f} m nominal, physics "
          f"{1000 * args.physics_dt:g} ms, {args.seeds} seeds × {args.seconds:g} s)", file=report_out)
    print(table(rows, stand, legs, nominal), file=report_out)
    print("verdict: " + ("PASS" if not failed else "FAIL\n  " + "\n  ".join(failed)), file=report_out)
    _write_json(args.json, result)
    return 1 if failed and args.require_pass else 0


def _write_json(target, result):
    if target is None:
        return
    text = json.dumps(result, indent=1)
    if target == "-":
        print(text)
    else:
        Path(target).write_text(text + "\n")


if __name__ == "__main__":
    sys.exit(main())
