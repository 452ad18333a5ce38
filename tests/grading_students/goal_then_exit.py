"""Go to a point and exit, as the TurtleBot3 examples' position control does: a test fixture.

A timer node on sim time: turn to the goal, drive to it, and once within 0.05 m stop the robot
and leave (exit code 0). ``goal_x`` and ``goal_y`` (odom frame, m) are ROS parameters.
"""

import math

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from rclpy.node import Node


class GoalThenExit(Node):

    def __init__(self):
        super().__init__("goal_then_exit")
        self.declare_parameter("goal_x", 1.0)
        self.declare_parameter("goal_y", 0.0)
        self.pose = None
        self.done = False
        self.create_subscription(Odometry, "odom", self.on_odom, 10)
        self.pub = self.create_publisher(Twist, "cmd_vel", 10)
        self.create_timer(0.05, self.on_timer)

    def on_odom(self, msg):
        q = msg.pose.pose.orientation
        yaw = math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))
        self.pose = (msg.pose.pose.position.x, msg.pose.pose.position.y, yaw)

    def on_timer(self):
        if self.pose is None or self.done:
            return
        x, y, yaw = self.pose
        dx = self.get_parameter("goal_x").value - x
        dy = self.get_parameter("goal_y").value - y
        twist = Twist()
        if math.hypot(dx, dy) < 0.05:
            self.done = True  # stop, and the main loop ends
        else:
            error = math.atan2(math.sin(math.atan2(dy, dx) - yaw),
                               math.cos(math.atan2(dy, dx) - yaw))
            twist.angular.z = max(-1.5, min(1.5, 2.0 * error))
            twist.linear.x = min(0.3, math.hypot(dx, dy)) if abs(error) < 0.3 else 0.0
        self.pub.publish(twist)


def main():
    rclpy.init()
    node = GoalThenExit()
    while rclpy.ok() and not node.done:
        rclpy.spin_once(node)
    node.get_logger().info("goal reached")
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == "__main__":
    main()
