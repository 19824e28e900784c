#!/usr/bin/env python3
"""The MuJoCo judge over a grid of plants: seeds x friction models (creep, stick) x friction
scales, run in parallel, each run `mujoco_judge --json`, summarised per (friction model,
scale) as docs/judge.md's tables (issue #40). Runs with `-- --discover` add a table per run
(issue #42): calibrated and extended model against the floor, and what `pa10 discover` named
against the plant's hidden springs (plant.py's `Truth`, which the judge never reads).

    python3 tests/mujoco/study.py [--judge target/release/examples/mujoco_judge]
        [--seeds 1-10] [--models creep,stick] [--friction 0,1,2] [--jobs 2] [--quick]
        [--out runs.jsonl] [--check RATIO] [-- judge arguments, e.g. --torque-source model --identify]

Every run's JSON line (or its failure) goes to --out as it ends; the summary goes to stdout
(`--summary FILE` prints it for the lines of an earlier --out; `--selftest` checks the --check
rules on made-up runs). With
--check RATIO the exit status is 1 when a run failed, faulted or aborted, or a calibrated mean
error exceeded RATIO x the Monte Carlo floor, or an extended model was worse than the
calibrated one by more than EXTENDED_SLACK x the floor at a load (on sticking drives, also by
more than PAIRED_T paired standard errors over the validation poses). A run has a time limit (30 min).
"""
import argparse
import concurrent.futures as cf
import json
import os
import statistics
import subprocess
import sys

RUN_TIMEOUT_S = 1800
HERE = os.path.dirname(os.path.abspath(__file__))
# On creeping drives an extended model's mean error may exceed the calibrated one's by this
# fraction of the floor before the check calls it worse: one model validated twice differs by up
# to 0.12x the floor at a load. On sticking drives (a stuck drive rests anywhere in its holding
# band; one model validated twice differs by up to 0.18x) the means alone are not checked:
# docs/judge.md §9 has the extended model worse by 0.22-0.28x at 0 N on 2 of 7 named seeds of
# six poses each there; the pose-by-pose comparison below is. The models' own error at rest (the judge's prediction_mean_mm, where the servo
# stopped taken out) is checked on creeping drives too; on sticking ones it is reported: 12-06,
# stick seeds 3 and 8, the extended model's is within +0.07x of the calibrated model's at 0 N
# where its placement was +0.22 and +0.28x worse, but the same model validated twice (seed 4)
# still differs by 0.21x at 90 N. The judge's --check uses the creeping rules (its reduced runs
# have too few poses for the paired one).
EXTENDED_SLACK = 0.15
# On sticking drives the placement is compared pose by pose instead (`paired`): both models are
# validated on the same poses, so the differences' mean and its standard error say whether the
# extended model is worse beyond where the stuck drives happened to rest. A sticking run fails
# --check when the extended model is worse by more than EXTENDED_SLACK x the floor at a load *and*
# by more than PAIRED_T paired standard errors, over at least PAIRED_MIN_POSES poses (one-sided
# p ≈ 0.004 at 17 degrees of freedom: about one false alarm in four 20-run studies at 3 loads if
# the two models were equal; with fewer poses the standard error means little and the comparison
# is reported only).
PAIRED_T = 3.0
PAIRED_MIN_POSES = 6


def paired(r):
    """Per load, the extended model's placement error minus the calibrated model's over the
    validation poses both reached (the judge's `validation_poses_detail`), ÷ the floor: (mean,
    its standard error, t = mean / standard error, poses); None where the run has no extended
    model or fewer than two such poses."""
    detail = r.get("validation_poses_detail") or []
    out = []
    for l in range(len(r["loads"])):
        d = [(p["error_mm"][2][l] - p["error_mm"][1][l]) / r["floor_mm"] for p in detail
             if len(p["error_mm"]) == 3 and p["error_mm"][1] is not None and p["error_mm"][2] is not None]
        if len(d) < 2:
            out.append(None)
            continue
        mean, se = statistics.mean(d), statistics.stdev(d) / len(d) ** 0.5
        out.append((mean, se, mean / se if se > 0 else 0.0, len(d)))
    return out


