"""A 360-ray 2D LiDAR cast against the world with pymunk.

Two paths compute the same ranges:

* ``Lidar.raw_ranges_reference`` asks pymunk once per ray (``Space.segment_query_first``): simple
  and obviously right, about ten times slower (``benchmarks/bench_physics.py``).
* ``Lidar.raw_ranges`` asks pymunk's spatial index once for the shapes within range_max
  (``Space.bb_query``) and intersects every ray with those shapes at once with numpy. Tests hold
  it equal to the reference to 1e-9 m.

The static shapes are the world's arrays (``physics.geometry.WorldShapes``). Other robots are
discs at this tick's poses (``discs``: one row ``(x, y, radius)`` each, never the scanning
robot's own footprint); the reference sees them as their pymunk bodies (``seen_by``).

What a beam reports:

* a hit at ``range_min <= d``: ``d`` (plus Gaussian noise when ``scan_sigma_m > 0``);
* nothing within ``range_max``: ``range_max`` as the course platform does, or ``+inf`` with
  ``no_return: inf`` (REP 117);
* a hit closer than ``range_min`` (too close to measure): ``0.0``, or ``-inf`` with
  ``no_return: inf`` (REP 117). ``0.0`` is below ``range_min``, so every LaserScan consumer that
  follows the message's rules discards it, the JSON stays finite, and a naive "min of ranges"
  obstacle check errs on the safe side.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np
import numpy.typing as npt
import pymunk

from physics.geometry import WorldShapes
from physics.params import LidarParams
from physics.snapshots import LaserScan, Pose2D
from physics.space import WALLS_ONLY, WorldSpace

FloatArray = npt.NDArray[np.float64]

PARALLEL_EPS = 1e-12
"""|ray x wall| below this counts as parallel: pymunk reports no hit for a zero-thickness wall
seen edge-on, and so does the fast path."""

CULL_ABOVE_SHAPES = 32
"""Worlds of more shapes than this are culled to those within range_max (pymunk's spatial
index); in smaller ones, asking the index costs more than intersecting every shape."""

TOO_CLOSE_COURSE_M = 0.0
"""Reported for a hit closer than range_min unless REP 117 values are asked for."""


NO_DISCS: FloatArray = np.empty((0, 3))
"""No other robot: ``discs`` of a robot alone in its world."""


class Lidar:
    """Casts the beams of one LiDAR against one world.

    Args:
        params: beam layout, limits and mounting.
        world_space: the world's shapes in pymunk (its index culls large worlds; the reference
            path queries it).
        shapes: the same shapes as arrays (``physics.geometry.world_shapes`` of the world).
    """

    def __init__(self, params: LidarParams, world_space: WorldSpace,
                 shapes: WorldShapes) -> None:
        self._params = params
        self._world_space = world_space
        beam_angles_rad = params.angle_min_rad + np.arange(
            params.num_rays, dtype=np.float64) * params.angle_increment_rad
        self._beam_cos: FloatArray = np.cos(beam_angles_rad)
        self._beam_sin: FloatArray = np.sin(beam_angles_rad)
        """Each beam's direction in the laser frame (angle_min + i * angle_increment)."""
        self._directions_theta = math.nan
        self._directions = (self._beam_cos, self._beam_sin)
        walls = world_space.wall_shapes
        self._wall_index: dict[pymunk.Shape, int] = {s: i for i, s in enumerate(walls)}
        self._wall_a = shapes.wall_a
        self._wall_b = shapes.wall_b
        circles = world_space.circle_shapes
        self._circle_index: dict[pymunk.Shape, int] = {s: i for i, s in enumerate(circles)}
        self._circle_centre = shapes.circle_centre
        self._circle_radius = shapes.circle_radius
        self._all_walls = np.arange(len(walls), dtype=np.intp)
        self._all_circles = np.arange(len(circles), dtype=np.intp)
        self._edge = self._wall_b - self._wall_a
        a, b, e = self._wall_a, self._wall_b, self._edge
        self._fixed_rows = np.concatenate([np.stack((e[:, 1], -e[:, 0]), axis=1),
                                           np.stack((a[:, 1], -a[:, 0]), axis=1),
                                           np.stack((b[:, 1], -b[:, 0]), axis=1)])
        """Per wall: (e_y, -e_x), then (a_y, -a_x), then (b_y, -b_x)."""
        self._row_moves = np.concatenate([np.zeros((len(walls), 1)),
                                          np.ones((2 * len(walls), 1))])
        """Which rows move with the laser (a - o and b - o do, e does not)."""
        self._a_cross_e = (a[:, 0] * e[:, 1] - a[:, 1] * e[:, 0])[:, None]
        self.geometry_key = (params, *shapes.key())
        """Equal for LiDARs that read the same ranges at the same pose (same beams, mount and
        world shapes): one's ``raw_ranges_many`` serves them all."""

    @property
    def params(self) -> LidarParams:
        """The LiDAR's parameters."""
        return self._params

    def laser_pose(self, robot_pose: Pose2D) -> Pose2D:
        """The laser frame's pose in the map frame for a robot pose in the map frame."""
        p = self._params
        cos_t, sin_t = math.cos(robot_pose.theta), math.sin(robot_pose.theta)
        return Pose2D(robot_pose.x + cos_t * p.mount_x_m - sin_t * p.mount_y_m,
                      robot_pose.y + sin_t * p.mount_x_m + cos_t * p.mount_y_m,
                      robot_pose.theta + p.mount_yaw_rad)

    def _world_directions(self, laser: Pose2D) -> tuple[FloatArray, FloatArray]:
        """Each beam's direction in the map frame: its laser-frame direction, rotated."""
        if laser.theta != self._directions_theta:
            cos_t, sin_t = math.cos(laser.theta), math.sin(laser.theta)
            self._directions = (cos_t * self._beam_cos - sin_t * self._beam_sin,
                                sin_t * self._beam_cos + cos_t * self._beam_sin)
            self._directions_theta = laser.theta
        return self._directions

    def raw_ranges_reference(self, robot_pose: Pose2D,
                             query_filter: pymunk.ShapeFilter = WALLS_ONLY) -> FloatArray:
        """Distance to the first shape along each beam, +inf if none within range_max (m).

        One pymunk segment query per beam: the reference the fast path must equal. With
        ``query_filter`` ``physics.space.seen_by(group)`` it sees the other robots' bodies
        too (where the world last placed them), never robot ``group``'s own.
        """
        laser = self.laser_pose(robot_pose)
        range_max = self._params.range_max_m
        dir_x, dir_y = self._world_directions(laser)
        ranges = np.full(self._params.num_rays, np.inf)
        query = self._world_space.space.segment_query_first
        for i in range(self._params.num_rays):
            end = (laser.x + range_max * dir_x[i], laser.y + range_max * dir_y[i])
            hit = query((laser.x, laser.y), end, 0.0, query_filter)
            if hit is not None:
                ranges[i] = hit.alpha * range_max
        return ranges

    def raw_ranges(self, robot_pose: Pose2D, discs: FloatArray = NO_DISCS) -> FloatArray:
        """Distance to the first shape along each beam, +inf if none within range_max (m).

        In a world of more than ``CULL_ABOVE_SHAPES`` shapes, culls them with pymunk's spatial
        index first; then intersects all beams with the remaining walls and circles in numpy,
        and with ``discs`` (the other robots: rows of x, y, radius).
        """
        laser = self.laser_pose(robot_pose)
        range_max = self._params.range_max_m
        dir_x, dir_y = self._world_directions(laser)
        walls, circles = self._shapes_within(laser, range_max)
        ranges: FloatArray | None = None
        if len(walls):
            ranges = self._hit_walls(laser, dir_x, dir_y, walls)
        if len(circles):
            hits = self._hit_circles(laser, dir_x, dir_y, self._circle_centre[circles],
                                     self._circle_radius[circles])
            ranges = hits if ranges is None else np.minimum(ranges, hits)
        if ranges is None:
            ranges = np.full(self._params.num_rays, np.inf)
        if len(discs):
            ranges = self.add_discs(ranges, robot_pose, discs)
        ranges[ranges > range_max] = np.inf
        return ranges

    def add_discs(self, raw_ranges_m: FloatArray, robot_pose: Pose2D,
                  discs: FloatArray) -> FloatArray:
        """``raw_ranges_m`` (of the static world, at ``robot_pose``) with ``discs`` seen too.

        Args:
            raw_ranges_m: the static world's ranges (m, +inf: nothing).
            robot_pose: the scanning robot's pose in the map frame.
            discs: the other robots' footprints, rows of (x, y, radius) (m).
        """
        laser = self.laser_pose(robot_pose)
        dir_x, dir_y = self._world_directions(laser)
        hits = self._hit_circles(laser, dir_x, dir_y, discs[:, :2], discs[:, 2])
        return np.minimum(raw_ranges_m, hits)

    def _shapes_within(self, laser: Pose2D,
                       range_max: float) -> tuple[npt.NDArray[np.intp], npt.NDArray[np.intp]]:
        """Indices of the walls and circles a beam may reach: all of them in a small world."""
        if len(self._wall_index) + len(self._circle_index) <= CULL_ABOVE_SHAPES:
            return self._all_walls, self._all_circles
        reach = pymunk.BB(laser.x - range_max, laser.y - range_max,
                          laser.x + range_max, laser.y + range_max)
        walls: list[int] = []
        circles: list[int] = []
        for shape in self._world_space.space.bb_query(reach, WALLS_ONLY):
            if shape in self._wall_index:
                walls.append(self._wall_index[shape])
            else:
                circles.append(self._circle_index[shape])
        return np.array(walls, dtype=np.intp), np.array(circles, dtype=np.intp)

    def _hit_walls(self, laser: Pose2D, dir_x: FloatArray, dir_y: FloatArray,
                   indices: npt.NDArray[np.intp]) -> FloatArray:
        """Ray-segment distances: ray o + t*d meets wall a..b at t >= 0, a and b either side.

        With e = b - a and w = a - o: t = (w x e) / (d x e); a and b lie either side of the
        ray (or on it) when d x w and d x (b - o) differ in sign. The three cross products over
        the beams come from one matrix product, whose rows are fixed per world but for the
        laser's position (``_rows``). A ray along its wall meets it nowhere (t = 0/0), as
        pymunk reports for a wall seen edge-on. Arrays are laid out wall by beam, so the
        nearest wall per beam is a fast reduction over rows.
        """
        rows, t_num = self._rows(laser, indices)
        count = len(indices)
        products = rows @ np.stack((dir_x, dir_y))
        denom = products[:count]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = t_num / denom
        missed = (products[count:2 * count] * products[2 * count:] > 0.0) | ~(t >= 0.0) | \
            (np.abs(denom) < PARALLEL_EPS)
        t[missed] = np.inf
        return t.min(axis=0)  # type: ignore[no-any-return]

    def _rows(self, laser: Pose2D,
              indices: npt.NDArray[np.intp]) -> tuple[FloatArray, FloatArray]:
        """The cross-product rows (e, a - o, b - o as (y, -x)) and w x e for these walls.

        For every wall of the world (no culling) both are a fixed part less the laser's
        position: two small operations per scan instead of building them.
        """
        if indices is self._all_walls:
            shift = np.array((laser.y, -laser.x))
            return (self._fixed_rows - self._row_moves * shift,
                    self._a_cross_e - (laser.x * self._edge[:, 1] - laser.y * self._edge[:, 0])
                    [:, None])
        a = self._wall_a[indices]
        edge = self._wall_b[indices] - a
        to_a = a - (laser.x, laser.y)
        to_b = self._wall_b[indices] - (laser.x, laser.y)
        rows = np.concatenate([np.stack((edge[:, 1], -edge[:, 0]), axis=1),
                               np.stack((to_a[:, 1], -to_a[:, 0]), axis=1),
                               np.stack((to_b[:, 1], -to_b[:, 0]), axis=1)])
        return rows, (to_a[:, 0] * edge[:, 1] - to_a[:, 1] * edge[:, 0])[:, None]

    @staticmethod
    def _hit_circles(laser: Pose2D, dir_x: FloatArray, dir_y: FloatArray,
                     centre: FloatArray, radius: FloatArray) -> FloatArray:
        """Ray-disc distances; a laser inside a disc reads 0, as pymunk reports it."""
        to_c_x = (centre[:, 0] - laser.x)[:, None]
        to_c_y = (centre[:, 1] - laser.y)[:, None]
        along = to_c_x * dir_x + to_c_y * dir_y
        outside = to_c_x**2 + to_c_y**2 - radius[:, None]**2
        disc = along**2 - outside
        t = along - np.sqrt(np.maximum(disc, 0.0))
        inside = outside <= 0.0
        t = np.where(inside, 0.0, t)
        valid = inside | ((disc >= 0.0) & (t >= 0.0))
        return np.where(valid, t, np.inf).min(axis=0)  # type: ignore[no-any-return]

    def finish(self, raw_ranges_m: FloatArray, rng: np.random.Generator | None,
               sigma_m: float) -> FloatArray:
        """Turn raw distances into reported ranges: noise, too-close and no-return values."""
        p = self._params
        ranges = raw_ranges_m.copy()
        hit = np.isfinite(ranges)
        if sigma_m > 0.0 and rng is not None:
            noisy = ranges + rng.normal(0.0, sigma_m, size=ranges.shape)
            ranges = np.where(hit, np.clip(noisy, 0.0, p.range_max_m), ranges)
        too_close = hit & (ranges < p.range_min_m)
        rep117 = p.no_return == "inf"
        ranges[too_close] = -np.inf if rep117 else TOO_CLOSE_COURSE_M
        ranges[~hit] = p.no_return_range_m
        return ranges  # type: ignore[no-any-return]

    def scan(self, robot_pose: Pose2D, rng: np.random.Generator | None = None,
             sigma_m: float = 0.0) -> LaserScan:
        """A full scan from the robot at ``robot_pose`` (map frame), as a ``LaserScan``."""
        return self.scan_from_raw(self.raw_ranges(robot_pose), rng, sigma_m)

    def scan_from_raw(self, raw_ranges_m: FloatArray, rng: np.random.Generator | None = None,
                      sigma_m: float = 0.0) -> LaserScan:
        """The ``LaserScan`` of raw distances (``raw_ranges``, or a row of ``raw_ranges_many``)."""
        p = self._params
        ranges = self.finish(raw_ranges_m, rng, sigma_m)
        return LaserScan(ranges=tuple(ranges.tolist()), angle_min=p.angle_min_rad,
                         angle_max=p.angle_max_rad, angle_increment=p.angle_increment_rad,
                         range_min=p.range_min_m, range_max=p.range_max_m,
                         scan_time=p.scan_time_s, time_increment=p.time_increment_s)

    def raw_ranges_many(self, robot_poses: Sequence[Pose2D]) -> FloatArray:
        """``raw_ranges`` at each of ``robot_poses``, one row each, computed together.

        The robots of a class in one world scan on the same tick: one set of array
        operations over robots x walls x beams instead of one per robot, where numpy's
        per-call cost, not the arithmetic, is most of the price (measured: about half the
        time per robot for ten robots). Worlds worth culling go one robot at a time.
        """
        if len(robot_poses) < 2 or \
                len(self._wall_index) + len(self._circle_index) > CULL_ABOVE_SHAPES:
            return np.stack([self.raw_ranges(pose) for pose in robot_poses])
        lasers = [self.laser_pose(pose) for pose in robot_poses]
        origin = np.array([(laser.x, laser.y) for laser in lasers])
        theta = np.array([laser.theta for laser in lasers])
        cos_t, sin_t = np.cos(theta)[:, None], np.sin(theta)[:, None]
        dir_x = cos_t * self._beam_cos - sin_t * self._beam_sin  # robots x beams
        dir_y = sin_t * self._beam_cos + cos_t * self._beam_sin
        if len(self._wall_a):
            ranges = self._hit_walls_many(origin, dir_x, dir_y)
        else:
            ranges = np.full(dir_x.shape, np.inf)
        if len(self._circle_radius):
            for row, laser in enumerate(lasers):
                ranges[row] = np.minimum(ranges[row], self._hit_circles(
                    laser, dir_x[row], dir_y[row], self._circle_centre, self._circle_radius))
        ranges[ranges > self._params.range_max_m] = np.inf
        return ranges

    def _hit_walls_many(self, origin: FloatArray, dir_x: FloatArray,
                        dir_y: FloatArray) -> FloatArray:
        """``_hit_walls`` of every wall for several lasers: robots x beams."""
        count = len(self._wall_a)
        shift = np.stack((origin[:, 1], -origin[:, 0]), axis=1)[:, None, :]
        rows = self._fixed_rows[None] - self._row_moves[None] * shift  # robots x 3W x 2
        products = rows @ np.stack((dir_x, dir_y), axis=1)  # robots x 3W x beams
        denom = products[:, :count]
        edge = self._edge
        t_num = (self._a_cross_e[None, :, 0] - (origin[:, :1] * edge[None, :, 1]
                                                 - origin[:, 1:] * edge[None, :, 0]))[..., None]
        with np.errstate(divide="ignore", invalid="ignore"):
            t = t_num / denom
        missed = (products[:, count:2 * count] * products[:, 2 * count:] > 0.0) | \
            ~(t >= 0.0) | (np.abs(denom) < PARALLEL_EPS)
        t[missed] = np.inf
        return t.min(axis=1)  # type: ignore[no-any-return]


