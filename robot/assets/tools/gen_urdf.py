#!/usr/bin/env python3
"""Generates the project's own quadruped URDF files (robots/assets/*.urdf).

Each robot is described by a small table of published physical parameters: leg link masses and
centre-of-mass offsets, joint positions, joint axes and limits, body box size and foot radius. Inertias
are computed from primitive shapes (solid box for the body and hip, rod for thigh and calf), so they are
approximations; collision shapes are a box (body), capsules (thigh, calf) and a sphere (foot).
Sources per robot are listed in robots/NOTES.md. Run: python3 gen_urdf.py (writes ../*.urdf).
"""
import math, os

def box_inertia(m, x, y, z):
    return (m*(y*y+z*z)/12, m*(x*x+z*z)/12, m*(x*x+y*y)/12)

def rod_inertia(m, r, l):  # rod along z
    i = m*(3*r*r+l*l)/12
    return (i, i, m*r*r/2)

def f(v):
    return " ".join(f"{x:.6g}" for x in v)

ROBOTS = {
  # name: dict(...)  — all leg vectors are for the front-left leg; y is mirrored for right legs,
  # x of the hind hip position is mirrored; mirror_x also mirrors leg offsets for hind legs (ANYmal).
  "a1": dict(base="trunk", legs=["FL","FR","RL","RR"], fmt="{leg}_{part}", parts=["hip","thigh","calf","foot"],
     jfmt="{leg}_{part}_joint", body=(0.267,0.194,0.114), base_mass=6.001, base_com=(0,0.0041,-0.0005),
     hip=(0.1805,0.047,0), thigh_off=(0,0.0838,0), knee_off=(0,0,-0.2), foot_off=(0,0,-0.2), foot_r=0.02,
     m=(0.696,1.013,0.166,0.06), com_hip=(-0.0033,0.0006,0), com_thigh=(-0.0032,-0.0223,-0.0273), com_calf=(0.0047,0,-0.1),
     r_thigh=0.02, r_calf=0.012, hip_box=(0.08,0.08,0.08), mirror_x=False,
     lim=[(-0.802851,0.802851),(-1.047198,4.188790),(-2.696534,-0.916298)], lim_hind_thigh=None,
     effort=[33.5,33.5,33.5], vel=[21.0,21.0,21.0]),
  "go1": dict(base="trunk", legs=["FL","FR","RL","RR"], fmt="{leg}_{part}", parts=["hip","thigh","calf","foot"],
     jfmt="{leg}_{part}_joint", body=(0.3762,0.0935,0.114), base_mass=5.5611, base_com=(0.0209,0.0019,-0.0005),
     hip=(0.1881,0.04675,0), thigh_off=(0,0.08,0), knee_off=(0,0,-0.213), foot_off=(0,0,-0.213), foot_r=0.02,
     m=(0.68,1.009,0.1359,0.06), com_hip=(-0.0049,-0.0076,0), com_thigh=(-0.003,-0.0193,-0.0305), com_calf=(0.0043,0.001,-0.11),
     r_thigh=0.02, r_calf=0.012, hip_box=(0.08,0.08,0.08), mirror_x=False,
     lim=[(-0.863,0.863),(-0.686,4.501),(-2.818,-0.888)], lim_hind_thigh=None,
     effort=[23.7,23.7,35.55], vel=[30.1,30.1,20.06]),
  "go2": dict(base="base", legs=["FL","FR","RL","RR"], fmt="{leg}_{part}", parts=["hip","thigh","calf","foot"],
     jfmt="{leg}_{part}_joint", body=(0.3762,0.0935,0.114), base_mass=7.279, base_com=(0.0202,0,-0.0051),
     hip=(0.1934,0.0465,0), thigh_off=(0,0.0955,0), knee_off=(0,0,-0.213), foot_off=(0,0,-0.213), foot_r=0.022,
     m=(0.767,1.241,0.154,0.04), com_hip=(-0.0048,0.0017,0), com_thigh=(-0.0035,-0.023,-0.0304), com_calf=(0.0044,-0.0008,-0.12),
     r_thigh=0.02, r_calf=0.013, hip_box=(0.08,0.08,0.08), mirror_x=False,
     lim=[(-1.0472,1.0472),(-1.5708,3.4907),(-2.7227,-0.83776)], lim_hind_thigh=(-0.5236,4.5379),
     effort=[23.7,23.7,45.43], vel=[30.1,30.1,15.7]),
  "anymal_b": dict(base="base", legs=["LF","RF","LH","RH"], fmt="{leg}_{part}", parts=["HIP","THIGH","SHANK","FOOT"],
     jfmt="{leg}_{part}", jparts=["HAA","HFE","KFE"], body=(0.531,0.27,0.24), body_z=0.08, base_mass=16.7935, base_com=(-0.002,-0.0014,0.0502),
     hip=(0.277,0.116,0), thigh_off=(0.0635,0.041,0), knee_off=(0,0.109,-0.25), foot_off=(0.1,-0.02,-0.298), foot_r=0.031,
     m=(1.4246,1.635,0.2874,0.06), com_hip=(0.0645,-0.0038,0), com_thigh=(-0.0039,0.0542,-0.2146), com_calf=(0.0587,-0.0108,-0.0981),
     r_thigh=0.04, r_calf=0.025, hip_box=(0.12,0.1,0.1), mirror_x=True,
     lim=[(-0.72,0.49),(-9.42,9.42),(-9.42,9.42)], lim_hind_thigh=None,
     effort=[80,80,80], vel=[15,15,15]),
  "anymal_c": dict(base="base", legs=["LF","RF","LH","RH"], fmt="{leg}_{part}", parts=["HIP","THIGH","SHANK","FOOT"],
     jfmt="{leg}_{part}", jparts=["HAA","HFE","KFE"], body=(0.58,0.14,0.18), base_mass=26.3732, base_com=(-0.0178,-0.0002,0.0085),
     hip=(0.2999,0.104,0), thigh_off=(0.0599,0.08381,0), knee_off=(0,0.1003,-0.285), foot_off=(0.08795,0.01305,-0.31547), foot_r=0.03,
     m=(2.781,3.071,0.5284,0.06), com_hip=(0.0567,0.0174,0), com_thigh=(0,0.0308,-0.2457), com_calf=(0.0613,0.0055,-0.0807),
     r_thigh=0.045, r_calf=0.03, hip_box=(0.15,0.12,0.12), mirror_x=True,
     lim=[(-0.72,0.49),(-9.424778,9.424778),(-9.424778,9.424778)], lim_hind_thigh=None,
     effort=[80,80,80], vel=[7.5,7.5,7.5]),
  "anymal_d": dict(base="base", legs=["LF","RF","LH","RH"], fmt="{leg}_{part}", parts=["HIP","THIGH","SHANK","FOOT"],
     jfmt="{leg}_{part}", jparts=["HAA","HFE","KFE"], body=(0.894,0.1615,0.256), body_z=0.016,
     # base mass includes the 5.27 kg inspection payload (pan/tilt joints fixed)
     base_mass=31.8518, base_com=(0.0, 0.0, 0.02),
     hip=(0.304,0.109,0), thigh_off=(0.069,0.006,0), knee_off=(0,0.1805,-0.285), foot_off=(0.1,0.01411,-0.36208), foot_r=0.031455,
     m=(0.3659,5.1322,0.736,0.06), com_hip=(0.035,-0.0012,0), com_thigh=(0,0.0905,-0.1402), com_calf=(0.0509,0.0081,-0.09),
     r_thigh=0.045, r_calf=0.03, hip_box=(0.1,0.1,0.1), mirror_x=True,
     lim=[(-0.7853985,0.6108655),(-9.424778,9.424778),(-9.424778,9.424778)], lim_hind_thigh=None,
     effort=[80,80,80], vel=[8.5,8.5,8.5]),
  # Spot: kinematics from the Spot SDK's kinematic URDF; masses are estimates that sum to the
  # published 32.7 kg (Boston Dynamics Spot specifications), leg/body split estimated.
  "spot": dict(base="body", legs=["fl","fr","hl","hr"], fmt="{leg}_{part}", parts=["hip","uleg","lleg","foot"],
     jfmt="{leg}_{part}", jparts=["hx","hy","kn"], body=(0.85,0.24,0.18), base_mass=20.7, base_com=(0,0,0),
     hip=(0.29785,0.055,0), thigh_off=(0,0.1108,0), knee_off=(0.025,0,-0.32), foot_off=(0,0,-0.3365), foot_r=0.036,
     m=(1.0,1.5,0.4,0.1), com_hip=(0,0,0), com_thigh=(0,0,-0.14), com_calf=(0,0,-0.16),
     r_thigh=0.045, r_calf=0.025, hip_box=(0.1,0.1,0.1), mirror_x=False,
     lim=[(-0.785398,0.785398),(-0.898845,2.295108),(-2.7929,-0.254402)], lim_hind_thigh=None,
     effort=[45,45,115], vel=[15,15,15]),
}