def seeds(text):
    out = []
    for part in text.split(","):
        if "-" in part:
            a, b = part.split("-")
            out.extend(range(int(a), int(b) + 1))
        else:
            out.append(int(part))
    if not out or any(s < 0 for s in out):
        raise argparse.ArgumentTypeError(f"seeds: e.g. 1-10 or 1,4,7, got {text}")
    return out


def floats(text):
    try:
        v = [float(x) for x in text.split(",")]
    except ValueError:
        raise argparse.ArgumentTypeError(f"a comma-separated list of numbers, got {text}")
    if any(not 0 <= x <= 10 for x in v):
        raise argparse.ArgumentTypeError(f"friction scales 0...10, got {text}")
    return v


def run(judge, seed, model, friction, quick, extra):
    cmd = [judge, "--json", "--seed", str(seed), "--friction-model", model,
           "--friction", str(friction)] + (["--quick"] if quick else []) + extra
    key = {"seed": seed, "friction_model": model, "friction_scale": friction}
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return dict(key, failed=f"no answer in {RUN_TIMEOUT_S} s")
    lines = [l for l in p.stdout.splitlines() if l.startswith("{")]
    if p.returncode != 0 or not lines:
        said = [l for l in p.stderr.splitlines() if l.startswith(("check failed", "Error"))]
        return dict(key, failed="; ".join(said) or (p.stderr.strip().splitlines() or ["(no output)"])[-1])
    out = json.loads(lines[-1])
    return dict(out, **key)


def problems(r, ratio):
    if "failed" in r:
        return [f"failed: {r['failed']}"]
    bad = [f"fault: {f}" for f in r["validation_faults"]]
    bad += [f"campaign fault: {f}" for f in r.get("campaign_faults", [])]
    if r["aborted"]:
        bad.append(f"aborted: {r['aborted']}")
    diffs = paired(r)
    for k, l in enumerate(r["loads"]):
        if ratio is not None and l["calibrated_mean_mm"] > ratio * r["floor_mm"]:
            bad.append(f"{l['load_n']:.0f} N: {l['calibrated_mean_mm'] / r['floor_mm']:.2f}x the floor")
        ext = l.get("extended_mean_mm")
        if ext is not None and ext > l["calibrated_mean_mm"] + EXTENDED_SLACK * r["floor_mm"]:
            pair = diffs[k]
            if r["friction_model"] == "creep":
                bad.append(f"{l['load_n']:.0f} N: extended {ext:.3f} mm worse than calibrated "
                           f"{l['calibrated_mean_mm']:.3f} mm")
            elif pair is not None and pair[3] >= PAIRED_MIN_POSES and pair[2] > PAIRED_T:
                bad.append(f"{l['load_n']:.0f} N: extended {ext:.3f} mm worse than calibrated "
                           f"{l['calibrated_mean_mm']:.3f} mm by {pair[2]:.1f} paired standard errors "
                           f"over {pair[3]} poses")
        own = l.get("prediction_mean_mm", [])
        if (len(own) == 3 and r["friction_model"] == "creep"
                and own[2] > own[1] + EXTENDED_SLACK * r["floor_mm"]):
            bad.append(f"{l['load_n']:.0f} N: the extended model's own error at rest {own[2]:.3f} mm "
                       f"worse than the calibrated model's {own[1]:.3f} mm")
    return bad


def hidden_compliance(seed):
    """The plant's spring compliances per joint for `seed`, rad/(N·m), from plant.py's Truth
    (the model calls J1, J4 and J6 rigid; a load hung at the tool loads J4 only: J1's axis is
    vertical and the tool point lies on J6's axis)."""
    sys.path.insert(0, HERE)
    import plant
    t = plant.Truth(seed)
    return [1.0 / (plant.K1[j] * t.k_scale[j]) for j in range(6)]


def named_text(f, truth):
    """One effect `pa10 discover` named, with the plant's value where it hides one."""
    j = f.get("joint")
    if f["name"] == "joint_compliance_linear" and j:
        c = f["params"]["compliance"]
        return f"J{j} spring {c:.3g} (plant {truth[j - 1]:.3g}) rad/(N·m)"
    return f["label"] + " " + ", ".join(f"{k} {v:.3g}" for k, v in f["params"].items())


