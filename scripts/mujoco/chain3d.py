#!/usr/bin/env python3
"""MuJoCo reference trajectories of motionlab's `chain3d` (src/physics/body3d/chain3d.rs).

The model is built from `motionlab describe chain3d`'s JSON (bodies, joints, masses, full
inertia tensors, offsets, joint-frame quaternions, damping, gravity), so the two simulators
read one description. MuJoCo runs it with its RK4 integrator, no contact, armature 0, and
the motors' torques applied as `qfrc_applied` (a ball's three torques act about the body's
axes, as in motionlab).

State conventions are the same in both: `qpos` = [torso position (world, m), torso
quaternion (w, x, y, z), upper ball quaternion, lower angle, arm angle] and `qvel` =
[torso linear velocity in world coordinates, torso angular velocity in body coordinates,
upper relative angular velocity in its body coordinates, lower rate, arm rate]. MuJoCo's
free joint stores the linear velocity in the world frame and the angular velocity in the
body's local frame (mjModel docs, "qvel"; engine_core_smooth.c, mj_comPos uses the body
axes for the rotational dofs); `check_conventions` below verifies both on this model by
differentiating qpos with mj_differentiatePos.

MuJoCo's RK4 moves positions on the manifold (mj_integratePos: q ⊗ exp(h ω̄ / 2)), which
is second order for a quaternion whose angular velocity turns; motionlab's RK4 steps
q̇ = ½ q ⊗ (0, ω) in R⁴ (fourth order). Both converge to the same solution; `--converge`
measures how far MuJoCo at the stored step is from MuJoCo at a 64 times smaller one, so the
references are written at a step where that distance is far below the test tolerance.

Usage (from the repository root):

    motionlab describe chain3d > /tmp/chain3d.json
    python scripts/mujoco/chain3d.py --describe /tmp/chain3d.json --out tests/data/chain3d
    python scripts/mujoco/chain3d.py --describe /tmp/chain3d.json --converge

Needs `mujoco` and `numpy` (pip install mujoco numpy).
"""

import argparse
import json
import math
import sys
from pathlib import Path

import mujoco
import numpy as np

DURATION = 2.0  # s
EVERY = 0.02  # s between written rows


def axis_angle_quat(axis, angle):
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    return [math.cos(angle / 2)] + list(math.sin(angle / 2) * a)


# Starts: (name, torso position, torso quaternion, upper quaternion, lower angle, arm angle,
# torso linear velocity (world), torso angular velocity (body), upper angular velocity (body),
# lower rate, arm rate, constant torques [upper tx, ty, tz, lower, arm]).
STARTS = [
    (
        "tumble",
        [0.1, -0.2, 1.0],
        axis_angle_quat([0.3, -0.5, 0.8], 0.7),
        axis_angle_quat([1.0, 0.4, -0.2], 0.5),
        0.4,
        -0.3,
        [0.3, -0.1, 1.5],
        [0.8, -0.6, 1.1],
        [-0.5, 0.9, 0.3],
        1.2,
        -0.8,
        [0.0] * 5,
    ),
    (
        "spin",
        [0.0, 0.0, 2.0],
        axis_angle_quat([-0.6, 0.2, 0.5], 2.1),
        axis_angle_quat([0.1, -0.9, 0.4], 1.3),
        -1.1,
        0.9,
        [-0.4, 0.6, 0.2],
        [2.0, 1.5, -2.5],
        [1.5, -1.0, 2.0],
        -2.0,
        3.0,
        [0.0] * 5,
    ),
    (
        "driven",
        [0.5, 0.3, 0.8],
        axis_angle_quat([0.0, 1.0, 0.2], -0.4),
        axis_angle_quat([0.7, 0.7, 0.1], 0.9),
        0.8,
        0.2,
        [0.0, 0.0, 0.5],
        [-0.3, 0.4, 0.2],
        [0.2, 0.1, -0.4],
        0.5,
        -1.5,
        [0.3, -0.2, 0.15, 0.1, -0.05],
    ),
]


