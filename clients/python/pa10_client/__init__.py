"""A typed, pure-Python client for pa10d (the PA10-6CE control daemon).

One :class:`Client` is one connection to the daemon's Unix socket (newline-delimited JSON,
``docs/api.md`` and ``docs/motion.md`` in the pa10 repository). Every refusal raises
:class:`Pa10Error` carrying the daemon's own message; joint values are link-side radians,
positions metres, quaternions ``[w, x, y, z]``.

    >>> from pa10_client import Client
    >>> with Client("/run/pa10d/pa10d.sock") as arm:      # doctest: +SKIP
    ...     arm.move_joints([0.1, 0.45, 1.55, 0.0, 1.1, -0.1], wait=True)
"""

from __future__ import annotations

import json
import os
import socket
import time
from typing import Any, Callable, Dict, Iterator, List, Optional, Sequence

__all__ = ["Client", "Pa10Error", "TrajectoryPoint", "DEFAULT_SOCKET"]

DEFAULT_SOCKET = os.environ.get("PA10D_SOCKET", "/run/pa10d/pa10d.sock")

Json = Dict[str, Any]
TrajectoryPoint = Dict[str, Any]
"""``{"positions": [6], "velocities"?: [6], "accelerations"?: [6], "time_from_start": s}``"""


class Pa10Error(RuntimeError):
    """The daemon refused a request; ``str(e)`` and ``e.message`` are its own words."""

    def __init__(self, message: str, request: Optional[Json] = None) -> None:
        super().__init__(message)
        self.message = message
        self.request = request


def _six(name: str, values: Sequence[float]) -> List[float]:
    v = [float(x) for x in values]
    if len(v) != 6:
        raise ValueError(f"{name}: 6 values needed, got {len(v)}")
    return v


