#!/usr/bin/env python3
"""Reference: the two-level calibration of `pa10 calibrate --weighting paper --starts 1`,
written with NumPy and SciPy's `least_squares`, for the speed comparison in BENCHMARKS.md.

Same problem as src/calib/fit.rs with the paper's row weighting: the 30 parameters scaled
(departures / the paper's tolerances, stiffness as ln(K / K_seed)), residuals = position
error / r_max (1 m) and orientation error (rad) of every row, the base frame Ψ re-solved by
an inner `least_squares` on the inner configurations at every outer evaluation, priors on
the directions the SVD of the start Jacobian shows the data cannot see, and a ln(10) prior on
log-stiffness. Jacobians by finite differences (SciPy's '2-point'), as a straightforward
implementation would.

    cargo run --release --bin pa10 -- sim measure --seed 1 --out /tmp/sim
    python3 benches/reference/calibration_scipy.py /tmp/sim
"""
import math
import sys
import time

import numpy as np
import yaml
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

TOL = np.array([0.25e-3] * 6 + [1e-3] * 6 + [0.25e-3, 1e-3, 0.25e-3, 0.25e-3, 0.25e-3, 0.25e-3] + [5e-4] * 6)
DH = [(0.0, -math.pi / 2, 0.317, 0.0), (0.450, 0.0, 0.0, -math.pi / 2), (0.0, math.pi / 2, 0.0, math.pi / 2),
      (0.0, -math.pi / 2, 0.480, 0.0), (0.0, math.pi / 2, 0.0, 0.0), (0.0, 0.0, 0.070, 0.0)]
K_SEED = np.array([1.98e4, 1.27e4, 2.56e3, 3.35e7, 1.46e7, 3.83e7])  # klin J2 J3 J5, kcub J2 J3 J5
STIFF = [1, 2, 4]


def load(path):
    data = np.genfromtxt(path, delimiter=",", names=True, dtype=None, encoding=None)
    ids = np.array([str(x) for x in data["config_id"]])
    q = np.stack([data[f"q{j}"] for j in range(1, 7)], axis=1).astype(float)
    tau = np.stack([data[f"tau{j}"] for j in range(1, 7)], axis=1).astype(float)
    pos = np.stack([data["x"], data["y"], data["z"]], axis=1).astype(float)
    quat = np.stack([data["qx"], data["qy"], data["qz"], data["qw"]], axis=1).astype(float)
    return ids, np.asarray(data["load_n"], float), q, tau, pos, Rotation.from_quat(quat).as_matrix()


def physical(s):
    dep = s[:24] * TOL
    k = K_SEED * np.exp(s[24:])
    return dep, k


def deflection(k1, k3, tau):
    a = np.abs(tau)
    x = np.minimum(a / k1, np.cbrt(a / k3))
    for _ in range(30):
        x = x - (k3 * x ** 3 + k1 * x - a) / (3 * k3 * x ** 2 + k1)
    return np.sign(tau) * x


def fk(dep, k, q, tau, tool):
    ql = q.copy()
    for n, j in enumerate(STIFF):
        ql[:, j] -= deflection(k[n], k[3 + n], tau[:, j])
    n = q.shape[0]
    T = np.tile(np.eye(4), (n, 1, 1))
    for j in range(6):
        a, al, d, off = DH[j]
        a += dep[j]; al += dep[6 + j]; th = ql[:, j] + off + dep[18 + j]
        beta = dep[12 + j] if j == 1 else 0.0
        if j != 1:
            d += dep[12 + j]
        ct, st, ca, sa = np.cos(th), np.sin(th), math.cos(al), math.sin(al)
        A = np.zeros((n, 4, 4))
        A[:, 0, 0] = ct; A[:, 0, 1] = -st * ca; A[:, 0, 2] = st * sa; A[:, 0, 3] = a * ct
        A[:, 1, 0] = st; A[:, 1, 1] = ct * ca; A[:, 1, 2] = -ct * sa; A[:, 1, 3] = a * st
        A[:, 2, 1] = sa; A[:, 2, 2] = ca; A[:, 2, 3] = d; A[:, 3, 3] = 1
        if beta:
            cb, sb = math.cos(beta), math.sin(beta)
            Ry = np.array([[cb, 0, sb, 0], [0, 1, 0, 0], [-sb, 0, cb, 0], [0, 0, 0, 1]])
            A = A @ Ry
        T = T @ A
    return T @ tool


