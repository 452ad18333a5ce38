"""Contacts with walls: how many, when, for how long, and which wall.

A contact is a stretch of consecutive samples in which the robot touches a wall. Touching is
the simulation's own contact flag when every sample carries it (``Sample.collided``: the
footprint met a wall during that tick), else the geometry: the robot's centre within its
footprint radius (plus ``contact_tolerance_m``) of a wall or disc of the world.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

from grading.geometry import nearest_obstacles, obstacle_origins, world_shapes
from grading.metric_fields import non_negative, optional, param, positive, whole
from grading.results import MetricResult
from grading.trajectory import Trajectory, check_trajectory, positions
from physics.world import World

CONTACT_TOLERANCE_M = 0.001
"""How close to a wall the footprint counts as touching it when contacts come from the
geometry (m): the kinematic model stops a micrometre short of a wall, the dynamic one lets
pymunk overlap it by up to half a millimetre (``physics.space.COLLISION_SLOP_M``)."""

MAX_CONTACTS_LISTED = 50
"""Contacts listed one by one in the result (all are counted): a report stays readable."""


class Contact(NamedTuple):
    """One stretch of touching a wall.

    Attributes:
        start_s: time of its first sample (s).
        end_s: time of its last sample (s).
        wall: the world file's entry of the shape touched first (``walls[3]``).
    """

    start_s: float
    end_s: float
    wall: str


class ContactLog(NamedTuple):
    """Every contact of a trajectory.

    Attributes:
        contacts: the contacts, in time order.
        time_in_contact_s: total time spent touching (s): each touching sample counts the
            time since the sample before it.
        source: ``"simulation"`` (contact flags) or ``"geometry"`` (pose and world).
    """

    contacts: tuple[Contact, ...]
    time_in_contact_s: float
    source: str


@dataclass(frozen=True)
class CollisionsParams:
    """Parameters of the collisions metric.

    Attributes:
        footprint_radius_m: the robot's collision radius (m), from its parameters.
        threshold: most contacts allowed for a pass (default 0: none).
        contact_tolerance_m: see ``CONTACT_TOLERANCE_M`` (m).
    """

    footprint_radius_m: float = param(unit="m", from_scenario="footprint_radius_m")
    threshold: float | None = param(0, unit="contacts", check=optional(whole))
    contact_tolerance_m: float = param(CONTACT_TOLERANCE_M, unit="m", check=non_negative)


def find_contacts(trajectory: Trajectory, world: World, footprint_radius_m: float,
                  contact_tolerance_m: float = CONTACT_TOLERANCE_M) -> ContactLog:
    """The contacts of ``trajectory`` with ``world``'s walls (see the module's docstring)."""
    positive("footprint_radius_m", footprint_radius_m)
    shapes = world_shapes(world)
    distances, indices = nearest_obstacles(shapes, positions(trajectory))
    origins = obstacle_origins(world)
    flags = [sample.collided for sample in trajectory]
    if all(flag is not None for flag in flags):
        touching, source = [bool(flag) for flag in flags], "simulation"
    else:
        limit = footprint_radius_m + contact_tolerance_m
        touching, source = [bool(d <= limit) for d in distances], "geometry"
    contacts: list[Contact] = []
    time_in_contact_s = 0.0
    start = None
    for index, touch in enumerate(touching):
        if touch:
            if index > 0:
                time_in_contact_s += trajectory[index].t_s - trajectory[index - 1].t_s
            if start is None:
                start = index
        if start is not None and (not touch or index == len(touching) - 1):
            last = index if touch else index - 1
            wall = origins[indices[start]] if indices[start] >= 0 else "?"
            contacts.append(Contact(trajectory[start].t_s, trajectory[last].t_s, wall))
            start = None
    return ContactLog(tuple(contacts), time_in_contact_s, source)


def describe_contact(contact: Contact) -> str:
    """``"walls[3] at t = 12.35 s"``."""
    return f"{contact.wall} at t = {contact.start_s:.2f} s"


def collisions(trajectory: Trajectory, params: CollisionsParams, world: World) -> MetricResult:
    """Count and time the contacts with walls; pass with at most ``threshold`` of them.

    Score: 1 / (1 + contacts): full marks without any, half with one, a third with two.
    """
    check_trajectory(trajectory)
    log = find_contacts(trajectory, world, params.footprint_radius_m,
                        params.contact_tolerance_m)
    count = len(log.contacts)
    passed = params.threshold is None or count <= params.threshold
    if count == 0:
        reason = "no contact with a wall"
    else:
        listed = ", ".join(describe_contact(c) for c in log.contacts[:3])
        more = f" and {count - 3} more" if count > 3 else ""
        limit = "" if params.threshold is None else f" (at most {params.threshold:g} allowed)"
        reason = f"{count} contact{'s' if count > 1 else ''} with walls{limit}: {listed}{more}"
    return MetricResult(
        name="collisions", kind="collisions", value=float(count), unit="contacts",
        threshold=params.threshold, passed=passed, score=1.0 / (1.0 + count), reason=reason,
        figures={"contacts": count,
                 "first_contact_s": log.contacts[0].start_s if log.contacts else None,
                 "time_in_contact_s": log.time_in_contact_s,
                 "listed": [c._asdict() for c in log.contacts[:MAX_CONTACTS_LISTED]]},
        inputs={"footprint_radius_m": params.footprint_radius_m,
                "contact_tolerance_m": params.contact_tolerance_m, "contact_source": log.source,
                "world": world.source, "samples": len(trajectory)})
