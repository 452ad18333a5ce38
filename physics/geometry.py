"""A world's static shapes as arrays: the one definition the LiDAR, collisions and grading read.

Built once per world from ``physics.world.World`` (boxes and polylines are walls already):
every wall as its two ends, every disc as its centre and radius, in the ``map`` frame (m).
The pymunk space (``physics.space``) holds the same shapes for pymunk's queries; these arrays
are what numpy computes on (the LiDAR's fast path, the grader's distances).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from physics.raycast import Walls
from physics.world import World

FloatArray = npt.NDArray[np.float64]


@dataclass(frozen=True)
class WorldShapes:
    """A world's walls and discs as arrays, built once per world.

    Attributes:
        wall_a: first end of each wall, shape (n, 2) (m).
        wall_b: second end of each wall, shape (n, 2) (m).
        circle_centre: centre of each disc, shape (m, 2) (m).
        circle_radius: radius of each disc, shape (m,) (m).
    """

    wall_a: FloatArray
    wall_b: FloatArray
    circle_centre: FloatArray
    circle_radius: FloatArray

    @property
    def count(self) -> int:
        """Walls and discs together."""
        return len(self.wall_a) + len(self.circle_radius)

    @functools.cached_property
    def walls(self) -> Walls:
        """The walls as the LiDAR casts against them (made once)."""
        return Walls.of(self.wall_a, self.wall_b)

    def key(self) -> tuple[bytes, bytes, bytes, bytes]:
        """Equal for worlds of the same shapes (two students' copies of one world file)."""
        return (self.wall_a.tobytes(), self.wall_b.tobytes(), self.circle_centre.tobytes(),
                self.circle_radius.tobytes())


def world_shapes(world: World) -> WorldShapes:
    """The arrays of ``world``'s walls (boxes and polylines included) and discs."""
    return WorldShapes(
        wall_a=np.array([(w.x1, w.y1) for w in world.walls], dtype=np.float64).reshape(-1, 2),
        wall_b=np.array([(w.x2, w.y2) for w in world.walls], dtype=np.float64).reshape(-1, 2),
        circle_centre=np.array([(c.x, c.y) for c in world.circles],
                               dtype=np.float64).reshape(-1, 2),
        circle_radius=np.array([c.radius_m for c in world.circles], dtype=np.float64))
