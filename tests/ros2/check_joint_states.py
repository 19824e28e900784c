"""Reads /joint_states with Eclipse Cyclone DDS (the implementation behind rmw_cyclonedds),
with the ROS 2 IDL types declared here, and checks what pa10-ros2 publishes.

    python3 tests/ros2/check_joint_states.py EXPECTED_Q1,...,EXPECTED_Q6

Domain from ROS_DOMAIN_ID. Prints a JSON summary; exits 1 with the reason on a failure.
"""
import json
import os
import sys
import time
from dataclasses import dataclass

from cyclonedds.core import Policy, Qos
from cyclonedds.domain import DomainParticipant
from cyclonedds.idl import IdlStruct
from cyclonedds.idl.types import float64, int32, sequence, uint32
from cyclonedds.sub import DataReader
from cyclonedds.topic import Topic
from cyclonedds.util import duration


@dataclass
class Time(IdlStruct, typename="builtin_interfaces::msg::dds_::Time_"):
    sec: int32
    nanosec: uint32


@dataclass
class Header(IdlStruct, typename="std_msgs::msg::dds_::Header_"):
    stamp: Time
    frame_id: str


@dataclass
class JointState(IdlStruct, typename="sensor_msgs::msg::dds_::JointState_"):
    header: Header
    name: sequence[str]
    position: sequence[float64]
    velocity: sequence[float64]
    effort: sequence[float64]


def main() -> None:
    expected = [float(x) for x in sys.argv[1].split(",")]
    dp = DomainParticipant(int(os.environ.get("ROS_DOMAIN_ID", "0")))
    reader = DataReader(dp, Topic(dp, "rt/joint_states", JointState),
                        qos=Qos(Policy.Reliability.Reliable(duration(seconds=1)), Policy.History.KeepLast(10)))
    got = []
    end = time.time() + 10
    first_at = None
    while time.time() < end and len(got) < 200:
        for s in reader.take(N=50):
            if first_at is None:
                first_at = time.time()
            got.append(s)
        time.sleep(0.005)
    if len(got) < 50:
        sys.exit(f"only {len(got)} joint states in 10 s")
    rate = (len(got) - 1) / max(time.time() - first_at, 1e-9)
    last = got[-1]
    assert list(last.name) == [f"pa10_joint_{j}" for j in range(1, 7)], last.name
    worst = max(abs(a - b) for a, b in zip(last.position, expected))
    stamps = [s.header.stamp.sec + 1e-9 * s.header.stamp.nanosec for s in got]
    assert all(b >= a for a, b in zip(stamps, stamps[1:])), "stamps go back"
    assert abs(stamps[-1] - time.time()) < 5.0, "stamps are wall-clock time"
    assert len(last.effort) == 6 and abs(last.effort[1]) > 1.0, f"gravity on J2: {last.effort}"
    print(json.dumps({"messages": len(got), "rate_hz": rate, "worst_position_error": worst}))
    if worst > 1e-3:
        sys.exit(f"positions {list(last.position)} vs pa10 status {expected}")


if __name__ == "__main__":
    main()