def bodies_of(desc):
    """Bodies in describe's order, each a dict of its parameters."""
    params = {p["name"]: p["value"] for p in desc["parameters"]}
    names = [p["name"][: -len(".parent")] for p in desc["parameters"] if p["name"].endswith(".parent")]
    out = []
    for n in names:
        g = lambda k, n=n: params[f"{n}.{k}"]  # noqa: E731
        b = {
            "name": n,
            "parent": int(g("parent")),
            "joint": {0: "free", 1: "ball", 2: "hinge"}[int(g("joint"))],
            "mass": g("mass"),
            "com": [g(f"com.{c}") for c in "xyz"],
            "inertia": [g(f"inertia.{c}") for c in ("ixx", "iyy", "izz", "ixy", "ixz", "iyz")],
        }
        if b["parent"] >= 0:
            b["offset"] = [g(f"offset.{c}") for c in "xyz"]
            b["orientation"] = [g(f"orientation.{c}") for c in "wxyz"]
            b["damping"] = g("damping")
        if b["joint"] == "hinge":
            b["axis"] = [g(f"axis.{c}") for c in "xyz"]
        out.append(b)
    return out, params["gravity"]


def mjcf(desc, dt):
    bodies, gravity = bodies_of(desc)
    f = lambda v: " ".join(repr(float(x)) for x in v)  # noqa: E731

    def body_xml(i, depth):
        b = bodies[i]
        pad = "  " * depth
        if b["parent"] < 0:
            head = f'{pad}<body name="{b["name"]}">\n{pad}  <freejoint name="{b["name"]}"/>\n'
        else:
            head = f'{pad}<body name="{b["name"]}" pos="{f(b["offset"])}" quat="{f(b["orientation"])}">\n'
            axis = f' axis="{f(b["axis"])}"' if b["joint"] == "hinge" else ""
            head += (
                f'{pad}  <joint name="{b["name"]}" type="{b["joint"]}"{axis} '
                f'damping="{b["damping"]!r}" armature="0"/>\n'
            )
        head += (
            f'{pad}  <inertial pos="{f(b["com"])}" mass="{b["mass"]!r}" '
            f'fullinertia="{f(b["inertia"])}"/>\n'
        )
        kids = "".join(body_xml(j, depth + 1) for j, c in enumerate(bodies) if c["parent"] == i)
        return head + kids + f"{pad}</body>\n"

    roots = "".join(body_xml(i, 2) for i, b in enumerate(bodies) if b["parent"] < 0)
    return f"""<mujoco model="chain3d">
  <option timestep="{dt!r}" integrator="RK4" gravity="0 0 {-gravity!r}">
    <flag contact="disable" energy="enable"/>
  </option>
  <worldbody>
{roots}  </worldbody>
</mujoco>
"""


def start_state(s):
    _, p, q0, q1, a, b, v, w0, w1, ra, rb, tau = s
    return np.array(p + q0 + q1 + [a, b]), np.array(v + w0 + w1 + [ra, rb]), np.array(tau)


def simulate(model, start, dt, every):
    """Rows [t, qpos, qvel, potential + kinetic energy] every `every` seconds over DURATION."""
    data = mujoco.MjData(model)
    qpos, qvel, tau = start_state(start)
    data.qpos[:] = qpos
    data.qvel[:] = qvel
    data.qfrc_applied[:] = np.concatenate([np.zeros(6), tau])
    steps = round(DURATION / dt)
    stride = round(every / dt)
    rows = []
    for k in range(steps + 1):
        if k % stride == 0:
            mujoco.mj_forward(model, data)
            rows.append(np.concatenate([[k * dt], data.qpos, data.qvel, [data.energy.sum()]]))
        if k < steps:
            mujoco.mj_step(model, data)
    return np.array(rows)


def quat_angle(a, b):
    """Angle (rad) of the rotation a⁻¹ b between unit quaternions a and b."""
    r = np.zeros(4)
    inv = np.array([a[0], -a[1], -a[2], -a[3]])
    mujoco.mju_mulQuat(r, inv / np.linalg.norm(a), b / np.linalg.norm(b))
    # atan2 keeps full precision for tiny angles (acos of the dot product does not).
    return 2.0 * math.atan2(float(np.linalg.norm(r[1:])), abs(float(r[0])))


