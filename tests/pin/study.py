#!/usr/bin/env python3
"""The statistics of `pa10 calibrate` + `pa10 discover` over random campaign designs from the
Pinocchio generator (`campaign.py`), judged against the generator's truth. The tool under
test is a black box: the `pa10` binary, as a user runs it.

    python3 tests/pin/study.py --pa10 target/release/pa10 --count 300 [--first 1]
        [--nominal-every 3] [--check] [--keep DIR]

For each seed: generate a campaign (0, 1 or 2 hidden effects, drawn from the seed),
calibrate it from the nominal model, discover from the calibrated model with the
validation set held out; every `--nominal-every`-th clean campaign is also discovered from
the rigid nominal model. Prints one line a campaign, then the rates against the bars and the
misses by campaign design. `--check` exits 1 when a hard invariant breaks (an abort, a
"gap closed" verdict with the held-out error above 1.25x the floor, a false naming on more
than 2 % of clean campaigns); `--bars` also when a statistical bar is missed.
"""

import argparse
import collections
import json
import os
import subprocess
import sys
import tempfile
import time

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import campaign  # noqa: E402

NOMINAL = os.path.join(HERE, "..", "..", "config", "model-nominal.yaml")

# When a campaign can reveal an effect at all (the generator's noncentrality λ, from its
# truth alone: campaign.noncentrality). The calibration set: a candidate of k <= 2
# parameters must show Delta-chi2 of about 24 (Bonferroni over ~28 candidates at 1 %, and
# Delta-BIC > 10 at ln n ~ 7); a noncentral chi2_2(λ) exceeds that in 95 % of campaigns from
# λ ~ 45. The held-out set: the paired test over its 30 configurations has t ~ sqrt(λ)/2
# (a configuration's gain has mean λ_i and variance 4 λ_i), above 2.76 in 95 % of campaigns
# from λ ~ (2 (2.76 + 1.645))^2 ~ 78.
LAMBDA_CAL = 45.0
LAMBDA_HOLDOUT = 80.0


def revealable(h):
    return h.get("noncentrality", 0.0) >= LAMBDA_CAL and h.get("noncentrality_holdout", 0.0) >= LAMBDA_HOLDOUT

# What a correct localisation looks like, per hidden effect: the joint and the labels.
EXPECT = {
    "spring_j4": (4, ("joint_compliance_linear[J4]",)),
    "transmission_j3": (3, ("transmission_error[J3]", "encoder_eccentricity[J3]", "generic[J3: sin q]", "generic[J3: cos q]")),
    "scale_j3": (3, ("gear_ratio_error[J3]",)),
    "scale_j5": (5, ("gear_ratio_error[J5]",)),
    # sin q = q - q^3/6 + ...: the eccentricity is q^3's library look-alike on J1.
    "cubic_j1": (1, ("generic[J1: q³]", "encoder_eccentricity[J1]")),
    "tool_sag": (None, ("tool_sag",)),
}


def run(cmd):
    t0 = time.time()
    p = subprocess.run(cmd, capture_output=True, text=True)
    return p, time.time() - t0


def discover(pa10, model, d, holdout=True):
    cmd = [pa10, "discover", "--model", model, "--data", os.path.join(d, "cal.csv"), "--json"]
    if holdout:
        cmd += ["--holdout", os.path.join(d, "val.csv")]
    p, dt = run(cmd)
    if p.returncode != 0:
        return None, p.stderr.strip().splitlines()[-1:] or ["(no message)"], dt
    return json.loads(p.stdout), None, dt


def judge(truth, disc):
    """(all hidden found on the right joint and form, false namings, per-effect hits)."""
    labels = [e["label"] for e in disc["effects"]]
    joints = {e["joint"] for e in disc["effects"]}
    hits = {}
    allowed_joints = set()
    allowed_labels = set()
    for h in truth["hidden"]:
        j, ok = EXPECT[h["name"]]
        if h["in_library"]:
            # The bar for a library effect: named on the right joint.
            hits[h["name"]] = j in joints
            ok = tuple(e["label"] for e in disc["effects"] if e["joint"] == j)
        else:
            # Outside the library: the right joint and form.
            hits[h["name"]] = any(lab in ok for lab in labels)
        allowed_joints.add(j)
        allowed_labels.update(ok)
    # A naming is false when it is on a joint (or the tool) where nothing is hidden.
    false = [e["label"] for e in disc["effects"] if e["label"] not in allowed_labels and e["joint"] not in allowed_joints - {None}]
    return hits, false, joints


