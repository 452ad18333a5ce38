"""Reference solution, the heading PID (assignment 2.4), as an rclpy node.

    WEBSIM_SETPOINT_RAD=1.5708 python3 heading_pid_rclpy.py --ros-args -p use_sim_time:=true
    websim grade heading_pid --ros -- python3 heading_pid_rclpy.py

Turns in place to the setpoint WEBSIM_SETPOINT_RAD (rad, relative to the heading at the start:
the odom frame) and holds it, as ``heading_pid.py`` does over rosbridge, here on the ROS graph
of ``websim serve --ros``. It answers every /odom with one /cmd_vel (a callback, not a timer),
so ``websim grade --ros`` can run it in deterministic mode; ``websim grade --ros`` appends
``--ros-args -p use_sim_time:=true``, which ``rclpy.init()`` reads from ``sys.argv``. A
setpoint that changes during the run (WEBSIM_SETPOINT_RAD_CHANGES, ``at_s:value`` pairs) is
applied at the first /odom whose time since the start reaches it. WEBSIM_KP overrides the
gain (default 4 rad/s per rad).

Needs ROS 2's rclpy, geometry_msgs and nav_msgs.
"""

from __future__ import annotations

import math
import os

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node

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


class HeadingPid(Node):
    """error = wrap(setpoint - yaw); command = clamp(kp error), one per /odom."""

    def __init__(self) -> None:
        super().__init__("heading_pid")
        self.kp = float(os.environ.get("WEBSIM_KP", "4.0"))
        self.setpoint = float(os.environ["WEBSIM_SETPOINT_RAD"])
        self.changes = changes(os.environ.get("WEBSIM_SETPOINT_RAD_CHANGES", ""))
        self.first_stamp: float | None = None
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(Odometry, "/odom", self.on_odom, 10)

    def on_odom(self, odom: Odometry) -> None:
        """One /odom in, one /cmd_vel out."""
        now = odom.header.stamp.sec + odom.header.stamp.nanosec * 1e-9
        if self.first_stamp is None:
            self.first_stamp = now - TICK_S
        while self.changes and now - self.first_stamp >= self.changes[0][0] - 1e-6:
            self.setpoint = self.changes.pop(0)[1]
        q = odom.pose.pose.orientation
        yaw = 2.0 * math.atan2(q.z, q.w)
        command = Twist()
        command.angular.z = max(-MAX_ANGULAR_RPS, min(MAX_ANGULAR_RPS,
                                                      self.kp * wrap(self.setpoint - yaw)))
        self.cmd.publish(command)


def main(args: list[str] | None = None) -> int:
    """Control until the grader stops the node (SIGINT or SIGTERM)."""
    rclpy.init(args=args)
    node = HeadingPid()
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
