"""Drives pa10-ros2's FollowJointTrajectory action, its Trigger services and reads
/diagnostics with Eclipse Cyclone DDS (the implementation behind rmw_cyclonedds), through the
raw DDS topics a ROS 2 action is made of, with the ROS 2 IDL types declared here — no ROS
installation, nothing of ours on this side but a plain socket to pa10d for the truth.

    PA10D_SOCKET=… ROS_DOMAIN_ID=… python3 tests/ros2/follow_trajectory.py cyclone|enhanced

`cyclone`: requests and replies carry rmw_cyclonedds' 16-byte header (client GUID half,
sequence number); `enhanced`: none (the reply is matched by the DDS sample identity, which a
single client here need not check). Prints a JSON summary; exits 1 with the reason on a failure.
"""
import json
import os
import random
import socket
import sys
import time
import types as pytypes
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import array, float64, int8, int32, sequence, uint8, uint16, uint32
from cyclonedds.pub import DataWriter
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration

NAMES = [f"pa10_joint_{j}" for j in range(1, 7)]
ACTION = "pa10_controller/follow_joint_trajectory/_action"
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6


def struct(name, typename, fields):
    ns = {"__annotations__": dict(fields)}
    return dataclass(pytypes.new_class(name, (IdlStruct,), {"typename": typename}, lambda d: d.update(ns)))


def msg(pkg, name, fields, kind="msg"):
    return struct(name, f"{pkg}::{kind}::dds_::{name}_", fields)


Time = msg("builtin_interfaces", "Time", [("sec", int32), ("nanosec", uint32)])
Duration = msg("builtin_interfaces", "Duration", [("sec", int32), ("nanosec", uint32)])
Header = msg("std_msgs", "Header", [("stamp", Time), ("frame_id", str)])
UUID = msg("unique_identifier_msgs", "UUID", [("uuid", array[uint8, 16])])
Point = msg("trajectory_msgs", "JointTrajectoryPoint", [
    ("positions", sequence[float64]), ("velocities", sequence[float64]),
    ("accelerations", sequence[float64]), ("effort", sequence[float64]),
    ("time_from_start", Duration)])
Trajectory = msg("trajectory_msgs", "JointTrajectory", [
    ("header", Header), ("joint_names", sequence[str]), ("points", sequence[Point])])
Vector3 = msg("geometry_msgs", "Vector3", [("x", float64), ("y", float64), ("z", float64)])
Quaternion = msg("geometry_msgs", "Quaternion", [("x", float64), ("y", float64), ("z", float64), ("w", float64)])
Transform = msg("geometry_msgs", "Transform", [("translation", Vector3), ("rotation", Quaternion)])
Twist = msg("geometry_msgs", "Twist", [("linear", Vector3), ("angular", Vector3)])
MdPoint = msg("trajectory_msgs", "MultiDOFJointTrajectoryPoint", [
    ("transforms", sequence[Transform]), ("velocities", sequence[Twist]),
    ("accelerations", sequence[Twist]), ("time_from_start", Duration)])
MdTrajectory = msg("trajectory_msgs", "MultiDOFJointTrajectory", [
    ("header", Header), ("joint_names", sequence[str]), ("points", sequence[MdPoint])])
JointTolerance = msg("control_msgs", "JointTolerance", [
    ("name", str), ("position", float64), ("velocity", float64), ("acceleration", float64)])
ComponentTolerance = msg("control_msgs", "JointComponentTolerance", [
    ("joint_name", str), ("component", uint16), ("position", float64), ("velocity", float64),
    ("acceleration", float64)])
Goal = msg("control_msgs", "FollowJointTrajectory_Goal", [
    ("trajectory", Trajectory), ("multi_dof_trajectory", MdTrajectory),
    ("path_tolerance", sequence[JointTolerance]), ("component_path_tolerance", sequence[ComponentTolerance]),
    ("goal_tolerance", sequence[JointTolerance]), ("component_goal_tolerance", sequence[ComponentTolerance]),
    ("goal_time_tolerance", Duration)], "action")
