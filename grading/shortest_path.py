"""The shortest way a round robot can drive between two points of a world: go-to-goal's yardstick.

A grid over the world's bounds keeps the cells whose centre is more than the robot's radius
from every wall (``grading.geometry``); Dijkstra over 8 neighbours finds a path of cell
centres, and string pulling then replaces runs of it by straight segments wherever the robot
fits along them. Where the true shortest path bends round the end of a wall on an arc of the
robot's radius, this one turns at a cell centre instead: it is longer by up to about 2 %
(3.066 m for 3.010 m round one wall end, tests/test_grading_metrics.py); a path that needs no
turn is the straight line exactly.
"""

from __future__ import annotations

import heapq
import itertools
import math

import numpy as np

from grading.geometry import WorldShapes, obstacle_distances_m
from physics.world import World

GRID_RESOLUTION_M = 0.05
"""Cell side of the search grid (m): a twentieth of the shipped worlds' 1 m corridors."""

GRID_MARGIN_M = 0.25
"""How far beyond the world's bounds (and the robot's clearance) the grid reaches (m)."""

MAX_GRID_CELLS = 250_000
"""Most cells searched: a larger world is searched on coarser cells, so the work is bounded
(the 6 x 6 m shipped worlds take 14 400)."""

_NEIGHBOURS = ((1, 0), (-1, 0), (0, 1), (0, -1), (1, 1), (1, -1), (-1, 1), (-1, -1))


def segment_is_clear(shapes: WorldShapes, start: tuple[float, float],
                     end: tuple[float, float], clearance_m: float,
                     step_m: float = GRID_RESOLUTION_M / 2) -> bool:
    """Whether a disc of radius ``clearance_m`` fits all along the segment start-end."""
    length = math.hypot(end[0] - start[0], end[1] - start[1])
    count = max(2, math.ceil(length / step_m) + 1)
    fractions = np.linspace(0.0, 1.0, count)
    points = np.array(start)[None, :] + fractions[:, None] * (np.array(end) - np.array(start))
    return bool(np.all(obstacle_distances_m(shapes, points) > clearance_m))


def shortest_path_m(world: World, shapes: WorldShapes, start: tuple[float, float],
                    goal: tuple[float, float], clearance_m: float) -> float | None:
    """Length of the shortest path from ``start`` to ``goal`` for a disc of ``clearance_m`` (m).

    None when no such path exists. The straight line when the disc fits along it.
    """
    if segment_is_clear(shapes, start, goal, clearance_m):
        return math.hypot(goal[0] - start[0], goal[1] - start[1])
    min_x, min_y, max_x, max_y = world.bounds
    margin = clearance_m + GRID_MARGIN_M  # room to drive round the end of an outermost wall
    min_x, max_x = min(min_x, start[0], goal[0]) - margin, max(max_x, start[0], goal[0]) + margin
    min_y, max_y = min(min_y, start[1], goal[1]) - margin, max(max_y, start[1], goal[1]) + margin
    resolution = max(GRID_RESOLUTION_M,
                     math.sqrt((max_x - min_x) * (max_y - min_y) / MAX_GRID_CELLS))
    columns = max(1, math.ceil((max_x - min_x) / resolution))
    rows = max(1, math.ceil((max_y - min_y) / resolution))
    xs = min_x + (np.arange(columns) + 0.5) * resolution
    ys = min_y + (np.arange(rows) + 0.5) * resolution
    grid_x, grid_y = np.meshgrid(xs, ys)  # [row, column]
    centres = np.column_stack([grid_x.ravel(), grid_y.ravel()])
    free = (obstacle_distances_m(shapes, centres) > clearance_m).reshape(rows, columns)

    def cell_of(point: tuple[float, float]) -> tuple[int, int]:
        column = min(columns - 1, max(0, int((point[0] - min_x) / resolution)))
        row = min(rows - 1, max(0, int((point[1] - min_y) / resolution)))
        return row, column

    first, last = cell_of(start), cell_of(goal)
    free[first] = free[last] = True
    path = _dijkstra(free, first, last)
    if path is None:
        return None
    waypoints = [start, *((float(xs[c]), float(ys[r])) for r, c in path[1:-1]), goal]
    taut = _pulled(shapes, waypoints, clearance_m)
    return sum(math.dist(a, b) for a, b in itertools.pairwise(taut))


def _dijkstra(free: np.ndarray, first: tuple[int, int],
              last: tuple[int, int]) -> list[tuple[int, int]] | None:
    """Cells of the shortest 8-connected path over ``free`` cells, first to last, or None."""
    rows, columns = free.shape
    best = {first: 0.0}
    came_from: dict[tuple[int, int], tuple[int, int]] = {}
    queue = [(0.0, first)]
    while queue:
        cost, cell = heapq.heappop(queue)
        if cell == last:
            path = [cell]
            while cell in came_from:
                cell = came_from[cell]
                path.append(cell)
            return path[::-1]
        if cost > best[cell]:
            continue
        row, column = cell
        for d_row, d_column in _NEIGHBOURS:
            neighbour = (row + d_row, column + d_column)
            if not (0 <= neighbour[0] < rows and 0 <= neighbour[1] < columns) \
                    or not free[neighbour]:
                continue
            if d_row and d_column and not (free[row + d_row, column]
                                           and free[row, column + d_column]):
                continue  # no cutting a corner between two blocked cells
            new_cost = cost + (math.sqrt(2.0) if d_row and d_column else 1.0)
            if new_cost < best.get(neighbour, math.inf):
                best[neighbour] = new_cost
                came_from[neighbour] = cell
                heapq.heappush(queue, (new_cost, neighbour))
    return None


def _pulled(shapes: WorldShapes, waypoints: list[tuple[float, float]],
            clearance_m: float) -> list[tuple[float, float]]:
    """The waypoints string-pulled: from each kept one, straight to the last one ahead in sight.

    In sight: the robot fits all along the straight segment.
    """
    kept = [waypoints[0]]
    here = 0
    while here < len(waypoints) - 1:
        reach = here + 1
        while reach + 1 < len(waypoints) and segment_is_clear(
                shapes, waypoints[here], waypoints[reach + 1], clearance_m):
            reach += 1
        kept.append(waypoints[reach])
        here = reach
    return kept
