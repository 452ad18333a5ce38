"""Command smoothness: how much the controller's commands jump, per second of the run.

    mean |Δv| = Σ |v_k - v_k-1| / T      (m/s per s)
    mean |Δω| = Σ |ω_k - ω_k-1| / T      (rad/s per s)
    value     = mean |Δv| / v_max + mean |Δω| / ω_max      (1/s)

over the commands in force at consecutive samples, T the run's length and v_max, ω_max the
robot's limits: the value is how many full-range swings of the commands the run makes per
second, whatever the rate the samples or the controller have. Reported with weight 0 by
default: a controller is not marked down for it unless the scenario says so. Score:
``within_ratio(value, threshold)``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grading.metric_fields import optional, param, positive
from grading.results import MetricResult, within_ratio
from grading.trajectory import Trajectory, check_trajectory
from physics.world import World


@dataclass(frozen=True)
class SmoothnessParams:
    """Parameters of the smoothness metric.

    Attributes:
        max_linear_mps: the robot's linear limit (m/s), from its parameters.
        max_angular_rps: the robot's angular limit (rad/s), from its parameters.
        threshold: the largest value that passes (1/s); None for no limit.
    """

    max_linear_mps: float = param(unit="m/s", from_scenario="max_linear_mps")
    max_angular_rps: float = param(unit="rad/s", from_scenario="max_angular_rps")
    threshold: float | None = param(1.0, unit="1/s", check=optional(positive))


def smoothness(trajectory: Trajectory, params: SmoothnessParams,
               world: World | None = None) -> MetricResult:
    """Mean command changes per second; see the module's docstring."""
    check_trajectory(trajectory)
    duration = trajectory[-1].t_s - trajectory[0].t_s
    v = np.array([sample.v_cmd_mps for sample in trajectory])
    w = np.array([sample.w_cmd_rps for sample in trajectory])
    dv = float(np.sum(np.abs(np.diff(v)))) / duration if duration > 0.0 else 0.0
    dw = float(np.sum(np.abs(np.diff(w)))) / duration if duration > 0.0 else 0.0
    value = dv / params.max_linear_mps + dw / params.max_angular_rps
    passed = params.threshold is None or value <= params.threshold
    score = 1.0 if params.threshold is None else within_ratio(value, params.threshold)
    limit = "" if params.threshold is None else \
        f" ({'within' if passed else 'above'} {params.threshold:g} /s)"
    return MetricResult(
        name="smoothness", kind="smoothness", value=value, unit="1/s",
        threshold=params.threshold, passed=passed, score=score,
        reason=f"{value:.3f} full-range command swings per second{limit}: mean |Δv| "
               f"{dv:.3f} m/s per s, mean |Δω| {dw:.3f} rad/s per s",
        figures={"mean_abs_dv_mps_per_s": dv, "mean_abs_dw_rps_per_s": dw},
        inputs={"max_linear_mps": params.max_linear_mps,
                "max_angular_rps": params.max_angular_rps, "duration_s": duration,
                "samples": len(trajectory)})
