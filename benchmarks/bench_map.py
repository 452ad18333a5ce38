"""What /map costs: rasterising a world and encoding its message once (prints figures).

/map (``nav_msgs/OccupancyGrid``) is latched: built once when the robot starts and encoded once
per format for every subscriber (``rosbridge.core.capabilities.topics.Encoded``). Per world it
prints the grid's cells, the time to rasterise it (``physics.occupancy.rasterise``), and the
size and encoding time of its rosbridge ``publish`` frame
(``ros_nodes.robot_messages.occupancy_grid_msg``) in JSON and CBOR
(``rosbridge.core.encoding``). Worlds: the shipped maze, a 10 x 10 m arena with 100 random
walls at 0.05 m (40,000 cells inside), and the largest map allowed (``MAX_MAP_CELLS``) with
every cell occupied (the longest JSON: ``100,``).

Run it from the checkout::

    python benchmarks/bench_map.py
"""

from __future__ import annotations

import math
import statistics
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from physics import load_world
from physics.map_grid import MAX_MAP_CELLS, GridGeometry
from physics.occupancy import OCCUPIED, OccupancyGrid, rasterise
from physics.world import World, world_from_dict
from ros_nodes.robot_messages import occupancy_grid_msg
from rosbridge.core.encoding import to_cbor, to_json
from rosbridge.core.limits import ClientLimits

REPEATS = 7
"""Timed runs of each step; the median is printed."""


def median_ms(step: Callable[[], Any]) -> tuple[float, Any]:
    """The median time of ``step`` over ``REPEATS`` runs (ms), and its last result."""
    times, result = [], None
    for _ in range(REPEATS):
        start = time.perf_counter()
        result = step()
        times.append((time.perf_counter() - start) * 1e3)
    return statistics.median(times), result


def random_walls_world(seed: int = 7) -> World:
    """A 10 x 10 m arena with 100 random walls of 0.3 to 2 m."""
    rng = np.random.default_rng(seed)
    walls: list[list[float]] = []
    while len(walls) < 100:
        x, y = rng.uniform(-4.9, 4.9, 2)
        angle, length = rng.uniform(0, 2 * math.pi), rng.uniform(0.3, 2.0)
        end_x, end_y = x + length * math.cos(angle), y + length * math.sin(angle)
        if max(abs(end_x), abs(end_y)) < 4.9:  # inside the frame: the grid stays 10 x 10 m
            walls.append([float(x), float(y), float(end_x), float(end_y)])
    frame = {"points": [[-5, -5], [5, -5], [5, 5], [-5, 5]], "closed": True}
    return world_from_dict({"start": [0, 0, 0], "polylines": [frame], "walls": walls},
                           source="random walls")


def report(label: str, make_grid: Callable[[], OccupancyGrid], rasterised: bool = True) -> None:
    raster_ms, grid = median_ms(make_grid)
    raster = f"{raster_ms:>9.1f}" if rasterised else f"{'-':>9}"
    msg = occupancy_grid_msg(grid, time.time())
    envelope = {"op": "publish", "topic": "/map", "msg": msg}
    json_ms, text = median_ms(lambda: to_json(envelope))
    cbor_ms, data = median_ms(lambda: to_cbor(envelope))
    geometry = grid.geometry
    print(f"{label:<34} {geometry.width:>4} x {geometry.height:<4} {geometry.cell_count:>8,} "
          f"{raster} {len(text):>11,} {json_ms:>8.1f} "
          f"{len(data):>10,} {cbor_ms:>8.1f}")


def main() -> None:
    queue = ClientLimits().max_queued_bytes
    print(f"{'world':<34} {'grid':^11} {'cells':>8} {'raster ms':>9} "
          f"{'JSON bytes':>11} {'JSON ms':>8} {'CBOR bytes':>10} {'CBOR ms':>8}")
    report("maze (shipped)", lambda: rasterise(load_world("maze")))
    report("10 x 10 m, 100 random walls", lambda: rasterise(random_walls_world()))
    side = math.isqrt(MAX_MAP_CELLS)
    full = np.full((side, side), OCCUPIED, dtype=np.int8)
    report("largest allowed, all occupied", lambda: OccupancyGrid(
        GridGeometry(0.0, 0.0, 0.05, side, side), full), rasterised=False)
    print(f"a client's send queue: {queue:,} bytes")


if __name__ == "__main__":
    main()