def base(psi):
    R = Rotation.from_euler("XYZ", psi[3:]).as_matrix()
    return R, psi[:3]


def residuals(T, pos, rot, psi):
    R, p = base(psi)
    mp = pos @ R.T + p
    mr = R @ rot
    dp = T[:, :3, 3] - mp
    dr = Rotation.from_matrix(T[:, :3, :3] @ np.transpose(mr, (0, 2, 1))).as_rotvec()
    return np.concatenate([dp, dr], axis=1).ravel()


class Problem:
    def __init__(self, d):
        meta = yaml.safe_load(open(f"{d}/cal.meta.yaml"))
        self.ids, self.load, self.q, self.tau, self.pos, self.rot = load(f"{d}/cal.csv")
        t = meta["tool"]
        self.tool = np.eye(4)
        w, x, y, z = t["quaternion"]
        self.tool[:3, :3] = Rotation.from_quat([x, y, z, w]).as_matrix()
        self.tool[:3, 3] = t["translation"]
        self.inner = np.isin(self.ids, meta["inner_configs"]) & (self.load == 0)
        self.psi = np.zeros(6)
        self.priors = np.zeros((0, 30))

    def seed_psi(self, s):
        dep, k = physical(s)
        T = fk(dep, k, self.q[self.inner], self.tau[self.inner], self.tool)
        bp, ip = T[:, :3, 3], self.pos[self.inner]
        cb, ci = bp.mean(0), ip.mean(0)
        U, _, Vt = np.linalg.svd((ip - ci).T @ (bp - cb))
        D = np.diag([1, 1, np.sign(np.linalg.det(Vt.T @ U.T))])
        R = Vt.T @ D @ U.T
        self.psi = np.concatenate([cb - R @ ci, Rotation.from_matrix(R).as_euler("XYZ")])

    def inner_fit(self, dep, k):
        T = fk(dep, k, self.q[self.inner], self.tau[self.inner], self.tool)
        sol = least_squares(lambda psi: residuals(T, self.pos[self.inner], self.rot[self.inner], psi), self.psi, method="lm", xtol=1e-14, ftol=1e-14)
        return sol.x

    def data_residuals(self, s):
        dep, k = physical(s)
        psi = self.inner_fit(dep, k)
        T = fk(dep, k, self.q, self.tau, self.tool)
        return residuals(T, self.pos, self.rot, psi)

    def __call__(self, s):
        return np.concatenate([self.data_residuals(s), self.priors @ s])


def main():
    d = sys.argv[1] if len(sys.argv) > 1 else "/tmp/sim"
    pb = Problem(d)
    s0 = np.zeros(30)
    t0 = time.perf_counter()
    pb.seed_psi(s0)
    pb.psi = pb.inner_fit(*physical(s0))
    # weak directions at the start (noise level as src/calib/fit.rs: instrument + resolver)
    J0 = least_squares(pb.data_residuals, s0, max_nfev=1, jac="2-point").jac
    noise = math.sqrt((12.1e-6) ** 2 / 3 + (0.64 * math.pi / 10800 * 0.8) ** 2) * math.sqrt(len(pb.ids) / len(set(pb.ids)))
    U, sv, Vt = np.linalg.svd(J0, full_matrices=False)
    weak = [Vt[i] * noise for i in range(len(sv)) if sv[i] == 0 or noise / sv[i] > 0.5 or sv[i] < 1e-8 * sv[0]]
    stiff = [np.eye(30)[24 + i] * noise / math.log(10) for i in range(6)]
    pb.priors = np.array(weak + stiff)
    sol = least_squares(pb, s0, method="lm", jac="2-point", xtol=1e-10, ftol=1e-10)
    elapsed = time.perf_counter() - t0
    dep, k = physical(sol.x)
    print(f"scipy {__import__('scipy').__version__}: cost {2 * sol.cost:.6e}, {sol.nfev} evaluations, {elapsed:.2f} s")
    print("klin J2 J3 J5:", np.round(k[:3], 1), " kcub:", np.array2string(k[3:], precision=3))


if __name__ == "__main__":
    main()
