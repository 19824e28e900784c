#!/usr/bin/env python3
"""Reference: the resolver Monte Carlo of `pa10 accuracy`, as straightforward vectorised NumPy.

Same computation as src/accuracy: for every point of the CSV that `pa10 accuracy --csv`
writes (the same points, selected by the same seed), draw `draws` Gaussian joint errors
(sigma per joint, rad), push the tool point (0.35 m along the flange z) through the nominal
PA10-6C standard-DH chain for all draws at once, and take mean / sd / median / p95 / p99 /
max of the position error per point and per plane.

    cargo run --release --bin pa10 -- accuracy --csv /tmp/points.csv --draws 1
    python3 benches/reference/accuracy_numpy.py /tmp/points.csv --draws 100000

Prints per-plane statistics (mm) and the elapsed seconds of the Monte Carlo alone.
"""
import argparse
import csv
import math
import time
from collections import defaultdict

import numpy as np

# nominal PA10-6C standard DH: a, alpha, d, theta_offset (m, rad)
DH = [
    (0.0, -math.pi / 2, 0.317, 0.0),
    (0.450, 0.0, 0.0, -math.pi / 2),
    (0.0, math.pi / 2, 0.0, math.pi / 2),
    (0.0, -math.pi / 2, 0.480, 0.0),
    (0.0, math.pi / 2, 0.0, 0.0),
    (0.0, 0.0, 0.070, 0.0),
]


def tool_points(q, tool):
    """q: (n, 6) link angles -> (n, 3) tool point positions in the base frame."""
    n = q.shape[0]
    x = np.full(n, tool[0])
    y = np.full(n, tool[1])
    z = np.full(n, tool[2])
    for i in range(5, -1, -1):
        a, alpha, d, off = DH[i]
        ca, sa = math.cos(alpha), math.sin(alpha)
        th = q[:, i] + off
        ct, st = np.cos(th), np.sin(th)
        ny = ca * y - sa * z
        nz = sa * y + ca * z
        wx = x + a
        x, y, z = ct * wx - st * ny, st * wx + ct * ny, nz + d
    return np.stack([x, y, z], axis=1)


def stats(e):
    e = e * 1e3
    return dict(mean=e.mean(), sd=e.std(ddof=1), median=np.median(e),
                p95=np.percentile(e, 95), p99=np.percentile(e, 99), max=e.max())


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("points_csv")
    ap.add_argument("--draws", type=int, default=100_000)
    ap.add_argument("--sigma-arcmin", type=float, default=0.64)
    ap.add_argument("--tool-offset", type=float, default=0.35)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    sigma = args.sigma_arcmin * math.pi / (180 * 60)
    tool = (0.0, 0.0, args.tool_offset)
    planes = defaultdict(list)
    with open(args.points_csv) as f:
        for row in csv.DictReader(f):
            planes[float(row["z_m"])].append([float(row[f"q{j}"]) for j in range(1, 7)])
    rng = np.random.default_rng(args.seed)
    t0 = time.perf_counter()
    results = {}
    for z, qs in planes.items():
        errs = []
        for q in qs:
            q = np.asarray(q)
            p0 = tool_points(q[None, :], tool)[0]
            dq = rng.standard_normal((args.draws, 6)) * sigma
            p = tool_points(q[None, :] + dq, tool)
            errs.append(np.linalg.norm(p - p0, axis=1))
        results[z] = stats(np.concatenate(errs))
    elapsed = time.perf_counter() - t0
    for z, s in sorted(results.items()):
        print(f"z {z:.3f} m: mean {s['mean']:.4f} sd {s['sd']:.4f} median {s['median']:.4f} "
              f"p95 {s['p95']:.4f} p99 {s['p99']:.4f} max {s['max']:.4f} mm")
    n = sum(len(v) for v in planes.values()) * args.draws
    print(f"numpy {np.__version__}: {n} forward kinematics in {elapsed:.2f} s")


if __name__ == "__main__":
    main()
