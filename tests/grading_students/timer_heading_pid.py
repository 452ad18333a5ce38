"""A heading P controller in the usual ROS 2 course style: a node driven by a timer.

A test fixture for ``websim grade --ros`` (tests/test_grade_rclpy.py), written as course code
is (it is never changed to suit the grader):

- its gains and setpoint are ROS parameters (``setpoint_rad``, ``kp``, ``rate_hz``): the
  submission's ``websim-submission.yaml`` maps the scenario's values onto them;
- it reads its start time in its constructor, before the first ``/clock``, and stops
  commanding after ``run_s`` of it (a clock that started at 1.8e9 s stopped it at once);
- ``/odom`` arrives in a subscription callback that keeps the latest; a timer of its own
  period (not the simulator's tick) computes and publishes ``/cmd_vel``.
"""

import math

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node


class TimerHeadingPid(Node):

    def __init__(self):
        super().__init__("timer_heading_pid")
        self.declare_parameter("setpoint_rad", 0.0)
        self.declare_parameter("kp", 2.0)
        self.declare_parameter("rate_hz", 10.0)
        self.declare_parameter("run_s", 30.0)
        self.start = self.get_clock().now()
        self.yaw = None
        self.create_subscription(Odometry, "odom", self.on_odom, 10)
        self.pub = self.create_publisher(Twist, "cmd_vel", 10)
        period = 1.0 / self.get_parameter("rate_hz").value
        self.create_timer(period, self.on_timer)

    def on_odom(self, msg):
        q = msg.pose.pose.orientation
        self.yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))

    def on_timer(self):
        if self.yaw is None:
            return
        twist = Twist()
        elapsed = (self.get_clock().now() - self.start).nanoseconds * 1e-9
        if elapsed < self.get_parameter("run_s").value:
            error = self.get_parameter("setpoint_rad").value - self.yaw
            error = math.atan2(math.sin(error), math.cos(error))
            twist.angular.z = max(-2.5, min(2.5, self.get_parameter("kp").value * error))
        self.pub.publish(twist)


def main():
    rclpy.init()
    node = TimerHeadingPid()
    try:
        rclpy.spin(node)
    except KeyboardInterrupt:
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    main()