def link(name, m, com, inertia, colls):
    s = f'  <link name="{name}">\n'
    s += f'    <inertial>\n      <origin xyz="{f(com)}" rpy="0 0 0"/>\n      <mass value="{m:.6g}"/>\n'
    ixx, iyy, izz = inertia
    s += f'      <inertia ixx="{ixx:.6g}" ixy="0" ixz="0" iyy="{iyy:.6g}" iyz="0" izz="{izz:.6g}"/>\n    </inertial>\n'
    for (geom, xyz, rpy) in colls:
        s += f'    <collision>\n      <origin xyz="{f(xyz)}" rpy="{f(rpy)}"/>\n      <geometry>{geom}</geometry>\n    </collision>\n'
    return s + '  </link>\n'

def joint(name, typ, parent, child, xyz, axis=None, lim=None, effort=None, vel=None):
    s = f'  <joint name="{name}" type="{typ}">\n    <parent link="{parent}"/>\n    <child link="{child}"/>\n'
    s += f'    <origin xyz="{f(xyz)}" rpy="0 0 0"/>\n'
    if axis:
        s += f'    <axis xyz="{f(axis)}"/>\n'
    if lim:
        s += f'    <limit lower="{lim[0]:.6g}" upper="{lim[1]:.6g}" effort="{effort:.6g}" velocity="{vel:.6g}"/>\n'
    return s + '  </joint>\n'

