"""The metrics: pure functions of a trajectory (ground truth) and the world's geometry.

Each has one frozen dataclass of parameters and one function
``(trajectory, params, world) -> MetricResult``; ``METRICS`` is the table the scenario loader
and the grader read, by the name a scenario file gives (``kind``).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from grading.metrics.collisions import CollisionsParams, collisions
from grading.metrics.go_to_goal import GoToGoalParams, go_to_goal
from grading.metrics.heading_step import HeadingStepParams, heading_step
from grading.metrics.smoothness import SmoothnessParams, smoothness
from grading.metrics.wall_following import WallFollowingParams, wall_following
from grading.results import MetricResult
from grading.trajectory import Trajectory
from physics.world import World


@dataclass(frozen=True)
class MetricKind:
    """One kind of metric.

    Attributes:
        name: what a scenario file calls it (``kind: wall_following``).
        params_type: its frozen dataclass of parameters.
        measure: the function that computes it.
        default_weight: its weight in a scenario's score unless the file gives one.
    """

    name: str
    params_type: type[Any]
    measure: Callable[[Trajectory, Any, World], MetricResult]
    default_weight: float = 1.0


METRICS: Mapping[str, MetricKind] = MappingProxyType({kind.name: kind for kind in (
    MetricKind("heading_step", HeadingStepParams, heading_step),
    MetricKind("wall_following", WallFollowingParams, wall_following),
    MetricKind("go_to_goal", GoToGoalParams, go_to_goal),
    MetricKind("collisions", CollisionsParams, collisions),
    MetricKind("smoothness", SmoothnessParams, smoothness, default_weight=0.0),
)})
"""Every metric, by name."""

_SCENARIO_FACTS = {
    "footprint_radius_m": "the robot's `footprint_radius_m`",
    "max_linear_mps": "the robot's `max_linear_mps`",
    "max_angular_rps": "the robot's `max_angular_rps`",
    "duration_s": "the scenario's `duration_s`",
    "setpoints": "the parameter `setpoint_rad` and its `changes`",
    "end_x_m": "the scenario's `end.point`",
    "end_y_m": "the scenario's `end.point`",
    "end_radius_m": "the scenario's `end.radius_m`",
}


def parameters_table(kind: str) -> str:
    """A Markdown table of a metric's parameters: key, default, unit, where it comes from.

    docs/grading.md holds one per metric; a test holds them equal to this.
    """
    rows = ["| key | default | unit | set by |", "|---|---|---|---|"]
    for field in dataclasses.fields(METRICS[kind].params_type):
        meta = field.metadata
        if meta["from_scenario"] is not None:
            default, source = "—", f"not a key: {_SCENARIO_FACTS[meta['from_scenario']]}"
        else:
            default = "required" if field.default is dataclasses.MISSING else \
                "none" if field.default is None else f"{field.default:g}" \
                if isinstance(field.default, float) else str(field.default)
            source = "the metric, else `parameters`" if meta["from_parameter"] else "the metric"
        rows.append(f"| `{field.name}` | {default} | {meta['unit']} | {source} |")
    return "\n".join(rows)

__all__ = [
    "METRICS",
    "CollisionsParams",
    "GoToGoalParams",
    "HeadingStepParams",
    "MetricKind",
    "SmoothnessParams",
    "WallFollowingParams",
    "collisions",
    "go_to_goal",
    "heading_step",
    "parameters_table",
    "smoothness",
    "wall_following",
]
