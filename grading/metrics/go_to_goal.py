"""Go to a goal: reached within r, how fast, how direct, without touching a wall.

Weighted as Webots' robotbenchmark weights its square-path benchmark (distance, path and time
elements, 1 / 1 / 0.5), with its obstacle-avoidance rule that a collision costs time. Over
the run up to the first sample within ``goal_radius_m`` of the goal (the whole run if never):

- distance element, from the closest approach's miss m = max(0, closest - r) and the
  reference length L (below): 0.1 (1 - m/L) + 0.9 e^(-6 m/L), at least 0; 1 when reached;
- path element: (L - r) / P, at most 1, with P the length driven to the goal disc; 0 if
  never reached;
- time element: max(1 - t_eff / T, 0), with t_eff the time to the goal plus
  ``collision_penalty_s`` per contact, and T ``time_reference_s`` (the run's duration by
  default); 0 if never reached;
- score = (w_d distance + w_p path + w_t time) / (w_d + w_p + w_t).

L is the shortest path a disc of the robot's radius can drive from the start to the goal
(``grading.shortest_path``), or the straight line with ``reference: straight_line``. A pass
needs reaching the goal with at most ``max_collisions`` contacts, and within ``threshold``
seconds when one is given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from grading.geometry import world_shapes
from grading.metric_fields import (
    non_negative,
    number,
    one_of,
    optional,
    param,
    positive,
    whole,
)
from grading.metrics.collisions import CONTACT_TOLERANCE_M, describe_contact, find_contacts
from grading.results import MetricResult
from grading.shortest_path import shortest_path_m
from grading.trajectory import Trajectory, check_trajectory, first_within, path_length_m, until
from physics.world import World

REFERENCES = ("shortest", "straight_line")
"""What the path is compared with: the shortest drivable path, or the straight line."""

DISTANCE_SHARPNESS = 6.0
"""Webots' square path: 0.9 e^(-3 d) over a 2 m side, i.e. e^(-6 d/L)."""

DEFAULT_COLLISION_PENALTY_S = 10.0
"""Time a contact costs (s). Webots' obstacle avoidance counts a collision as 80 s on runs of
about a minute; ours are as long, and a contact here also fails the run by default."""


@dataclass(frozen=True)
class GoToGoalParams:
    """Parameters of the go-to-goal metric.

    Attributes:
        footprint_radius_m: the robot's collision radius (m), from its parameters.
        duration_s: the run's duration (s), from the scenario.
        goal_x_m: the goal's x in the map frame (m).
        goal_y_m: the goal's y in the map frame (m).
        goal_radius_m: how close to the goal counts as reached (m).
        reference: ``shortest`` or ``straight_line`` (see the module's docstring).
        time_reference_s: T of the time element (s); None: the run's duration.
        collision_penalty_s: time added per contact (s).
        max_collisions: most contacts a pass allows.
        weight_distance: w_d.
        weight_path: w_p.
        weight_time: w_t.
        threshold: the longest time to the goal that passes (s); None: within the run.
        contact_tolerance_m: see ``grading.metrics.collisions.CONTACT_TOLERANCE_M`` (m).
    """

    footprint_radius_m: float = param(unit="m", from_scenario="footprint_radius_m")
    duration_s: float = param(unit="s", from_scenario="duration_s")
    goal_x_m: float = param(unit="m", check=number, from_parameter=True)
    goal_y_m: float = param(unit="m", check=number, from_parameter=True)
    goal_radius_m: float = param(0.25, unit="m", check=positive, from_parameter=True)
    reference: str = param("shortest", check=one_of(*REFERENCES))
    time_reference_s: float | None = param(None, unit="s", check=optional(positive))
    collision_penalty_s: float = param(DEFAULT_COLLISION_PENALTY_S, unit="s",
                                       check=non_negative)
    max_collisions: int = param(0, unit="contacts", check=whole)
    weight_distance: float = param(1.0, check=non_negative)
    weight_path: float = param(1.0, check=non_negative)
    weight_time: float = param(0.5, check=non_negative)
    threshold: float | None = param(None, unit="s", check=optional(positive))
    contact_tolerance_m: float = param(CONTACT_TOLERANCE_M, unit="m", check=non_negative)


