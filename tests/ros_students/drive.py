"""A student's rclpy node: publish a Twist on the relative ``cmd_vel`` for a while.

Run with ``--ros-args -r __ns:=/alice`` to drive robot alice of a class. Arguments: linear
speed (m/s), seconds.
"""

from __future__ import annotations

import sys
import time

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node


def main() -> int:
    """Drive at ``argv[1]`` m/s for ``argv[2]`` s, then stop."""
    args = rclpy.utilities.remove_ros_args(sys.argv)
    speed_mps, seconds = float(args[1]), float(args[2])
    rclpy.init()
    node = Node("student")
    publisher = node.create_publisher(Twist, "cmd_vel", 10)
    command = Twist()
    command.linear.x = speed_mps
    found = time.monotonic() + 10.0  # discovery: wait for the robot's subscription
    while publisher.get_subscription_count() == 0 and time.monotonic() < found:
        rclpy.spin_once(node, timeout_sec=0.05)
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        publisher.publish(command)
        rclpy.spin_once(node, timeout_sec=0.1)
    publisher.publish(Twist())
    time.sleep(0.2)
    node.destroy_node()
    rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
