#!/usr/bin/env python3
"""`pa10 plan` judged on campaigns we did not make (the Pinocchio generator, tests/pin).

For each seed: the generator draws a robot, a tool, an instrument and its measuring volume, a
noise family and a design (loads, repeats); nothing hidden. The same budget — N configurations ×
the design's loads × its repeats — is spent twice: on N configurations the generator draws at
random in the volume, and on N that `pa10 plan` chooses in that volume for that
tool (the same sphere). Both are calibrated by `pa10 calibrate` and judged on the generator's held-out
configurations (the same set for both); the prediction `pa10 plan` made before measuring is
set beside what calibration reached.

    python3 tests/pin/plan_study.py --pa10 target/release/pa10 [--seeds 1-8] [--configs 12] [--json]

Prints a table and the means; `--check` exits 1 unless planned beats random on average and the
prediction is within 20 % of the measured error on average.
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))


def run(cmd):
    r = subprocess.run(cmd, capture_output=True, text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)}: {r.stderr.strip()}")
    return r.stdout


def quat(m):
    """Unit quaternion w, x, y, z of a rotation matrix."""
    w = math.sqrt(max(0.0, 1.0 + m[0][0] + m[1][1] + m[2][2])) / 2.0
    x = math.copysign(math.sqrt(max(0.0, 1.0 + m[0][0] - m[1][1] - m[2][2])) / 2.0, m[2][1] - m[1][2])
    y = math.copysign(math.sqrt(max(0.0, 1.0 - m[0][0] + m[1][1] - m[2][2])) / 2.0, m[0][2] - m[2][0])
    z = math.copysign(math.sqrt(max(0.0, 1.0 - m[0][0] - m[1][1] + m[2][2])) / 2.0, m[1][0] - m[0][1])
    n = math.sqrt(w * w + x * x + y * y + z * z)
    return [w / n, x / n, y / n, z / n]


def validation_mean(pa10, d):
    out = json.loads(run([pa10, "calibrate", "--data", f"{d}/cal.csv", "--validate", f"{d}/val.csv", "--starts", "2", "--out", f"{d}/model.yaml", "--json"]))
    after = out["validation"]["after"]
    return float(np.mean([v["mean_mm"] for v in after.values()]))


def study(pa10, seed, configs, tmp):
    gen = [sys.executable, os.path.join(HERE, "campaign.py"), "--seed", str(seed), "--hidden", "none", "--configs", str(configs)]
    rnd = os.path.join(tmp, f"{seed}-random")
    run(gen + ["--out", rnd])
    truth = json.load(open(os.path.join(rnd, "truth.json")))
    c, r = truth["volume"]["centre_m"], truth["volume"]["radius_m"]
    sphere = [c[0], c[1], c[2], r]
    t = truth["tool_matrix"]
    tool = [t[0][3], t[1][3], t[2][3], *quat(t)]
    loads = truth["design"]["loads_n"]
    poses = os.path.join(tmp, f"{seed}-planned.csv")
    plan = json.loads(
        run(
            [pa10, "plan", "--sphere=" + ",".join(f"{v:.6f}" for v in sphere), "--table-z", "0.05", "--configs", str(configs), "--loads", ",".join(str(x) for x in loads), "--repeats", str(truth["design"]["repeats"]), "--candidates", "600", "--tool", *[f"{v:.12f}" for v in tool], "--out", poses, "--json"]
        )
    )
    planned = os.path.join(tmp, f"{seed}-planned")
    run(gen + ["--out", planned, "--poses", poses])
    return {
        "seed": seed,
        "family": truth["design"]["family"],
        "repeats": truth["design"]["repeats"],
        "loads_n": loads,
        "floor_mm": truth["val_floor_mm"],
        "random_mm": validation_mean(pa10, rnd),
        "planned_mm": validation_mean(pa10, planned),
        "predicted_mm": plan["planned"]["predicted_mm"],
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pa10", required=True)
    ap.add_argument("--seeds", default="1-8", help="first-last")
    ap.add_argument("--configs", type=int, default=12)
    ap.add_argument("--json", action="store_true")
    ap.add_argument("--check", action="store_true")
    a = ap.parse_args()
    lo, hi = (int(x) for x in a.seeds.split("-"))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in range(lo, hi + 1):
            rows.append(study(a.pa10, seed, a.configs, tmp))
    mean = {k: float(np.mean([r[k] for r in rows])) for k in ("floor_mm", "random_mm", "planned_mm", "predicted_mm")}
    if a.json:
        print(json.dumps({"rows": rows, "mean": mean}))
    else:
        print("| seed | family | repeats | loads [N] | floor [mm] | random | planned | predicted |")
        print("|---|---|---|---|---|---|---|---|")
        for r in rows:
            print(f"| {r['seed']} | {r['family']} | {r['repeats']} | {r['loads_n']} | {r['floor_mm']:.3f} | {r['random_mm']:.3f} | {r['planned_mm']:.3f} | {r['predicted_mm']:.3f} |")
        print(f"| mean | | | | {mean['floor_mm']:.3f} | {mean['random_mm']:.3f} | {mean['planned_mm']:.3f} | {mean['predicted_mm']:.3f} |")
    if a.check:
        bad = []
        if mean["planned_mm"] >= mean["random_mm"]:
            bad.append(f"planned {mean['planned_mm']:.3f} mm does not beat random {mean['random_mm']:.3f} mm")
        if abs(mean["predicted_mm"] / mean["planned_mm"] - 1.0) > 0.2:
            bad.append(f"predicted {mean['predicted_mm']:.3f} mm vs measured {mean['planned_mm']:.3f} mm: more than 20 % apart")
        for b in bad:
            print(b, file=sys.stderr)
        sys.exit(1 if bad else 0)


if __name__ == "__main__":
    main()
