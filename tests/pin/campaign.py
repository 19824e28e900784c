#!/usr/bin/env python3
"""An independent generator of PA10-6C measurement campaigns, built on Pinocchio.

The judge of `pa10 calibrate` and `pa10 discover`: it shares no code with `src/` (no pa10
item, not `pa10 urdf`). Its robot is a URDF written here from `shared/pa10-facts.md` (the
standard DH table of section 1.2, the lumped 6C masses of section 2.3, the seed paper's
springs of section 4), with hidden departures within the paper's tolerances and Hayati's
beta on joint 2. Forward kinematics, the tool Jacobian and the gravity torques are
Pinocchio's (`forwardKinematics`, `computeFrameJacobian`, `computeGeneralizedGravity`).

Every campaign *design* is drawn from its seed, not fixed: tool length 0.1-0.5 m tilted
0-45 degrees; the instrument anywhere around the base (any yaw, +-0.1 rad roll and pitch,
0.5-1.5 m away); 15-40 configurations whose tool point lies in the instrument's measuring
volume; two to four loads up to 90 N; 1-10 repeats; one of three resolver-noise families
(reading noise, a repeatable error per configuration, both) with per-axis instrument noise
and torque noise; 0, 1 or 2 hidden effects from a pool in the discovery library and
outside it.

    python3 tests/pin/campaign.py --seed 7 --out DIR [--hidden none|spring_j4,scale_j3] \
        [--family reading|repeatable|both] [--configs N] [--paper] [--detectability] [--poses FILE]

writes DIR/cal.csv, DIR/val.csv (held-out configurations at 0/44/90 N, one measurement
each), their sidecars (`*.meta.yaml`: tool, noise), DIR/robot.urdf and DIR/truth.json (the
design, the hidden effects and the validation floor: what the judge scores against; the
tool under test never reads it; with `--detectability` also each hidden effect's
noncentrality on the calibration and held-out sets, `noncentrality()`). `--paper` keeps the design of the seed paper's campaign
(27 configurations x 0/22/44 N x 10 repeats, a 0.35 m tool) and still draws the robot,
the instrument and the noise. `--poses FILE` measures the configurations and loads of a pose
list (`pa10 plan --out`) instead of drawn ones, with the design's repeats, everything else the
seed's (truth.json gives the measuring volume and the tool to plan in: `volume`, `tool_matrix`).
"""

import argparse
import json
import math
import os
import sys

import numpy as np
import pinocchio as pin

G = 9.80665
ARCMIN = math.pi / (180.0 * 60.0)
HALF_PI = math.pi / 2.0

# pa10-facts.md section 1.2, standard DH: (a, alpha, d, theta offset), m and rad.
DH = [
    (0.0, -HALF_PI, 0.317, 0.0),
    (0.450, 0.0, 0.0, -HALF_PI),
    (0.0, HALF_PI, 0.0, HALF_PI),
    (0.0, -HALF_PI, 0.480, 0.0),
    (0.0, HALF_PI, 0.0, 0.0),
    (0.0, 0.0, 0.070, 0.0),
]
# pa10-facts.md section 4: the seed paper's springs (k1 N m/rad, k3 N m/rad^3), by joint.
SPRINGS = {2: (1.98e4, 3.35e7), 3: (1.27e4, 1.46e7), 5: (2.56e3, 3.83e7)}
# pa10-facts.md section 2.3, the lumped 6C approximation: (link, kg, distance of the
# centre of mass along the segment to the next joint, m, or None: on the link's origin).
MASSES = [
    (1, 9.78, None),
    (2, 11.92, 0.149),  # upper arm, from the shoulder
    (3, 1.00, None),  # elbow housing (not in the facts: a small guess)
    (4, 8.32, 0.164),  # forearm, from the elbow
    (5, 1.70, -0.020),  # wrist, from the wrist centre
    (6, 0.24, 0.010),
]
JOINT_LIMIT = [3.0892, 1.5882, 2.3911, 4.4506, 2.8798, 4.4506]
# Sampling ranges of the configurations (rad): clear of the limits and of the wrist
# singularity (|q5| small) and of the elbow singularity (q3 near 0).
Q_RANGE = [(-2.6, 2.6), (-1.2, 1.3), (0.25, 2.3), (-2.5, 2.5), (0.35, 2.2), (-2.5, 2.5)]

