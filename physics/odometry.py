"""Wheel odometry: integrates encoder speeds from the spawn pose, as the real robot does."""

from __future__ import annotations

from collections.abc import Iterable

from physics.kinematics import integrate_pose
from physics.robot import EncoderSample
from physics.snapshots import Odometry, Pose2D

ODOM_ORIGIN = Pose2D(0.0, 0.0, 0.0)


class OdometryIntegrator:
    """Dead reckoning in the ``odom`` frame, which starts at (0, 0, 0) at the spawn pose."""

    def __init__(self) -> None:
        self._pose = ODOM_ORIGIN
        self._v = 0.0
        self._omega = 0.0

    def reset(self) -> None:
        """Back to the odom origin, at rest."""
        self._pose = ODOM_ORIGIN
        self._v = 0.0
        self._omega = 0.0

    def place(self, pose: Pose2D) -> None:
        """Read ``pose`` from now on, at rest (a restored robot's odometry)."""
        self._pose = Pose2D(float(pose.x), float(pose.y), float(pose.theta))
        self._v = 0.0
        self._omega = 0.0

    def integrate(self, samples: Iterable[EncoderSample], v_noise_mps: float = 0.0,
                  omega_noise_rps: float = 0.0) -> None:
        """Integrate encoder samples with Eq. 1-3, each speed offset by the given noise."""
        for sample in samples:
            self._v = sample.v + v_noise_mps
            self._omega = sample.omega + omega_noise_rps
            self._pose = integrate_pose(self._pose, self._v, self._omega, sample.dt_s)

    def odometry(self) -> Odometry:
        """Pose in the odom frame and the last measured speeds."""
        return Odometry(self._pose.x, self._pose.y, self._pose.theta, self._v, self._omega)