def hidden_text(r):
    """The effects the judge had the plant hide (`--hide-gear`, `--hide-bearing`, `--hide-bend`,
    `--hide-payload`)."""
    h = r.get("hidden") or {}
    parts = [f"J{j + 1} gear {g:.3g}" for j, g in enumerate(h.get("gear", [])) if g]
    parts += [f"J{j + 1} bearing {a:.3g} rad at {phi:.3g}" for j, (a, phi) in enumerate(h.get("bearing", [])) if a]
    links = {1: "upper arm", 3: "forearm"}
    parts += [f"{links.get(row, f'row {row}')} (row {row}) bending {c:.3g} rad/(N·m)"
              for row, c in enumerate(h.get("bend", [])) if c]
    if h.get("payload_kg"):
        parts.append(f"{h['payload_kg']:.3g} kg at the tool undeclared")
    return f" (plant hid {', '.join(parts)})" if parts else ""


def discovery_table(results):
    """Per run with --discover: calibrated and extended mean / floor per load, what was named."""
    rs = sorted((r for r in results if "failed" not in r and r.get("discovered") is not None),
                key=lambda r: (r["friction_model"], r["friction_scale"], r["seed"]))
    if not rs:
        return
    print("\n| seed | drives | friction | calibrated / floor 0 / 45 / 90 N | extended / floor 0 / 45 / 90 N "
          "| the models' own error, calibrated → extended / floor 0 / 45 / 90 N "
          "| named (plant's truth) | discovery says closed | above 1.1x: what the judge finds it is, 0 / 45 / 90 N |")
    print("|---|---|---|---|---|---|---|---|---|")
    within, worse, j4 = 0, 0, []
    # the models' own error at rest (the judge's prediction_mean_mm: without where the servo
    # stopped), runs that have it, and those where the extended model's is the worse by > slack
    own_runs, own_worse = 0, 0
    # the judge's attribution of each load above 1.1x the floor (`extended_miss`; "–": within)
    misses = {}
    for r in rs:
        fl = r["floor_mm"]
        cal = [l["calibrated_mean_mm"] / fl for l in r["loads"]]
        ext = [l["extended_mean_mm"] / fl for l in r["loads"]]
        within += all(e <= 1.1 for e in ext)
        worse += r["friction_model"] == "creep" and any(e > c + EXTENDED_SLACK for c, e in zip(cal, ext))
        truth = hidden_compliance(r["seed"])
        for f in r["discovered"]:
            if f["name"] == "joint_compliance_linear" and f.get("joint") == 4:
                j4.append(f["params"]["compliance"] / truth[3] - 1)
        named = ("; ".join(named_text(f, truth) for f in r["discovered"]) or "nothing") + hidden_text(r)
        own = "–"
        if all(len(l.get("prediction_mean_mm", [])) == 3 for l in r["loads"]):
            pc = [l["prediction_mean_mm"][1] / fl for l in r["loads"]]
            pe = [l["prediction_mean_mm"][2] / fl for l in r["loads"]]
            own = " / ".join(f"{c:.2f} → {e:.2f}" for c, e in zip(pc, pe))
            own_runs += 1
            own_worse += any(e > c + EXTENDED_SLACK for c, e in zip(pc, pe))
        causes = [(l.get("extended_miss") or {}).get("cause", "–") for l in r["loads"]]
        for c in causes:
            misses[c] = misses.get(c, 0) + 1
        print(f"| {r['seed']} | {r['friction_model']} | ×{r['friction_scale']:g} "
              f"| {' / '.join(f'{c:.2f}' for c in cal)} | {' / '.join(f'{e:.2f}' for e in ext)} "
              f"| {own} | {named} | {'yes' if r['discovery']['gap_closed'] else 'no'} "
              f"| {' / '.join(causes)} |")
    j4_err = ""
    if j4:
        j4_err = (f", its compliance within {100 * max(abs(e) for e in j4):.0f} % of the plant's "
                  f"(median {100 * statistics.median(abs(e) for e in j4):.0f} %)")
    print(f"\nExtended within 1.1x the floor at every load: {within} of {len(rs)}; worse than calibrated "
          f"by more than {EXTENDED_SLACK}x the floor at a load (creeping drives): {worse}; J4's hidden spring named: "
          f"{len(j4)} of {len(rs)}{j4_err}.")
    if own_runs:
        print(f"The extended model's own error (at the rest angles, without where the servo stopped) worse "
              f"than the calibrated model's by more than {EXTENDED_SLACK}x the floor at a load: {own_worse} "
              f"of {own_runs} (any drives).")
    if any(c != "–" for c in misses):
        print("Loads above 1.1x the floor, by what the judge finds the miss is (the part whose removal helps "
              "most; `resolvers`: within 1.1x of the floor the poses realised): "
              + ", ".join(f"{c} {n}" for c, n in sorted(misses.items()) if c != "–")
              + f" (within: {misses.get('–', 0)} of {sum(misses.values())} loads).")
    paired_summary(rs)
    decomposition(rs)
    wrists(rs)


