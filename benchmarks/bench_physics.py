"""Benchmark the simulation core and print the figures (it asserts nothing about speed).

What it measures, single-threaded, on this machine:

1. Time per 360-ray LiDAR scan, median and p95 over random poses in free space, for the shipped
   ``maze`` and for generated worlds of 100 and 500 random walls: both the fast numpy path
   (``Lidar.raw_ranges``) and the one-query-per-ray reference (``Lidar.raw_ranges_reference``),
   over the same poses, with the largest difference between the two as a sanity figure.
2. Time per tick (``Simulation.step``) in the maze, kinematic and dynamic, driving a circle.
3. Real-time factor (simulated time / wall time) of a headless 20 s run in the maze with
   odometry read every tick (20 Hz) and a scan every second tick (10 Hz), driving the circle.

Run it from the checkout::

    python benchmarks/bench_physics.py              # full run, aligned table
    python benchmarks/bench_physics.py --quick      # smoke run, fewer repetitions
    python benchmarks/bench_physics.py --markdown   # a Markdown table for the README

Timings depend on the machine and its load; the targets are printed alongside for comparison.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import platform
import statistics
import time
from collections.abc import Callable, Sequence
from importlib.metadata import version

import numpy as np
import numpy.typing as npt

from physics import TICK_PERIOD_S, Pose2D, Simulation, World, load_world, raycast_kernel
from physics.world import world_from_dict

SEED = 12345
"""Seed of every random draw: same worlds, same poses, run after run."""

ARENA_HALF_M = 10.0
"""Generated worlds fill the square [-10, 10] x [-10, 10] m, enclosed by a box on its edge."""

WALL_LENGTH_M = (0.3, 2.0)
"""Shortest and longest generated wall (m)."""

CLEARANCE_M = 0.2
"""Spawn points and scan poses keep at least this distance from every wall and obstacle (m)."""

CIRCLE_COMMAND = (0.3, 0.5)
"""Command while ticking (m/s, rad/s): a 0.6 m radius circle that stays clear of the maze."""

RTF_DURATION_S = 20.0
"""Simulated time of one real-time-factor run (s)."""

SCAN_EVERY_TICKS = 2
"""Scan every second 20 Hz tick: the LiDAR's 10 Hz."""

WARMUP_CALLS = 20
"""Untimed calls before each timing, so first-call costs do not count."""

FloatArray = npt.NDArray[np.float64]


@dataclasses.dataclass(frozen=True)
class Row:
    """One printed figure: a median, an optional p95, and the target it is compared with."""

    figure: str
    world: str
    median: str
    p95: str = ""
    target: str = ""


def random_walls_world(n_walls: int, rng: np.random.Generator) -> World:
    """``n_walls`` random walls inside the arena plus its enclosing box, spawn in free space."""
    half = ARENA_HALF_M
    walls: list[list[float]] = []
    while len(walls) < n_walls:
        x1, y1 = rng.uniform(-half, half, size=2)
        length = rng.uniform(*WALL_LENGTH_M)
        heading = rng.uniform(-math.pi, math.pi)
        x2, y2 = x1 + length * math.cos(heading), y1 + length * math.sin(heading)
        if abs(x2) <= half and abs(y2) <= half:  # keep both ends inside the arena
            walls.append([float(x1), float(y1), float(x2), float(y2)])
    box = [[-half, -half], [half, -half], [half, half], [-half, half]]
    world = world_from_dict({"name": f"random-{n_walls}", "walls": walls,
                             "polylines": [{"points": box, "closed": True}]},
                            source=f"<{n_walls} random walls>")
    candidates = free_points(world, 200, rng)
    spawn = candidates[np.argmin(np.hypot(candidates[:, 0], candidates[:, 1]))]
    return dataclasses.replace(world, start=Pose2D(float(spawn[0]), float(spawn[1]), 0.0))