def capsule_between(a, b, r):
    d = [b[i]-a[i] for i in range(3)]
    n = math.sqrt(sum(x*x for x in d))
    ax = [-x/n for x in d]
    roll = math.asin(max(-1, min(1, -ax[1])))
    pitch = math.atan2(ax[0], ax[2])
    mid = [(a[i]+b[i])/2 for i in range(3)]
    length = max(n - 2*r, 0.01)
    return (f'<capsule radius="{r:.6g}" length="{length:.6g}"/>', mid, (roll, pitch, 0))

def gen(name, p):
    parts = p["parts"]; jparts = p.get("jparts", parts[:3])
    out = f'<?xml version="1.0"?>\n<!-- {name}: generated by assets/tools/gen_urdf.py from published parameters (see robots/NOTES.md). Primitive collision shapes only. -->\n<robot name="{name}">\n'
    bx, by, bz = p["body"]
    out += link(p["base"], p["base_mass"], p["base_com"], box_inertia(p["base_mass"], bx, by, bz),
                [(f'<box size="{f(p["body"])}"/>', (0, 0, p.get("body_z", 0)), (0, 0, 0))])
    for leg in p["legs"]:
        right = leg[-1].upper() == "R" if name != "spot" else leg[1] == "r"
        if name.startswith("anymal"):
            right = leg[0] == "R"; hind = leg[1] == "H"
        elif name == "spot":
            hind = leg[0] == "h"
        else:
            right = leg[1] == "R"; hind = leg[0] == "R"
        sy = -1 if right else 1
        sx = -1 if (hind and p["mirror_x"]) else 1
        def mir(v, mx=True):
            return (v[0]*(sx if mx else 1), v[1]*sy, v[2])
        hip_pos = (p["hip"][0]*(-1 if hind else 1), p["hip"][1]*sy, p["hip"][2])
        ln = [p["fmt"].format(leg=leg, part=pt) for pt in parts]
        jn = [p["jfmt"].format(leg=leg, part=pt) for pt in jparts]
        mh, mt, mc, mf = p["m"]
        com_hip = (p["com_hip"][0]*(-1 if hind else 1), p["com_hip"][1]*sy, p["com_hip"][2])
        out += link(ln[0], mh, com_hip, box_inertia(mh, *p["hip_box"]), [])
        ko = mir(p["knee_off"]); fo = mir(p["foot_off"])
        lt = math.sqrt(sum(x*x for x in ko)); lc = math.sqrt(sum(x*x for x in fo))
        top = (0, ko[1], 0)
        out += link(ln[1], mt, mir(p["com_thigh"]), rod_inertia(mt, p["r_thigh"], lt),
                    [capsule_between(top, ko, p["r_thigh"])])
        out += link(ln[2], mc, mir(p["com_calf"]), rod_inertia(mc, p["r_calf"], lc),
                    [capsule_between((0, 0, 0), fo, p["r_calf"])])
        r = p["foot_r"]
        fi = 2*mf*r*r/5
        out += link(ln[3], mf, (0, 0, 0), (fi, fi, fi), [(f'<sphere radius="{r:.6g}"/>', (0, 0, 0), (0, 0, 0))])
        lims = list(p["lim"])
        if hind and p["lim_hind_thigh"]:
            lims[1] = p["lim_hind_thigh"]
        hl = lims[0] if not right else (-lims[0][1], -lims[0][0])
        out += joint(jn[0], "revolute", p["base"], ln[0], hip_pos, (1, 0, 0), hl, p["effort"][0], p["vel"][0])
        out += joint(jn[1], "revolute", ln[0], ln[1], mir(p["thigh_off"]), (0, 1, 0), lims[1], p["effort"][1], p["vel"][1])
        out += joint(jn[2], "revolute", ln[1], ln[2], ko, (0, 1, 0), lims[2], p["effort"][2], p["vel"][2])
        out += joint(f"{ln[3]}_fixed", "fixed", ln[2], ln[3], fo)
    return out + "</robot>\n"

if __name__ == "__main__":
    here = os.path.dirname(os.path.abspath(__file__))
    for name, p in ROBOTS.items():
        with open(os.path.join(here, "..", f"{name}.urdf"), "w") as fh:
            fh.write(gen(name, p))
        total = p["base_mass"] + 4*sum(p["m"])
        print(f"{name}: total mass {total:.3f} kg")
