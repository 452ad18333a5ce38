"""Reference solution, go to a goal, as an rclpy node: plan on /map, follow the plan on /odom.

    websim grade go_to_goal --ros -- python3 go_to_goal_rclpy.py

The same controller as ``go_to_goal.py`` over rosbridge, here on the ROS graph: reads the goal
(WEBSIM_GOAL_X_M, WEBSIM_GOAL_Y_M, WEBSIM_GOAL_RADIUS_M; map frame, which is the odom frame
where the robot starts at the map's origin facing x), plans a path on the robot's /map (the
occupancy grid, transient local: breadth-first search, 8-connected, over the cells at least
CLEARANCE_M from any wall), then follows it (pure pursuit: steer at the path point LOOKAHEAD_M
ahead), answering every /odom with one /cmd_vel. ``websim grade --ros`` appends ``--ros-args
-p use_sim_time:=true``. Needs ROS 2's rclpy, geometry_msgs and nav_msgs.
"""

from __future__ import annotations

import math
import os
from collections import deque

import rclpy
from geometry_msgs.msg import Twist
from nav_msgs.msg import OccupancyGrid, Odometry
from rclpy.executors import ExternalShutdownException
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile

CLEARANCE_M = 0.3
"""How far from any wall (centre to wall) the path keeps: the footprint's 0.11 m and a margin."""

LOOKAHEAD_M = 0.35
SPEED_MPS = 0.3
K_HEADING = 3.0
MAX_ANGULAR_RPS = 2.5

LATCHED = QoSProfile(depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""/map is latched (as nav2's map_server publishes it): a late subscriber still gets it."""


def plan(grid: OccupancyGrid, start: tuple[float, float],
         goal: tuple[float, float]) -> list[tuple[float, float]]:
    """A path of points (m, map frame) from start to goal over the cells clear of walls."""
    width, height, resolution = grid.info.width, grid.info.height, grid.info.resolution
    ox, oy = grid.info.origin.position.x, grid.info.origin.position.y
    reach = math.ceil(CLEARANCE_M / resolution)
    offsets = [(dx, dy) for dx in range(-reach, reach + 1) for dy in range(-reach, reach + 1)
               if dx * dx + dy * dy <= reach * reach]
    blocked = bytearray(width * height)
    for index, value in enumerate(grid.data):
        if value != 0:  # a wall (100) or unknown (-1)
            cx, cy = index % width, index // width
            for dx, dy in offsets:
                x, y = cx + dx, cy + dy
                if 0 <= x < width and 0 <= y < height:
                    blocked[y * width + x] = 1

    def cell(point: tuple[float, float]) -> int:
        return int((point[1] - oy) / resolution) * width + int((point[0] - ox) / resolution)

    source, target = cell(start), cell(goal)
    came = {source: source}
    queue = deque([source])
    while queue and target not in came:
        here = queue.popleft()
        hx, hy = here % width, here // width
        for dx, dy in ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1)):
            x, y = hx + dx, hy + dy
            there = y * width + x
            if 0 <= x < width and 0 <= y < height and not blocked[there] and there not in came:
                came[there] = here
                queue.append(there)
    if target not in came:
        return [goal]
    path, here = [], target
    while here != source:
        path.append(((here % width + 0.5) * resolution + ox,
                     (here // width + 0.5) * resolution + oy))
        here = came[here]
    path.reverse()
    return [*path, goal]


class GoToGoal(Node):
    """Plans once the map arrives; steers along the plan."""

    def __init__(self) -> None:
        super().__init__("go_to_goal")
        self.goal = (float(os.environ["WEBSIM_GOAL_X_M"]), float(os.environ["WEBSIM_GOAL_Y_M"]))
        self.radius_m = float(os.environ.get("WEBSIM_GOAL_RADIUS_M", "0.25"))
        self.path: list[tuple[float, float]] | None = None
        self.cmd = self.create_publisher(Twist, "/cmd_vel", 10)
        self.create_subscription(OccupancyGrid, "/map", self.on_map, LATCHED)
        self.create_subscription(Odometry, "/odom", self.on_odom, 10)

    def on_map(self, grid: OccupancyGrid) -> None:
        """Plan from the start (the odom origin) to the goal."""
        if self.path is None:
            self.path = plan(grid, (0.0, 0.0), self.goal)

    def on_odom(self, odom: Odometry) -> None:
        """One /odom in, one /cmd_vel out."""
        pose = odom.pose.pose
        x, y = pose.position.x, pose.position.y
        yaw = 2.0 * math.atan2(pose.orientation.z, pose.orientation.w)
        linear = angular = 0.0
        if self.path and math.dist((x, y), self.goal) > self.radius_m * 0.5:
            nearest = min(range(len(self.path)), key=lambda i: math.dist(self.path[i], (x, y)))
            del self.path[:nearest]  # never steer back to where it has been
            target = next((p for p in self.path if math.dist(p, (x, y)) >= LOOKAHEAD_M),
                          self.path[-1])
            error = math.remainder(math.atan2(target[1] - y, target[0] - x) - yaw, 2 * math.pi)
            angular = max(-MAX_ANGULAR_RPS, min(MAX_ANGULAR_RPS, K_HEADING * error))
            linear = SPEED_MPS * max(0.0, math.cos(error)) ** 4
        twist = Twist()
        twist.linear.x, twist.angular.z = linear, angular
        self.cmd.publish(twist)


def main(args: list[str] | None = None) -> int:
    """Control until the grader stops the node (SIGINT or SIGTERM)."""
    rclpy.init(args=args)
    node = GoToGoal()
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
