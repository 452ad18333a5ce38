"""Reference solution, go to a goal, with roslibpy: plan on /map, follow the plan on /odom.

    websim grade go_to_goal -- python3 go_to_goal.py

Reads the goal (WEBSIM_GOAL_X_M, WEBSIM_GOAL_Y_M, WEBSIM_GOAL_RADIUS_M; map frame, which is the
odom frame where the robot starts at the map's origin facing x, as in go_to_goal.yaml), plans
a path on the robot's /map (the occupancy grid, latched: breadth-first search, 8-connected,
over the cells at least CLEARANCE_M from any wall), then follows it (pure pursuit: steer at the
path point LOOKAHEAD_M ahead), answering every /odom with one /cmd_vel, so ``websim grade``
can run it in deterministic mode. Needs ``pip install roslibpy``.
"""

from __future__ import annotations

import math
import os
import time
from collections import deque
from typing import Any
from urllib.parse import urlsplit

import roslibpy

CLEARANCE_M = 0.3
"""How far from any wall (centre to wall) the path keeps: the footprint's 0.11 m and a margin."""

LOOKAHEAD_M = 0.35
SPEED_MPS = 0.3
K_HEADING = 3.0
MAX_ANGULAR_RPS = 2.5


def plan(grid: dict[str, Any], start: tuple[float, float],
         goal: tuple[float, float]) -> list[tuple[float, float]]:
    """A path of points (m, map frame) from start to goal over the cells clear of walls."""
    info = grid["info"]
    width, height, resolution = info["width"], info["height"], info["resolution"]
    ox, oy = info["origin"]["position"]["x"], info["origin"]["position"]["y"]
    data = grid["data"]
    reach = math.ceil(CLEARANCE_M / resolution)
    offsets = [(dx, dy) for dx in range(-reach, reach + 1) for dy in range(-reach, reach + 1)
               if dx * dx + dy * dy <= reach * reach]
    blocked = bytearray(width * height)
    for index, value in enumerate(data):
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


class GoToGoal:
    """Plans once the map arrives; steers along the plan."""

    def __init__(self, ros: roslibpy.Ros) -> None:
        self.goal = (float(os.environ["WEBSIM_GOAL_X_M"]), float(os.environ["WEBSIM_GOAL_Y_M"]))
        self.radius_m = float(os.environ.get("WEBSIM_GOAL_RADIUS_M", "0.25"))
        self.path: list[tuple[float, float]] | None = None
        self.cmd = roslibpy.Topic(ros, "/cmd_vel", "geometry_msgs/msg/Twist")
        self.cmd.advertise()
        roslibpy.Topic(ros, "/map", "nav_msgs/msg/OccupancyGrid").subscribe(self.on_map)
        roslibpy.Topic(ros, "/odom", "nav_msgs/msg/Odometry").subscribe(self.on_odom)

    def on_map(self, grid: dict[str, Any]) -> None:
        """Plan from the start (the odom origin) to the goal."""
        if self.path is None:
            self.path = plan(grid, (0.0, 0.0), self.goal)

    def on_odom(self, odom: dict[str, Any]) -> None:
        """One /odom in, one /cmd_vel out."""
        pose = odom["pose"]["pose"]
        x, y = pose["position"]["x"], pose["position"]["y"]
        yaw = 2.0 * math.atan2(pose["orientation"]["z"], pose["orientation"]["w"])
        linear = angular = 0.0
        if self.path and math.dist((x, y), self.goal) > self.radius_m * 0.5:
            nearest = min(range(len(self.path)), key=lambda i: math.dist(self.path[i], (x, y)))
            del self.path[:nearest]  # never steer back to where it has been
            target = next((p for p in self.path if math.dist(p, (x, y)) >= LOOKAHEAD_M),
                          self.path[-1])
            error = math.remainder(math.atan2(target[1] - y, target[0] - x) - yaw, 2 * math.pi)
            angular = max(-MAX_ANGULAR_RPS, min(MAX_ANGULAR_RPS, K_HEADING * error))
            linear = SPEED_MPS * max(0.0, math.cos(error)) ** 4
        self.cmd.publish(roslibpy.Message({"linear": {"x": linear, "y": 0.0, "z": 0.0},
                                           "angular": {"x": 0.0, "y": 0.0, "z": angular}}))


def main() -> None:
    """Connect to WEBSIM_URL and control until the simulator closes the connection."""
    url = urlsplit(os.environ.get("WEBSIM_URL", "ws://localhost:9090"))
    ros = roslibpy.Ros(url.hostname or "localhost", url.port or 9090)
    ros.run()
    GoToGoal(ros)
    while ros.is_connected:
        time.sleep(0.2)


if __name__ == "__main__":
    main()
