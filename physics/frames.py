"""Planar rigid transforms between the robot's frames (REP 105: map -> odom -> base_link).

A ``Pose2D`` is also the transform from a child frame to its parent: the child's origin and
heading in the parent (m, rad). ``compose(a, b)`` chains parent <- a <- b.
"""

from __future__ import annotations

import math

from physics.snapshots import Pose2D


def compose(a: Pose2D, b: Pose2D) -> Pose2D:
    """``b`` (given in ``a``'s frame) in ``a``'s parent frame: ``a * b``."""
    cos_a, sin_a = math.cos(a.theta), math.sin(a.theta)
    return Pose2D(a.x + cos_a * b.x - sin_a * b.y, a.y + sin_a * b.x + cos_a * b.y,
                  a.theta + b.theta)


def inverse(a: Pose2D) -> Pose2D:
    """The parent frame in the child's: composed with ``a`` it gives the identity."""
    cos_a, sin_a = math.cos(a.theta), math.sin(a.theta)
    return Pose2D(-cos_a * a.x - sin_a * a.y, sin_a * a.x - cos_a * a.y, -a.theta)


def map_to_odom(truth: Pose2D, odometry: Pose2D) -> Pose2D:
    """The odom frame in map, given the robot's true pose in map and its odometry in odom.

    What a perfect localizer publishes as map -> odom: ``compose(map_to_odom(t, o), o) == t``
    whatever the odometry's drift.
    """
    return compose(truth, inverse(odometry))
