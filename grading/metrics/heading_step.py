"""The heading step response: settling time, overshoot and steady-state error of a heading PID.

The setpoint is relative to the heading at the start of the run, as the controller reads it
from ``/odom`` (the odom frame starts at the spawn pose); the response is the true heading
(ground truth), so a controller fed odometry that stops short of the setpoint is seen to.
A scenario may change the setpoint at set times (``changes``): each change is a step of its
own, measured until the next one.

Per step k, from its time t_k to the next step (or the end of the run), with h(t) = yaw(t) -
yaw(0) (unwrapped), the step S_k = wrap(setpoint_k - setpoint_k-1) (the first from 0), the
error e(t) = wrap(setpoint_k - h(t)) and the error along the way u(t) = S_0 + ... + S_k - h(t)
(unwrapped: a robot that turns the wrong way is not "past" the setpoint):

- settling time: from t_k to the first sample after which |e| stays within ``tolerance_rad``
  until the step ends; never, if the last sample of the step is outside;
- overshoot: how far the heading went past the setpoint, as a fraction of |S_k|:
  max(0, max(-sign(S_k) u)) / |S_k|;
- steady-state error: the size of the circular mean of e over the last ``final_window_s`` of
  the step (rad; ``grading.trajectory.circular_mean_rad``: errors that straddle ±pi, a robot
  wobbling at the opposite heading, do not average to 0).

The metric's figures are the worst over the steps. Score (docs/grading.md gives the reason):
the product of three factors, each 1 within its limit and limit/figure beyond it
(``within_ratio``): settling time against ``threshold`` (0 if it never settles), overshoot
against ``max_overshoot``, steady-state error against ``tolerance_rad``. It is 1 exactly when
the response meets every limit, which is when it passes.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grading.metric_fields import fraction, optional, param, positive
from grading.results import MetricResult, within_ratio
from grading.trajectory import (
    Trajectory,
    check_trajectory,
    circular_mean_rad,
    times,
    unwrapped_yaw,
)
from physics.pid import wrap_angle
from physics.world import World

DEFAULT_TOLERANCE_RAD = math.radians(2.0)
"""The settling band: ±2°, the 2 % band of a 90° step (0.0349 rad)."""


@dataclass(frozen=True)
class HeadingStepParams:
    """Parameters of the heading step metric.

    Attributes:
        setpoints: the setpoint schedule, (time (s), setpoint (rad)) pairs in time order, the
            first at 0 s; from the scenario's ``setpoint_rad`` parameter and its changes.
        threshold: the longest settling time that passes (s); None for no limit.
        tolerance_rad: half-width of the settling band, and the largest steady-state error
            that passes (rad).
        max_overshoot: the largest overshoot that passes, as a fraction of the step.
        final_window_s: the stretch at the end of each step whose mean error (circular) is its
            steady-state error (s).
    """

    setpoints: tuple[tuple[float, float], ...] = param(unit="s, rad",
                                                       from_scenario="setpoints")
    threshold: float | None = param(3.0, unit="s", check=optional(positive))
    tolerance_rad: float = param(DEFAULT_TOLERANCE_RAD, unit="rad", check=positive)
    max_overshoot: float = param(0.1, unit="", check=fraction)
    final_window_s: float = param(0.5, unit="s", check=positive)

    def __post_init__(self) -> None:
        if not self.setpoints or self.setpoints[0][0] != 0.0:
            raise ValueError("the setpoint schedule must start at 0 s")


def heading_step(trajectory: Trajectory, params: HeadingStepParams,
                 world: World | None = None) -> MetricResult:
    """Measure each step of the setpoint schedule; see the module's docstring."""
    check_trajectory(trajectory)
    t = times(trajectory) - trajectory[0].t_s
    heading = unwrapped_yaw(trajectory)
    heading = heading - heading[0]
    steps = [_step(t, heading, index, params) for index in range(len(params.setpoints))]
    settled = [step["settling_time_s"] for step in steps]
    settling = None if any(s is None for s in settled) else max(settled)
    overshoot = max(step["overshoot"] for step in steps)
    error = max(step["steady_state_error_rad"] for step in steps)

    settle_factor = 0.0 if settling is None else (
        1.0 if params.threshold is None else within_ratio(settling, params.threshold))
    score = settle_factor * within_ratio(overshoot, params.max_overshoot) \
        * within_ratio(error, params.tolerance_rad)
    failures = [_failure(step, params) for step in steps]
    failures = [failure for failure in failures if failure]
    passed = not failures
    if passed:
        reason = (f"settled within ±{params.tolerance_rad:.3f} rad in {settling:.2f} s, "
                  f"overshoot {overshoot:.1%}, steady-state error {error:.4f} rad")
    else:
        reason = "; ".join(failures)
    return MetricResult(
        name="heading_step", kind="heading_step", value=settling, unit="s",
        threshold=params.threshold, passed=passed, score=score, reason=reason,
        figures={"settling_time_s": settling, "overshoot": overshoot,
                 "steady_state_error_rad": error, "steps": steps},
        inputs={"setpoints": [list(pair) for pair in params.setpoints],
                "tolerance_rad": params.tolerance_rad, "max_overshoot": params.max_overshoot,
                "final_window_s": params.final_window_s, "heading": "ground truth",
                "samples": len(trajectory), "duration_s": float(t[-1])})