def clearance_m(world: World, points: FloatArray) -> FloatArray:
    """Distance from each (x, y) row of ``points`` to the nearest wall or disc edge (m)."""
    ends = np.array([(w.x1, w.y1, w.x2, w.y2) for w in world.walls], dtype=float)
    a, edge = ends[:, :2], ends[:, 2:] - ends[:, :2]
    to_p = points[:, None, :] - a[None, :, :]
    s = np.clip((to_p * edge).sum(axis=2) / (edge * edge).sum(axis=1), 0.0, 1.0)
    nearest = np.linalg.norm(to_p - s[:, :, None] * edge, axis=2).min(axis=1)
    for c in world.circles:
        nearest = np.minimum(nearest, np.hypot(points[:, 0] - c.x, points[:, 1] - c.y)
                             - c.radius_m)
    return nearest  # type: ignore[no-any-return]


def free_points(world: World, count: int, rng: np.random.Generator) -> FloatArray:
    """``count`` uniform (x, y) points inside the world's bounds, CLEARANCE_M clear of walls."""
    min_x, min_y, max_x, max_y = world.bounds
    found = np.empty((0, 2))
    while len(found) < count:
        points = rng.uniform((min_x, min_y), (max_x, max_y), size=(4 * count, 2))
        found = np.vstack([found, points[clearance_m(world, points) >= CLEARANCE_M]])
    return found[:count]


def free_poses(world: World, count: int, rng: np.random.Generator) -> list[Pose2D]:
    """``count`` poses in free space with uniform random headings (map frame, m and rad)."""
    headings = rng.uniform(-math.pi, math.pi, size=count)
    return [Pose2D(float(x), float(y), float(theta))
            for (x, y), theta in zip(free_points(world, count, rng), headings, strict=True)]


def timed(call: Callable[[Pose2D], FloatArray], pose: Pose2D) -> tuple[float, FloatArray]:
    """Wall time of ``call(pose)`` in ms, and its result."""
    start = time.perf_counter()
    result = call(pose)
    return (time.perf_counter() - start) * 1e3, result


def p95(values: Sequence[float]) -> float:
    """The 95th percentile."""
    return statistics.quantiles(values, n=20)[-1]


def compare_paths(fast: FloatArray, reference: FloatArray) -> tuple[float, int]:
    """Largest |fast - reference| over beams both paths hit (m), and beams hit by only one."""
    one_sided = int(np.count_nonzero(np.isinf(fast) != np.isinf(reference)))
    both = np.isfinite(fast) & np.isfinite(reference)
    return float(np.abs(fast[both] - reference[both]).max(initial=0.0)), one_sided


def bench_scans(world: World, n_poses: int, target_ms: str,
                rng: np.random.Generator) -> list[Row]:
    """Time both scan paths over the same poses and compare their ranges."""
    lidar = Simulation(world, seed=SEED).lidar
    poses = free_poses(world, n_poses, rng)
    for pose in poses[:WARMUP_CALLS]:
        lidar.raw_ranges(pose)
        lidar.raw_ranges_reference(pose)
    fast, reference, compared = [], [], []
    for pose in poses:  # alternate the two paths, so a slow spell of the machine hits both
        fast_ms, fast_ranges = timed(lidar.raw_ranges, pose)
        reference_ms, reference_ranges = timed(lidar.raw_ranges_reference, pose)
        fast.append(fast_ms)
        reference.append(reference_ms)
        compared.append(compare_paths(fast_ranges, reference_ranges))
    difference = f"{max(d for d, _ in compared):.1e}"
    one_sided = sum(n for _, n in compared)
    if one_sided:
        difference += f", {one_sided} beams hit in one path only"
    name = f"{world.name} ({len(world.walls)} segments"
    name += f", {len(world.circles)} circle(s))" if world.circles else ")"
    return [
        Row("scan, raw_ranges (ms)", name, f"{statistics.median(fast):.3f}",
            f"{p95(fast):.3f}", target_ms),
        Row("scan, raw_ranges_reference (ms)", name, f"{statistics.median(reference):.3f}",
            f"{p95(reference):.3f}"),
        Row("scan, max |fast - reference| (m)", name, difference, "", "<= 1e-9"),
    ]


