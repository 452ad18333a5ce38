"""Reference solution, wall following (after MIT RSS's wall follower lab), as an rclpy node.

    websim grade wall_following_suite --ros -- python3 wall_follower_rclpy.py

The same controller as ``wall_follower.py`` over rosbridge, here on the ROS graph of
``websim serve --ros``: it follows the wall on side WEBSIM_SIDE (``left`` or ``right``) at
WEBSIM_DESIRED_DISTANCE_M (m), driving at WEBSIM_SPEED_MPS (m/s), keeping the nearest LiDAR
hit on its side at the desired distance and abeam (90°),

    angular = side k_d (d - d*) + k_a (bearing - side pi/2),   side = +1 left, -1 right

from the latest /scan (sensor-data QoS, as /scan is published), answering every /odom with
one /cmd_vel. ``websim grade --ros`` appends ``--ros-args -p use_sim_time:=true``, which
``rclpy.init()`` reads from ``sys.argv``. Needs ROS 2's rclpy, geometry_msgs, nav_msgs and
sensor_msgs.
"""

from __future__ import annotations

import math
import os

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import qos_profile_sensor_data
from sensor_msgs.msg import LaserScan

K_DISTANCE = 3.0
"""rad/s per m of distance error."""

K_BEARING = 2.0
"""rad/s per rad of bearing error."""

MAX_ANGULAR_RPS = 2.5


class WallFollower(Node):
    """Holds the nearest wall point on its side at d* and abeam."""

    def __init__(self) -> None:
        super().__init__("wall_follower")
        self.side = 1.0 if os.environ["WEBSIM_SIDE"] == "left" else -1.0
        self.desired_m = float(os.environ["WEBSIM_DESIRED_DISTANCE_M"])
        self.speed_mps = float(os.environ["WEBSIM_SPEED_MPS"])
        self.scan: LaserScan | None = None
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(LaserScan, "/scan", self.on_scan, qos_profile_sensor_data)
        self.create_subscription(Odometry, "/odom", self.on_odom, 10)

    def on_scan(self, scan: LaserScan) -> None:
        """Keep the latest scan."""
        self.scan = scan

    def on_odom(self, odom: Odometry) -> None:
        """One /odom in, one /cmd_vel out (from the latest scan)."""
        linear, angular = (0.0, 0.0) if self.scan is None else self.command(self.scan)
        twist = Twist()
        twist.linear.x, twist.angular.z = linear, angular
        self.cmd.publish(twist)

    def command(self, scan: LaserScan) -> tuple[float, float]:
        """(linear m/s, angular rad/s) from a scan."""
        nearest, bearing = math.inf, 0.0
        for index, distance in enumerate(scan.ranges):
            if not scan.range_min <= distance < scan.range_max:
                continue  # no return
            angle = math.remainder(scan.angle_min + index * scan.angle_increment, 2.0 * math.pi)
            if self.side * angle >= 0.0 and distance < nearest:
                nearest, bearing = distance, angle
        if not math.isfinite(nearest):
            return self.speed_mps, self.side  # no wall on its side: turn towards it
        angular = (self.side * K_DISTANCE * (nearest - self.desired_m)
                   + K_BEARING * (bearing - self.side * math.pi / 2))
        return self.speed_mps, max(-MAX_ANGULAR_RPS, min(MAX_ANGULAR_RPS, angular))


def main(args: list[str] | None = None) -> int:
    """Control until the grader stops the node (SIGINT or SIGTERM)."""
    rclpy.init(args=args)
    node = WallFollower()
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
