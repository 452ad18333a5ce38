"""The occupancy grid of a world (``physics.occupancy``): geometry worked by hand, and an oracle.

Hand-worked cases fix what "the cells a shape occupies" means (every cell holding a point of
it, cells half-open as ``nav_msgs/OccupancyGrid``'s); random walls, boxes and discs are then
checked against an independent oracle (does the cell's closed square meet the shape?).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import pytest

from physics import ConfigError, load_world
from physics.map_grid import (
    DEFAULT_MAP_RESOLUTION_M,
    MARGIN_CELLS,
    MAX_MAP_CELLS,
    GridGeometry,
    grid_over,
)
from physics.occupancy import FREE, OCCUPIED, UNKNOWN, OccupancyGrid, rasterise
from physics.world import WORLDS_DIR, box_corners, world_from_dict

FRAME = {"points": [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]], "closed": True}
"""A 2 x 2 m square frame: bounds [-1, 1] on both axes, so with the one-cell margin the grid's
lines fall on multiples of the resolution (0.1 m or 0.05 m: the origin is -1 - r)."""


def framed(resolution_m: float, **shapes: Any) -> OccupancyGrid:
    """The grid of the frame plus ``shapes`` (world-file keys), spawning at (-0.5, -0.5)."""
    return rasterise(world_from_dict({"start": [-0.5, -0.5, 0.0], "polylines": [FRAME],
                                      "map_resolution_m": resolution_m, **shapes}))


def occupied_corners(grid: OccupancyGrid) -> set[tuple[float, float]]:
    """Lower-left corners (m, rounded to 1e-9) of the cells occupied besides the frame's."""
    geometry = grid.geometry
    frame = framed(geometry.resolution_m).cells == OCCUPIED
    rows, columns = np.nonzero((grid.cells == OCCUPIED) & ~frame)
    return {(round(geometry.column_x_m(int(c)), 9), round(geometry.row_y_m(int(r)), 9))
            for r, c in zip(rows, columns, strict=True)}


# ---- hand-worked geometry ----------------------------------------------------------------


def test_a_wall_along_x_1_occupies_exactly_the_column_it_lies_in() -> None:
    # Bounds (0, -1) .. (1, 1) (the wall and the start); at 0.05 m with one cell of margin the
    # origin is (-0.05, -1.05), so x = 1 m is the grid line between columns 20 and 21. A cell
    # is half-open, [x, x + r): the wall's points are in column 21, rows 1 (y = -1 m in
    # [-1.00, -0.95)) to 41 (y = 1 m in [1.00, 1.05)): 41 cells, both ends included.
    grid = rasterise(world_from_dict({"walls": [[1.0, -1.0, 1.0, 1.0]]}))
    geometry = grid.geometry
    assert (geometry.origin_x_m, geometry.origin_y_m) == pytest.approx((-0.05, -1.05), abs=1e-12)
    assert (geometry.width, geometry.height) == (23, 43)
    rows, columns = np.nonzero(grid.cells == OCCUPIED)
    assert sorted(zip(columns.tolist(), rows.tolist(), strict=True)) == \
        [(21, row) for row in range(1, 42)]
    # Inside the bounds (columns 1..21, rows 1..41) the rest is free, the one-cell ring unknown.
    inside = np.zeros_like(grid.cells, dtype=bool)
    inside[1:42, 1:22] = True
    assert (grid.cells[inside & (grid.cells != OCCUPIED)] == FREE).all()
    assert (grid.cells[~inside] == UNKNOWN).all()