def bench_ticks(world: World, mode: str, n_ticks: int) -> Row:
    """Median wall time of one ``Simulation.step()`` while driving a circle."""
    sim = Simulation(world, mode=mode, seed=SEED)
    sim.command(*CIRCLE_COMMAND)
    sim.step(WARMUP_CALLS)
    times = []
    for _ in range(n_ticks):
        start = time.perf_counter()
        sim.step()
        times.append(time.perf_counter() - start)
    micros = [t * 1e6 for t in times]
    return Row(f"tick, {mode} (us)", world.name, f"{statistics.median(micros):.1f}",
               f"{p95(micros):.1f}")


def bench_rtf(world: World, mode: str, runs: int, target: str) -> Row:
    """Real-time factor of a headless circle drive: odometry every tick, a scan every second."""
    n_ticks = round(RTF_DURATION_S / TICK_PERIOD_S)
    factors = []
    for _ in range(runs):
        sim = Simulation(world, mode=mode, seed=SEED)
        sim.command(*CIRCLE_COMMAND)
        start = time.perf_counter()
        for tick in range(n_ticks):
            sim.step()
            sim.odometry()
            if tick % SCAN_EVERY_TICKS == 0:
                sim.scan()
        factors.append(sim.time_s / (time.perf_counter() - start))
    label = f"RTF, {mode}, {RTF_DURATION_S:g} s, {runs} runs"
    return Row(label, world.name, f"{statistics.median(factors):.0f}",
               f"min {min(factors):.0f}", target)


HEADER = ("figure", "world", "median", "p95", "target")


def plain_table(rows: Sequence[Row]) -> str:
    """Rows as an aligned text table: labels left-aligned, figures right-aligned."""
    lines = [HEADER, *(dataclasses.astuple(row) for row in rows)]
    widths = [max(len(line[i]) for line in lines) for i in range(len(HEADER))]
    text = []
    for figure, world, median, high, target in lines:
        text.append(f"{figure:<{widths[0]}}  {world:<{widths[1]}}  {median:>{widths[2]}}  "
                    f"{high:>{widths[3]}}  {target}".rstrip())
    return "\n".join(text)


def markdown_table(rows: Sequence[Row]) -> str:
    """Rows as a Markdown table."""
    lines = ["| " + " | ".join(HEADER) + " |", "|---|---|--:|--:|---|"]
    for row in rows:
        cells = (cell.replace("|", "\\|") for cell in dataclasses.astuple(row))
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines)


def main(argv: Sequence[str] | None = None) -> int:
    """Run every benchmark and print one table; returns the exit status."""
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    parser.add_argument("--markdown", action="store_true", help="print a Markdown table")
    args = parser.parse_args(argv)
    n_poses, n_ticks, rtf_runs = (100, 400, 2) if args.quick else (1000, 4000, 10)

    rng = np.random.default_rng(SEED)
    maze = load_world("maze")
    rows = bench_scans(maze, n_poses, "<= 0.2", rng)
    rows += bench_scans(random_walls_world(100, rng), n_poses, "", rng)
    rows += bench_scans(random_walls_world(500, rng), n_poses, "<= 0.5", rng)
    rows += [bench_ticks(maze, "kinematic", n_ticks), bench_ticks(maze, "dynamic", n_ticks)]
    rows += [bench_rtf(maze, "kinematic", rtf_runs, ">= 500"),
             bench_rtf(maze, "dynamic", rtf_runs, "")]

    print(f"websim physics benchmark{' (quick)' if args.quick else ''}: "
          f"{n_poses} scan poses, {n_ticks} ticks, {rtf_runs} RTF runs per figure")
    print(f"Python {platform.python_version()}, numpy {np.__version__}, "
          f"pymunk {version('pymunk')}, {platform.platform()}; the LiDAR cast: "
          f"{raycast_kernel.chosen()} ({raycast_kernel.RAYCAST_ENV})\n")
    print(markdown_table(rows) if args.markdown else plain_table(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
