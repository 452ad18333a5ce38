"""The cells of a world's occupancy map: where the grid lies and which cell holds a point.

The conventions are ``nav_msgs/OccupancyGrid``'s: cell (column ``i``, row ``j``) is the
half-open square ``[x0 + i·r, x0 + (i+1)·r) × [y0 + j·r, y0 + (j+1)·r)`` of the ``map`` frame,
where ``(x0, y0)`` is the grid's origin, the lower-left corner of cell (0, 0), and ``r`` its
resolution; rows run along +y from the origin (row 0 at the bottom) and the data is row-major.
Every point of the plane lies in exactly one cell, so a shape "occupies the cells it crosses"
has one meaning: the cells that hold at least one point of it (``physics.occupancy``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from physics.validation import ConfigError, shown

DEFAULT_MAP_RESOLUTION_M = 0.05
"""A map cell's side when the world does not say (``map_resolution_m``): nav2's and
slam_toolbox's usual 5 cm, under half the robot's 0.11 m footprint radius."""

MARGIN_CELLS = 1
"""Cells of unknown (-1) around the world's bounds on every side, so the map says where the
world ends (as a SLAM map is unknown beyond what was seen)."""

MAX_MAP_CELLS = 500_000
"""The most cells a map may have: a 35 x 35 m world at 0.05 m. /map goes whole to every
subscriber; its JSON text is at most about 4 bytes a cell (``100,``), 2 MB, half of a
client's default 4 MiB send queue, so subscribing to /map never closes a client; its
rasterisation and encoding take tens of milliseconds, not seconds. Worlds beyond it need a
coarser ``map_resolution_m`` (the error says which)."""

SNAP_CELLS = 1e-9
"""A point this close (in cells) below a cell boundary counts as on it: 1.0 m is on a
grid line of a 0.05 m grid although 1.0 / 0.05 is not exact in binary."""


@dataclass(frozen=True)
class GridGeometry:
    """Where a grid lies in the ``map`` frame.

    Attributes:
        origin_x_m: x of the lower-left corner of cell (0, 0) (m).
        origin_y_m: y of that corner (m).
        resolution_m: a cell's side (m).
        width: columns, along +x.
        height: rows, along +y (row 0 at ``origin_y_m``).
    """

    origin_x_m: float
    origin_y_m: float
    resolution_m: float
    width: int
    height: int

    @property
    def cell_count(self) -> int:
        """Cells in the grid: ``width * height``."""
        return self.width * self.height

    def column_of(self, x: float) -> int:
        """The column whose half-open span holds ``x`` (may be outside 0..width-1)."""
        return cell_index(x - self.origin_x_m, self.resolution_m)

    def row_of(self, y: float) -> int:
        """The row whose half-open span holds ``y`` (may be outside 0..height-1)."""
        return cell_index(y - self.origin_y_m, self.resolution_m)

    def column_x_m(self, column: int) -> float:
        """The x of a column's left edge (m)."""
        return self.origin_x_m + column * self.resolution_m

    def row_y_m(self, row: int) -> float:
        """The y of a row's bottom edge (m)."""
        return self.origin_y_m + row * self.resolution_m


def cell_index(offset_m: float, resolution_m: float) -> int:
    """The index of the cell holding a point ``offset_m`` from the grid's origin (m)."""
    return math.floor(offset_m / resolution_m + SNAP_CELLS)


def check_resolution(where: str, resolution_m: float) -> float:
    """``resolution_m`` if it is a finite number > 0, else a ConfigError naming ``where``."""
    if isinstance(resolution_m, bool) or not isinstance(resolution_m, (int, float)) \
            or not math.isfinite(resolution_m) or resolution_m <= 0.0:
        raise ConfigError(f"{where}: a map resolution must be a finite number of metres > 0, "
                          f"got {shown(resolution_m)}")
    return float(resolution_m)


def grid_over(bounds: tuple[float, float, float, float], resolution_m: float,
              where: str = "map_resolution_m") -> GridGeometry:
    """The grid that covers ``bounds`` (min_x, min_y, max_x, max_y, m) with ``MARGIN_CELLS``.

    The origin is the bounds' lower-left corner less the margin, so the bounds' edges lie on
    grid lines; the grid ends with the cell that holds the bounds' upper edge, then the margin.

    Raises:
        ConfigError: the resolution is not a finite number > 0, or the grid would hold more
            than ``MAX_MAP_CELLS`` (the message gives the finest resolution that fits).
    """
    resolution_m = check_resolution(where, resolution_m)
    min_x, min_y, max_x, max_y = bounds
    span_x, span_y = max_x - min_x, max_y - min_y
    columns = span_x / resolution_m + 1 + 2 * MARGIN_CELLS
    rows = span_y / resolution_m + 1 + 2 * MARGIN_CELLS
    if not columns * rows <= MAX_MAP_CELLS:  # also catches inf and NaN from a tiny resolution
        finest = _finest_resolution_m(span_x, span_y)
        raise ConfigError(
            f"{where}: {resolution_m:g} m over the world's {span_x:g} x {span_y:g} m gives "
            f"about {_count(columns * rows)} cells, more than {MAX_MAP_CELLS:,} (/map goes whole "
            f"to every subscriber and must fit a client's send queue); use {finest:g} m or "
            "coarser")
    origin_x = min_x - MARGIN_CELLS * resolution_m
    origin_y = min_y - MARGIN_CELLS * resolution_m
    return GridGeometry(origin_x, origin_y, resolution_m,
                        cell_index(max_x - origin_x, resolution_m) + 1 + MARGIN_CELLS,
                        cell_index(max_y - origin_y, resolution_m) + 1 + MARGIN_CELLS)


def default_resolution_m(bounds: tuple[float, float, float, float]) -> float:
    """A world's resolution when it names none: the default, or the finest that fits."""
    min_x, min_y, max_x, max_y = bounds
    return max(DEFAULT_MAP_RESOLUTION_M, _finest_resolution_m(max_x - min_x, max_y - min_y))


def _count(cells: float) -> str:
    """A cell count for an error message (a tiny resolution gives an infinite one)."""
    return f"{cells:,.0f}" if math.isfinite(cells) else "infinitely many"


def _finest_resolution_m(span_x: float, span_y: float) -> float:
    """The finest resolution, to two significant figures rounded up, whose grid fits."""
    low, high = 1e-6, max(span_x, span_y, 1.0)
    for _ in range(200):  # bisection: the cell count falls as the resolution grows
        middle = (low + high) / 2.0
        cells = (span_x / middle + 1 + 2 * MARGIN_CELLS) * (span_y / middle + 1 + 2 * MARGIN_CELLS)
        low, high = (middle, high) if cells > MAX_MAP_CELLS else (low, middle)
    digits = 1 - math.floor(math.log10(high))
    scale = 10.0**digits
    return math.ceil(high * scale) / scale
