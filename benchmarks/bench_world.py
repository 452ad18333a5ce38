"""Benchmark one world of many robots headless, and print the figures (it asserts nothing).

What it measures, single-threaded: a world (``physics.world_sim.WorldSim``) of N robots, each
driving its own circle, ticked as the server ticks it: every tick one ``step`` of all robots
and every robot's odometry read (20 Hz), every second tick one scan pass of all robots
(``cast_scans``: 360 rays each, 10 Hz). Per N:

* the real-time factor (simulated time / wall time; >= 1 is real time on one core), with and
  without the scans;
* rays per second cast (N * 360 * 10 * RTF);
* the time of one step and of one scan pass (median, ms).

Then, for each kind of run, the largest N that holds real time (a search over N by doubling,
then halving the gap: ``--search``).

Worlds: ``open``, a 20 x 20 m box; ``walls``, the same box with 100 random walls (the maze's
density of walls over a larger floor, as ``bench_physics.py`` makes them). Robots start on a
grid of free places, 1 m apart or less. ``arena`` (not run by default): the shipped 6 x 6 m
``empty`` world with the robots packed around its start, as ``websim serve --class N --arena``
places them: most robots a laser could see hide behind nearer ones.

Run it from the checkout::

    python benchmarks/bench_world.py                    # N = 50 100 200 400, both worlds
    python benchmarks/bench_world.py --robots 200 --seconds 5
    python benchmarks/bench_world.py --search           # the largest N at real time
"""

from __future__ import annotations

import argparse
import math
import platform
import statistics
import time
from collections.abc import Sequence
from importlib.metadata import version

import numpy as np

from physics import LidarParams, Pose2D, World, WorldSim, load_world, raycast_kernel
from physics.world import world_from_dict

HALF_M = 10.0
"""The worlds are the square [-10, 10] x [-10, 10] m."""

SEED = 12345
TICK_S = 0.05


def world_of(kind: str) -> World:
    """``open`` or ``walls`` (100 random walls inside the box, ``bench_physics`` style)."""
    box = [[-HALF_M, -HALF_M], [HALF_M, -HALF_M], [HALF_M, HALF_M], [-HALF_M, HALF_M]]
    walls: list[list[float]] = []
    if kind == "walls":
        rng = np.random.default_rng(SEED)
        while len(walls) < 100:
            x1, y1 = rng.uniform(-HALF_M, HALF_M, size=2)
            length, heading = rng.uniform(0.3, 2.0), rng.uniform(-math.pi, math.pi)
            x2, y2 = x1 + length * math.cos(heading), y1 + length * math.sin(heading)
            if abs(x2) <= HALF_M and abs(y2) <= HALF_M:
                walls.append([float(x1), float(y1), float(x2), float(y2)])
    return world_from_dict({"name": kind, "walls": walls,
                            "polylines": [{"points": box, "closed": True}]},
                           source=f"<{kind}>")


def crowd(kind: str, robots: int) -> WorldSim:
    """A world of ``robots`` robots on free places of a grid, each given a circle to drive.

    ``arena``: the shipped 6 x 6 m ``empty`` world, each robot where ``serve --arena`` puts a
    robot the world file does not place (the nearest free pose to the start: a packed crowd).
    """
    rng = np.random.default_rng(SEED)
    if kind == "arena":
        world = WorldSim(load_world("empty"), seed=SEED, lidar=LidarParams())
        for index in range(robots):
            world.spawn(f"r{index}")
        for name in world.names:
            world.command(name, float(rng.uniform(0.05, 0.3)), float(rng.uniform(-1.0, 1.0)))
        return world
    world = WorldSim(world_of(kind), seed=SEED, lidar=LidarParams())
    spacing = min(1.0, 2 * HALF_M / math.ceil(math.sqrt(robots) + 1))
    cells = [(x, y) for x in np.arange(-HALF_M + spacing, HALF_M, spacing)
             for y in np.arange(-HALF_M + spacing, HALF_M, spacing)]
    rng.shuffle(cells)
    for x, y in cells:
        if len(world) == robots:
            break
        try:
            world.spawn(f"r{len(world)}", Pose2D(float(x), float(y), float(rng.uniform(-3, 3))))
        except ValueError:
            continue  # a wall there
    for name in world.names:
        world.command(name, float(rng.uniform(0.05, 0.3)), float(rng.uniform(-1.0, 1.0)))
    return world


