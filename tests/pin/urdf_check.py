#!/usr/bin/env python3
"""What Pinocchio makes of a URDF `pa10 urdf` wrote: the tool pose and the generalized gravity
torques at given joint angles, for tests/urdf.rs to compare with the model's own FK and statics.

Usage: urdf_check.py ROBOT.urdf < request.json, where the request is
{"q": [[q1..q6], ...] (rad), "gravity": [gx, gy, gz] (m/s^2, base frame)}. Prints one JSON
object: {"nq": 6, "mass_kg": total, "tool": [[x, y, z, qw, qx, qy, qz], ...] (m),
"gravity_torque": [[t1..t6], ...] (N m: the torques that hold the arm still, Pinocchio's g(q))}.
Needs `pip install pin`.
"""
import json
import sys

import numpy as np
import pinocchio as pin


def main():
    if len(sys.argv) != 2:
        sys.exit("usage: urdf_check.py ROBOT.urdf < request.json")
    model = pin.buildModelFromUrdf(sys.argv[1])
    req = json.load(sys.stdin)
    model.gravity.linear = np.array(req["gravity"], dtype=float)
    data = model.createData()
    tool = model.getFrameId("tool0")
    out = {"nq": model.nq, "mass_kg": float(sum(i.mass for i in model.inertias)), "tool": [], "gravity_torque": []}
    for q in req["q"]:
        q = np.array(q, dtype=float)
        pin.framesForwardKinematics(model, data, q)
        m = data.oMf[tool]
        quat = pin.Quaternion(m.rotation)
        out["tool"].append(list(m.translation) + [quat.w, quat.x, quat.y, quat.z])
        out["gravity_torque"].append(list(pin.computeGeneralizedGravity(model, data, q)))
    print(json.dumps(out))


if __name__ == "__main__":
    main()
