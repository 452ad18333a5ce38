"""Distances between the robot and a world's walls, from the world's geometry alone.

Pure numpy over the world's shapes (``physics.geometry.WorldShapes``, the simulator's own
arrays): no pymunk space, so a trajectory from a recording is measured exactly as one from a
live simulation. Every coordinate is in the ``map`` frame (m).
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from grading.trajectory import FloatArray
from physics.geometry import WorldShapes, world_shapes
from physics.world import World

IntArray = npt.NDArray[np.intp]

__all__ = ["SIDES", "WorldShapes", "nearest_obstacles", "obstacle_distances_m",
           "obstacle_origins", "side_distance_m", "world_shapes"]

SIDES = ("left", "right")
"""The side of the robot a wall follower keeps the wall on (MIT RSS: +1 left, -1 right)."""

PARALLEL_EPS = 1e-12
"""A lateral offset change below this along a wall counts as none (the wall is parallel to
the robot's axis), so clipping never divides by zero."""


def _point_segment_distances(points: FloatArray, a: FloatArray, b: FloatArray) -> FloatArray:
    """Distance from each point (k, 2) to each segment a-b (n, 2): shape (k, n) (m)."""
    edge = b - a                                             # (n, 2)
    length2 = np.maximum(np.einsum("ij,ij->i", edge, edge), PARALLEL_EPS)
    rel = points[:, None, :] - a[None, :, :]                 # (k, n, 2)
    t = np.clip(np.einsum("knj,nj->kn", rel, edge) / length2, 0.0, 1.0)
    nearest = a[None, :, :] + t[:, :, None] * edge[None, :, :]
    gap = points[:, None, :] - nearest
    distances: FloatArray = np.hypot(gap[:, :, 0], gap[:, :, 1])
    return distances


def obstacle_distances_m(shapes: WorldShapes, points: FloatArray) -> FloatArray:
    """Distance from each point (k, 2) to the nearest wall or disc surface, shape (k,) (m).

    Inf where the world has nothing at all; 0 for a point inside a disc.
    """
    return nearest_obstacles(shapes, points)[0]


def nearest_obstacles(shapes: WorldShapes, points: FloatArray) -> tuple[FloatArray, IntArray]:
    """For each point (k, 2): the distance to the nearest shape (m) and which shape it is.

    Shapes are numbered walls first, then discs, in the world's order (``obstacle_origins``);
    -1 where the world has none.
    """
    points = np.asarray(points, dtype=np.float64).reshape(-1, 2)
    columns = []
    if len(shapes.wall_a):
        columns.append(_point_segment_distances(points, shapes.wall_a, shapes.wall_b))
    if len(shapes.circle_radius):
        gap = points[:, None, :] - shapes.circle_centre[None, :, :]
        surface = np.hypot(gap[:, :, 0], gap[:, :, 1]) - shapes.circle_radius[None, :]
        columns.append(np.maximum(surface, 0.0))
    if not columns:
        return np.full(len(points), math.inf), np.full(len(points), -1, dtype=np.intp)
    distances = np.concatenate(columns, axis=1)
    indices: IntArray = np.argmin(distances, axis=1)
    nearest: FloatArray = distances[np.arange(len(points)), indices]
    return nearest, indices


def obstacle_origins(world: World) -> list[str]:
    """Each shape's entry in the world file (``walls[2]``, ``circles[0]``).

    Numbered as in ``nearest_obstacles``: walls first, then discs.
    """
    return [wall.origin for wall in world.walls] + [disc.origin for disc in world.circles]


def side_distance_m(shapes: WorldShapes, x_m: float, y_m: float, yaw_rad: float,
                    side: str) -> float:
    """Distance from (x, y) to the nearest wall point on the robot's ``side`` (m); inf if none.

    The robot's side is the half-plane left (or right) of the line through (x, y) along its
    heading, that line included: what a LiDAR's beams on that side can hit, at any range. A
    wall crossing the line is clipped to the part on that side.
    """
    if side not in SIDES:
        raise ValueError(f"side must be one of {', '.join(SIDES)}, got {side!r}")
    sign = 1.0 if side == "left" else -1.0
    centre = np.array([x_m, y_m])
    normal = sign * np.array([-math.sin(yaw_rad), math.cos(yaw_rad)])
    best = math.inf
    if len(shapes.wall_a):
        a, b = shapes.wall_a, shapes.wall_b
        lateral_a = (a - centre) @ normal
        lateral_b = (b - centre) @ normal
        keep = (lateral_a >= 0.0) | (lateral_b >= 0.0)
        a, b, lateral_a, lateral_b = a[keep], b[keep], lateral_a[keep], lateral_b[keep]
        # Move an end that lies on the far side to where the wall crosses the line.
        change = lateral_a - lateral_b
        safe = np.where(np.abs(change) < PARALLEL_EPS, 1.0, change)
        crossing = a + (lateral_a / safe)[:, None] * (b - a)
        a = np.where((lateral_a < 0.0)[:, None], crossing, a)
        b = np.where((lateral_b < 0.0)[:, None], crossing, b)
        if len(a):
            best = float(_point_segment_distances(centre[None, :], a, b).min())
    for (cx, cy), radius in zip(shapes.circle_centre, shapes.circle_radius, strict=True):
        offset = np.array([cx, cy]) - centre
        lateral = float(offset @ normal)
        if lateral >= 0.0:
            best = min(best, max(float(np.hypot(*offset)) - radius, 0.0))
        elif -lateral <= radius:  # the disc reaches over the line: its chord on the line
            along = abs(float(offset @ np.array([math.cos(yaw_rad), math.sin(yaw_rad)])))
            half_chord = math.sqrt(radius * radius - lateral * lateral)
            best = min(best, max(along - half_chord, 0.0))
    return best
