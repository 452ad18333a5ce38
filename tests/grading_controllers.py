"""Python controllers for ``grading.run_headless``: right ones, and deliberately wrong ones.

Each reads only what a student's controller reads (the observation: /odom, /ground_truth,
/scan and the scenario's parameters) and answers (linear m/s, angular rad/s).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

from grading import Observation
from physics.pid import HeadingPid, PidGains, wrap_angle


class HeadingPidController:
    """The course's heading PID (physics.pid) on /odom, following the setpoint in force."""

    def __init__(self, kp: float = 4.0, slew_rps: float | None = None) -> None:
        self.pid = HeadingPid(PidGains(kp=kp))
        self.slew_rps = slew_rps
        self.last_rps = 0.0

    def __call__(self, observation: Observation) -> tuple[float, float]:
        self.pid.setpoint_rad = float(observation.parameters["setpoint_rad"])
        angular = self.pid.update(observation.odometry.theta)
        if self.slew_rps is not None:  # at most this change per call: the wheels do not slip
            angular = min(self.last_rps + self.slew_rps,
                          max(self.last_rps - self.slew_rps, angular))
        self.last_rps = angular
        return 0.0, angular


class WrongSignP:
    """A proportional heading controller with Kp of the wrong sign: it turns away."""

    def __init__(self, kp: float = -4.0) -> None:
        self.kp = kp

    def __call__(self, observation: Observation) -> tuple[float, float]:
        error = wrap_angle(float(observation.parameters["setpoint_rad"])
                           - observation.odometry.theta)
        return 0.0, self.kp * error


def standing_still(observation: Observation) -> tuple[float, float]:
    """Never moves."""
    return 0.0, 0.0


class WallFollower:
    """Keeps the nearest LiDAR hit on its side at the desired distance and abeam (90°).

    omega = side k_d (d - d*) + k_a (bearing - side pi/2), at the speed it is told.
    """

    def __init__(self, k_d: float = 3.0, k_a: float = 2.0) -> None:
        self.k_d = k_d
        self.k_a = k_a

    def __call__(self, observation: Observation) -> tuple[float, float]:
        parameters = observation.parameters
        side = 1.0 if parameters["side"] == "left" else -1.0
        scan = observation.scan
        nearest, bearing = math.inf, 0.0
        for index, distance in enumerate(scan.ranges):
            angle = wrap_angle(scan.angle_min + index * scan.angle_increment)
            if side * angle >= 0.0 and scan.range_min <= distance < scan.range_max \
                    and distance < nearest:
                nearest, bearing = distance, angle
        if not math.isfinite(nearest):
            return float(parameters["speed_mps"]), side
        angular = side * self.k_d * (nearest - float(parameters["desired_distance_m"])) \
            + self.k_a * (bearing - side * math.pi / 2)
        return float(parameters["speed_mps"]), max(-2.5, min(2.5, angular))


class IntoTheWall:
    """Drives at its speed, turning towards the wall it should follow: it hits it."""

    def __call__(self, observation: Observation) -> tuple[float, float]:
        side = 1.0 if observation.parameters["side"] == "left" else -1.0
        return float(observation.parameters["speed_mps"]), side * 0.5


class Waypoints:
    """Turns towards the next waypoint (map frame, from /ground_truth) and drives to it."""

    def __init__(self, points: Sequence[tuple[float, float]], speed_mps: float = 0.3) -> None:
        self.points = list(points)
        self.speed_mps = speed_mps

    def __call__(self, observation: Observation) -> tuple[float, float]:
        pose = observation.ground_truth
        while self.points and math.dist(self.points[0], (pose.x, pose.y)) < 0.1:
            self.points.pop(0)
        if not self.points:
            return 0.0, 0.0
        x, y = self.points[0]
        error = wrap_angle(math.atan2(y - pose.y, x - pose.x) - pose.theta)
        return (self.speed_mps if abs(error) < 0.3 else 0.0), max(-2.5, min(2.5, 3.0 * error))


MAZE_ROUTE = ((0.5, -0.5), (0.5, -2.5), (1.5, -2.5), (1.5, -0.5), (2.5, -0.5), (2.5, 2.5))
"""From (0, 0) to (2.5, 2.5) in worlds/maze.yaml, through the gaps, 0.5 m from the walls."""
