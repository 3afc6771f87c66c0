#!/usr/bin/env python3
"""Run an l3p export (policy.safetensors) with numpy only: no torch, no safetensors package.

    python3 numpy_policy.py <export dir or policy.safetensors> [observations.json]

Reads a JSON list of observations (each `obs_dim` floats; stdin when no file is given) and prints
a JSON list of action means. Each control period a controller then (see config["io"]):
  - filters the action: a = a_prev + alpha * (clip(raw) - a_prev), a_prev = 0 at start
    (`filtered_action`; alpha = io["action_filter_alpha"], 1 = no filter); `a` is also the next
    observation's `last_action`;
  - sends joint targets q* = default + action_scale * a (`joint_targets`);
  - with io["gait_clock_hz"] > 0, appends the clock's [sin, cos] to the observation (`gait_clock`,
    ticks = policy steps since the policy took over).
"""
import json
import struct
import sys
from pathlib import Path

import numpy as np


def load(path):
    path = Path(path)
    if path.is_dir():
        path = path / "policy.safetensors"
    raw = path.read_bytes()
    (header_len,) = struct.unpack("<Q", raw[:8])
    header = json.loads(raw[8 : 8 + header_len])
    config = json.loads(header.pop("__metadata__")["l3p_export"])
    data = raw[8 + header_len :]
    tensors = {}
    for name, t in header.items():
        assert t["dtype"] == "F32", (name, t["dtype"])
        begin, end = t["data_offsets"]
        tensors[name] = np.frombuffer(data[begin:end], dtype="<f4").reshape(t["shape"])
    return config, tensors


def act(config, tensors, obs):
    """Action means for observations `obs` ([n, obs_dim]): dense layers in order, ELU where named."""
    x = np.asarray(obs, dtype=np.float32)
    for layer in config["layers"]:
        w = tensors[layer["name"] + ".weight"]  # [out, in], like torch.nn.Linear
        b = tensors[layer["name"] + ".bias"]
        x = x @ w.T + b
        if layer["activation"] == "elu":
            x = np.where(x > 0, x, np.expm1(np.minimum(x, 0)))
    return x


def filtered_action(config, previous, raw):
    """The applied action: the raw output clipped, then low-pass filtered against the previous one."""
    io = config["io"]
    alpha = io.get("action_filter_alpha", 1.0)
    a = np.clip(np.nan_to_num(raw, nan=0.0), -io["action_clip"], io["action_clip"])
    return previous + alpha * (a - previous)


def gait_clock(config, ticks):
    """The `gait_clock` observation segment after `ticks` policy steps: [sin 2*pi*phi, cos 2*pi*phi]."""
    io = config["io"]
    cycles = ticks * float(io.get("gait_clock_hz", 0.0)) * float(np.float32(io["control_dt"]))
    phase = cycles - np.floor(cycles)
    return np.array([np.sin(2 * np.pi * phase), np.cos(2 * np.pi * phase)], dtype=np.float32)


def joint_targets(config, actions):
    io = config["io"]
    a = np.clip(actions, -io["action_clip"], io["action_clip"])
    q = np.asarray(io["default_joint_pos"], dtype=np.float32) + config["action_scale"] * a
    lo, hi = np.asarray(io["soft_joint_limits"], dtype=np.float32).T
    return np.clip(q, lo, hi)


if __name__ == "__main__":
    config, tensors = load(sys.argv[1])
    source = open(sys.argv[2]) if len(sys.argv) > 2 else sys.stdin
    obs = np.asarray(json.load(source), dtype=np.float32).reshape(-1, config["obs_dim"])
    print(json.dumps(act(config, tensors, obs).tolist()))
