"""A 2D LiDAR (360 rays by default) cast against the world and the other robots.

Two paths compute the same ranges:

* ``Lidar.raw_ranges_reference`` asks pymunk once per ray (``Space.segment_query_first``): simple
  and obviously right, and slow (``benchmarks/bench_physics.py``).
* the batched path (``physics.raycast.cast``): every laser of a tick together, each shape
  tried only on the beams whose directions it covers, in numpy. ``Lidar.raw_ranges`` is one
  laser of it; ``scan_many`` casts every scan of a tick at once, those of worlds of the same
  shapes together. Tests hold it equal to the reference to 1e-9 m, other robots included.

The static shapes are the world's arrays (``physics.geometry.WorldShapes``). Other robots are
discs at this tick's poses (a world's ``footprints``: one row ``(x, y, radius)`` each, the
scanning robot's own never seen); the reference sees them as their pymunk bodies
(``physics.space.seen_by``).

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

from physics import raycast, raycast_kernel
from physics.geometry import WorldShapes
from physics.params import LidarParams
from physics.raycast import cast, cast_one
from physics.snapshots import LaserScan, Pose2D
from physics.space import WALLS_ONLY, WorldSpace

FloatArray = npt.NDArray[np.float64]
IntArray = npt.NDArray[np.intp]

TOO_CLOSE_COURSE_M = 0.0
"""Reported for a hit closer than range_min unless REP 117 values are asked for."""

NO_DISCS: FloatArray = np.empty((0, 3))
"""No other robot: the footprints of a world without robots, rows of (x, y, radius)."""


class Lidar:
    """Casts the beams of one LiDAR against one world.

    Args:
        params: beam layout, limits and mounting.
        world_space: the world's shapes in pymunk (the reference path queries it).
        shapes: the same shapes as arrays (``physics.geometry.world_shapes`` of the world).
    """

    def __init__(self, params: LidarParams, world_space: WorldSpace,
                 shapes: WorldShapes) -> None:
        self._params = params
        self._world_space = world_space
        self._shapes = shapes
        raycast_kernel.kernel()  # the cast chosen (numba loaded) now, not on a first scan tick
        beam_angles_rad = params.angle_min_rad + np.arange(
            params.num_rays, dtype=np.float64) * params.angle_increment_rad
        self.beam_cos: FloatArray = np.cos(beam_angles_rad)
        self.beam_sin: FloatArray = np.sin(beam_angles_rad)
        """Each beam's direction in the laser frame (angle_min + i * angle_increment)."""
        self.geometry_key = (params, *shapes.key())
        """Equal for LiDARs that read the same ranges at the same pose (same beams, mount and
        world shapes): their scans are cast together (``scan_many``)."""

    @property
    def params(self) -> LidarParams:
        """The LiDAR's parameters."""
        return self._params

    @property
    def shapes(self) -> WorldShapes:
        """The world's static shapes it casts against."""
        return self._shapes

    def laser_pose(self, robot_pose: Pose2D) -> Pose2D:
        """The laser frame's pose in the map frame for a robot pose in the map frame."""
        p = self._params
        cos_t, sin_t = math.cos(robot_pose.theta), math.sin(robot_pose.theta)
        return Pose2D(robot_pose.x + cos_t * p.mount_x_m - sin_t * p.mount_y_m,
                      robot_pose.y + sin_t * p.mount_x_m + cos_t * p.mount_y_m,
                      robot_pose.theta + p.mount_yaw_rad)

    def raw_ranges_reference(self, robot_pose: Pose2D,
                             query_filter: pymunk.ShapeFilter = WALLS_ONLY) -> FloatArray:
        """Distance to the first shape along each beam, +inf if none within range_max (m).

        One pymunk segment query per beam: the reference the fast path must equal. With
        ``query_filter`` ``physics.space.seen_by(group)`` it sees the other robots' bodies
        too (where the world last placed them), never robot ``group``'s own.
        """
        laser = self.laser_pose(robot_pose)
        range_max = self._params.range_max_m
        cos_t, sin_t = math.cos(laser.theta), math.sin(laser.theta)
        dir_x = cos_t * self.beam_cos - sin_t * self.beam_sin
        dir_y = sin_t * self.beam_cos + cos_t * self.beam_sin
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

        The walls and obstacles, and ``discs`` (other robots: rows of x, y, radius). Few
        shapes (the maze): every beam on every shape in one product (``cast_one``); many, or
        with the compiled kernel (``physics.raycast_kernel``): ``raw_ranges_many``.
        """
        shapes = self._shapes
        if len(discs) or len(shapes.walls) + len(shapes.circle_radius) > raycast.DENSE_MAX_PAIRS \
                or raycast_kernel.kernel() is not None:
            ranges: FloatArray = self.raw_ranges_many([robot_pose], discs)[0]
            return ranges
        laser = self.laser_pose(robot_pose)
        return cast_one(laser.x, laser.y, laser.theta, self.beam_cos, self.beam_sin,
                        self._params.range_max_m, shapes.walls, shapes.circle_centre,
                        shapes.circle_radius)

    def raw_ranges_many(self, robot_poses: Sequence[Pose2D],
                        discs: FloatArray = NO_DISCS,
                        own: Sequence[int] | None = None) -> FloatArray:
        """``raw_ranges`` at each of ``robot_poses``, one row each, cast together.

        Args:
            robot_poses: the robots' poses (map frame).
            discs: more discs every laser sees (rows of x, y, radius): the robots.
            own: for each pose, the row of ``discs`` that is that robot's own footprint (never
                seen by it), or -1.
        """
        shapes = self._shapes
        centre, radius = shapes.circle_centre, shapes.circle_radius
        skip = None
        if len(discs):
            centre = np.concatenate([centre, discs[:, :2]])
            radius = np.concatenate([radius, discs[:, 2]])
            if own is not None:
                skip = np.array([index + len(shapes.circle_radius) if index >= 0 else -1
                                 for index in own], dtype=np.intp)
        origins, headings = self._lasers(robot_poses)
        p = self._params
        return cast(origins, headings, self.beam_cos, self.beam_sin, p.angle_min_rad,
                    p.angle_increment_rad, p.range_max_m, shapes.walls, centre, radius, skip)

    def _lasers(self, robot_poses: Sequence[Pose2D]) -> tuple[FloatArray, FloatArray]:
        """The lasers' positions (S, 2) and yaws (S,) in the map frame."""
        lasers = [self.laser_pose(pose) for pose in robot_poses]
        return (np.array([(laser.x, laser.y) for laser in lasers],
                         dtype=np.float64).reshape(-1, 2),
                np.array([laser.theta for laser in lasers], dtype=np.float64))

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
        ranges[too_close] = -np.inf if p.no_return == "inf" else TOO_CLOSE_COURSE_M
        ranges[~hit] = p.no_return_range_m
        return ranges  # type: ignore[no-any-return]

    def finish_many(self, raw_ranges_m: FloatArray,
                    rngs: Sequence[np.random.Generator | None],
                    sigmas_m: Sequence[float]) -> FloatArray:
        """``finish`` of each row of ``raw_ranges_m``, each with its own noise stream."""
        p = self._params
        ranges = raw_ranges_m.copy()
        hit = np.isfinite(ranges)
        for row, (rng, sigma_m) in enumerate(zip(rngs, sigmas_m, strict=True)):
            if sigma_m > 0.0 and rng is not None:
                noisy = ranges[row] + rng.normal(0.0, sigma_m, size=ranges.shape[1])
                ranges[row] = np.where(hit[row], np.clip(noisy, 0.0, p.range_max_m),
                                       ranges[row])
        too_close = hit & (ranges < p.range_min_m)
        ranges[too_close] = -np.inf if p.no_return == "inf" else TOO_CLOSE_COURSE_M
        ranges[~hit] = p.no_return_range_m
        return ranges  # type: ignore[no-any-return]

    def scans_from_raw(self, raw_ranges_m: FloatArray,
                       rngs: Sequence[np.random.Generator | None],
                       sigmas_m: Sequence[float]) -> list[LaserScan]:
        """The ``LaserScan`` of each row of raw distances, each with its own noise."""
        p = self._params
        fields = (p.angle_min_rad, p.angle_max_rad, p.angle_increment_rad, p.range_min_m,
                  p.range_max_m, p.scan_time_s, p.time_increment_s)
        return [LaserScan(tuple(row), *fields)
                for row in self.finish_many(raw_ranges_m, rngs, sigmas_m).tolist()]

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

