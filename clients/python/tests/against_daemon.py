"""The Python client against a running pa10d on the simulated backend (pa10's tests start it:
tests/daemon.rs). Every request the client sends and every reply it reads is validated against
the protocol's JSON Schema, docs/api.schema.json (generated from pa10::daemon::wire), by the
`jsonschema` package. Exits non-zero with the reason on the first failure.

    python3 clients/python/tests/against_daemon.py SOCKET
"""
import json
import pathlib
import sys
import time

import jsonschema

from pa10_client import Client, Json, Pa10Error

SCHEMA = json.loads(
    (pathlib.Path(__file__).resolve().parents[3] / "docs" / "api.schema.json").read_text()
)


def validator(definition: str) -> jsonschema.Draft202012Validator:
    """A validator of one definition of the protocol's schema."""
    schema = {"$ref": f"#/$defs/{definition}", "$defs": SCHEMA["$defs"]}
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


REQUEST = validator("ApiRequest")
REPLY = validator("Reply")
CHECKED = {"requests": 0, "invalid": 0, "replies": 0}


class Checked(Client):
    """The client, every request and reply validated against the schema on the way: a reply
    must be valid, and a request the schema refuses must be refused by the daemon too (the
    tests send some on purpose, to hear the daemon's words)."""

    _valid = True

    def _send(self, request: Json) -> None:
        self._valid = REQUEST.is_valid(request)
        CHECKED["requests" if self._valid else "invalid"] += 1
        super()._send(request)

    def _receive(self, line: bytes) -> Json:
        answer = super()._receive(line)
        REPLY.validate(answer)
        assert self._valid or answer["ok"] is False, f"pa10d accepted what the schema refuses: {answer}"
        if answer.get("ok"):
            # an accepted reply's status is a Status (the flat reply form leaves it open)
            if "status" in answer:
                validator("Status").validate(answer["status"])
        CHECKED["replies"] += 1
        return answer


def schema_refuses(request: Json) -> None:
    assert not REQUEST.is_valid(request), f"the schema accepts {request}"


def expect_refusal(call, contains: str) -> None:
    try:
        call()
    except Pa10Error as e:
        assert contains in e.message, f"{contains!r} not in {e.message!r}"
        return
    raise AssertionError(f"no refusal (expected {contains!r})")


def main(sock: str) -> None:
    # what the daemon refuses as a bad request, the schema refuses too
    schema_refuses({"cmd": "move_joints", "q": [0.0, 0.0]})
    schema_refuses({"cmd": "stop", "speed": 0})
    schema_refuses({"cmd": "teleport"})
    schema_refuses({"cmd": "subscribe", "rate_hz": 1000.0})
    with Checked(sock) as arm, Checked(sock) as other:
        st = arm.status()
        assert st["state"] == "holding", st
        home = st["setpoint"]
        # moves, with the daemon's own words on a refusal
        arm.move_joints([0.1, 0.45, 1.55, 0.0, 1.1, -0.1], wait=True)
        st = arm.status()
        assert abs(st["setpoint"][0] - 0.1) < 1e-9
        assert st["in_position"] is True, st
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
        with Checked(sock) as watcher:
            stream = watcher.subscribe(50.0)
            first = next(stream)
            second = next(stream)
            assert second["cycle"]["cycles"] > first["cycle"]["cycles"]
    assert CHECKED["requests"] > 50 and CHECKED["replies"] > 50 and CHECKED["invalid"] > 0, CHECKED
    print(
        f"python client: {CHECKED['requests']} requests and {CHECKED['replies']} replies valid against"
        f" docs/api.schema.json; {CHECKED['invalid']} the schema refuses, refused by pa10d too"
    )
    print("python client: all checks passed")


if __name__ == "__main__":
    main(sys.argv[1])