FAMILIES = {
    "reading": dict(reading=0.64 * ARCMIN, repeatable=0.0),
    "repeatable": dict(reading=0.0, repeatable=0.64 * ARCMIN),
    "both": dict(reading=0.45 * ARCMIN, repeatable=0.45 * ARCMIN),
}

# The hidden-effect pool: name -> (in the discovery library?, what it is).
POOL = {
    "spring_j4": (True, "a linear spring on J4"),
    "transmission_j3": (True, "a once-per-revolution transmission error on J3"),
    "scale_j3": (False, "a gear-ratio (scale) error on J3: dq3 = s*q3"),
    "scale_j5": (False, "a gear-ratio (scale) error on J5: dq5 = s*q5"),
    "cubic_j1": (False, "dq1 = c*q1^3 on J1"),
    "tool_sag": (False, "the tool sags along gravity in proportion to the load"),
}


def rot(axis, a):
    c, s = math.cos(a), math.sin(a)
    m = np.eye(4)
    i, j = {0: (1, 2), 1: (2, 0), 2: (0, 1)}[axis]
    m[i, i], m[i, j], m[j, i], m[j, j] = c, -s, s, c
    return m


def trans(x, y, z):
    m = np.eye(4)
    m[:3, 3] = (x, y, z)
    return m


def rpy(r):
    """URDF roll-pitch-yaw of a rotation matrix (R = Rz(yaw) Ry(pitch) Rx(roll))."""
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    roll = math.atan2(r[2, 1], r[2, 2])
    yaw = math.atan2(r[1, 0], r[0, 0])
    return roll, pitch, yaw


def quat(r):
    """Unit quaternion [w, x, y, z] of a rotation matrix, w >= 0."""
    q = pin.Quaternion(r[:3, :3].copy())
    q.normalize()
    v = np.array([q.w, q.x, q.y, q.z])
    return v if v[0] >= 0 else -v