def paired_summary(rs):
    """Per drives: the extended model's placement against the calibrated one's, pose by pose
    (`paired`): how many loads it is worse at by more than 2 and PAIRED_T paired standard errors,
    the largest t, and the mean difference ÷ the floor at 0 / 45 / 90 N."""
    for drives, scale in sorted({(r["friction_model"], r["friction_scale"]) for r in rs}):
        g = [(r, paired(r)) for r in rs if (r["friction_model"], r["friction_scale"]) == (drives, scale)]
        cells = [(r, k, p) for r, ps in g for k, p in enumerate(ps) if p is not None]
        if not cells:
            continue
        r, k, top = max(cells, key=lambda c: c[2][2])
        mean = " / ".join(f"{statistics.mean(p[0] for _, kk, p in cells if kk == k):+.2f}"
                          for k in range(3))
        print(f"{drives} ×{scale:g}, pose by pose over {len(g)} runs: the extended model's placement worse than the "
              f"calibrated one's by more than 2 / {PAIRED_T:g} paired standard errors at "
              f"{sum(p[2] > 2 for _, _, p in cells)} / {sum(p[2] > PAIRED_T for _, _, p in cells)} of "
              f"{len(cells)} loads (largest t {top[2]:+.1f}: seed {r['seed']} at "
              f"{r['loads'][k]['load_n']:.0f} N, {top[0]:+.2f} ± {top[1]:.2f}x the floor over {top[3]} poses); "
              f"mean difference / floor at 0 / 45 / 90 N {mean}.")


def decomposition(rs):
    """Where the judge says the plant's springs (docs/judge.md §9): per drives, the extended model
    alone (MuJoCo's motor angles and torques) / the floor, and its own error ÷ the floor the
    validation poses realised (the resolvers' share), mean (max) at 0 / 45 / 90 N."""
    keys = ("prediction_exact_mean_mm", "resolver_share_mean_mm", "prediction_true_torque_mean_mm")
    have = [r for r in rs if all(len(l.get(k, [])) == 3 for l in r["loads"] for k in keys)]
    for drives in sorted({r["friction_model"] for r in have}):
        g = [r for r in have if r["friction_model"] == drives]
        alone = [[l["prediction_exact_mean_mm"][2] / r["floor_mm"] for l in r["loads"]] for r in g]
        own = [[l["prediction_mean_mm"][2] / l["resolver_share_mean_mm"][2] for l in r["loads"]] for r in g]
        true = [[l["prediction_true_torque_mean_mm"][2] / l["resolver_share_mean_mm"][2] for l in r["loads"]]
                for r in g]
        col = lambda v: " / ".join(f"{statistics.mean(x[i] for x in v):.2f} ({max(x[i] for x in v):.2f})"
                                   for i in range(3))
        print(f"{drives}, {len(g)} runs: the extended model alone / floor {col(alone)}; its own error ÷ the "
              f"floor the poses realised {col(own)}, with MuJoCo's torques {col(true)}; within 1.1x of the "
              f"realised floor at every load: {sum(all(x <= 1.1 for x in o) for o in own)} of {len(g)}.")


