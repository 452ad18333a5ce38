"""A right-wall follower as rplidar-era course code writes it: a test fixture, never changed.

- it subscribes ``/scan`` RELIABLE (the QoS rclpy gives a bare depth, as the Neato driver's
  and many a course's nodes do): a best-effort ``/scan`` gives it nothing;
- it reads sectors in -pi..pi (rplidar_ros's angles): the right wall is around -pi/2, the
  front around 0; in a 0..2pi scan it never finds its right sector;
- a 10 Hz timer on sim time steers; ``distance`` and ``speed`` are ROS parameters.
"""

import math

import rclpy
from geometry_msgs.msg import Twist
from rclpy.node import Node
from rclpy.qos import QoSProfile
from sensor_msgs.msg import LaserScan


class RightWallFollower(Node):

    def __init__(self):
        super().__init__("right_wall_follower")
        self.declare_parameter("distance", 0.5)
        self.declare_parameter("speed", 0.3)
        self.scan = None
        self.create_subscription(LaserScan, "scan", self.on_scan, QoSProfile(depth=10))
        self.pub = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_timer(0.1, self.on_timer)

    def on_scan(self, msg):
        self.scan = msg

    def sector(self, low, high):
        """The nearest valid range between two angles of -pi..pi, or None."""
        scan, found = self.scan, []
        for i, r in enumerate(scan.ranges):
            angle = scan.angle_min + i * scan.angle_increment
            if low <= angle <= high and scan.range_min < r < scan.range_max:
                found.append(r)
        return min(found) if found else None

    def on_timer(self):
        if self.scan is None:
            return
        right = self.sector(-math.pi / 2 - 0.35, -math.pi / 2 + 0.35)
        front = self.sector(-0.3, 0.3)
        twist = Twist()
        twist.linear.x = self.get_parameter("speed").value
        if right is None:  # its sector is not in this scan: it cannot follow
            self.pub.publish(twist)
            return
        error = self.get_parameter("distance").value - right
        twist.angular.z = max(-2.0, min(2.0, 3.0 * error))
        if front is not None and front < 0.6:
            twist.angular.z = 1.5
        self.pub.publish(twist)


def main():
    rclpy.init()
    node = RightWallFollower()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
