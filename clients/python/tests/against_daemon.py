"""The Python client against a running pa10d on the simulated backend (pa10's tests start it:
tests/daemon.rs). Exits non-zero with the reason on the first failure.

    python3 clients/python/tests/against_daemon.py SOCKET
"""
import sys
import time

from pa10_client import Client, Pa10Error


def expect_refusal(call, contains: str) -> None:
    try:
        call()
    except Pa10Error as e:
        assert contains in e.message, f"{contains!r} not in {e.message!r}"
        return
    raise AssertionError(f"no refusal (expected {contains!r})")


def main(sock: str) -> None:
    with Client(sock) as arm, Client(sock) as other:
        st = arm.status()
        assert st["state"] == "holding", st
        home = st["setpoint"]
        # moves, with the daemon's own words on a refusal
        arm.move_joints([0.1, 0.45, 1.55, 0.0, 1.1, -0.1], wait=True)
        assert abs(arm.status()["setpoint"][0] - 0.1) < 1e-9
        expect_refusal(lambda: arm.move_joints([0.0, 2.5, 0.0, 0.0, 0.0, 0.0]), "joint 2")
        # a trajectory back home, followed to the end
        t = arm.follow_trajectory(
            [{"positions": [0.05, 0.42, 1.58, 0.0, 1.1, -0.05], "time_from_start": 0.8},
             {"positions": home, "time_from_start": 1.6}],
            wait=True,
        )
        assert t["state"] == "succeeded" and t["progress"] == 1.0, t
        expect_refusal(lambda: arm.follow_trajectory([]), "points")
        # the lease: the other connection may look and stop, not move
        arm.acquire()
        expect_refusal(lambda: other.move_joints(home), "motion lease")
        assert other.status()["leased"] is True
        arm.release()
        # a servo stream, then silence: the daemon stops it by itself
        for k in range(50):
            q = list(home)
            q[5] += 0.0004 * k
            arm.servo(q)
            time.sleep(0.004)
        st = arm.wait_holding(5.0)
        assert "servo.deadline_ms" in (st["stream_end"] or ""), st
        arm.jog([0.0, 0.0, 0.0, 0.0, 0.0, 0.1])
        arm.stop()
        arm.wait_holding(5.0)
        arm.set_speed_scaling(1.0)
        expect_refusal(lambda: arm.set_speed_scaling(2.0), "speed scaling")
        # subscribe streams status
        with Client(sock) as watcher:
            stream = watcher.subscribe(50.0)
            first = next(stream)
            second = next(stream)
            assert second["cycle"]["cycles"] > first["cycle"]["cycles"]
    print("python client: all checks passed")


if __name__ == "__main__":
    main(sys.argv[1])