@dataclass(frozen=True)
class ScanRequest:
    """One scan to cast: which LiDAR, from where, with which noise, among which robots.

    Attributes:
        lidar: the LiDAR (its beams, limits and world).
        robot_pose: the robot's pose in the map frame (m, rad).
        rng: the noise stream of this scan (None: noiseless).
        sigma_m: the range noise's standard deviation (m).
        discs: every robot of its world (``WorldSim.footprints``: rows of x, y, radius, m),
            one array shared by the requests of one world.
        own: the row of ``discs`` that is this robot's own footprint (never seen), or -1.
    """

    lidar: Lidar
    robot_pose: Pose2D
    rng: np.random.Generator | None = None
    sigma_m: float = 0.0
    discs: FloatArray = field(default_factory=lambda: NO_DISCS, compare=False)
    own: int = -1


def scan_many(requests: Sequence[ScanRequest]) -> list[LaserScan]:
    """The scan of every request, in order, cast together.

    Requests of LiDARs of equal geometry (``Lidar.geometry_key``: the robots of one world, or
    of a class's copies of one world) are cast in one ``physics.raycast.cast``; each sees the
    robots of its own world (its ``discs``, its own footprint aside) and adds its own noise
    from its own stream, so each scan is what ``Lidar.scan`` gives it alone (to rounding,
    ~1e-15 m).
    """
    if len(requests) == 1:  # a robot's own scan (its world's others among its discs)
        request = requests[0]
        lidar = request.lidar
        if len(request.discs):
            raws = lidar.raw_ranges_many([request.robot_pose], request.discs, [request.own])
        else:
            raws = lidar.raw_ranges(request.robot_pose)[None]
        return lidar.scans_from_raw(raws, [request.rng], [request.sigma_m])
    alike: dict[Any, list[int]] = {}
    for index, request in enumerate(requests):
        alike.setdefault(request.lidar.geometry_key, []).append(index)
    scans: dict[int, LaserScan] = {}
    for indices in alike.values():
        lidar = requests[indices[0]].lidar
        group = [requests[index] for index in indices]
        raws = _cast_alike(lidar, group)
        made = lidar.scans_from_raw(raws, [request.rng for request in group],
                                    [request.sigma_m for request in group])
        for index, scan in zip(indices, made, strict=True):
            scans[index] = scan
    return [scans[index] for index in range(len(requests))]