@dataclass(frozen=True)
class ScanRequest:
    """One scan to cast: which LiDAR, from where, with which noise.

    Attributes:
        lidar: the LiDAR (its beams, limits and world).
        robot_pose: the robot's pose in the map frame (m, rad).
        rng: the noise stream of this scan (None: noiseless).
        sigma_m: the range noise's standard deviation (m).
        discs: the other robots of its world, rows of (x, y, radius) (m).
    """

    lidar: Lidar
    robot_pose: Pose2D
    rng: np.random.Generator | None = None
    sigma_m: float = 0.0
    discs: FloatArray = field(default_factory=lambda: NO_DISCS, compare=False)


def scan_many(requests: Sequence[ScanRequest]) -> list[LaserScan]:
    """The scan of every request, in order; requests of alike LiDARs are cast together.

    LiDARs of equal geometry (``Lidar.geometry_key``: the robots of a class in one world)
    have their rays intersected in one ``raw_ranges_many``; each request still adds its own
    noise from its own stream, so each scan is what ``Lidar.scan`` gives it alone (to
    rounding, ~1e-15 m).
    """
    alike: dict[Any, list[int]] = {}
    for index, request in enumerate(requests):
        alike.setdefault(request.lidar.geometry_key, []).append(index)
    scans: dict[int, LaserScan] = {}
    for indices in alike.values():
        raws = requests[indices[0]].lidar.raw_ranges_many(
            [requests[index].robot_pose for index in indices])
        for index, raw in zip(indices, raws, strict=True):
            request = requests[index]
            if len(request.discs):
                raw = request.lidar.add_discs(raw, request.robot_pose, request.discs)
                raw[raw > request.lidar.params.range_max_m] = np.inf
            scans[index] = request.lidar.scan_from_raw(raw, request.rng, request.sigma_m)
    return [scans[index] for index in range(len(requests))]