def go_to_goal(trajectory: Trajectory, params: GoToGoalParams, world: World) -> MetricResult:
    """Score reaching the goal; see the module's docstring."""
    check_trajectory(trajectory)
    start = (trajectory[0].x_m, trajectory[0].y_m)
    goal = (params.goal_x_m, params.goal_y_m)
    radius = params.goal_radius_m
    reached_s = first_within(trajectory, *goal, radius)
    window = trajectory if reached_s is None else until(trajectory, reached_s)
    elapsed_s = reached_s - trajectory[0].t_s if reached_s is not None else None
    if params.reference == "straight_line":
        reference_m: float | None = math.dist(start, goal)
    else:
        reference_m = shortest_path_m(world, world_shapes(world), start, goal,
                                      params.footprint_radius_m)
    log = find_contacts(window, world, params.footprint_radius_m, params.contact_tolerance_m)
    contacts = len(log.contacts)
    driven_m = path_length_m(window)
    closest = min(math.dist((s.x_m, s.y_m), goal) for s in window)
    length = max(reference_m if reference_m is not None else math.dist(start, goal), radius)
    miss = max(0.0, closest - radius)
    distance_term = max(0.0, min(1.0, 0.1 * (1.0 - miss / length)
                                 + 0.9 * math.exp(-DISTANCE_SHARPNESS * miss / length)))
    time_reference = params.time_reference_s or params.duration_s
    effective_s = None if elapsed_s is None else elapsed_s + params.collision_penalty_s * contacts
    if elapsed_s is None or effective_s is None:
        path_term = time_term = 0.0
    else:
        path_term = min(1.0, (length - radius) / driven_m) if driven_m > 0.0 else 1.0
        time_term = max(1.0 - effective_s / time_reference, 0.0)
    weights = (params.weight_distance, params.weight_path, params.weight_time)
    total = sum(weights)
    score = (weights[0] * distance_term + weights[1] * path_term + weights[2] * time_term) \
        / total if total > 0.0 else 0.0

    where = f"({goal[0]:g}, {goal[1]:g})"
    problems = []
    if elapsed_s is None:
        problems.append(f"did not come within {radius:g} m of the goal {where} "
                        f"(closest {closest:.2f} m)")
    elif params.threshold is not None and elapsed_s > params.threshold:
        problems.append(f"reached the goal in {elapsed_s:.2f} s > {params.threshold:g} s")
    if contacts > params.max_collisions:
        problems.append(f"{contacts} contact{'s' if contacts > 1 else ''} with walls, first "
                        f"{describe_contact(log.contacts[0])}")
    passed = not problems
    reason = "; ".join(problems) if problems else (
        f"reached the goal {where} in {elapsed_s:.2f} s over {driven_m:.2f} m "
        f"(reference {length:.2f} m)")
    return MetricResult(
        name="go_to_goal", kind="go_to_goal", value=elapsed_s, unit="s",
        threshold=params.threshold, passed=passed, score=min(1.0, max(0.0, score)),
        reason=reason,
        figures={"reached": elapsed_s is not None, "time_to_goal_s": elapsed_s,
                 "path_length_m": driven_m, "reference_path_m": reference_m,
                 "closest_to_goal_m": closest, "contacts": contacts,
                 "effective_time_s": effective_s, "distance_term": distance_term,
                 "path_term": path_term, "time_term": time_term},
        inputs={"goal": list(goal), "goal_radius_m": radius, "start": list(start),
                "reference": params.reference, "time_reference_s": time_reference,
                "collision_penalty_s": params.collision_penalty_s,
                "max_collisions": params.max_collisions, "weights": list(weights),
                "footprint_radius_m": params.footprint_radius_m,
                "contact_source": log.source, "world": world.source,
                "samples": len(window)})
