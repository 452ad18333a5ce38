"""Wall following, scored as MIT RSS's wall follower lab (2026) scores it.

From the start until the robot first comes within ``end_radius_m`` of the scenario's end
point (the run, like MIT's test, ends there), every sample's distance d to the wall on the
followed side is taken from the world's geometry (``grading.geometry.side_distance_m``: the
nearest wall point in the half-plane on that side, capped at ``max_distance_m``, as a LiDAR
sees no farther). Then:

    loss  = mean |d - d*|                      (m; d* = desired_distance_m)
    score = 1 / (1 + (alpha * loss)^2)

A pass needs reaching the end point before the run's timeout and no contact with a wall on
the way (a crash fails the run); a failed run scores 0, as MIT scores only completed tests.
With a ``threshold`` the loss must also be at most that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from grading.geometry import SIDES, side_distance_m, world_shapes
from grading.metric_fields import non_negative, one_of, optional, param, positive
from grading.metrics.collisions import CONTACT_TOLERANCE_M, describe_contact, find_contacts
from grading.results import MetricResult
from grading.trajectory import Trajectory, check_trajectory, first_within, until
from physics.world import World

MIT_END_RADIUS_M = 1.0
"""MIT's test ends when the car is within 1.0 m of the end point."""

DEFAULT_ALPHA_PER_M = 4.0
"""With alpha = 4 /m a mean error of 5 cm scores 0.96 and 25 cm scores 0.5 (MIT chose its alpha
so that the staff's solution scores in the high 90s; ours puts a controller that holds a few
centimetres there in the shipped worlds, 1 m corridors)."""

DEFAULT_MAX_DISTANCE_M = 3.5
"""Farthest wall distance counted (m): the shipped LiDAR's range_max."""


@dataclass(frozen=True)
class WallFollowingParams:
    """Parameters of the wall-following metric.

    Attributes:
        end_x_m: the end point's x (m), from the scenario's ``end``.
        end_y_m: the end point's y (m), from the scenario's ``end``.
        end_radius_m: how close to the end point the run ends (m), from the scenario's
            ``end`` (MIT: 1.0).
        footprint_radius_m: the robot's collision radius (m), from its parameters.
        side: the side the wall is on, ``left`` or ``right``.
        desired_distance_m: the distance to hold, d* (m).
        alpha_per_m: the score's alpha (1/m).
        max_distance_m: distances beyond this count as this (m).
        threshold: the largest loss that passes (m); None (the default) for no limit.
        contact_tolerance_m: see ``grading.metrics.collisions.CONTACT_TOLERANCE_M`` (m).
    """

    end_x_m: float = param(unit="m", from_scenario="end_x_m")
    end_y_m: float = param(unit="m", from_scenario="end_y_m")
    end_radius_m: float = param(unit="m", from_scenario="end_radius_m")
    footprint_radius_m: float = param(unit="m", from_scenario="footprint_radius_m")
    side: str = param(unit="", check=one_of(*SIDES), from_parameter=True)
    desired_distance_m: float = param(unit="m", check=positive, from_parameter=True)
    alpha_per_m: float = param(DEFAULT_ALPHA_PER_M, unit="1/m", check=positive)
    max_distance_m: float = param(DEFAULT_MAX_DISTANCE_M, unit="m", check=positive)
    threshold: float | None = param(None, unit="m", check=optional(non_negative))
    contact_tolerance_m: float = param(CONTACT_TOLERANCE_M, unit="m", check=non_negative)


def wall_following(trajectory: Trajectory, params: WallFollowingParams,
                   world: World) -> MetricResult:
    """MIT's loss and score over the run up to the end point; see the module's docstring."""
    check_trajectory(trajectory)
    reached_s = first_within(trajectory, params.end_x_m, params.end_y_m, params.end_radius_m)
    window = trajectory if reached_s is None else until(trajectory, reached_s)
    shapes = world_shapes(world)
    distances = np.array([min(side_distance_m(shapes, s.x_m, s.y_m, s.yaw_rad, params.side),
                              params.max_distance_m) for s in window])
    loss = float(np.mean(np.abs(distances - params.desired_distance_m)))
    log = find_contacts(window, world, params.footprint_radius_m, params.contact_tolerance_m)
    closest = min(math.hypot(s.x_m - params.end_x_m, s.y_m - params.end_y_m)
                  for s in trajectory)
    end = f"({params.end_x_m:g}, {params.end_y_m:g})"
    score = 1.0 / (1.0 + (params.alpha_per_m * loss) ** 2)
    if log.contacts:
        passed, score = False, 0.0
        reason = (f"crashed: {describe_contact(log.contacts[0])}"
                  f"{'' if reached_s is None else ' before the end point'}")
    elif reached_s is None:
        passed, score = False, 0.0
        duration = trajectory[-1].t_s - trajectory[0].t_s
        reason = (f"did not come within {params.end_radius_m:g} m of the end point {end} in "
                  f"{duration:.1f} s (closest {closest:.2f} m)")
    elif params.threshold is not None and loss > params.threshold:
        passed = False
        reason = f"mean distance error {loss:.3f} m > {params.threshold:g} m"
    else:
        passed = True
        reason = (f"reached the end point at {reached_s:.2f} s, mean |d - d*| = {loss:.3f} m "
                  f"on the {params.side}")
    return MetricResult(
        name="wall_following", kind="wall_following", value=loss, unit="m",
        threshold=params.threshold, passed=passed, score=score, reason=reason,
        figures={"loss_m": loss, "reached_end_s": reached_s, "closest_to_end_m": closest,
                 "contacts": len(log.contacts),
                 "first_contact_s": log.contacts[0].start_s if log.contacts else None,
                 "mean_distance_m": float(np.mean(distances)),
                 "min_distance_m": float(np.min(distances)),
                 "max_distance_m": float(np.max(distances))},
        inputs={"side": params.side, "desired_distance_m": params.desired_distance_m,
                "alpha_per_m": params.alpha_per_m, "end_point": [params.end_x_m, params.end_y_m],
                "end_radius_m": params.end_radius_m, "max_distance_m": params.max_distance_m,
                "footprint_radius_m": params.footprint_radius_m,
                "contact_source": log.source, "world": world.source,
                "samples": len(window)})