def test_a_wall_between_grid_lines_and_a_diagonal_wall() -> None:
    # At 0.3 m the frame's grid has lines at -1.3 + 0.3 k: ..., -0.7, -0.4, -0.1, 0.2, 0.5,
    # 0.8. A wall along x = 0.6 from y = -0.6 to 0.6 lies in column [0.5, 0.8) and crosses
    # rows [-0.7, -0.4) (its end y = -0.6) .. [0.5, 0.8) (its end y = 0.6): 5 cells.
    grid = framed(0.3, walls=[[0.6, -0.6, 0.6, 0.6]])
    assert occupied_corners(grid) == {(0.5, y) for y in (-0.7, -0.4, -0.1, 0.2, 0.5)}
    # The diagonal from (-0.45, -0.45) to (0.45, 0.2) at 0.1 m: it enters each column at
    # x = -0.5 + 0.1 k (k = 1..9), y rising 0.65/0.9 = 0.7222 m per metre. Worked per column:
    # x in [-0.45, -0.4): y from -0.45 to -0.4139 -> row [-0.5, -0.4)
    # x in [-0.4, -0.3): y -0.4139 .. -0.3417 -> rows [-0.5, -0.4), [-0.4, -0.3)
    # x in [-0.3, -0.2): y -0.3417 .. -0.2694 -> rows [-0.4, -0.3), [-0.3, -0.2)
    # x in [-0.2, -0.1): y -0.2694 .. -0.1972 -> rows [-0.3, -0.2), [-0.2, -0.1)
    # x in [-0.1, 0.0): y -0.1972 .. -0.1250 -> row [-0.2, -0.1)
    # x in [0.0, 0.1): y -0.1250 .. -0.0528 -> rows [-0.2, -0.1), [-0.1, 0.0)
    # x in [0.1, 0.2): y -0.0528 .. 0.0194 -> rows [-0.1, 0.0), [0.0, 0.1)
    # x in [0.2, 0.3): y 0.0194 .. 0.0917 -> row [0.0, 0.1)
    # x in [0.3, 0.4): y 0.0917 .. 0.1639 -> rows [0.0, 0.1), [0.1, 0.2)
    # x in [0.4, 0.45]: y 0.1639 .. 0.2 -> rows [0.1, 0.2), [0.2, 0.3) (its end, y = 0.2)
    grid = framed(0.1, walls=[[-0.45, -0.45, 0.45, 0.2]])
    assert occupied_corners(grid) == {
        (-0.5, -0.5), (-0.4, -0.5), (-0.4, -0.4), (-0.3, -0.4), (-0.3, -0.3), (-0.2, -0.3),
        (-0.2, -0.2), (-0.1, -0.2), (0.0, -0.2), (0.0, -0.1), (0.1, -0.1), (0.1, 0.0),
        (0.2, 0.0), (0.3, 0.0), (0.3, 0.1), (0.4, 0.1), (0.4, 0.2)}


def test_a_disc_occupies_the_cells_holding_its_points() -> None:
    # Disc of radius 0.2 at (0.52, 0.51), cells of 0.1 m (lines at multiples of 0.1). Per row,
    # the x extent of the disc over the row's y span (nearest y to 0.51 gives the widest):
    # [0.3, 0.4): dy 0.11, half-width sqrt(0.04 - 0.0121) = 0.1670: x 0.353..0.687 -> 4 cells
    # [0.4, 0.5): dy 0.01, 0.1997: x 0.3203..0.7197 -> columns 0.3..0.7, 5 cells
    # [0.5, 0.6): holds y = 0.51, 0.2: x 0.32..0.72 -> 5 cells
    # [0.6, 0.7): dy 0.09, 0.1786: x 0.3414..0.6986 -> 4 cells
    # [0.7, 0.8): dy 0.19, 0.0624: x 0.4576..0.5824 -> columns 0.4, 0.5
    grid = framed(0.1, circles=[{"center": [0.52, 0.51], "radius": 0.2}])
    assert occupied_corners(grid) == {
        *((x, 0.3) for x in (0.3, 0.4, 0.5, 0.6)), *((x, 0.4) for x in (0.3, 0.4, 0.5, 0.6, 0.7)),
        *((x, 0.5) for x in (0.3, 0.4, 0.5, 0.6, 0.7)), *((x, 0.6) for x in (0.3, 0.4, 0.5, 0.6)),
        (0.4, 0.7), (0.5, 0.7)}


