"""A world as an occupancy grid: what ``/map`` carries and ``websim map`` writes.

Cells follow ``nav_msgs/OccupancyGrid`` (``physics.map_grid``: half-open cells, row 0 at the
origin's y, row-major). Values: ``OCCUPIED`` (100) where a wall, box or disc is, ``FREE`` (0)
elsewhere inside the world's bounds, ``UNKNOWN`` (-1) outside them.

Which cells a shape occupies: **every cell that holds at least one point of it** (the shape
closed, the cell half-open, ties within ``map_grid.SNAP_CELLS``). Walls have no thickness, as
in the physics (pymunk segments of radius 0), so a wall occupies exactly the cells it
crosses: a wall from (1, -1) to (1, 1) on a grid with a line at x = 1 occupies the one column
to the right of that line, 41 cells of 5 cm (both ends included, as Bresenham's line). Boxes
and discs are solid: their insides are occupied too, and a disc's cells lie within one cell's
diagonal of it.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from physics.map_grid import SNAP_CELLS, GridGeometry, grid_over
from physics.world import World, box_corners

OCCUPIED = 100
"""A cell an obstacle occupies (``nav_msgs/OccupancyGrid``'s certainty, in percent)."""

FREE = 0
"""A cell inside the world's bounds that no obstacle occupies."""

UNKNOWN = -1
"""A cell outside the world's bounds."""


@dataclass(frozen=True, eq=False)
class OccupancyGrid:
    """A rasterised world.

    Attributes:
        geometry: where the grid lies in ``map`` (origin, resolution, width, height).
        cells: ``int8`` values, shape ``(height, width)``, ``cells[row, column]``, row 0 at
            the origin's y; read-only. ``cells.ravel()`` is ``OccupancyGrid.data``'s order.
    """

    geometry: GridGeometry
    cells: np.ndarray


def rasterise(world: World, resolution_m: float | None = None,
              where: str = "map_resolution_m") -> OccupancyGrid:
    """The occupancy grid of ``world`` at ``resolution_m`` (default: the world's own).

    ``where`` names the resolution's source in errors (``--resolution``).

    Raises:
        ConfigError: a resolution that is not a finite number > 0, or a grid beyond
            ``map_grid.MAX_MAP_CELLS``.
    """
    resolution = world.map_resolution_m if resolution_m is None else resolution_m
    geometry = grid_over(world.bounds, resolution, where)
    cells = np.full((geometry.height, geometry.width), UNKNOWN, dtype=np.int8)
    min_x, min_y, max_x, max_y = world.bounds
    cells[geometry.row_of(min_y):geometry.row_of(max_y) + 1,
          geometry.column_of(min_x):geometry.column_of(max_x) + 1] = FREE
    for wall in world.walls:
        columns, rows = segment_cells(geometry, wall.x1, wall.y1, wall.x2, wall.y2)
        cells[rows, columns] = OCCUPIED
    for box in world.boxes:
        _fill_convex(cells, geometry, box_corners(box))
    for disc in world.circles:
        _fill_disc(cells, geometry, disc.x, disc.y, disc.radius_m)
    cells.flags.writeable = False
    return OccupancyGrid(geometry, cells)


def segment_cells(geometry: GridGeometry, x1: float, y1: float, x2: float,
                  y2: float) -> tuple[np.ndarray, np.ndarray]:
    """(columns, rows) of the cells a thin segment crosses: every cell holding a point of it.

    The segment is cut where it crosses a grid line; each piece between two crossings lies in
    one cell (that of its midpoint), and each crossing point and end lies in the cell the
    half-open convention gives it (on a grid line: the cell above or to the right).
    """
    dx, dy = x2 - x1, y2 - y1
    crossings = [np.array([0.0, 1.0])]
    for start, end, index_of, line_of in (
            (x1, x2, geometry.column_of, geometry.column_x_m),
            (y1, y2, geometry.row_of, geometry.row_y_m)):
        first, last = sorted((index_of(start), index_of(end)))
        delta = end - start
        if delta != 0.0 and last > first:
            lines = np.array([line_of(k) for k in range(first + 1, last + 1)])
            crossings.append((lines - start) / delta)
    t = np.unique(np.clip(np.concatenate(crossings), 0.0, 1.0))
    t = np.concatenate([t, (t[:-1] + t[1:]) / 2.0])
    resolution = geometry.resolution_m
    columns = np.floor((x1 + t * dx - geometry.origin_x_m) / resolution + SNAP_CELLS)
    rows = np.floor((y1 + t * dy - geometry.origin_y_m) / resolution + SNAP_CELLS)
    return _clipped(geometry, columns.astype(np.intp), rows.astype(np.intp))


def _clipped(geometry: GridGeometry, columns: np.ndarray,
             rows: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Only the cells inside the grid (a shape inside the bounds never leaves it)."""
    inside = (columns >= 0) & (columns < geometry.width) & (rows >= 0) & (rows < geometry.height)
    return columns[inside], rows[inside]


def _row_span(geometry: GridGeometry, row: int, low_m: float,
              high_m: float) -> tuple[float, float]:
    """The y interval of ``row`` within [low_m, high_m] (m); its top edge is the next row's."""
    top = geometry.row_y_m(row + 1) - SNAP_CELLS * geometry.resolution_m
    return max(geometry.row_y_m(row), low_m), min(top, high_m)


def _fill_columns(cells: np.ndarray, geometry: GridGeometry, row: int, left_m: float,
                  right_m: float) -> None:
    """Occupy the cells of ``row`` holding an x in [left_m, right_m]."""
    if 0 <= row < geometry.height:
        first = max(geometry.column_of(left_m), 0)
        last = min(geometry.column_of(right_m), geometry.width - 1)
        cells[row, first:last + 1] = OCCUPIED


def _fill_convex(cells: np.ndarray, geometry: GridGeometry,
                 corners: Sequence[tuple[float, float]]) -> None:
    """Occupy every cell holding a point of the convex polygon ``corners`` (solid)."""
    ys = [y for _, y in corners]
    low, high = min(ys), max(ys)
    edges = list(zip(corners, [*corners[1:], corners[0]], strict=True))
    for row in range(geometry.row_of(low), geometry.row_of(high) + 1):
        bottom, top = _row_span(geometry, row, low, high)
        if bottom > top:
            continue
        # A convex polygon's x extent over a strip is reached at a corner inside the strip or
        # where an edge meets the strip's bottom or top.
        xs = [x for x, y in corners if bottom <= y <= top]
        for (ax, ay), (bx, by) in edges:
            for y in (bottom, top):
                if ay != by and min(ay, by) <= y <= max(ay, by):
                    xs.append(ax + (y - ay) * (bx - ax) / (by - ay))
        if xs:
            _fill_columns(cells, geometry, row, min(xs), max(xs))


def _fill_disc(cells: np.ndarray, geometry: GridGeometry, x: float, y: float,
               radius_m: float) -> None:
    """Occupy every cell holding a point of the disc of ``radius_m`` at (x, y) (solid)."""
    for row in range(geometry.row_of(y - radius_m), geometry.row_of(y + radius_m) + 1):
        bottom, top = _row_span(geometry, row, y - radius_m, y + radius_m)
        if bottom > top:
            continue
        nearest_dy = 0.0 if bottom <= y <= top else min(abs(bottom - y), abs(top - y))
        half_width = math.sqrt(max(radius_m * radius_m - nearest_dy * nearest_dy, 0.0))
        _fill_columns(cells, geometry, row, x - half_width, x + half_width)