def _cast_alike(lidar: Lidar, requests: Sequence[ScanRequest]) -> FloatArray:
    """The raw ranges of requests of one geometry: one cast, each world's robots its own."""
    worlds: dict[int, tuple[int, FloatArray]] = {}
    for request in requests:  # each world's footprints once, in order of first use
        if len(request.discs) and id(request.discs) not in worlds:
            offset = sum(len(discs) for _, discs in worlds.values())
            worlds[id(request.discs)] = (offset, request.discs)
    if not worlds:
        return lidar.raw_ranges_many([request.robot_pose for request in requests])
    if len(worlds) == 1:  # one world (an arena): every robot sees every other
        (_, discs), = worlds.values()
        return lidar.raw_ranges_many([request.robot_pose for request in requests], discs,
                                     [request.own for request in requests])
    # Several worlds of the same shapes (a class): one cast of the walls for all, then each
    # world's robots among its own lasers.
    raws = lidar.raw_ranges_many([request.robot_pose for request in requests])
    for key, (_, discs) in worlds.items():
        rows = [row for row, request in enumerate(requests) if id(request.discs) == key]
        others = [requests[row].own for row in rows]
        if len(discs) <= 1 and all(index == 0 for index in others):
            continue  # a world of one robot: nothing else to see
        with_robots = lidar.raw_ranges_many([requests[row].robot_pose for row in rows], discs,
                                            others)
        raws[rows] = np.minimum(raws[rows], with_robots)
    return raws