Result = msg("control_msgs", "FollowJointTrajectory_Result", [("error_code", int32), ("error_string", str)], "action")
Feedback = msg("control_msgs", "FollowJointTrajectory_Feedback", [
    ("header", Header), ("joint_names", sequence[str]), ("desired", Point), ("actual", Point),
    ("error", Point), ("multi_dof_joint_names", sequence[str]), ("multi_dof_desired", MdPoint),
    ("multi_dof_actual", MdPoint), ("multi_dof_error", MdPoint)], "action")
FeedbackMessage = msg("control_msgs", "FollowJointTrajectory_FeedbackMessage",
                      [("goal_id", UUID), ("feedback", Feedback)], "action")
GoalInfo = msg("action_msgs", "GoalInfo", [("goal_id", UUID), ("stamp", Time)])
GoalStatus = msg("action_msgs", "GoalStatus", [("goal_info", GoalInfo), ("status", int8)])
GoalStatusArray = msg("action_msgs", "GoalStatusArray", [("status_list", sequence[GoalStatus])])
KeyValue = msg("diagnostic_msgs", "KeyValue", [("key", str), ("value", str)])
DiagnosticStatus = msg("diagnostic_msgs", "DiagnosticStatus", [
    ("level", uint8), ("name", str), ("message", str), ("hardware_id", str), ("values", sequence[KeyValue])])
DiagnosticArray = msg("diagnostic_msgs", "DiagnosticArray", [("header", Header), ("status", sequence[DiagnosticStatus])])

RELIABLE = Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10))


class Service:
    """A ROS 2 service client over raw DDS topics."""

    def __init__(self, dp, name, typename, request, response, header):
        pre = [("client_guid", array[uint8, 8]), ("seq_high", int32), ("seq_low", uint32)] if header else []
        self.header = header
        self.Req = struct("Req", f"{typename}_Request_", pre + request)
        self.Resp = struct("Resp", f"{typename}_Response_", pre + response)
        self.w = DataWriter(dp, Topic(dp, f"rq/{name}Request", self.Req), qos=RELIABLE)
        self.r = DataReader(dp, Topic(dp, f"rr/{name}Reply", self.Resp), qos=RELIABLE)
        self.guid = [random.randrange(256) for _ in range(8)]
        self.seq = 0
        self.name = name

    def wait_matched(self, until):
        while time.time() < until:
            if self.w.get_matched_subscriptions() and self.r.get_matched_publications():
                return
            time.sleep(0.05)
        sys.exit(f"{self.name}: no server matched")

    def call(self, timeout=10.0, **fields):
        self.seq += 1
        extra = dict(client_guid=self.guid, seq_high=0, seq_low=self.seq) if self.header else {}
        self.w.write(self.Req(**extra, **fields))
        end = time.time() + timeout
        while time.time() < end:
            for s in self.r.take(N=10):
                if not self.header or (list(s.client_guid) == self.guid and s.seq_low == self.seq):
                    return s
            time.sleep(0.01)
        sys.exit(f"{self.name}: no reply in {timeout} s")


def daemon(req):
    with socket.socket(socket.AF_UNIX) as s:
        s.connect(os.environ["PA10D_SOCKET"])
        s.sendall((json.dumps(req) + "\n").encode())
        buf = b""
        while not buf.endswith(b"\n"):
            buf += s.recv(65536)
    return json.loads(buf)


def dur(t):
    return Duration(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))


def zero_time():
    return Time(sec=0, nanosec=0)


def goal(names, points):
    """points: (positions in the order of names, t)."""
    return Goal(
        trajectory=Trajectory(header=Header(stamp=zero_time(), frame_id=""), joint_names=names,
                              points=[Point(positions=q, velocities=[], accelerations=[], effort=[],
                                            time_from_start=dur(t)) for q, t in points]),
        multi_dof_trajectory=MdTrajectory(header=Header(stamp=zero_time(), frame_id=""), joint_names=[], points=[]),
        path_tolerance=[], component_path_tolerance=[], goal_tolerance=[], component_goal_tolerance=[],
        goal_time_tolerance=dur(0.0))


