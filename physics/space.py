"""The pymunk space of a world: its static shapes, its robots' bodies, the collision categories.

Walls and obstacles are static shapes in category ``WALL_CATEGORY``; every robot's footprint is
in ``ROBOT_CATEGORY`` and in a pymunk group of its own (``robot_filter``), so a query made for
a robot (``seen_by``) sees the walls and the other robots, never itself. ``WALLS_ONLY`` sees
the static shapes alone.
"""

from __future__ import annotations

from dataclasses import dataclass

import pymunk

from physics.world import World

WALL_CATEGORY = 0b01
ROBOT_CATEGORY = 0b10
WALLS_ONLY = pymunk.ShapeFilter(categories=ROBOT_CATEGORY, mask=WALL_CATEGORY)
"""Query filter that sees walls and obstacles, never a robot."""


def robot_filter(group: int) -> pymunk.ShapeFilter:
    """The filter of the footprint of the robot numbered ``group`` (> 0) in its world."""
    return pymunk.ShapeFilter(group=group, categories=ROBOT_CATEGORY)


def seen_by(group: int) -> pymunk.ShapeFilter:
    """Query filter for robot ``group``: walls, obstacles and the other robots, not itself."""
    return pymunk.ShapeFilter(group=group, categories=ROBOT_CATEGORY,
                              mask=WALL_CATEGORY | ROBOT_CATEGORY)

COLLISION_SLOP_M = 0.0005
"""Overlap pymunk tolerates between touching shapes. Its default, 0.1, would be 10 cm here."""

WALL_FRICTION = 0.3
"""Coulomb friction between the footprint and walls (a plastic bumper on painted wood)."""


@dataclass(frozen=True)
class WorldSpace:
    """A world's shapes in a pymunk space.

    Attributes:
        space: the pymunk space; the robot model adds its body to it.
        wall_shapes: one ``pymunk.Segment`` per ``World.walls`` entry, same order.
        circle_shapes: one ``pymunk.Circle`` per ``World.circles`` entry, same order.
    """

    space: pymunk.Space
    wall_shapes: tuple[pymunk.Segment, ...]
    circle_shapes: tuple[pymunk.Circle, ...]


def build_world_space(world: World) -> WorldSpace:
    """Create a gravity-free pymunk space holding the world's walls and obstacles."""
    space = pymunk.Space()
    space.collision_slop = COLLISION_SLOP_M
    body = space.static_body
    walls = tuple(pymunk.Segment(body, (w.x1, w.y1), (w.x2, w.y2), 0.0) for w in world.walls)
    circles = tuple(pymunk.Circle(body, c.radius_m, (c.x, c.y)) for c in world.circles)
    for shape in (*walls, *circles):
        shape.filter = pymunk.ShapeFilter(categories=WALL_CATEGORY)
        shape.friction = WALL_FRICTION
        shape.elasticity = 0.0
    space.add(*walls, *circles)
    return WorldSpace(space=space, wall_shapes=walls, circle_shapes=circles)
