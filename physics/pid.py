"""The course's heading PID (Module 2.4, Eq. 9) as a pure function of its inputs.

One step every ``dt_s`` (0.1 s: the course's 10 Hz controller) from a measured heading to a yaw
rate command::

    error      = wrap(setpoint - heading)               # shortest way round, in (-pi, pi]
    derivative = -wrap(heading - previous heading) / dt  # on the measurement: no kick when
                                                         # the setpoint jumps
    candidate  = integral + error * dt
    output     = kp * error + ki * candidate + kd * derivative, clamped to +-output_limit
    integral   = candidate, unless the output is saturated and the error pushes further into
                 the saturation (conditional integration: anti-windup)

The browser's heading panel (``web-interface/js/pid.js``) implements the same steps; a test
feeds both the same inputs and compares their outputs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import NamedTuple

from physics.validation import as_finite_float, as_non_negative_float, as_positive_float

CONTROL_PERIOD_S = 0.1
"""The course's PID node runs at 10 Hz."""


def wrap_angle(angle_rad: float) -> float:
    """``angle_rad`` wrapped into (-pi, pi]."""
    wrapped = math.remainder(angle_rad, 2.0 * math.pi)
    return math.pi if wrapped == -math.pi else wrapped


@dataclass(frozen=True)
class PidGains:
    """Gains and limits of the heading controller.

    Attributes:
        kp: proportional gain (rad/s per rad of error).
        ki: integral gain (rad/s per rad s).
        kd: derivative gain (rad/s per rad/s).
        output_limit: largest yaw rate command (rad/s), e.g. the robot's max_angular_rps.
    """

    kp: float = 2.0
    ki: float = 0.0
    kd: float = 0.0
    output_limit: float = 2.5

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            object.__setattr__(self, name, as_non_negative_float(name, getattr(self, name)))
        object.__setattr__(self, "output_limit",
                           as_positive_float("output_limit", self.output_limit))


class PidState(NamedTuple):
    """What the controller remembers between steps.

    Attributes:
        integral: accumulated error (rad s).
        previous_heading: the last measured heading (rad), None before the first step.
    """

    integral: float = 0.0
    previous_heading: float | None = None


class PidStep(NamedTuple):
    """One step's result.

    Attributes:
        output: the yaw rate command (rad/s).
        error: wrapped heading error (rad).
        state: the state for the next step.
    """

    output: float
    error: float
    state: PidState


def pid_step(gains: PidGains, state: PidState, setpoint_rad: float, heading_rad: float,
             dt_s: float = CONTROL_PERIOD_S) -> PidStep:
    """Advance the heading PID by one period; pure, so any caller gets the same answer."""
    setpoint = as_finite_float("setpoint_rad", setpoint_rad)
    heading = as_finite_float("heading_rad", heading_rad)
    dt = as_positive_float("dt_s", dt_s)
    error = wrap_angle(setpoint - heading)
    derivative = 0.0
    if state.previous_heading is not None:
        derivative = -wrap_angle(heading - state.previous_heading) / dt
    candidate = state.integral + error * dt
    unclamped = gains.kp * error + gains.ki * candidate + gains.kd * derivative
    output = max(-gains.output_limit, min(gains.output_limit, unclamped))
    winding_up = output != unclamped and error * unclamped > 0.0
    integral = state.integral if winding_up else candidate
    return PidStep(output, error, PidState(integral, heading))


class HeadingPid:
    """A stateful wrapper around ``pid_step`` for nodes and scripts."""

    def __init__(self, gains: PidGains, setpoint_rad: float = 0.0) -> None:
        self.gains = gains
        self.setpoint_rad = as_finite_float("setpoint_rad", setpoint_rad)
        self.state = PidState()

    def reset(self) -> None:
        """Forget the integral and the last heading."""
        self.state = PidState()

    def update(self, heading_rad: float, dt_s: float = CONTROL_PERIOD_S) -> float:
        """One control step from a measured heading; returns the yaw rate command (rad/s)."""
        step = pid_step(self.gains, self.state, self.setpoint_rad, heading_rad, dt_s)
        self.state = step.state
        return step.output