class Client:
    """One connection to pa10d. The motion lease (``acquire``) belongs to it."""

    def __init__(self, path: str = DEFAULT_SOCKET, timeout_s: float = 10.0) -> None:
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        self._sock.settimeout(timeout_s)
        self._sock.connect(path)
        self._file = self._sock.makefile("rwb")

    def close(self) -> None:
        """Closes the connection (a held lease ends; a move it made stops)."""
        try:
            self._file.close()
        finally:
            self._sock.close()

    def __enter__(self) -> "Client":
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # -- the wire ------------------------------------------------------------------------

    def _send(self, request: Json) -> None:
        """Writes one request line (a subclass may check it first: the tests validate every
        request against ``docs/api.schema.json``)."""
        self._file.write(json.dumps(request).encode() + b"\n")
        self._file.flush()

    def _receive(self, line: bytes) -> Json:
        """One reply line as JSON (a subclass may check it: the tests validate every reply)."""
        answer: Json = json.loads(line)
        return answer

    def call(self, request: Json) -> Json:
        """Sends one request, returns the answer; a refusal raises :class:`Pa10Error`."""
        self._send(request)
        line = self._file.readline()
        if not line:
            raise Pa10Error("pa10d closed the connection", request)
        answer = self._receive(line)
        if answer.get("ok") is not True:
            raise Pa10Error(str(answer.get("error", "unknown error")), request)
        return answer

    # -- state ---------------------------------------------------------------------------

    def status(self) -> Json:
        """The daemon's state (``docs/api.md``)."""
        return self.call({"cmd": "status"})["status"]

    def subscribe(self, rate_hz: float = 10.0) -> Iterator[Json]:
        """Yields ``status`` at ``rate_hz`` until the connection closes (use a separate
        :class:`Client` for commands)."""
        self._send({"cmd": "subscribe", "rate_hz": rate_hz})
        while True:
            line = self._file.readline()
            if not line:
                return
            answer = self._receive(line)
            if answer.get("ok") is not True:
                raise Pa10Error(str(answer.get("error")), {"cmd": "subscribe"})
            yield answer["status"]

    def _wait(self, done: Callable[[Json], bool], what: str, timeout_s: float, poll_s: float) -> Json:
        """Polls ``status`` until ``done`` says so; a fault, or ``timeout_s`` passing, raises
        :class:`Pa10Error` (``"<what> within <timeout_s> s"``)."""
        end = time.monotonic() + timeout_s
        while True:
            st = self.status()
            if done(st):
                return st
            if st["state"] == "fault":
                raise Pa10Error(f"fault: {st['fault']}")
            if time.monotonic() > end:
                raise Pa10Error(f"{what} within {timeout_s} s (state {st['state']})")
            time.sleep(poll_s)

    def wait_holding(self, timeout_s: float = 30.0, poll_s: float = 0.01) -> Json:
        """Waits until the arm holds; a fault or the timeout raises :class:`Pa10Error`."""
        return self._wait(lambda st: st["state"] == "holding", "not holding", timeout_s, poll_s)

    def wait_in_position(self, timeout_s: float = 5.0, poll_s: float = 0.01) -> Json:
        """Waits until the arm holds *in position* (``status.in_position``: every motor still
        and within its holding band of its target; docs/daemon.md) — what to wait for before
        measuring: a sticking drive can wind up for seconds after the setpoint stopped. A fault,
        or not in position within ``timeout_s``, raises :class:`Pa10Error`."""
        return self._wait(
            lambda st: st["state"] == "holding" and bool(st.get("in_position")),
            "not in position",
            timeout_s,
            poll_s,
        )

    # -- moves ---------------------------------------------------------------------------

    def move_joints(self, q: Sequence[float], wait: bool = False) -> float:
        """A joint move to link angles ``q`` (rad); its duration, s. With ``wait``, returns
        when the arm holds in position (:meth:`wait_in_position`)."""
        d = float(self.call({"cmd": "move_joints", "q": _six("q", q)})["duration_s"])
        if wait:
            self.wait_holding(d + 10.0)
            self.wait_in_position()
        return d

    def move_pose(self, position: Sequence[float], quaternion: Sequence[float], wait: bool = False) -> float:
        """A straight-line tool move (base frame, m, unit quaternion w, x, y, z); its duration, s.
        With ``wait``, returns when the arm holds in position (:meth:`wait_in_position`)."""
        d = float(
            self.call({"cmd": "move_pose", "position": list(position), "quaternion": list(quaternion)})["duration_s"]
        )
        if wait:
            self.wait_holding(d + 10.0)
            self.wait_in_position()
        return d

    def follow_trajectory(
        self,
        points: Sequence[TrajectoryPoint],
        path_tolerance: Optional[Sequence[float]] = None,
        goal_tolerance: Optional[Sequence[float]] = None,
        goal_time_tolerance: Optional[float] = None,
        wait: bool = False,
    ) -> Json:
        """Follows a timed joint trajectory; ``{"id": N}``, or with ``wait`` the final
        ``status.trajectory`` (raises unless it succeeded)."""
        req: Json = {"cmd": "follow_trajectory", "points": list(points)}
        if path_tolerance is not None:
            req["path_tolerance"] = _six("path_tolerance", path_tolerance)
        if goal_tolerance is not None:
            req["goal_tolerance"] = _six("goal_tolerance", goal_tolerance)
        if goal_time_tolerance is not None:
            req["goal_time_tolerance"] = float(goal_time_tolerance)
        ident = self.call(req)["id"]
        if not wait:
            return {"id": ident}
        while True:
            t = self.status()["trajectory"]
            if t["id"] != ident:
                raise Pa10Error(f"trajectory {ident} was replaced by {t['id']}")
            if t["state"] == "succeeded":
                return t
            if t["state"] != "executing":
                raise Pa10Error(f"trajectory {ident} {t['state']}: {t['result']}")
            time.sleep(0.01)

    def servo(self, positions: Sequence[float]) -> None:
        """One streamed setpoint (link angles, rad); send them at up to the cycle rate."""
        self.call({"cmd": "servo", "positions": _six("positions", positions)})

    def jog(self, joint_velocities: Sequence[float]) -> None:
        """Streamed joint velocities (rad/s); repeat within the daemon's deadline."""
        self.call({"cmd": "jog", "joint_velocities": _six("joint_velocities", joint_velocities)})

    def jog_tool(self, twist: Sequence[float], frame: str = "base") -> None:
        """A streamed tool twist (vx, vy, vz m/s, wx, wy, wz rad/s) in ``base`` or ``tool``."""
        self.call({"cmd": "jog", "tool_twist": _six("twist", twist), "frame": frame})

    def set_speed_scaling(self, fraction: float) -> None:
        """Slows running and future trajectories (0 < fraction ≤ 1)."""
        self.call({"cmd": "set_speed_scaling", "fraction": float(fraction)})

    def stop(self) -> None:
        """A controlled stop (always allowed)."""
        self.call({"cmd": "stop"})

    def estop(self) -> None:
        """An emergency stop (always allowed; a fault until ``reset``)."""
        self.call({"cmd": "estop"})

    def reset(self) -> None:
        """Clears a fault."""
        self.call({"cmd": "reset"})

    # -- the lease -----------------------------------------------------------------------

    def acquire(self) -> None:
        """Takes the motion lease for this connection."""
        self.call({"cmd": "acquire"})

    def release(self) -> None:
        """Gives the motion lease back."""
        self.call({"cmd": "release"})