def test_a_box_rotated_30_degrees_occupies_the_cells_holding_its_points() -> None:
    # Box 0.4 x 0.2 at (0.33, 0.24), yaw 30 deg (cos 0.8660, sin 0.5). Its corners:
    # A = (0.33 - 0.1732 + 0.05, 0.24 - 0.1 - 0.0866) = (0.2068, 0.0534)
    # B = (0.33 + 0.1732 + 0.05, 0.24 + 0.1 - 0.0866) = (0.5532, 0.2534)
    # C = (0.33 + 0.1732 - 0.05, 0.24 + 0.1 + 0.0866) = (0.4532, 0.4266)
    # D = (0.33 - 0.1732 - 0.05, 0.24 - 0.1 + 0.0866) = (0.1068, 0.2266)
    # Edges AB and DC rise at 30 deg (x += dy * 1.7321), DA and CB at 120 deg (x -= dy * 0.5774).
    # Per 0.1 m row, the x extent:
    # [0.0, 0.1): DA at 0.1: 0.2068 - 0.0466 * 0.5774 = 0.1799; AB at 0.1: 0.2875 -> 0.1, 0.2
    # [0.1, 0.2): DA at 0.2: 0.1222; AB at 0.2: 0.4607 -> columns 0.1 .. 0.4
    # [0.2, 0.3): holds D (0.1068) and B (0.5532) -> columns 0.1 .. 0.5
    # [0.3, 0.4): DC at 0.3: 0.1068 + 0.0734 * 1.7321 = 0.2339; CB at 0.3: 0.5263 -> 0.2 .. 0.5
    # [0.4, 0.5): DC at 0.4: 0.4071; CB at 0.4: 0.4686 -> column 0.4
    grid = framed(0.1, boxes=[{"center": [0.33, 0.24], "size": [0.4, 0.2],
                               "yaw": math.radians(30.0)}])
    assert occupied_corners(grid) == {
        (0.1, 0.0), (0.2, 0.0), *((x, 0.1) for x in (0.1, 0.2, 0.3, 0.4)),
        *((x, 0.2) for x in (0.1, 0.2, 0.3, 0.4, 0.5)), *((x, 0.3) for x in (0.2, 0.3, 0.4, 0.5)),
        (0.4, 0.4)}


def test_the_arena_and_the_maze_by_hand() -> None:
    # The arena: a closed 6 x 6 m square from -3 to 3. At 0.05 m: 121 cells per side, the
    # four corners shared: 480 occupied; with the margin, 123 x 123 cells from (-3.05, -3.05);
    # the ring of unknown: 4 * 122 = 488 cells; the rest free.
    arena = rasterise(load_world("empty"))
    assert arena.geometry == GridGeometry(-3.05, -3.05, 0.05, 123, 123)
    assert np.count_nonzero(arena.cells == OCCUPIED) == 480
    assert np.count_nonzero(arena.cells == UNKNOWN) == 4 * 122
    assert np.count_nonzero(arena.cells == FREE) == 123 * 123 - 480 - 488
    # Row order: row 0 at the origin's y. The maze's wall from (-3, 2) to (1, 2) is in row
    # (2 + 3.05) / 0.05 = 101, columns 1 (x = -3) to 81 (x = 1); the row below is free there.
    maze = rasterise(load_world("maze"))
    assert (maze.cells[101, 1:82] == OCCUPIED).all()
    assert (maze.cells[100, 2:20] == FREE).all()
    # The pillar of radius 0.25 at (-2, -2): the cell holding its centre is occupied.
    assert maze.cells[maze.geometry.row_of(-2.0), maze.geometry.column_of(-2.0)] == OCCUPIED


def test_the_grid_is_read_only_and_int8() -> None:
    grid = rasterise(load_world("maze"))
    assert grid.cells.dtype == np.int8
    with pytest.raises(ValueError, match="read-only"):
        grid.cells[0, 0] = FREE


@pytest.mark.parametrize("path", sorted(WORLDS_DIR.glob("*.yaml")), ids=lambda p: p.stem)
def test_every_shipped_world_has_a_map_with_its_walls_inside_its_bounds(path: Any) -> None:
    world = load_world(path)
    grid = rasterise(world)
    assert world.map_resolution_m == DEFAULT_MAP_RESOLUTION_M
    assert (grid.cells[0, :] == UNKNOWN).all() and (grid.cells[-1, :] == UNKNOWN).all()
    assert (grid.cells[:, 0] == UNKNOWN).all() and (grid.cells[:, -1] == UNKNOWN).all()
    for wall in world.walls:
        for x, y in ((wall.x1, wall.y1), (wall.x2, wall.y2)):
            assert grid.cells[grid.geometry.row_of(y), grid.geometry.column_of(x)] == OCCUPIED
    # The spawn cell is free: the robot starts clear of every wall.
    assert grid.cells[grid.geometry.row_of(world.start.y),
                      grid.geometry.column_of(world.start.x)] == FREE