def wrists(rs):
    """Per drives, from the judge's per-pose detail (`validation_poses_detail`): each model's
    position error and the model alone (MuJoCo's motor angles and torques) / the floor, mean at
    0 / 45 / 90 N, over the validation poses with the wrist as the paper's grid (J5 > 0) and
    with it flipped (J5 < 0: J4 near ±π), and how many of each."""
    have = [r for r in rs if r.get("validation_poses_detail")]
    for drives in sorted({r["friction_model"] for r in have}):
        g = [r for r in have if r["friction_model"] == drives]
        for flipped in (False, True):
            poses = [(r, p) for r in g for p in r["validation_poses_detail"]
                     if p["setpoint_rad"] is not None and (p["setpoint_rad"][4] < 0) == flipped
                     and all(e is not None for e in p["error_mm"])]
            if not poses:
                continue
            names = ("nominal", "calibrated", "extended")[:len(poses[0][1]["error_mm"])]
            cells = []
            for m, name in enumerate(names[1:], start=1):
                err = " / ".join(f"{statistics.mean(p['error_mm'][m][l] / r['floor_mm'] for r, p in poses):.2f}"
                                 for l in range(3))
                exact = [[(p["exact_mm"][m][l], r["floor_mm"]) for r, p in poses] for l in range(3)]
                alone = " / ".join(f"{statistics.mean(x / f for x, f in a):.2f}" for a in exact) if all(
                    x is not None for a in exact for x, _ in a) else "–"
                cells.append(f"{name} {err} (alone {alone})")
            print(f"{drives}, wrist {'flipped' if flipped else 'as the grid'}, {len(poses)} poses of "
                  f"{len(g)} runs: position error / floor at 0 / 45 / 90 N: {'; '.join(cells)}.")


def summary(results):
    groups = {}
    for r in results:
        groups.setdefault((r["friction_model"], r["friction_scale"]), []).append(r)
    print("| drives | friction | runs (failed/faulted/aborted) | calibrated / floor at 0 / 45 / 90 N: mean (max) "
          "| still after a move arriving at 0 N / with 90 N [s]: mean (max) | tracking RMS calibrated [mrad]: mean (max) "
          "| gravity RMS J2 / J3 / J5 [N·m], nominal → identified |")
    print("|---|---|---|---|---|---|---|")
    for (model, scale), rs in sorted(groups.items()):
        ok = [r for r in rs if "failed" not in r]
        failed = len(rs) - len(ok)
        faulted = sum(1 for r in ok if r["validation_faults"] or r.get("campaign_faults"))
        aborted = sum(1 for r in ok if r["aborted"])
        ratios = []
        for k in range(3):
            v = [r["loads"][k]["calibrated_mean_mm"] / r["floor_mm"] for r in ok]
            ratios.append(f"{statistics.mean(v):.2f} ({max(v):.2f})" if v else "–")
        still0 = [r["move_settle_mean_s"][0] for r in ok]
        still90 = [r["move_settle_mean_s"][1] for r in ok]
        track = [r["tracking"]["calibrated_rms_mrad"] for r in ok]
        ids = [r["identification"] for r in ok if r.get("identification")]
        grav = "–"
        if ids:
            g = lambda k, j: statistics.mean(i["gravity_rms_nm"][k][j] for i in ids)
            grav = " / ".join(f"{g(0, j):.2f} → {g(1, j):.2f}" for j in (1, 2, 4))
        fmt = lambda v: f"{statistics.mean(v):.2f} ({max(v):.2f})" if v else "–"
        print(f"| {model} | ×{scale:g} | {len(rs)} ({failed}/{faulted}/{aborted}) | {' / '.join(ratios)} "
              f"| {fmt(still0)} / {fmt(still90)} | {fmt(track)} | {grav} |")
    discovery_table(results)


