"""The discrete differential-drive (unicycle) model of the course text, Eq. 1-3.

One step of length ``dt_s`` with body-frame speeds ``v`` and ``omega``, heading taken from
before the update::

    x[k+1]     = x[k] + v * cos(theta[k]) * dt
    y[k+1]     = y[k] + v * sin(theta[k]) * dt
    theta[k+1] = theta[k] + omega * dt

Written out exactly in this order so results agree bit for bit with the same arithmetic done
by hand or in a student's script.
"""

from __future__ import annotations

import math

from physics.snapshots import Command, Pose2D


def integrate_pose(pose: Pose2D, v: float, omega: float, dt_s: float) -> Pose2D:
    """Advance ``pose`` by one Euler step of Eq. 1-3 (m, rad; v in m/s, omega in rad/s)."""
    return Pose2D(
        pose.x + v * math.cos(pose.theta) * dt_s,
        pose.y + v * math.sin(pose.theta) * dt_s,
        pose.theta + omega * dt_s,
    )


def clamp(value: float, limit: float) -> float:
    """Clamp ``value`` to ``[-limit, limit]``."""
    return max(-limit, min(limit, value))


def clamp_command(linear_mps: float, angular_rps: float,
                  max_linear_mps: float, max_angular_rps: float) -> Command:
    """Clamp a velocity command to the robot's limits, each component on its own."""
    return Command(clamp(linear_mps, max_linear_mps), clamp(angular_rps, max_angular_rps))


def wheel_rim_speeds(v: float, omega: float, half_wheelbase_m: float) -> tuple[float, float]:
    """Left and right wheel rim speeds (m/s) for body speeds ``v`` (m/s), ``omega`` (rad/s)."""
    return v - omega * half_wheelbase_m, v + omega * half_wheelbase_m


def body_speeds(left_mps: float, right_mps: float,
                half_wheelbase_m: float) -> tuple[float, float]:
    """Body speeds ``(v, omega)`` (m/s, rad/s) from left and right wheel rim speeds (m/s)."""
    return 0.5 * (left_mps + right_mps), (right_mps - left_mps) / (2.0 * half_wheelbase_m)