# ---- against an independent oracle -------------------------------------------------------


def _square(geometry: GridGeometry, column: int, row: int) -> tuple[float, float, float, float]:
    x, y = geometry.column_x_m(column), geometry.row_y_m(row)
    return x, y, x + geometry.resolution_m, y + geometry.resolution_m


def _segment_meets(square: tuple[float, float, float, float], a: np.ndarray,
                   b: np.ndarray) -> bool:
    """Liang-Barsky: does segment a-b meet the closed square?"""
    low, high = 0.0, 1.0
    direction = b - a
    for axis, (lo, hi) in enumerate(((square[0], square[2]), (square[1], square[3]))):
        if abs(direction[axis]) < 1e-15:
            if not lo <= a[axis] <= hi:
                return False
            continue
        t1, t2 = sorted(((lo - a[axis]) / direction[axis], (hi - a[axis]) / direction[axis]))
        low, high = max(low, t1), min(high, t2)
    return low <= high


def _polygon_meets(square: tuple[float, float, float, float], corners: np.ndarray) -> bool:
    """Separating axes: does the convex polygon meet the closed square?"""
    box = np.array([[square[0], square[1]], [square[2], square[1]], [square[2], square[3]],
                    [square[0], square[3]]])
    axes = [np.array([1.0, 0.0]), np.array([0.0, 1.0])]
    axes += [np.array([-(b - a)[1], (b - a)[0]]) for a, b in
             zip(corners, np.roll(corners, -1, axis=0), strict=True)]
    for axis in axes:
        p, q = box @ axis, corners @ axis
        if p.max() < q.min() or q.max() < p.min():
            return False
    return True


def _disc_meets(square: tuple[float, float, float, float], centre: np.ndarray,
                radius: float) -> bool:
    nearest = np.clip(centre, square[:2], square[2:])
    return bool(np.hypot(*(nearest - centre)) <= radius)


@pytest.mark.parametrize("seed", range(6))
def test_random_shapes_occupy_exactly_the_cells_they_meet(seed: int) -> None:
    # Random shapes never fall exactly on a grid line, so "holds a point of it" (half-open
    # cells) and "its closed square meets it" agree cell for cell.
    rng = np.random.default_rng(seed)
    resolution = float(rng.choice([0.05, 0.1, 0.17]))
    a, b = rng.uniform(-0.9, 0.9, 2), rng.uniform(-0.9, 0.9, 2)
    centre, radius = rng.uniform(-0.6, 0.6, 2), float(rng.uniform(0.02, 0.3))
    box = {"center": rng.uniform(-0.5, 0.5, 2).tolist(),
           "size": rng.uniform(0.05, 0.6, 2).tolist(), "yaw": float(rng.uniform(-3, 3))}
    cases = [
        ({"walls": [[*a.tolist(), *b.tolist()]]}, lambda sq: _segment_meets(sq, a, b)),
        ({"circles": [{"center": centre.tolist(), "radius": radius}]},
         lambda sq: _disc_meets(sq, centre, radius)),
        ({"boxes": [box]}, None),
    ]
    frame_only = framed(resolution).cells == OCCUPIED
    for shapes, meets in cases:
        world = world_from_dict({"start": [-0.95, -0.95, 0.0], "polylines": [FRAME],
                                 "map_resolution_m": resolution, **shapes})
        grid = rasterise(world)
        if meets is None:
            corners = np.array(box_corners(world.boxes[0]))

            def meets(sq: tuple[float, float, float, float],
                      corners: np.ndarray = corners) -> bool:
                return _polygon_meets(sq, corners)
        geometry = grid.geometry
        for row in range(geometry.height):
            for column in range(geometry.width):
                if frame_only[row, column]:
                    continue
                expected = meets(_square(geometry, column, row))
                assert (grid.cells[row, column] == OCCUPIED) == expected, \
                    (shapes, column, row)


