"""The drive wheels' rotation as their encoders count it (what ``/joint_states`` reports).

Each encoder sample's body speeds (``EncoderSample``: what the wheel encoders measured, the
same speeds odometry integrates) are split into the two wheels' rim speeds
(``kinematics.wheel_rim_speeds``) and integrated into wheel angles: a wheel that rolls a
distance d without slipping turns d / wheel_radius. Positive rotation is about the wheel's
axle, +y of base_link, which rolls the robot forward.
"""

from __future__ import annotations

from collections.abc import Iterable

from physics.kinematics import wheel_rim_speeds
from physics.robot import EncoderSample
from physics.snapshots import WheelState

WHEELS_AT_REST = WheelState(0.0, 0.0, 0.0, 0.0)


class WheelEncoders:
    """The left and right wheel angles (rad) since spawn, and their last angular speeds."""

    def __init__(self) -> None:
        self._state = WHEELS_AT_REST

    def reset(self) -> None:
        """Back to zero angles, at rest (spawn, ``/reset_simulation``, a restored pose)."""
        self._state = WHEELS_AT_REST

    def integrate(self, samples: Iterable[EncoderSample], half_wheelbase_m: float,
                  wheel_radius_m: float, v_noise_mps: float = 0.0,
                  omega_noise_rps: float = 0.0) -> None:
        """Turn the wheels by what the encoder samples measured.

        Args:
            samples: the encoders' body speeds over one tick (m/s, rad/s, s).
            half_wheelbase_m: distance from the centre to each wheel (m).
            wheel_radius_m: the wheels' radius (m).
            v_noise_mps: odometry noise on the linear speed this tick (m/s): the encoders'
                error, which odometry integrates too.
            omega_noise_rps: odometry noise on the yaw rate this tick (rad/s).
        """
        left_rad, right_rad, left_rad_s, right_rad_s = self._state
        for sample in samples:
            left_mps, right_mps = wheel_rim_speeds(sample.v + v_noise_mps,
                                                   sample.omega + omega_noise_rps,
                                                   half_wheelbase_m)
            left_rad_s = left_mps / wheel_radius_m
            right_rad_s = right_mps / wheel_radius_m
            left_rad += left_rad_s * sample.dt_s
            right_rad += right_rad_s * sample.dt_s
        self._state = WheelState(left_rad, right_rad, left_rad_s, right_rad_s)

    def state(self) -> WheelState:
        """The wheels' angles and angular speeds now."""
        return self._state