def selftest():
    """The --check rules on made-up runs (`--selftest`): exits 1 with what disagreed."""
    def run_of(model, cal, ext, floor=0.2):
        """A run whose validation poses at 0 N had placement errors `cal` and `ext` (mm)."""
        detail = [{"error_mm": [[1.0] * 3, [c] * 3, [e] * 3], "setpoint_rad": None} for c, e in zip(cal, ext)]
        load = {"load_n": 0.0, "calibrated_mean_mm": statistics.mean(cal), "extended_mean_mm": statistics.mean(ext)}
        return {"seed": 1, "friction_model": model, "friction_scale": 1.0, "floor_mm": floor, "aborted": None,
                "validation_faults": [], "loads": [load], "validation_poses_detail": detail}
    cal = [0.20 + 0.01 * (i % 5) for i in range(18)]
    steady = [c + (0.10 if i % 2 else 0.02) for i, c in enumerate(cal)]  # +0.3x the floor, t ≈ 6
    scattered = [c + (0.66 if i % 2 else -0.54) for i, c in enumerate(cal)]  # the same mean, t ≈ 0.5
    cases = [
        ("sticking, worse by 0.3x the floor, by 0.1–0.5x on every pose", run_of("stick", cal, steady), True),
        ("sticking, worse by 0.3x on average, pose to pose ±0.6 mm", run_of("stick", cal, scattered), False),
        ("sticking, worse by 0.3x over two poses", run_of("stick", cal[:2], steady[:2]), False),
        ("sticking, worse by 0.1x the floor on every pose (within the slack)",
         run_of("stick", cal, [c + 0.02 for c in cal]), False),
        ("creeping, worse by 0.3x on average however scattered", run_of("creep", cal, scattered), True),
    ]
    wrong = [f"{name}: flagged {bool(problems(r, None))}, expected {want}"
             for name, r, want in cases if bool(problems(r, None)) != want]
    for w in wrong:
        print(f"selftest: {w}", file=sys.stderr)
    print(f"study.py selftest: {len(cases) - len(wrong)} of {len(cases)} cases as expected")
    sys.exit(1 if wrong else 0)


def main():
    if sys.argv[1:2] == ["--selftest"]:
        selftest()
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--judge", default="target/release/examples/mujoco_judge")
    ap.add_argument("--seeds", type=seeds, default=seeds("1-10"))
    ap.add_argument("--models", default="creep,stick")
    ap.add_argument("--friction", type=floats, default=floats("0,1,2"))
    ap.add_argument("--jobs", type=int, default=2)
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--out")
    ap.add_argument("--check", type=float, metavar="RATIO")
    ap.add_argument("extra", nargs="*", help="after --: arguments for every judge run")
    ap.add_argument("--summary", metavar="FILE", help="only summarise an earlier --out")
    a = ap.parse_args()
    if a.summary:
        with open(a.summary) as f:
            summary([json.loads(l) for l in f if l.strip()])
        return
    models = a.models.split(",")
    if any(m not in ("creep", "stick") for m in models):
        ap.error(f"--models: creep and/or stick, got {a.models}")
    if not 1 <= a.jobs <= 64:
        ap.error("--jobs: 1...64")
    grid = [(s, m, f) for m in models for f in a.friction for s in a.seeds]
    results = []
    out = open(a.out, "w") if a.out else None
    with cf.ThreadPoolExecutor(a.jobs) as ex:
        futs = [ex.submit(run, a.judge, s, m, f, a.quick, a.extra) for (s, m, f) in grid]
        for fut in cf.as_completed(futs):
            r = fut.result()
            results.append(r)
            if out:
                out.write(json.dumps(r) + "\n")
                out.flush()
            print(f"seed {r['seed']} {r['friction_model']} x{r['friction_scale']:g}: "
                  + ("; ".join(problems(r, a.check)) or "ok"), file=sys.stderr, flush=True)
    if out:
        out.close()
    summary(results)
    bad = [(r, p) for r in results for p in problems(r, a.check)]
    if a.check is not None and bad:
        for r, p in bad:
            print(f"check failed: seed {r['seed']} {r['friction_model']} x{r['friction_scale']:g}: {p}",
                  file=sys.stderr)
        sys.exit(1)


if __name__ == "__main__":
    main()