def test_a_disc_s_cells_lie_within_its_radius_and_one_cell() -> None:
    grid = framed(0.05, circles=[{"center": [0.123, -0.0456], "radius": 0.37}])
    geometry = grid.geometry
    rows, columns = np.nonzero(grid.cells == OCCUPIED)
    centres_x = geometry.origin_x_m + (columns + 0.5) * geometry.resolution_m
    centres_y = geometry.origin_y_m + (rows + 0.5) * geometry.resolution_m
    distance = np.hypot(centres_x - 0.123, centres_y + 0.0456)
    disc = distance < 0.9  # the frame is farther
    assert distance[disc].max() <= 0.37 + geometry.resolution_m
    # ... and every cell whose centre is inside the disc is occupied (it is solid).
    all_rows, all_columns = np.indices(grid.cells.shape)
    inside = np.hypot(geometry.origin_x_m + (all_columns + 0.5) * 0.05 - 0.123,
                      geometry.origin_y_m + (all_rows + 0.5) * 0.05 + 0.0456) <= 0.37
    assert (grid.cells[inside] == OCCUPIED).all()


# ---- resolution and size -----------------------------------------------------------------


def test_the_resolution_is_a_world_key_with_a_default() -> None:
    coarse = world_from_dict({"polylines": [FRAME], "start": [0.5, 0.5, 0],
                              "map_resolution_m": 0.1})
    assert coarse.map_resolution_m == 0.1
    assert rasterise(coarse).geometry.width == 2 * MARGIN_CELLS + 21
    assert rasterise(coarse, 0.05).geometry.width == 2 * MARGIN_CELLS + 41


@pytest.mark.parametrize(("value", "message"), [
    (0, "finite number of metres > 0, got 0"),
    (-0.05, "> 0, got -0.05"),
    (".nan", "got nan"),
    ("fine", "got 'fine'"),
    (True, "got True"),
    (1e-4, "more than 500,000"),
])
def test_a_bad_resolution_in_a_world_file_is_refused_with_the_key(tmp_path: Any, value: Any,
                                                                  message: str) -> None:
    path = tmp_path / "w.yaml"
    path.write_text(f"walls: [[0, 0, 5, 0]]\nstart: [1, 1, 0]\nmap_resolution_m: {value}\n")
    with pytest.raises(ConfigError, match="map_resolution_m") as raised:
        load_world(path)
    assert message in str(raised.value)
    assert str(path) in str(raised.value)


def test_an_absurd_grid_is_refused_with_the_finest_resolution_that_fits() -> None:
    with pytest.raises(ConfigError) as raised:
        grid_over((0.0, 0.0, 100.0, 100.0), 0.05)
    text = str(raised.value)
    assert "4,012,009 cells, more than 500,000" in text
    finest = float(text.rsplit("use ", 1)[1].split(" m")[0])
    assert grid_over((0.0, 0.0, 100.0, 100.0), finest).cell_count <= MAX_MAP_CELLS
    assert finest == 0.15
    with pytest.raises(ConfigError, match="infinitely many cells"):
        grid_over((0.0, 0.0, 10.0, 10.0), 1e-300)


def test_a_large_world_that_names_no_resolution_gets_the_finest_that_fits(tmp_path: Any) -> None:
    """A 100 m world loads (its /map coarser than the default, within the cap); naming the
    default resolution outright in the same world is refused with the one that fits."""
    path = tmp_path / "large.yaml"
    path.write_text("walls: [[0, 0, 100, 0], [0, 100, 100, 100]]\nstart: [1, 1, 0]\n")
    world = load_world(path)
    assert world.map_resolution_m == 0.15
    assert rasterise(world).cells.size <= MAX_MAP_CELLS
    small = tmp_path / "small.yaml"
    small.write_text("walls: [[0, 0, 5, 0]]\nstart: [1, 1, 0]\n")
    assert load_world(small).map_resolution_m == 0.05
    path.write_text(path.read_text() + "map_resolution_m: 0.05\n")
    with pytest.raises(ConfigError, match=r"use 0\.15 m or coarser"):
        load_world(path)