def run(kind: str, robots: int, seconds: float, scans: bool) -> dict[str, float]:
    """Tick a crowd for ``seconds`` of sim time; its figures."""
    world = crowd(kind, robots)
    names = world.names
    ticks = round(seconds / TICK_S)
    steps: list[float] = []
    passes: list[float] = []
    started = time.perf_counter()
    for tick in range(ticks):
        t0 = time.perf_counter()
        world.step()
        for name in names:
            world.odometry(name)
        t1 = time.perf_counter()
        steps.append(t1 - t0)
        if scans and tick % 2 == 0:
            world.cast_scans()
            passes.append(time.perf_counter() - t1)
    wall_s = time.perf_counter() - started
    rtf = ticks * TICK_S / wall_s
    return {"robots": len(names), "rtf": rtf,
            "rays_per_s": len(names) * 360 * 10 * rtf if scans else 0.0,
            "step_ms": 1e3 * statistics.median(steps),
            "pass_ms": 1e3 * statistics.median(passes) if passes else 0.0}


def largest_real_time(kind: str, scans: bool, seconds: float, cap: int) -> int:
    """The largest N whose run holds real time (RTF >= 1), by doubling then bisecting."""
    low, high = 0, 25
    while high <= cap and run(kind, high, seconds, scans)["rtf"] >= 1.0:
        low, high = high, high * 2
    high = min(high, cap + 1)
    while high - low > max(5, low // 20):
        middle = (low + high) // 2
        if run(kind, middle, seconds, scans)["rtf"] >= 1.0:
            low = middle
        else:
            high = middle
    return low


def main(argv: Sequence[str] | None = None) -> int:
    """Run the figures and print them."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--robots", type=int, nargs="+", default=[50, 100, 200, 400])
    parser.add_argument("--worlds", nargs="+", default=["open", "walls"],
                        choices=["open", "walls", "arena"])
    parser.add_argument("--seconds", type=float, default=10.0, help="sim time per run")
    parser.add_argument("--search", action="store_true",
                        help="also the largest N at real time, with and without scans")
    parser.add_argument("--search-max", type=int, default=3200)
    args = parser.parse_args(argv)
    print(f"websim world benchmark: Python {platform.python_version()}, numpy "
          f"{np.__version__}, pymunk {version('pymunk')}, {platform.platform()}; the LiDAR "
          f"cast: {raycast_kernel.chosen()} ({raycast_kernel.RAYCAST_ENV})")
    print(f"{'world':<6} {'robots':>6} {'scans':>5} {'RTF':>8} {'rays/s':>10} "
          f"{'step ms':>8} {'pass ms':>8}")
    for kind in args.worlds:
        for robots in args.robots:
            for scans in (True, False):
                row = run(kind, robots, args.seconds, scans)
                print(f"{kind:<6} {row['robots']:>6} {'yes' if scans else 'no':>5} "
                      f"{row['rtf']:>8.2f} {row['rays_per_s']:>10.0f} {row['step_ms']:>8.2f} "
                      f"{row['pass_ms']:>8.2f}", flush=True)
    if args.search:
        for kind in args.worlds:
            for scans in (True, False):
                largest = largest_real_time(kind, scans, min(args.seconds, 5.0),
                                            args.search_max)
                print(f"{kind}: largest N at real time {'with' if scans else 'without'} "
                      f"scans: {largest}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
