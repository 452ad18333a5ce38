"""The course's rosbridge snippets (section 2.5.5) with roslibpy instead of roslibjs.

    python examples/course_snippets.py [ws://localhost:9090]
    python examples/course_snippets.py ws://HOST:9090/robots/NAME?token=TOKEN   (a class)
    python examples/course_snippets.py HOST [PORT]

Connects to rosbridge, subscribes to /odom and /scan, drives the robot forward and into a left
turn for two seconds by publishing geometry_msgs/msg/Twist on /cmd_vel, prints what it sees,
stops the robot and exits (status 1 if no data arrived, or if the robot did not move: the
bridge refused the commands). The same script runs unmodified
against ``websim serve`` (ws://localhost:9090), the Docker stack (ws://HOST:9090) or the real
robot's rosbridge: only the address changes. In a class (``websim serve --class``) the address
is your robot's, with its token: without the token you may watch it but not drive it. Needs
``pip install roslibpy``.
"""

from __future__ import annotations

import math
import sys
import threading
import time
from typing import Any
from urllib.parse import urlsplit

import roslibpy

DRIVE_S = 2.0
COMMAND_PERIOD_S = 0.1
CONNECT_TIMEOUT_S = 5.0
TIMEOUT_S = 10.0
NOT_DRIVEN = ("the robot did not move: the bridge refused the commands. A class robot drives "
              "only with its token, ws://HOST:9090/robots/NAME?token=TOKEN (without it your "
              "code may watch the robot, not drive it).")


def address(argv: list[str]) -> tuple[str, int, bool]:
    """(host, port, secure) from ``ws[s]://HOST:PORT[/PATH]`` or ``HOST [PORT]``."""
    if not argv:
        return "localhost", 9090, False
    if "://" in argv[0]:
        parts = urlsplit(argv[0])
        secure = parts.scheme == "wss"
        return parts.hostname or "localhost", parts.port or (443 if secure else 9090), secure
    return argv[0], int(argv[1]) if len(argv) > 1 else 9090, False


def yaw_of(pose: dict[str, Any]) -> float:
    """Yaw (rad) of a planar quaternion: 2 atan2(z, w)."""
    q = pose["orientation"]
    return 2.0 * math.atan2(q["z"], q["w"])


def describe(odom: dict[str, Any]) -> str:
    """An Odometry message's pose as one line (m, rad)."""
    pose = odom["pose"]["pose"]
    return (f"x={pose['position']['x']:.3f} m y={pose['position']['y']:.3f} m "
            f"yaw={yaw_of(pose):.3f} rad")


def twist(linear_mps: float, angular_rps: float) -> roslibpy.Message:
    """A geometry_msgs/msg/Twist: linear.x (m/s) and angular.z (rad/s)."""
    return roslibpy.Message({"linear": {"x": linear_mps, "y": 0.0, "z": 0.0},
                             "angular": {"x": 0.0, "y": 0.0, "z": angular_rps}})


def main(argv: list[str]) -> int:
    """Connect, look, drive, stop; 0 on success, 1 if no data arrived."""
    if argv and "://" in argv[0]:  # a URL as given: its path (/robots/NAME) and ?token=
        ros = roslibpy.Ros(host=argv[0])
        shown = argv[0].split("?", 1)[0]  # never print the token
    else:
        host, port, secure = address(argv)
        ros = roslibpy.Ros(host=host, port=port, is_secure=secure)
        shown = f"{host}:{port}"
    ros.run(timeout=CONNECT_TIMEOUT_S)  # raises if the connection fails
    print(f"Connected to ROS 2 at {shown}")

    cmd_vel = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
    odom_listener = roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry")
    scan_listener = roslibpy.Topic(ros, "/scan", "sensor_msgs/msg/LaserScan")
    odoms: list[dict[str, Any]] = []
    scans: list[dict[str, Any]] = []
    have_data = threading.Event()

    def on_odom(message: dict[str, Any]) -> None:
        odoms.append(message)
        if scans:
            have_data.set()

    def on_scan(message: dict[str, Any]) -> None:
        scans.append(message)
        if odoms:
            have_data.set()

    odom_listener.subscribe(on_odom)
    scan_listener.subscribe(on_scan)
    try:
        if not have_data.wait(TIMEOUT_S):
            print(f"no /odom and /scan within {TIMEOUT_S} s", file=sys.stderr)
            return 1
        print(f"odom start: {describe(odoms[0])}")
        scan = scans[0]
        valid = [r for r in scan["ranges"]
                 if r is not None and scan["range_min"] <= r <= scan["range_max"]]
        print(f"scan: {len(scan['ranges'])} beams, nearest {min(valid):.3f} m, "
              f"straight ahead {float(scan['ranges'][0]):.3f} m")

        print("drive: linear.x=0.3 m/s angular.z=0.5 rad/s")
        end = time.monotonic() + DRIVE_S
        while time.monotonic() < end:  # resent at 10 Hz, as a teleop does
            cmd_vel.publish(twist(0.3, 0.5))
            time.sleep(COMMAND_PERIOD_S)
    finally:
        cmd_vel.publish(twist(0.0, 0.0))
        print("stop: published a zero Twist")
        odom_listener.unsubscribe()
        scan_listener.unsubscribe()
        time.sleep(0.2)  # let the stop command leave before closing
        ros.terminate()
    print(f"odom end: {describe(odoms[-1])}")
    print(f"received {len(scans)} scans")
    if describe(odoms[-1]) == describe(odoms[0]):  # it turned 1 rad if it drove
        print(NOT_DRIVEN, file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