def main() -> None:
    header = sys.argv[1] == "cyclone"
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    send = Service(dp, f"{ACTION}/send_goal", "control_msgs::action::dds_::FollowJointTrajectory_SendGoal",
                   [("goal_id", UUID), ("goal", Goal)], [("accepted", bool), ("stamp", Time)], header)
    result = Service(dp, f"{ACTION}/get_result", "control_msgs::action::dds_::FollowJointTrajectory_GetResult",
                     [("goal_id", UUID)], [("status", int8), ("result", Result)], header)
    cancel = Service(dp, f"{ACTION}/cancel_goal", "action_msgs::srv::dds_::CancelGoal",
                     [("goal_info", GoalInfo)], [("return_code", int8), ("goals_canceling", sequence[GoalInfo])], header)
    stop = Service(dp, "pa10_driver/stop", "std_srvs::srv::dds_::Trigger",
                   [("structure_needs_at_least_one_member", uint8)], [("success", bool), ("message", str)], header)
    feedback = DataReader(dp, Topic(dp, f"rt/{ACTION}/feedback", FeedbackMessage),
                          qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1000)))
    status = DataReader(dp, Topic(dp, f"rt/{ACTION}/status", GoalStatusArray),
                        qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(1),
                                Policy.Durability.TransientLocal))
    diagnostics = DataReader(dp, Topic(dp, "rt/diagnostics", DiagnosticArray), qos=RELIABLE)
    until = time.time() + 20
    for s in (send, result, cancel, stop):
        s.wait_matched(until)
    out = {}

    def run(g, cancel_after=None):
        gid = UUID(uuid=[random.randrange(256) for _ in range(16)])
        r = send.call(goal_id=gid, goal=g)
        assert r.accepted, "goal not accepted"
        if cancel_after is not None:
            time.sleep(cancel_after)
            c = cancel.call(goal_info=GoalInfo(goal_id=gid, stamp=zero_time()))
            assert c.return_code == 0 and len(c.goals_canceling) == 1, f"cancel: {c}"
        res = result.call(timeout=30.0, goal_id=gid)
        fb = [m for m in feedback.take(N=1000) if list(m.goal_id.uuid) == list(gid.uuid)]
        return res, fb

    # 0. hostile input is ordinary input: a goal request that is not one (the request type's
    # name, a UUID and nothing else) from another participant must not stop the bridge
    dp2 = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    pre = [("client_guid", array[uint8, 8]), ("seq_high", int32), ("seq_low", uint32)] if header else []
    Bad = struct("Bad", "control_msgs::action::dds_::FollowJointTrajectory_SendGoal_Request_", pre + [("goal_id", UUID)])
    bad_w = DataWriter(dp2, Topic(dp2, f"rq/{ACTION}/send_goalRequest", Bad), qos=RELIABLE)
    end = time.time() + 10
    while not bad_w.get_matched_subscriptions() and time.time() < end:
        time.sleep(0.05)
    extra = dict(client_guid=[0] * 8, seq_high=0, seq_low=1) if header else {}
    for _ in range(3):
        bad_w.write(Bad(**extra, goal_id=UUID(uuid=[7] * 16)))
    time.sleep(0.5)

    st = daemon({"cmd": "status"})["status"]
    start = st["setpoint"]
    target = [q + d for q, d in zip(start, [0.10, -0.08, 0.12, 0.10, -0.10, 0.15])]
    # 1. a MoveIt-like goal: joints in another order, the start state first at t = 0
    order = [2, 0, 5, 1, 4, 3]
    names = [NAMES[j] for j in order]
    res, fb = run(goal(names, [([start[j] for j in order], 0.0), ([target[j] for j in order], 2.0)]))
    assert res.status == SUCCEEDED and res.result.error_code == 0, f"goal 1: {res}"
    actual = daemon({"cmd": "status"})["status"]["trajectory"]["actual"]
    worst = max(abs(a - b) for a, b in zip(actual, target))
    assert worst < 0.005, f"goal 1 arrived {worst} rad from its target: {actual} vs {target}"
    assert len(fb) >= 25, f"goal 1: {len(fb)} feedback messages in 2 s (20 Hz)"
    assert list(fb[-1].feedback.joint_names) == NAMES
    out["goal_succeeded"] = {"feedback": len(fb), "worst_error_rad": worst}
    # 2. joints that are not the arm's: accepted, then ABORTED with INVALID_JOINTS and the words
    bad = list(NAMES)
    bad[4] = "elbow"
    res, _ = run(goal(bad, [(target, 1.0)]))
    assert res.status == ABORTED and res.result.error_code == -2, f"goal 2: {res}"
    assert "elbow" in res.result.error_string, res.result.error_string
    out["goal_invalid_joints"] = res.result.error_string
    # 3. a trajectory the daemon refuses (back to the start in 50 ms: too fast): ABORTED,
    # INVALID_GOAL, the daemon's words
    res, _ = run(goal(NAMES, [(start, 0.05)]))
    assert res.status == ABORTED and res.result.error_code == -1, f"goal 3: {res}"
    assert "refused" in res.result.error_string, res.result.error_string
    out["goal_refused_by_pa10d"] = res.result.error_string
    # 4. cancelled after 1 s of 6: CANCELED, the arm stopped short of the goal
    res, fb = run(goal(NAMES, [(start, 6.0)]), cancel_after=1.0)
    assert res.status == CANCELED, f"goal 4: {res}"
    time.sleep(1.0)
    st = daemon({"cmd": "status"})["status"]
    assert st["state"] == "holding", st["state"]
    left = max(abs(a - b) for a, b in zip(st["setpoint"], start))
    assert left > 0.01, f"cancelled, yet the arm reached the goal ({left} rad)"
    out["goal_canceled"] = {"feedback": len(fb), "stopped_short_rad": left}
    # the status topic (transient local) knows the goals' ends
    ends = [s.status for a in status.take(N=10) for s in a.status_list]
    out["goal_statuses"] = ends
    # 4b. a newer goal replaces the running one: the old one CANCELED ("replaced"), the new one
    # followed from where the arm was (no jump) to SUCCEEDED
    first = UUID(uuid=[random.randrange(256) for _ in range(16)])
    assert send.call(goal_id=first, goal=goal(NAMES, [(target, 6.0)])).accepted
    time.sleep(0.5)
    res_b, _ = run(goal(NAMES, [(start, 4.0)]))
    res_a = result.call(timeout=10.0, goal_id=first)
    assert res_a.status == CANCELED and res_a.result.error_code == -1, f"replaced goal: {res_a}"
    assert "replaced" in res_a.result.error_string, res_a.result.error_string
    assert res_b.status == SUCCEEDED, f"replacing goal: {res_b}"
    actual = daemon({"cmd": "status"})["status"]["trajectory"]["actual"]
    worst = max(abs(a - b) for a, b in zip(actual, start))
    assert worst < 0.005, f"the replacing goal arrived {worst} rad from its target"
    out["goal_replaced"] = {"old": res_a.result.error_string, "new_worst_error_rad": worst}
    # 5. ~/stop
    r = stop.call(structure_needs_at_least_one_member=0)
    assert r.success, r.message
    out["stop"] = r.message
    # 6. /diagnostics
    end = time.time() + 5
    d = []
    while time.time() < end and not d:
        d = diagnostics.take(N=10)
        time.sleep(0.1)
    assert d, "no /diagnostics in 5 s"
    s = d[-1].status[0]
    # OK, or WARN for the loop's wake-up jitter on a loaded test host — never ERROR or STALE
    assert s.level in (0, 1) and s.hardware_id == "pa10-6ce", s
    assert (s.level == 1) == ("jitter" in s.message), s
    keys = {kv.key: kv.value for kv in s.values}
    assert int(keys["cycles"]) > 0, keys
    out["diagnostics"] = {"level": s.level, "message": s.message, "values": len(keys)}
    print(json.dumps(out))


if __name__ == "__main__":
    main()