def design_keys(truth):
    d = truth["design"]
    return {
        "family": d["family"],
        "tool": "tool < 0.25 m" if d["tool_length_m"] < 0.25 else "tool >= 0.25 m",
        "configs": "15-24 configs" if d["configs"] < 25 else "25-40 configs",
        "repeats": "1-3 repeats" if d["repeats"] <= 3 else "4-10 repeats",
        "loads": f"{len(d['loads_n'])} loads",
    }


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--pa10", default=os.path.join(HERE, "..", "..", "target", "release", "pa10"))
    ap.add_argument("--count", type=int, default=30)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--nominal-every", type=int, default=3, help="every k-th clean campaign is also discovered from the rigid nominal model (0: never)")
    ap.add_argument("--check", action="store_true", help="exit 1 when a hard invariant breaks")
    ap.add_argument("--bars", action="store_true", help="exit 1 when a statistical bar is missed too")
    ap.add_argument("--keep", help="keep every campaign under this folder")
    ap.add_argument("--json", help="write every campaign's outcome to this file")
    a = ap.parse_args()
    root = a.keep or tempfile.mkdtemp(prefix="pa10-pin-study-")
    n = collections.Counter()
    misses = collections.defaultdict(collections.Counter)
    totals = collections.defaultdict(collections.Counter)
    outcomes = []
    closed_above = 0
    t_start = time.time()
    clean_seen = 0
    for seed in range(a.first, a.first + a.count):
        d = os.path.join(root, str(seed))
        cal, val, meta, truth, urdf = campaign.generate(seed, detectability=True)
        campaign.write(d, cal, val, meta, truth, urdf)
        keys = design_keys(truth)
        hidden = [h["name"] for h in truth["hidden"]]
        out = {"seed": seed, "hidden": hidden, "design": truth["design"], "truth": truth["hidden"]}
        p, t_cal = run([a.pa10, "calibrate", "--data", os.path.join(d, "cal.csv"), "--out", os.path.join(d, "calibrated.yaml")])
        if p.returncode != 0:
            n["aborts"] += 1
            out["abort"] = "calibrate: " + (p.stderr.strip().splitlines() or ["?"])[-1]
            print(f"seed {seed:4d} {hidden}: ABORT {out['abort']}", flush=True)
            outcomes.append(out)
            continue
        disc, err, t_disc = discover(a.pa10, os.path.join(d, "calibrated.yaml"), d)
        n["runs"] += 1
        if disc is None:
            n["aborts"] += 1
            out["abort"] = "discover: " + err[0]
            print(f"seed {seed:4d} {hidden}: ABORT {err[0]}", flush=True)
            outcomes.append(out)
            continue
        hits, false, _ = judge(truth, disc)
        ratio = disc["gap_after_mm"] / disc["noise_floor_mm"]
        if disc["gap_closed"] and ratio > 1.25:
            closed_above += 1
        labels = [e["label"] for e in disc["effects"]]
        # every named effect with its estimate (what the JSON of `pa10 discover` says of it),
        # beside the generator's truth in "truth": how close an estimate came, not only its name
        out.update(labels=labels, effects=disc["effects"], false=false, hits=hits, ratio=ratio, closed=disc["gap_closed"], seconds=t_disc)
        note = ""
        if not hidden:
            n["clean"] += 1
            n["clean_false"] += bool(labels)
            for k, v in keys.items():
                totals["clean: " + k][v] += 1
                if labels:
                    misses["clean: " + k][v] += 1
        for hd in truth["hidden"]:
            h = hd["name"]
            lib = campaign.POOL[h][0]
            tag = "in" if lib else "out"
            n[f"{tag}"] += 1
            n[f"{tag}_hit"] += hits[h]
            if revealable(hd):
                n[f"{tag}_rev"] += 1
                n[f"{tag}_rev_hit"] += hits[h]
            elif not hits[h]:
                # Below what the campaign can reveal: missed, and the verdict?
                n[f"{tag}_weak_miss"] += 1
                n[f"{tag}_weak_miss_closed_ok"] += disc["gap_closed"] and ratio <= 1.25
                n[f"{tag}_weak_miss_admitted"] += not disc["gap_closed"]
            if not lib and not hits[h]:
                n["out_admitted"] += not disc["gap_closed"]
            lam = hd.get("noncentrality", 0.0)
            reveal = "revealable" if revealable(hd) else ("λ < 45" if lam < LAMBDA_CAL else "held-out λ < 80")
            for k, v in {**keys, "lambda": reveal}.items():
                totals[f"{tag}: " + k][v] += 1
                if not hits[h]:
                    misses[f"{tag}: " + k][v] += 1
        if hidden:
            n["hidden_runs"] += 1
            n["hidden_false"] += bool(false)
        if not hidden and a.nominal_every and clean_seen % a.nominal_every == 0:
            nd, nerr, t_nom = discover(a.pa10, NOMINAL, d)
            n["nominal"] += 1
            if nd is None:
                n["aborts"] += 1
                note = f"; from nominal: ABORT {nerr[0]}"
            else:
                springs = sorted(e["joint"] for e in nd["effects"] if e["name"] == "joint_compliance_linear")
                others = [e["label"] for e in nd["effects"] if e["joint"] not in (2, 3, 5)]
                nratio = nd["gap_after_mm"] / nd["noise_floor_mm"]
                ok = springs == [2, 3, 5] and not others and nratio <= 1.3
                n["nominal_ok"] += ok
                if nd["gap_closed"] and nratio > 1.25:
                    closed_above += 1
                out["nominal"] = {"labels": [e["label"] for e in nd["effects"]], "ratio": nratio, "ok": ok, "seconds": t_nom}
                note = f"; from nominal: {'ok' if ok else 'MISS'} {[e['label'] for e in nd['effects']]} {nratio:.2f}x ({t_nom:.1f} s)"
        if not hidden:
            clean_seen += 1
        mark = "ok" if all(hits.values()) and not false and not (not hidden and labels) else "MISS"
        print(f"seed {seed:4d} {hidden} {truth['design']['family']}, {truth['design']['configs']} cfg x {len(truth['design']['loads_n'])} loads x {truth['design']['repeats']}: {mark} {labels} {ratio:.2f}x, closed {disc['gap_closed']} ({t_cal:.1f}+{t_disc:.1f} s){note}", flush=True)
        outcomes.append(out)

    def rate(k, of):
        return f"{n[k]}/{n[of]}" + (f" ({100.0 * n[k] / n[of]:.0f} %)" if n[of] else "")

    print()
    print(f"{a.count} campaigns in {time.time() - t_start:.0f} s; aborts {n['aborts']}; 'gap closed' above 1.25x the floor: {closed_above}")
    print(f"clean campaigns with a false naming: {rate('clean_false', 'clean')} (bar <= 2 %)")
    print(f"hidden in-library effects named on the right joint: {rate('in_hit', 'in')}; of those the campaign can reveal (λ >= {LAMBDA_CAL:g} calibration, >= {LAMBDA_HOLDOUT:g} held-out): {rate('in_rev_hit', 'in_rev')} (bar >= 95 %)")
    print(f"  missed below that: {n['in_weak_miss']}, of which 'gap closed' within 1.25x the floor {n['in_weak_miss_closed_ok']}, admitted (not closed) {n['in_weak_miss_admitted']}")
    print(f"hidden effects outside the library localised (joint and form): {rate('out_hit', 'out')} (bar >= 80 %); not localised but admitted (gap not closed): {n['out_admitted']}; of those the campaign can reveal: {rate('out_rev_hit', 'out_rev')}")
    print(f"campaigns with a hidden effect and a naming elsewhere: {rate('hidden_false', 'hidden_runs')}")
    print(f"from the rigid nominal model, J2/J3/J5 springs and <= 1.3x the floor: {rate('nominal_ok', 'nominal')} (bar >= 95 %)")
    print("\nmisses by campaign design (missed / campaigns):")
    for group in sorted(totals):
        cells = ", ".join(f"{v}: {misses[group][v]}/{t}" for v, t in sorted(totals[group].items()))
        print(f"  {group:<18} {cells}")
    if a.json:
        with open(a.json, "w") as f:
            json.dump(outcomes, f, indent=1)
    hard = n["aborts"] == 0 and closed_above == 0 and 50 * n["clean_false"] <= max(n["clean"], 1)
    bars = (
        hard
        and (n["in_rev"] == 0 or 100 * n["in_rev_hit"] >= 95 * n["in_rev"])
        and (n["out"] == 0 or 100 * n["out_hit"] >= 80 * n["out"])
        and (n["nominal"] == 0 or 100 * n["nominal_ok"] >= 95 * n["nominal"])
    )
    print("hard invariants " + ("held" if hard else "BROKEN") + "; statistical bars " + ("met" if bars else "missed"))
    if (a.check and not hard) or (a.bars and not bars):
        sys.exit(1)


if __name__ == "__main__":
    main()
