"""Reference solution, the heading PID (assignment 2.4), with roslibpy.

    WEBSIM_URL=ws://localhost:9090 WEBSIM_SETPOINT_RAD=1.5708 python heading_pid.py
    websim grade heading_pid -- python3 heading_pid.py

Turns in place to the setpoint WEBSIM_SETPOINT_RAD (rad, relative to the heading at the start:
the odom frame) and holds it. It answers every /odom with one /cmd_vel (a callback, not a
timer), so ``websim grade`` can run it in deterministic mode. A setpoint that changes
during the run (WEBSIM_SETPOINT_RAD_CHANGES, ``at_s:value`` pairs) is applied at the first
/odom whose time since the start reaches it. WEBSIM_KP overrides the gain (default 4 rad/s
per rad). For the payload bonus (``heading_pid_payload``), ``--slew RPS`` limits how much
the command may change per /odom, so the wheels never slip (``--slew 0.25``: 0.5 rad/s per
0.1 s)::

    websim grade heading_pid_payload -- python3 heading_pid.py --slew 0.25

Needs ``pip install roslibpy``.
"""

from __future__ import annotations

import argparse
import math
import os
import time
from typing import Any
from urllib.parse import urlsplit

import roslibpy

TICK_S = 0.05
"""The simulator's tick: the first /odom comes one tick after the start."""

MAX_ANGULAR_RPS = 2.5


def wrap(angle: float) -> float:
    """An angle in (-pi, pi]."""
    return math.remainder(angle, 2.0 * math.pi)


def changes(text: str) -> list[tuple[float, float]]:
    """``5.0:0.0,8.0:1.57`` as [(5.0, 0.0), (8.0, 1.57)]."""
    return [(float(at), float(value)) for at, value in
            (item.split(":") for item in text.split(",") if item)]


class HeadingPid:
    """error = wrap(setpoint - yaw); command = clamp(kp error)."""

    def __init__(self, ros: roslibpy.Ros, kp: float, slew_rps: float | None = None) -> None:
        self.kp = kp
        self.slew_rps = slew_rps
        self.last_rps = 0.0
        self.setpoint = float(os.environ["WEBSIM_SETPOINT_RAD"])
        self.changes = changes(os.environ.get("WEBSIM_SETPOINT_RAD_CHANGES", ""))
        self.first_stamp: float | None = None
        self.cmd = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
        self.cmd.advertise()
        roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(self.on_odom)

    def on_odom(self, odom: dict[str, Any]) -> None:
        """One /odom in, one /cmd_vel out."""
        stamp = odom["header"]["stamp"]
        now = stamp["sec"] + stamp["nanosec"] * 1e-9
        if self.first_stamp is None:
            self.first_stamp = now - TICK_S
        while self.changes and now - self.first_stamp >= self.changes[0][0] - 1e-6:
            self.setpoint = self.changes.pop(0)[1]
        q = odom["pose"]["pose"]["orientation"]
        yaw = 2.0 * math.atan2(q["z"], q["w"])
        angular = max(-MAX_ANGULAR_RPS, min(MAX_ANGULAR_RPS,
                                            self.kp * wrap(self.setpoint - yaw)))
        if self.slew_rps is not None:  # at most this change per /odom: the wheels do not slip
            angular = min(self.last_rps + self.slew_rps,
                          max(self.last_rps - self.slew_rps, angular))
        self.last_rps = angular
        self.cmd.publish(roslibpy.Message({"linear": {"x": 0.0, "y": 0.0, "z": 0.0},
                                           "angular": {"x": 0.0, "y": 0.0, "z": angular}}))


def main() -> None:
    """Connect to WEBSIM_URL and control until the simulator closes the connection."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--slew", type=float, default=None, metavar="RPS",
                        help="largest change of the command per /odom (rad/s)")
    args = parser.parse_args()
    url = urlsplit(os.environ.get("WEBSIM_URL", "ws://localhost:9090"))
    ros = roslibpy.Ros(url.hostname or "localhost", url.port or 9090)
    ros.run()
    HeadingPid(ros, float(os.environ.get("WEBSIM_KP", "4.0")), args.slew)
    while ros.is_connected:
        time.sleep(0.2)


if __name__ == "__main__":
    main()