def angle_errors(model, ra, rb):
    """Largest angle difference (rad) between two trajectories over every joint."""
    worst = 0.0
    for x, y in zip(ra, rb):
        qa, qb = x[1 : 1 + model.nq], y[1 : 1 + model.nq]
        for j in range(model.njnt):
            adr = model.jnt_qposadr[j]
            t = model.jnt_type[j]
            if t == mujoco.mjtJoint.mjJNT_FREE:
                e = quat_angle(qa[adr + 3 : adr + 7], qb[adr + 3 : adr + 7])
            elif t == mujoco.mjtJoint.mjJNT_BALL:
                e = quat_angle(qa[adr : adr + 4], qb[adr : adr + 4])
            else:
                e = abs(qa[adr] - qb[adr])
            worst = max(worst, e)
    return worst


def check_conventions(model):
    """The free joint's qvel: linear in world, angular in body coordinates."""
    data = mujoco.MjData(model)
    qpos, qvel, _ = start_state(STARTS[1])
    data.qpos[:] = qpos
    data.qvel[:] = qvel
    h = 1e-7
    q2 = data.qpos.copy()
    mujoco.mj_integratePos(model, q2, data.qvel, h)
    # Linear: the position moves by h ṗ in world coordinates.
    assert np.allclose((q2[:3] - qpos[:3]) / h, qvel[:3], atol=1e-6)
    # Angular: q(t+h) ≈ q ⊗ (1, h ω/2) with ω in body coordinates.
    qb = np.zeros(4)
    mujoco.mju_mulQuat(qb, qpos[3:7], np.concatenate([[1.0], 0.5 * h * qvel[3:6]]))
    assert np.allclose(q2[3:7], qb / np.linalg.norm(qb), atol=1e-12)
    # And the body's world angular velocity (cvel) is R ω.
    mujoco.mj_forward(model, data)
    wv = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, 1, wv, 0)
    r = data.xmat[1].reshape(3, 3)
    assert np.allclose(wv[:3], r @ qvel[3:6], atol=1e-12)


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--describe", required=True, help="`motionlab describe chain3d` JSON")
    ap.add_argument("--out", help="folder for the reference CSVs")
    ap.add_argument("--dt", type=float, help="MuJoCo step (s); default describe's dt")
    ap.add_argument("--converge", action="store_true", help="report MuJoCo's own step error")
    args = ap.parse_args()
    desc = json.loads(Path(args.describe).read_text())
    dt = args.dt or desc["dt"]
    model = mujoco.MjModel.from_xml_string(mjcf(desc, dt))
    assert model.nq + model.nv == len(desc["state"]), "state layout differs"
    check_conventions(model)
    if args.converge:
        fine = mujoco.MjModel.from_xml_string(mjcf(desc, dt / 64))
        for s in STARTS:
            a = simulate(model, s, dt, EVERY)
            b = simulate(fine, s, dt / 64, EVERY)
            print(f"{s[0]}: largest angle difference, step {dt} vs {dt / 64}: "
                  f"{angle_errors(model, a, b):.3e} rad")
    if args.out:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        header = ["t"] + desc["state"] + ["energy"] + [f"u_{c}" for c in desc["controls"]]
        for s in STARTS:
            rows = simulate(model, s, dt, EVERY)
            tau = np.tile(start_state(s)[2], (len(rows), 1))
            rows = np.hstack([rows, tau])
            path = out / f"{s[0]}.csv"
            with path.open("w") as fh:
                fh.write(f"# MuJoCo {mujoco.__version__} RK4, dt = {dt!r} s, chain3d start `{s[0]}`\n")
                fh.write(",".join(header) + "\n")
                for r in rows:
                    fh.write(",".join(f"{v:.17g}" for v in r) + "\n")
            print(f"wrote {path} ({len(rows)} rows)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