class Robot:
    """The hidden robot: departures, springs, masses, tool, hidden effects."""

    def __init__(self, rng, tool_len, tool_tilt, hidden):
        self.dh = []
        for j, (a, al, d, off) in enumerate(DH):
            # The seed paper's tolerances: a, d 0.25 mm; alpha 1 mrad; theta 0.5 mrad.
            self.dh.append(
                (
                    a + rng.uniform(-0.25e-3, 0.25e-3),
                    al + rng.uniform(-1e-3, 1e-3),
                    d + (rng.uniform(-0.25e-3, 0.25e-3) if j != 1 else 0.0),
                    off + rng.uniform(-0.5e-3, 0.5e-3),
                )
            )
        self.beta2 = rng.uniform(-1e-3, 1e-3)
        self.springs = {j: (k1 * rng.uniform(0.9, 1.1), k3 * rng.uniform(0.8, 1.2)) for j, (k1, k3) in SPRINGS.items()}
        self.mass_scale = [rng.uniform(0.9, 1.1) for _ in MASSES]
        az = rng.uniform(-math.pi, math.pi)
        self.tool = rot(2, az) @ rot(0, tool_tilt) @ trans(0.0, 0.0, tool_len)
        self.hidden = {}
        for h in hidden:
            sgn = rng.choice([-1.0, 1.0])
            if h == "spring_j4":
                self.springs[4] = (rng.uniform(2500.0, 6000.0), 0.0)
                self.hidden[h] = {"joint": 4, "klin": self.springs[4][0]}
            elif h == "transmission_j3":
                amp, ph = rng.uniform(3e-4, 6e-4), rng.uniform(-math.pi, math.pi)
                self.hidden[h] = {"joint": 3, "amplitude_rad": amp, "phase_rad": ph}
            elif h in ("scale_j3", "scale_j5"):
                j = int(h[-1])
                self.hidden[h] = {"joint": j, "scale": sgn * rng.uniform(0.7e-3, 1.5e-3)}
            elif h == "cubic_j1":
                self.hidden[h] = {"joint": 1, "coefficient": sgn * rng.uniform(2e-4, 4e-4)}
            elif h == "tool_sag":
                self.hidden[h] = {"joint": None, "m_per_n": rng.uniform(1.5e-6, 3e-6)}
            else:
                raise SystemExit(f"unknown hidden effect {h!r}; known: {', '.join(POOL)}")
        self.build()

    def build(self):
        """The Pinocchio model of the current DH table, beta2 and tool."""
        self.model = pin.buildModelFromXML(self.urdf())
        self.model.gravity.linear = np.array([0.0, 0.0, -G])
        self.data = self.model.createData()
        self.tool_id = self.model.getFrameId("target", pin.FrameType.BODY)

    def origins(self):
        """Joint origins (4x4): joint 1 at the base, joint k+1 after DH row k's fixed part."""
        out = [np.eye(4)]
        for j, (a, al, d, off) in enumerate(self.dh):
            t = rot(2, off) @ trans(0.0, 0.0, d) @ trans(a, 0.0, 0.0) @ rot(0, al)
            if j == 1:
                t = t @ rot(1, self.beta2)
            out.append(t)
        return out  # out[6]: wrist flange

    def urdf(self):
        o = self.origins()

        def origin(t):
            r = rpy(t[:3, :3])
            return '<origin xyz="{:.17g} {:.17g} {:.17g}" rpy="{:.17g} {:.17g} {:.17g}"/>'.format(*t[:3, 3], *r)

        links = ['<link name="base"/>']
        joints = []
        for k in range(1, 7):
            mass_entry = MASSES[k - 1]
            m = mass_entry[1] * self.mass_scale[k - 1]
            seg = o[k][:3, 3]  # the next joint's origin, in this link's frame
            if mass_entry[2] is None or np.linalg.norm(seg) == 0.0:
                com = np.zeros(3)
            else:
                com = seg / np.linalg.norm(seg) * mass_entry[2]
            links.append(
                f'<link name="link{k}"><inertial><origin xyz="{com[0]:.17g} {com[1]:.17g} {com[2]:.17g}"/>'
                f'<mass value="{m:.17g}"/><inertia ixx="0.05" ixy="0" ixz="0" iyy="0.05" iyz="0" izz="0.05"/>'
                "</inertial></link>"
            )
            parent = "base" if k == 1 else f"link{k - 1}"
            joints.append(
                f'<joint name="J{k}" type="revolute"><parent link="{parent}"/><child link="link{k}"/>'
                f"{origin(o[k - 1])}"
                f'<axis xyz="0 0 1"/><limit lower="{-JOINT_LIMIT[k - 1]}" upper="{JOINT_LIMIT[k - 1]}" effort="1000" velocity="2"/></joint>'
            )
        links.append('<link name="flange"/><link name="target"/>')
        joints.append(f'<joint name="flange_joint" type="fixed"><parent link="link6"/><child link="flange"/>{origin(o[6])}</joint>')
        joints.append(f'<joint name="target_joint" type="fixed"><parent link="flange"/><child link="target"/>{origin(self.tool)}</joint>')
        return '<?xml version="1.0"?>\n<robot name="pa10_6c_hidden">\n' + "\n".join(links + joints) + "\n</robot>\n"

    def tool_pose(self, q):
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.tool_id].homogeneous.copy()

    def holding_torque(self, q, load_n):
        """Joint torques that hold the arm and the load hung at the target, N m."""
        tau = pin.computeGeneralizedGravity(self.model, self.data, q).copy()
        jac = pin.computeFrameJacobian(self.model, self.data, q, self.tool_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return tau + jac[2, :] * load_n

    def position_jacobian(self, q):
        jac = pin.computeFrameJacobian(self.model, self.data, q, self.tool_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED)
        return jac[:3, :].copy()

    def deflection(self, j, tau):
        if j not in self.springs:
            return 0.0
        k1, k3 = self.springs[j]
        d = tau / k1
        for _ in range(40):
            d -= (k1 * d + k3 * d**3 - tau) / (k1 + 3.0 * k3 * d * d)
        return d

    def joint_error(self, qm):
        e = np.zeros(6)
        for h, p in self.hidden.items():
            if h == "transmission_j3":
                e[2] += p["amplitude_rad"] * math.sin(qm[2] + p["phase_rad"])
            elif h.startswith("scale_j"):
                e[p["joint"] - 1] += p["scale"] * qm[p["joint"] - 1]
            elif h == "cubic_j1":
                e[0] += p["coefficient"] * qm[0] ** 3
        return e

    def settle(self, qm, load_n):
        """Link angles and holding torques for motor angles qm under load_n."""
        q = qm.copy()
        e = self.joint_error(qm)
        for _ in range(80):
            tau = self.holding_torque(q, load_n)
            nxt = np.array([qm[j] - self.deflection(j + 1, tau[j]) - e[j] for j in range(6)])
            step = np.max(np.abs(nxt - q))
            q = nxt
            if step < 1e-15:
                break
        return q, self.holding_torque(q, load_n)

    def target(self, q, load_n):
        """The true target pose in the base frame (with a sagging tool, if hidden)."""
        t = self.tool_pose(q)
        if "tool_sag" in self.hidden:
            t[2, 3] -= self.hidden["tool_sag"]["m_per_n"] * load_n
        return t


def instrument_frame(rng):
    """The instrument's frame in the robot base frame: any yaw, +-0.1 rad roll and pitch,
    0.5-1.5 m away, and the centre of its measuring volume between it and the robot."""
    ang = rng.uniform(-math.pi, math.pi)
    dist = rng.uniform(0.5, 1.5)
    pos = np.array([dist * math.cos(ang), dist * math.sin(ang), rng.uniform(-0.3, 0.6)])
    frame = trans(*pos) @ rot(2, rng.uniform(-math.pi, math.pi)) @ rot(0, rng.uniform(-0.1, 0.1)) @ rot(1, rng.uniform(-0.1, 0.1))
    # The volume: a sphere centred on the robot's side of the instrument, around 0.6 m
    # from the base axis, 0.45-0.75 m high.
    toward = -pos[:2] / np.linalg.norm(pos[:2])
    reach = rng.uniform(0.45, 0.75)
    centre = np.array([reach * -toward[0], reach * -toward[1], rng.uniform(0.45, 0.75)])
    return frame, centre, rng.uniform(0.45, 0.65)


def draw_configs(rng, robot, n, centre, radius):
    """n configurations whose tool point lies in the measuring volume."""
    out = []
    tries = 0
    while len(out) < n:
        tries += 1
        if tries > 200000:
            raise SystemExit("no configurations reach the measuring volume")
        q = np.array([rng.uniform(lo, hi) for lo, hi in Q_RANGE])
        p = robot.tool_pose(q)[:3, 3]
        if np.linalg.norm(p - centre) <= radius and p[2] > 0.05:
            out.append(q)
    return out


def csv_row(cid, load, q, tau, pose):
    qq = quat(pose)
    vals = [*q, *tau, *pose[:3, 3], *qq]
    return f"{cid},{load}," + ",".join(f"{v:.15e}" for v in vals)


HEADER = "config_id,load_n,q1,q2,q3,q4,q5,q6,tau1,tau2,tau3,tau4,tau5,tau6,x,y,z,qw,qx,qy,qz"


def rotvec(v):
    return pin.exp3(np.asarray(v, dtype=float))


def pose6(t, ref):
    """Position and rotation vector of pose t relative to ref (base frame), 6-vector."""
    return np.concatenate([t[:3, 3] - ref[:3, 3], pin.log3(t[:3, :3] @ ref[:3, :3].T)])


def noncentrality(robot, designs, fam):
    """Each hidden effect's detectability on this campaign, from the generator's truth only:
    `{effect: [λ for each design]}`, `designs` a list of (configurations, loads, repeats),
    the first the calibration set. λ is the noncentrality of the likelihood-ratio test for
    the effect: its signature on a design's cells (the true target with it minus without it,
    position and orientation, at each configuration and load) whitened by the noise of a
    cell's mean (the repeatable resolver error a configuration's loads share, reading noise
    and instrument noise over the repeats, through the manipulator Jacobian), net of what
    the calibrated model absorbs: least squares on the calibration cells over the Jacobian
    of the DH table, beta2, the J2/J3/J5 springs and the base frame (finite differences on
    Pinocchio models), the same fit subtracted on the other designs (what a held-out set
    sees). Consumes no random numbers: the campaign is the same with or without it."""
    cells = [(q, load) for cfgs, loads, _ in designs for q in cfgs for load in loads]

    def poses():
        out = []
        for q, load in cells:
            ql, _ = robot.settle(q, load)
            out.append(robot.target(ql, load))
        return out

    ref = poses()
    original = (robot.model, robot.data, robot.tool_id)

    def column(mutate, h):
        saved = (list(robot.dh), robot.beta2, dict(robot.springs))
        mutate()
        robot.build()
        col = np.concatenate([pose6(t, r) for t, r in zip(poses(), ref)]) / h
        robot.dh, robot.beta2, robot.springs = saved
        robot.model, robot.data, robot.tool_id = original
        return col

    cols = []
    for j in range(6):
        for k in range(4):
            if j == 1 and k == 2:
                continue  # d2: parallel joints, beta2 instead

            def bump(j=j, k=k):
                row = list(robot.dh[j])
                row[k] += 1e-6
                robot.dh[j] = tuple(row)

            cols.append(column(bump, 1e-6))

    def bump_beta():
        robot.beta2 += 1e-6

    cols.append(column(bump_beta, 1e-6))
    for j in SPRINGS:
        for k in (0, 1):
            k1, k3 = robot.springs[j]
            h = 1e-3 * (k1, max(k3, 1e5))[k]

            def bump_spring(j=j, k=k, h=h):
                k1, k3 = robot.springs[j]
                robot.springs[j] = (k1 + h, k3) if k == 0 else (k1, k3 + h)

            cols.append(column(bump_spring, h))
    # The base frame: a translation and a small rotation of every target about the origin.
    for k in range(6):
        col = []
        for t in ref:
            v = np.zeros(6)
            if k < 3:
                v[k] = 1.0
            else:
                w = np.zeros(3)
                w[k - 3] = 1.0
                v[:3] = np.cross(w, t[:3, 3])
                v[3:] = w
            col.append(v)
        cols.append(np.concatenate(col))
    nuisance = np.stack(cols, axis=1)
    # The noise of a cell's mean, per configuration block (its loads share a repeatable error).
    inst = np.concatenate([np.array(fam["instrument_m"]) ** 2, np.array(fam["instrument_rad"]) ** 2])
    blocks = []  # (design index, first row, rows, whitening)
    row = 0
    for di, (cfgs, loads, repeats) in enumerate(designs):
        for _ in cfgs:
            jacs = []
            for q, load in cells[row // 6 : row // 6 + len(loads)]:
                ql, _ = robot.settle(q, load)
                pin.computeJointJacobians(robot.model, robot.data, ql)
                pin.framesForwardKinematics(robot.model, robot.data, ql)
                jacs.append(pin.getFrameJacobian(robot.model, robot.data, robot.tool_id, pin.ReferenceFrame.LOCAL_WORLD_ALIGNED).copy())
            n = 6 * len(jacs)
            cov = np.zeros((n, n))
            for a, ja in enumerate(jacs):
                for b, jb in enumerate(jacs):
                    cov[6 * a : 6 * a + 6, 6 * b : 6 * b + 6] = fam["repeatable"] ** 2 * ja @ jb.T
                cov[6 * a : 6 * a + 6, 6 * a : 6 * a + 6] += (fam["reading"] ** 2 * ja @ ja.T + np.diag(inst)) / repeats
            blocks.append((di, row, n, np.linalg.inv(np.linalg.cholesky(cov))))
            row += n

    def white(v, di):
        return np.concatenate([w @ v[r : r + n] for d, r, n, w in blocks if d == di])

    nw = [np.stack([white(nuisance[:, k], di) for k in range(nuisance.shape[1])], axis=1) for di in range(len(designs))]
    scale = np.linalg.norm(nw[0], axis=0)
    scale = np.where(scale > 0, scale, 1.0)
    out = {}
    for h in list(robot.hidden):
        saved_hidden, saved_springs = dict(robot.hidden), dict(robot.springs)
        del robot.hidden[h]
        if h == "spring_j4":
            del robot.springs[4]
        without = poses()
        robot.hidden, robot.springs = saved_hidden, saved_springs
        sig = np.concatenate([pose6(t, r) for t, r in zip(ref, without)])
        fit, *_ = np.linalg.lstsq(nw[0] / scale, white(sig, 0), rcond=1e-10)
        out[h] = [float(np.sum((white(sig, di) - nw[di] / scale @ fit) ** 2)) for di in range(len(designs))]
    return out


def read_poses(path):
    """A pose list (`config_id,load_n,q1..q6`, link-side rad: what `pa10 plan` writes)."""
    rows = []
    with open(path) as f:
        head = f.readline().strip().split(",")
        if head[:8] != ["config_id", "load_n", "q1", "q2", "q3", "q4", "q5", "q6"]:
            raise SystemExit(f"{path}: the header must be config_id,load_n,q1..q6")
        for n, line in enumerate(f, start=2):
            v = line.strip().split(",")
            if len(v) < 8:
                raise SystemExit(f"{path}:{n}: 8 columns expected")
            q = np.array([float(x) for x in v[2:8]])
            load = float(v[1])
            if not (np.all(np.isfinite(q)) and 0.0 <= load <= 500.0):
                raise SystemExit(f"{path}:{n}: finite angles and a load within 0-500 N")
            rows.append((v[0], load, q))
    return rows


def generate(seed, hidden=None, family=None, paper=False, configs=None, detectability=False, poses=None):
    rng = np.random.default_rng([seed, 0x9A10])
    if hidden is None:
        k = rng.choice([0, 1, 2], p=[0.34, 0.33, 0.33])
        hidden = [str(h) for h in rng.choice(sorted(POOL), size=k, replace=False)]
        # Two effects of the same joint and form are one effect: draw again.
        if "scale_j3" in hidden and "transmission_j3" in hidden:
            hidden = ["scale_j3"]
    fam_name = family or str(rng.choice(sorted(FAMILIES)))
    fam = dict(FAMILIES[fam_name])
    fam["instrument_m"] = [rng.uniform(5e-6, 12e-6) for _ in range(3)]
    fam["instrument_rad"] = [rng.uniform(3e-5, 9e-5) for _ in range(3)]
    fam["torque_rel"] = rng.uniform(0.005, 0.03)
    fam["torque_abs_nm"] = rng.uniform(0.05, 0.3)
    if paper:
        tool_len, tilt = 0.35, rng.uniform(0.0, math.radians(35.0))
        n_cfg, loads, repeats = 27, [0.0, 22.0, 44.0], 10
    else:
        tool_len, tilt = rng.uniform(0.1, 0.5), rng.uniform(0.0, math.radians(45.0))
        n_cfg = int(rng.integers(15, 41))
        top = rng.uniform(40.0, 90.0)
        n_loads = int(rng.integers(2, 5))
        loads = [0.0] + sorted(round(float(x), 1) for x in rng.uniform(0.25 * top, top, n_loads - 1))
        loads[-1] = round(top, 1)
        repeats = int(rng.integers(1, 11))
    if configs is not None:
        n_cfg = configs
    robot = Robot(rng, tool_len, tilt, hidden)
    inst, centre, radius = instrument_frame(rng)
    inst_inv = np.linalg.inv(inst)

    def measure(q_cmd, rep, load, tau_true, q_link, r=rng):
        reading = q_cmd + fam["reading"] * r.standard_normal(6)
        tau_m = tau_true * (1.0 + fam["torque_rel"] * r.standard_normal(6)) + fam["torque_abs_nm"] * r.standard_normal(6)
        truth = inst_inv @ robot.target(q_link, load)
        pose = truth.copy()
        pose[:3, :3] = rotvec(np.array(fam["instrument_rad"]) * r.standard_normal(3)) @ truth[:3, :3]
        pose[:3, 3] += np.array(fam["instrument_m"]) * r.standard_normal(3)
        return reading, tau_m, pose

    cal = [HEADER]
    cfgs = draw_configs(rng, robot, n_cfg, centre, radius)
    for c, q in enumerate(cfgs):
        rep = fam["repeatable"] * rng.standard_normal(6)
        for load in loads:
            # The servo holds the motor where the (repeatable-error-laden) reading is the command.
            ql, tau = robot.settle(q - rep, load)
            for _ in range(repeats):
                r, t, p = measure(q, rep, load, tau, ql)
                cal.append(csv_row(f"k{c:02d}", load, r, t, p))
    if poses is not None:
        # The given configurations replace the drawn ones, measured with their own generator so
        # that everything else (the robot, the instrument, the validation set) is the seed's.
        prng = np.random.default_rng([seed, 0x9A11])
        cal = [HEADER]
        reps = {}
        for cid, load, q in poses:
            rep = reps.setdefault(cid, fam["repeatable"] * prng.standard_normal(6))
            ql, tau = robot.settle(q - rep, load)
            for _ in range(repeats):
                r, t, p = measure(q, rep, load, tau, ql, prng)
                cal.append(csv_row(cid, load, r, t, p))
    val = [HEADER]
    floor, n = 0.0, 0
    s = math.hypot(fam["reading"], fam["repeatable"])
    vcfgs = draw_configs(rng, robot, 30, centre, radius)
    for c, q in enumerate(vcfgs):
        rep = fam["repeatable"] * rng.standard_normal(6)
        for load in [0.0, 44.0, 90.0]:
            ql, tau = robot.settle(q - rep, load)
            r, t, p = measure(q, rep, load, tau, ql)
            val.append(csv_row(f"v{c:02d}", load, r, t, p))
            # What a perfect model misses here: resolver error through the Jacobian plus
            # instrument noise (Monte Carlo, 200 draws).
            jp = robot.position_jacobian(ql)
            e = jp @ (s * rng.standard_normal((6, 200))) + np.array(fam["instrument_m"])[:, None] * rng.standard_normal((3, 200))
            floor += float(np.linalg.norm(e, axis=0).sum())
            n += 200
    lam = noncentrality(robot, [(cfgs, loads, repeats), (vcfgs, [0.0, 44.0, 90.0], 1)], fam) if hidden and detectability else {}
    tq = quat(robot.tool)
    meta = (
        f"instrument: Pinocchio generator (tests/pin), family {fam_name}, seed {seed}\n"
        "tool:\n"
        f"  translation: [{robot.tool[0, 3]:.15e}, {robot.tool[1, 3]:.15e}, {robot.tool[2, 3]:.15e}]\n"
        f"  quaternion: [{tq[0]:.15e}, {tq[1]:.15e}, {tq[2]:.15e}, {tq[3]:.15e}]\n"
        "noise: {position_m: 12.1e-6, resolver_arcmin: 0.64}\n"
    )
    truth = {
        "seed": seed,
        "design": {
            "tool_length_m": tool_len,
            "tool_tilt_deg": math.degrees(tilt),
            "instrument_distance_m": float(np.linalg.norm(inst[:2, 3])),
            "configs": n_cfg,
            "loads_n": loads,
            "repeats": repeats,
            "family": fam_name,
        },
        "hidden": [{"name": h, "in_library": POOL[h][0], **({"noncentrality": lam[h][0], "noncentrality_holdout": lam[h][1]} if h in lam else {}), **robot.hidden[h]} for h in hidden],
        "val_floor_mm": floor / n * 1e3,
        "volume": {"centre_m": [float(x) for x in centre], "radius_m": float(radius)},
        "tool_matrix": [[float(x) for x in row] for row in robot.tool],
        "springs": {f"J{j}": list(v) for j, v in robot.springs.items()},
        "beta2_rad": robot.beta2,
    }
    return cal, val, meta, truth, robot.urdf()


def write(out, cal, val, meta, truth, urdf):
    os.makedirs(out, exist_ok=True)
    for name, text in [
        ("cal.csv", "\n".join(cal) + "\n"),
        ("val.csv", "\n".join(val) + "\n"),
        ("cal.meta.yaml", meta),
        ("val.meta.yaml", meta),
        ("truth.json", json.dumps(truth, indent=1) + "\n"),
        ("robot.urdf", urdf),
    ]:
        with open(os.path.join(out, name), "w") as f:
            f.write(text)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seed", type=int, required=True, help="first seed")
    ap.add_argument("--count", type=int, default=1, help="campaigns: seeds seed..seed+count-1, each in OUT/<seed>/")
    ap.add_argument("--out", required=True)
    ap.add_argument("--hidden", help="comma-separated effects, or 'none' (default: drawn from the seed)")
    ap.add_argument("--family", choices=sorted(FAMILIES))
    ap.add_argument("--paper", action="store_true", help="the seed paper's campaign design")
    ap.add_argument("--configs", type=int, help="number of calibration configurations")
    ap.add_argument("--detectability", action="store_true", help="write each hidden effect's noncentrality (truth.json; a few seconds)")
    ap.add_argument("--poses", help="measure these configurations (a pose list, config_id,load_n,q1..q6) instead of drawn ones")
    a = ap.parse_args()
    poses = read_poses(a.poses) if a.poses else None
    hidden = None
    if a.hidden is not None:
        hidden = [] if a.hidden == "none" else a.hidden.split(",")
        for h in hidden:
            if h not in POOL:
                sys.exit(f"unknown hidden effect {h!r}; known: {', '.join(sorted(POOL))}")
    for seed in range(a.seed, a.seed + a.count):
        out = a.out if a.count == 1 else os.path.join(a.out, str(seed))
        write(out, *generate(seed, hidden, a.family, a.paper, a.configs, a.detectability, poses))


if __name__ == "__main__":
    main()