def _step(t: np.ndarray, heading: np.ndarray, index: int,
          params: HeadingStepParams) -> dict[str, Any]:
    """The figures of step ``index`` of the schedule."""
    start_s, setpoint = params.setpoints[index]
    previous = params.setpoints[index - 1][1] if index else 0.0
    end_s = params.setpoints[index + 1][0] if index + 1 < len(params.setpoints) else math.inf
    inside = (t >= start_s) & (t < end_s)
    window_t = t[inside]
    step = {"start_s": start_s, "setpoint_rad": setpoint,
            "step_rad": wrap_angle(setpoint - previous)}
    if len(window_t) == 0:
        return {**step, "settling_time_s": None, "overshoot": 0.0,
                "steady_state_error_rad": math.inf, "final_error_rad": None}
    error = np.array([wrap_angle(setpoint - h) for h in heading[inside]])
    size = step["step_rad"]
    target = sum(wrap_angle(params.setpoints[k][1] - (params.setpoints[k - 1][1] if k else 0.0))
                 for k in range(index + 1))
    overshoot = 0.0
    if abs(size) > params.tolerance_rad:
        along = target - heading[inside]
        overshoot = max(0.0, float(np.max(-math.copysign(1.0, size) * along))) / abs(size)
    outside = np.flatnonzero(np.abs(error) > params.tolerance_rad)
    if len(outside) == 0:
        settling: float | None = 0.0
    elif outside[-1] == len(error) - 1:
        settling = None
    else:
        settling = float(window_t[outside[-1] + 1] - start_s)
    final = window_t >= window_t[-1] - params.final_window_s
    return {**step, "settling_time_s": settling, "overshoot": overshoot,
            "steady_state_error_rad": abs(circular_mean_rad(error[final])),
            "final_error_rad": float(error[-1])}


def _failure(step: dict[str, Any], params: HeadingStepParams) -> str:
    """Why a step fails, or "" when it passes."""
    what = f"step to {step['setpoint_rad']:.3f} rad at {step['start_s']:g} s"
    problems = []
    if step["settling_time_s"] is None:
        final = step["final_error_rad"]
        at_end = "" if final is None else f", error at the end {final:+.3f} rad"
        problems.append(f"never settled within ±{params.tolerance_rad:.3f} rad{at_end}")
    elif params.threshold is not None and step["settling_time_s"] > params.threshold:
        problems.append(f"settling time {step['settling_time_s']:.2f} s > "
                        f"{params.threshold:g} s")
    if step["overshoot"] > params.max_overshoot:
        problems.append(f"overshoot {step['overshoot']:.1%} > {params.max_overshoot:.0%}")
    if step["steady_state_error_rad"] > params.tolerance_rad and \
            step["settling_time_s"] is not None:
        problems.append(f"steady-state error {step['steady_state_error_rad']:.4f} rad > "
                        f"{params.tolerance_rad:.4f} rad")
    return f"{what}: {', '.join(problems)}" if problems else ""


def setpoint_schedule(initial_rad: float,
                      changes: Sequence[tuple[float, float]]) -> tuple[tuple[float, float], ...]:
    """The schedule of a setpoint that starts at ``initial_rad`` and changes at set times."""
    return ((0.0, initial_rad), *((float(at), float(value)) for at, value in changes))
