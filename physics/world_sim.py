"""A world and the robots in it: the unit of simulation. Robots are rows, stepped together.

Example::

    from physics import load_world
    from physics.world_sim import WorldSim
    world = WorldSim(load_world("maze"), seed=0)
    world.spawn("alice", Pose2D(0.0, 0.0, 0.0))
    world.spawn("bob")                       # the nearest free pose to the world's start
    world.command("alice", 0.3, 0.0)
    world.step()                             # one tick of every robot
    scans = world.cast_scans()               # one pass: each sees the others, never itself
    alice = Simulation.of(world, "alice")    # one robot's view: a single robot's API

A world holds one definition of its static shapes (``physics.geometry.WorldShapes`` for numpy,
``physics.space.WorldSpace`` for pymunk) and its robots in spawn order. ``step`` advances all
of them by one tick: each one's command through its motor driver
(``physics.command_pipeline``: lag, scales, ramps), then the kinematic robots first, each in
turn stopping at contact with a wall or with another robot where that one stands now (so no
two footprints ever overlap), then the dynamic robots together in pymunk (one space, one
``Space.step`` per substep: contacts between bodies are pymunk's). What every robot needs at
once is an array (``poses``, ``footprints``: one row per robot, spawn order); what one robot
integrates (odometry, wheels, its noise streams) stays its own. ``Simulation``
(``physics.simulation``) is one robot's view of its world, with the API a single robot always
had.

The world counts its ticks (``tick``): the one tick counter. A robot's own time (its ``tick``
and ``time_s``, what its sensors' rates and its odometry count) starts at its spawn or its last
reset: the world's tick minus the tick it (re)started at. ``paused`` is for whoever drives the
ticks (``ros_nodes.tick_driver``): a paused world is not stepped by it, but ``step`` always
steps (what ``StepSimulation`` asks of a paused simulation).
"""

from __future__ import annotations

import dataclasses
import difflib
import math
import zlib
from collections.abc import Collection, Iterator, Sequence
from typing import Any

import numpy as np
import numpy.typing as npt
import pymunk

from physics.command_pipeline import AT_REST, drive
from physics.frames import map_to_odom
from physics.geometry import WorldShapes, world_shapes
from physics.kinematics import clamp_command
from physics.lidar import Lidar, ScanRequest, scan_many
from physics.odometry import OdometryIntegrator
from physics.params import LidarParams, NoiseParams, RobotParams
from physics.robot import MODES, Disc, MobileRobotPhysics, dynamic_substeps
from physics.snapshots import Command, LaserScan, Odometry, Pose2D, RobotState, WheelState
from physics.space import WALLS_ONLY, WorldSpace, build_world_space, seen_by
from physics.validation import ConfigError, as_finite_float
from physics.wheels import WheelEncoders
from physics.world import World

FloatArray = npt.NDArray[np.float64]

TICK_PERIOD_S = 0.05
"""One tick of the course's virtual_robot node: 20 Hz."""

RUNTIME_PARAMS = tuple(item.name for item in dataclasses.fields(RobotParams))
"""Robot parameters that ``update_params`` may change between ticks."""

FREE_POSE_STEP_M = 0.05
"""Spacing of the candidates ``free_pose_near`` tries, ring by ring around the wanted pose."""

REACH_SLACK_M = 1e-6
"""Added to how far two robots can come in a tick before their contact is even looked at."""


class RobotSeed:
    """A robot's noise streams' seed when it is given none: from its world's seed and its name.

    An int seed (as ``Simulation(seed=...)`` always took) is used as it is; a robot spawned
    without one gets ``RobotSeed.of``, so the same world seed gives the same run.
    """

    @staticmethod
    def of(world_seed: int | None, name: str) -> np.random.SeedSequence:
        """The seed sequence of robot ``name`` in a world seeded ``world_seed``."""
        return np.random.SeedSequence(world_seed, spawn_key=(zlib.crc32(name.encode()),))


class _Robot:
    """One robot of a world: its model, LiDAR, integrators, noise streams and command."""

    def __init__(self, name: str, group: int, model: MobileRobotPhysics, lidar: Lidar,
                 noise: NoiseParams, spawn: Pose2D,
                 seed: int | np.random.SeedSequence | None, tick: int) -> None:
        self.name = name
        self.group = group
        self.model = model
        self.lidar = lidar
        self.noise = noise
        self.spawn = spawn
        self.seed = seed
        self.odometry = OdometryIntegrator()
        self.wheels = WheelEncoders()
        self.command = Command(0.0, 0.0)
        self.drive = AT_REST
        """The motor driver's memory (``physics.command_pipeline``)."""
        self.wheels_command = Command(0.0, 0.0)
        """What the driver gives the wheels this tick."""
        self.start_tick = tick
        self.scan_cache: tuple[int, LaserScan] | None = None
        self.episode = 0
        self.odom_rng = np.random.default_rng()
        self.scan_seed = np.random.SeedSequence()
        self.seed_noise(seed)

    def seed_noise(self, seed: int | np.random.SeedSequence | None) -> None:
        """Give each noise source its own stream, so reading one never shifts another."""
        sequence = seed if isinstance(seed, np.random.SeedSequence) else \
            np.random.SeedSequence(seed)
        odom_seed, self.scan_seed = sequence.spawn(2)
        self.odom_rng = np.random.default_rng(odom_seed)
        self.episode = 0

    def draw_noise(self, sigma: float) -> float:
        return float(self.odom_rng.normal(0.0, sigma)) if sigma > 0.0 else 0.0


class WorldSim:
    """A world and its robots, advanced together in fixed ticks of ``dt_s``.

    Args:
        world: the world (its walls and obstacles; ``start``: where a robot given no pose
            goes, or the nearest free pose to it).
        dt_s: tick length (s).
        seed: the world's seed: a robot spawned without a seed of its own gets one derived
            from it and its name (``RobotSeed``), so the same seed gives the same run.
        lidar: the LiDAR of a robot spawned without one (default: the shipped parameters).
        noise: the noise of a robot spawned without its own (default: noiseless).

    Attributes:
        paused: whether whoever drives the ticks leaves it alone (``step`` still steps).
    """

    def __init__(self, world: World, *, dt_s: float = TICK_PERIOD_S, seed: int | None = None,
                 lidar: LidarParams | None = None, noise: NoiseParams | None = None) -> None:
        self._world = world
        self._dt_s = as_finite_float("dt_s", dt_s)
        self._seed = seed
        self._lidar_params = LidarParams() if lidar is None else lidar
        self._noise = NoiseParams() if noise is None else noise
        self._shapes = world_shapes(world)
        self._space = build_world_space(world)
        self._robots: dict[str, _Robot] = {}
        self._next_group = 1
        self._tick = 0
        self._version = 0
        """Moves on whenever a robot moves, appears or goes: what scans are cached against."""
        self._footprints: tuple[int, FloatArray] | None = None
        self._indices: dict[str, int] = {}
        self._bodies_placed = -1
        self.paused = False

    # ---- the world ------------------------------------------------------------------------

    @property
    def world(self) -> World:
        """The world's description (walls, obstacles, start)."""
        return self._world

    @property
    def shapes(self) -> WorldShapes:
        """Its static shapes as arrays (the one definition; ``physics.geometry``)."""
        return self._shapes

    @property
    def space(self) -> WorldSpace:
        """Its pymunk space: the static shapes and every robot's body."""
        return self._space

    @property
    def dt_s(self) -> float:
        """Tick length (s)."""
        return self._dt_s

    @property
    def seed(self) -> int | None:
        """The world's seed (None: fresh entropy)."""
        return self._seed

    @property
    def tick(self) -> int:
        """Ticks the world has run since it began or was reset: the one tick counter."""
        return self._tick

    @property
    def time_s(self) -> float:
        """The world's simulated time (s): ``tick * dt_s``."""
        return self._tick * self._dt_s

    @property
    def names(self) -> tuple[str, ...]:
        """The robots' names, in spawn order."""
        return tuple(self._robots)

    def __len__(self) -> int:
        return len(self._robots)

    def __contains__(self, name: object) -> bool:
        return name in self._robots

    def __iter__(self) -> Iterator[str]:
        return iter(tuple(self._robots))

    def _row(self, name: str) -> _Robot:
        try:
            return self._robots[name]
        except KeyError:
            known = ", ".join(self._robots) or "none"
            raise KeyError(f"no robot '{name}' in world '{self._world.name}' "
                           f"(robots: {known})") from None

    # ---- robots in and out ------------------------------------------------------------------

    def spawn(self, name: str, pose: Pose2D | None = None, params: RobotParams | None = None,
              *, mode: str = "kinematic", lidar: LidarParams | None = None,
              noise: NoiseParams | None = None,
              seed: int | np.random.SeedSequence | None = None) -> Pose2D:
        """Add robot ``name`` at ``pose`` (map frame), at rest; the pose it got.

        Args:
            name: its name, unique in the world.
            pose: where; None: the world's start, or the nearest free pose to it (clear of
                the starts the world file keeps for the robots it places: ``World.robots``).
            params: the robot (default: the Pi 4B robot).
            mode: ``"kinematic"`` or ``"dynamic"``.
            lidar: its LiDAR (default: the world's).
            noise: its noise sigmas (default: the world's).
            seed: its noise streams' seed (default: ``RobotSeed.of(world seed, name)``).

        Returns:
            Where it stands: its spawn pose, where ``reset_robot`` puts it back. Its view,
            with a single robot's API, is ``physics.simulation.Simulation.of(world, name)``.

        Raises:
            ConfigError: the name is taken, the mode unknown, or the footprint at ``pose``
                overlaps a wall, an obstacle or another robot; nothing is added.
        """
        if not isinstance(name, str) or not name:
            raise ConfigError(f"a robot's name must be non-empty text, got {name!r}")
        if name in self._robots:
            raise ConfigError(f"a robot named '{name}' is in world '{self._world.name}' "
                              "already")
        if mode not in MODES:
            raise ConfigError(f"mode must be one of {', '.join(MODES)}, got {mode!r}")
        params = RobotParams() if params is None else params
        if pose is None:  # clear of the places the world keeps for robots not here yet
            pose = self._free_pose(self._world.start, params.footprint_radius_m, (),
                                   self._kept_places(name))
        pose = Pose2D(*(as_finite_float(f"{name}: pose", value) for value in pose))
        self._check_clear(pose.x, pose.y, params.footprint_radius_m, None,
                          f"{self._world.source}: {name}", f"spawn pose {list(pose)}")
        group = self._next_group
        self._next_group += 1
        model = MobileRobotPhysics(params, self._space, pose, mode, group=group)
        row = _Robot(name, group, model,
                     Lidar(self._lidar_params if lidar is None else lidar, self._space,
                           self._shapes),
                     self._noise if noise is None else noise, pose,
                     RobotSeed.of(self._seed, name) if seed is None else seed, self._tick)
        self._robots[name] = row
        self._indices = {}
        self._moved()
        return pose

    def delete(self, name: str) -> None:
        """Take robot ``name`` out of the world (KeyError: no such robot)."""
        row = self._row(name)
        row.model.remove()
        del self._robots[name]
        self._indices = {}
        self._moved()

    def spawn_pose(self, name: str) -> Pose2D:
        """Where robot ``name`` spawned: where ``reset_robot`` puts it back when free."""
        return self._row(name).spawn

    # ---- commanding and moving ------------------------------------------------------------

    def command(self, name: str, linear_mps: float, angular_rps: float) -> Command:
        """Robot ``name``'s velocity command (a ``/cmd_vel``), clamped to its limits.

        Raises:
            ConfigError: a value is not a finite number; the command in force is unchanged.
        """
        row = self._row(name)
        linear = as_finite_float("linear_mps", linear_mps)
        angular = as_finite_float("angular_rps", angular_rps)
        params = row.model.params
        row.command = clamp_command(linear, angular, params.max_linear_mps,
                                    params.max_angular_rps)
        return row.command

    def teleport(self, name: str, pose: Pose2D) -> None:
        """Put robot ``name`` at ``pose`` (map frame), at rest, its odometry left as it is.

        What a simulator's "set entity state" does: the robot is moved, its wheels did not
        turn, so its odometry does not see it (map -> odom changes instead).

        Raises:
            ConfigError: the footprint there overlaps a wall, an obstacle or another robot,
                or a value is not finite; nothing is changed.
        """
        row = self._row(name)
        pose = Pose2D(*(as_finite_float("pose", value) for value in pose))
        self._check_clear(pose.x, pose.y, row.model.params.footprint_radius_m, row,
                          f"teleport {name}", f"{list(pose)}")
        row.model.teleport(pose)
        row.command = Command(0.0, 0.0)
        row.drive = AT_REST
        self._moved()

    def place(self, name: str, pose: Pose2D, odometry: Pose2D) -> None:
        """Put robot ``name`` at rest at ``pose`` with its odometry reading ``odometry``.

        What a class restores after a restart; a pose whose footprint overlaps a wall,
        an obstacle or another robot is refused (ConfigError) and nothing is changed.
        """
        row = self._row(name)
        pose = Pose2D(*(as_finite_float("pose", value) for value in pose))
        self._check_clear(pose.x, pose.y, row.model.params.footprint_radius_m, row,
                          "restored pose", f"{list(pose)}")
        row.model.teleport(pose)
        row.odometry.place(odometry)
        row.wheels.reset()
        row.command = Command(0.0, 0.0)
        row.drive = AT_REST
        self._moved()

    def reset_robot(self, name: str, *, seed: int | None = None) -> Pose2D:
        """Robot ``name`` back to its spawn pose, at rest, odometry zeroed; the pose it got.

        The nearest free pose if another robot stands on the spawn pose; its wheels zeroed and
        its time back to 0. Parameters and mode stay. ``seed`` restarts its noise streams as
        if it had been spawned with it; without it, its noise goes on with fresh values.
        """
        return self._reset_row(self._row(name), seed, ())

    def _reset_row(self, row: _Robot, seed: int | np.random.SeedSequence | None,
                   away: Collection[_Robot]) -> Pose2D:
        """``reset_robot`` of ``row``, the robots of ``away`` not standing anywhere yet."""
        if seed is not None:
            row.seed = seed
            row.seed_noise(seed)
        else:
            row.episode += 1
        radius = row.model.params.footprint_radius_m
        pose = row.spawn
        skip = {row, *away}
        if self._blocked(pose.x, pose.y, radius, skip) is not None:
            pose = self._free_pose(pose, radius, skip)
        row.model.teleport(pose)
        row.odometry.reset()
        row.wheels.reset()
        row.command = Command(0.0, 0.0)
        row.drive = AT_REST
        row.start_tick = self._tick
        row.scan_cache = None
        self._moved()
        return pose

    def reset(self, *, seed: int | None = None) -> None:
        """Every robot back to its spawn (``reset_robot``, in spawn order), the time to 0.

        ``seed`` reseeds the world, and every robot's noise streams from it
        (``RobotSeed.of(seed, name)``), as if they had been spawned in a world of that seed.
        """
        if seed is not None:
            self._seed = seed
        self._tick = 0
        rows = list(self._robots.values())
        for index, row in enumerate(rows):  # each placed as if the later ones were not there
            self._reset_row(row, None if seed is None else RobotSeed.of(seed, row.name),
                            rows[index + 1:])

    def hold(self, name: str, held: bool = True) -> None:
        """Hold robot ``name`` where it stands (``held`` True) or let it go on.

        A held robot is not stepped and its time stands still, while the world and the other
        robots go on: to them it is an obstacle that does not yield. What a paused robot of a
        shared world is (a world of one whose robot is paused is simply not stepped).
        """
        self._row(name).model.hold(held)
        self._moved()

    def is_held(self, name: str) -> bool:
        """Whether robot ``name`` is held (``hold``)."""
        return self._row(name).model.held

    def set_mode(self, name: str, mode: str) -> None:
        """Switch robot ``name``'s model between ticks; pose and velocity are carried over."""
        self._row(name).model.mode = mode

    def update_params(self, name: str, **changes: Any) -> RobotParams:
        """Change robot ``name``'s parameters now (``RUNTIME_PARAMS``); those in force.

        Raises:
            ConfigError: an unknown name or an invalid value, or a footprint that would
                overlap a wall, an obstacle or another robot; nothing is changed.
        """
        row = self._row(name)
        for key in changes:
            if key not in RUNTIME_PARAMS:
                close = difflib.get_close_matches(key, RUNTIME_PARAMS, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise ConfigError(f"{key}: unknown robot parameter{hint}")
        params = dataclasses.replace(row.model.params, **changes)
        if params.footprint_radius_m != row.model.params.footprint_radius_m:
            pose = row.model.pose
            self._check_clear(pose.x, pose.y, params.footprint_radius_m, row,
                              "footprint_radius_m",
                              f"{params.footprint_radius_m!r} at the robot's current position")
        row.model.set_params(params)
        row.command = clamp_command(*row.command, params.max_linear_mps,
                                    params.max_angular_rps)
        self._moved()
        return params

    # ---- stepping ------------------------------------------------------------------------

    def step(self, n: int = 1) -> None:
        """Advance every robot ``n`` ticks of ``dt_s`` (paused or not)."""
        for _ in range(n):
            self._step_once()

    def _step_once(self) -> None:
        if len(self._robots) == 1:
            self._step_alone(next(iter(self._robots.values())))
            return
        everyone = list(self._robots.values())
        rows = [row for row in everyone if not row.model.held]
        for row in everyone:
            if row.model.held:
                row.start_tick += 1  # its time stands still
        dt_s = self._dt_s
        samples: dict[str, Sequence[Any]] = {}
        for row in rows:  # the command in force reaches the wheels through the motor driver
            row.drive, row.wheels_command = drive(row.drive, row.command, row.model.params,
                                                  dt_s)
        kinematic = [row for row in rows if row.model.mode == "kinematic"]
        dynamic = [row for row in rows if row.model.mode == "dynamic"]
        neighbours = self._neighbours(everyone) if len(everyone) > 1 else {}
        for row in kinematic:  # in turn: each against the others where they stand now
            others = [self._robots[other].model.footprint
                      for other in neighbours.get(row.name, ())]
            samples[row.name] = row.model.step_kinematic(row.wheels_command, dt_s, others)
        if dynamic:
            for row in everyone:
                row.model.place_body()  # kinematic and held ones: where they stand
            substeps, sub_dt = dynamic_substeps(dt_s)
            for row in dynamic:
                row.model.begin_dynamic()
            for _ in range(substeps):
                for row in dynamic:
                    row.model.push(row.wheels_command, sub_dt)
                self._space.space.step(sub_dt)
                for row in dynamic:
                    row.model.note_contacts()
            for row in dynamic:
                samples[row.name] = row.model.end_dynamic()
        for row in rows:
            self._integrate(row, samples[row.name])
        self._tick += 1
        self._moved()

    def _step_alone(self, row: _Robot) -> None:
        """``_step_once`` of a world of one robot: the same steps, nobody else to meet."""
        if row.model.held:
            row.start_tick += 1
        else:
            row.drive, row.wheels_command = drive(row.drive, row.command, row.model.params,
                                                  self._dt_s)
            self._integrate(row, row.model.step(row.wheels_command, self._dt_s))
        self._tick += 1
        self._version += 1  # ``_moved``

    @staticmethod
    def _integrate(row: _Robot, samples: Sequence[Any]) -> None:
        """A tick's encoder samples into a robot's odometry and wheels, with its noise."""
        noise = row.noise
        v_noise = row.draw_noise(noise.odom_linear_sigma_mps)
        omega_noise = row.draw_noise(noise.odom_angular_sigma_rps)
        row.odometry.integrate(samples, v_noise, omega_noise)
        params = row.model.params
        row.wheels.integrate(samples, params.half_wheelbase_m, params.wheel_radius_m,
                             v_noise, omega_noise)

    def _neighbours(self, rows: list[_Robot]) -> dict[str, list[str]]:
        """For each kinematic robot, the robots it could touch this tick (one array pass).

        Robot i can reach robot j within a tick only if their centres are closer than
        r_i + r_j plus the distance both may move in it (a kinematic robot moves its wheels'
        command's |v| dt; a dynamic one moves after the kinematic ones, so not yet).
        """
        moving = np.array([abs(row.wheels_command.linear_mps) * self._dt_s
                           if row.model.mode == "kinematic" and not row.model.held else 0.0
                           for row in rows])
        movers = np.nonzero(moving > 0.0)[0]
        if not len(movers):
            return {}
        discs = self.footprints()  # rows are every robot, in spawn order: the same order
        gap_x = discs[movers, None, 0] - discs[None, :, 0]
        gap_y = discs[movers, None, 1] - discs[None, :, 1]
        reach = discs[movers, None, 2] + discs[None, :, 2] + moving[movers, None] + \
            moving[None, :] + REACH_SLACK_M
        close = gap_x * gap_x + gap_y * gap_y < reach * reach
        close[np.arange(len(movers)), movers] = False
        found: dict[str, list[str]] = {}
        for i, j in zip(*np.nonzero(close), strict=True):
            found.setdefault(rows[movers[i]].name, []).append(rows[j].name)
        return found

    def _moved(self) -> None:
        """Something moved, appeared or went: cached scans and footprints are stale."""
        self._version += 1

    # ---- what all robots need at once ------------------------------------------------------

    def footprints(self) -> FloatArray:
        """Every robot's footprint now, rows of (x, y, radius) (m), spawn order."""
        if self._footprints is None or self._footprints[0] != self._version:
            rows = self._robots.values()
            array = np.array([(row.model.pose.x, row.model.pose.y,
                               row.model.params.footprint_radius_m) for row in rows],
                             dtype=np.float64).reshape(-1, 3)
            self._footprints = (self._version, array)
        return self._footprints[1]

    def poses(self) -> FloatArray:
        """Every robot's true pose now, rows of (x, y, theta) in the map frame, spawn order."""
        return np.array([tuple(row.model.pose) for row in self._robots.values()],
                        dtype=np.float64).reshape(-1, 3)

    def scan_request(self, name: str) -> ScanRequest:
        """This tick's scan of robot ``name`` to cast (``physics.lidar.scan_many``).

        It sees every robot of the world but itself.
        """
        row = self._row(name)
        if len(self._robots) == 1:  # alone in its world: no other robot to see
            return ScanRequest(row.lidar, row.model.pose, self._scan_rng(row),
                               row.noise.scan_sigma_m)
        return ScanRequest(row.lidar, row.model.pose, self._scan_rng(row), row.noise.scan_sigma_m,
                           self.footprints(), self._index(name))

    def _index(self, name: str) -> int:
        """Robot ``name``'s row in ``footprints`` and ``poses``."""
        if not self._indices:  # made again after a robot came or went
            self._indices = {other: row for row, other in enumerate(self._robots)}
        return self._indices[name]

    def scan(self, name: str) -> LaserScan:
        """Robot ``name``'s LiDAR scan now, the other robots seen (computed once per tick)."""
        row = self._row(name)
        cache = row.scan_cache
        if cache is not None and cache[0] == self._version:
            return cache[1]
        if len(self._robots) == 1:  # alone: its LiDAR against the walls, nothing else
            scan = row.lidar.scan(row.model.pose, self._scan_rng(row), row.noise.scan_sigma_m)
        else:
            scan = scan_many([self.scan_request(name)])[0]
        row.scan_cache = (self._version, scan)
        return scan

    def scan_is_current(self, name: str) -> bool:
        """Whether robot ``name``'s scan of this tick has been cast already."""
        cache = self._row(name).scan_cache
        return cache is not None and cache[0] == self._version

    def accept_scan(self, name: str, scan: LaserScan) -> None:
        """Keep ``scan``, cast from this tick's ``scan_request``, as robot ``name``'s scan."""
        self._row(name).scan_cache = (self._version, scan)

    def cast_scans(self, names: Sequence[str] | None = None) -> dict[str, LaserScan]:
        """One scan pass: every robot's (or those of ``names``) scan now, cast together."""
        wanted = list(self._robots) if names is None else list(names)
        pending = [name for name in wanted if not self.scan_is_current(name)]
        for name, scan in zip(pending, scan_many([self.scan_request(name) for name in pending]),
                              strict=True):
            self.accept_scan(name, scan)
        return {name: self.scan(name) for name in wanted}

    def scan_reference(self, name: str) -> FloatArray:
        """Robot ``name``'s raw ranges, one pymunk query per beam, the other robots included.

        The reference the batched scan must equal (slow).
        """
        row = self._row(name)
        self.place_bodies()
        return row.lidar.raw_ranges_reference(row.model.pose, seen_by(row.group))

    def place_bodies(self) -> None:
        """Bring every kinematic robot's pymunk body to where it stands (for pymunk queries)."""
        if self._bodies_placed != self._version:
            for row in self._robots.values():
                row.model.place_body()
            self._bodies_placed = self._version

    def _scan_rng(self, row: _Robot) -> np.random.Generator | None:
        """This tick's scan noise stream of ``row``, or None when its scan is noiseless.

        A function of seed, episode and the robot's tick only, so a client that reads every
        scan and one that reads every tenth see the same values.
        """
        if row.noise.scan_sigma_m <= 0.0:
            return None
        key = (*row.scan_seed.spawn_key, row.episode, self._tick - row.start_tick)
        return np.random.default_rng(
            np.random.SeedSequence(row.scan_seed.entropy, spawn_key=key))

    # ---- one robot's readings ---------------------------------------------------------------

    def robot_tick(self, name: str) -> int:
        """Ticks since robot ``name`` spawned or was last reset."""
        return self._tick - self._row(name).start_tick

    def odometry(self, name: str) -> Odometry:
        """Robot ``name``'s wheel odometry in its ``odom`` frame."""
        return self._row(name).odometry.odometry()

    def wheels(self, name: str) -> WheelState:
        """Robot ``name``'s drive wheels, as its encoders count them."""
        return self._row(name).wheels.state()

    def ground_truth(self, name: str) -> Odometry:
        """Robot ``name``'s true pose and body-frame velocity in the ``map`` frame."""
        model = self._row(name).model
        pose = model.pose
        return Odometry(pose.x, pose.y, pose.theta, model.v, model.omega)

    def map_to_odom(self, name: str) -> Pose2D:
        """Robot ``name``'s ``odom`` frame in ``map``: what perfect localization publishes."""
        row = self._row(name)
        odom = row.odometry.odometry()
        return map_to_odom(row.model.pose, Pose2D(odom.x, odom.y, odom.theta))

    def state(self, name: str) -> RobotState:
        """A snapshot of everything of robot ``name`` that changes per tick."""
        row = self._row(name)
        tick = self._tick - row.start_tick
        return RobotState(time_s=tick * self._dt_s, tick=tick, mode=row.model.mode,
                          command=row.command, ground_truth=self.ground_truth(name),
                          odometry=row.odometry.odometry(), collided=row.model.collided)

    # ---- free space ---------------------------------------------------------------------------

    def free_pose_near(self, pose: Pose2D, radius_m: float) -> Pose2D:
        """``pose`` if a footprint of ``radius_m`` fits there, else the nearest pose that does.

        Candidates lie on rings ``FREE_POSE_STEP_M`` apart around ``pose`` (nearest first,
        then counter-clockwise from +x), each in sight of ``pose`` (no wall between: the same
        room, never outside the world's walls or inside an obstacle), clear of the walls,
        obstacles and every robot. Heading is kept.

        Raises:
            ConfigError: no free pose within the world's bounds.
        """
        return self._free_pose(pose, radius_m, ())

    def _kept_places(self, name: str) -> list[Disc]:
        """The starts the world file keeps for robots it places that are not here yet."""
        default = RobotParams().footprint_radius_m
        return [Disc(placed.start.x, placed.start.y,
                     dict(placed.params).get("footprint_radius_m", default))
                for placed in self._world.robots
                if placed.name != name and placed.name not in self._robots]

    def _free_pose(self, pose: Pose2D, radius_m: float, skip: Collection[_Robot],
                   kept: Sequence[Disc] = ()) -> Pose2D:
        """The first candidate (``free_pose_near``'s order) clear of walls, robots and ``kept``.

        Each ring's candidates are tried against every robot at once (one array operation),
        and only the ones clear of them against the walls: in a crowd (an arena's spawns)
        most candidates fall to the robots, and the search costs a few ms, not one Python
        comparison per robot per candidate.
        """
        discs = np.array([(footprint.x, footprint.y, footprint.radius_m)
                          for footprint in (row.model.footprint for row in self._robots.values()
                                            if row not in skip)],
                         dtype=np.float64).reshape(-1, 3)
        places = np.array([(place.x, place.y, place.radius_m) for place in kept],
                          dtype=np.float64).reshape(-1, 3)
        space = self._space.space

        # a disc can touch a candidate at ``distance`` from pose only if its centre lies
        # within radius_m + its radius of that ring (the triangle inequality; 1 um to spare)
        ring_of_disc = np.hypot(discs[:, 0] - pose.x, discs[:, 1] - pose.y) \
            if len(discs) else np.zeros(0)
        reach_of_disc = discs[:, 2] + radius_m + 1e-6 if len(discs) else np.zeros(0)

        def clear_of_robots(xs: FloatArray, ys: FloatArray,
                            distance: float = 0.0) -> npt.NDArray[np.bool_]:
            free = np.ones(len(xs), dtype=bool)
            near = discs[np.abs(ring_of_disc - distance) < reach_of_disc]
            if len(near):  # as ``_blocked``: the gap to each footprint at least radius_m
                gap = np.hypot(xs[:, None] - near[None, :, 0],
                               ys[:, None] - near[None, :, 1]) - near[None, :, 2]
                free &= ~(gap < radius_m).any(axis=1)
            if len(places):
                apart = np.hypot(xs[:, None] - places[None, :, 0],
                                 ys[:, None] - places[None, :, 1])
                free &= ~(apart < radius_m + places[None, :, 2]).any(axis=1)
            return free

        if clear_of_robots(np.array([pose.x]), np.array([pose.y]))[0] and \
                self._wall_within(pose.x, pose.y, radius_m) is None:
            return pose
        min_x, min_y, max_x, max_y = self._world.bounds
        farthest = math.hypot(max_x - min_x, max_y - min_y)
        rings = int(farthest / FREE_POSE_STEP_M) + 1
        for ring in range(1, rings + 1):
            distance = ring * FREE_POSE_STEP_M
            count = max(8, int(2.0 * math.pi * distance / FREE_POSE_STEP_M))
            angles = [2.0 * math.pi * k / count for k in range(count)]
            xs = np.array([pose.x + distance * math.cos(angle) for angle in angles])
            ys = np.array([pose.y + distance * math.sin(angle) for angle in angles])
            for k in np.flatnonzero(clear_of_robots(xs, ys, distance)).tolist():
                x, y = float(xs[k]), float(ys[k])
                if self._wall_within(x, y, radius_m) is not None:
                    continue
                if space.segment_query_first((pose.x, pose.y), (x, y), 0.0,
                                             WALLS_ONLY) is not None:
                    continue  # another room, or the other side of the world's walls
                return Pose2D(x, y, pose.theta)
        raise ConfigError(f"{self._world.source}: no free place for a footprint of radius "
                          f"{radius_m} m near {list(pose)}")

    def _blocked(self, x: float, y: float, radius_m: float,
                 skip: Collection[_Robot]) -> str | None:
        """What a footprint of ``radius_m`` at (x, y) would overlap, or None if nothing.

        The robots of ``skip`` are not there.
        """
        nearest = self._wall_within(x, y, radius_m)
        if nearest is not None:
            shapes = (*self._space.wall_shapes, *self._space.circle_shapes)
            origins = [wall.origin for wall in self._world.walls] + \
                [disc.origin for disc in self._world.circles]
            gap = max(nearest.distance, 0.0)
            return (f"{gap:.3f} m from {origins[shapes.index(nearest.shape)]}; it needs "
                    f"{radius_m} m of clearance")
        for other in self._robots.values():
            if other in skip:
                continue
            footprint = other.model.footprint
            gap = math.hypot(x - footprint.x, y - footprint.y) - footprint.radius_m
            if gap < radius_m:
                return (f"{max(gap, 0.0):.3f} m from robot '{other.name}'; it needs "
                        f"{radius_m} m of clearance")
        return None

    def _wall_within(self, x: float, y: float, radius_m: float) -> pymunk.PointQueryInfo | None:
        """The nearest wall or obstacle closer to (x, y) than ``radius_m``, or None."""
        nearest = self._space.space.point_query_nearest((x, y), radius_m, WALLS_ONLY)
        return nearest if nearest is not None and nearest.distance < radius_m else None

    def _check_clear(self, x: float, y: float, radius_m: float, moving: _Robot | None,
                     where: str, what: str) -> None:
        """Raise if a footprint of ``radius_m`` at (x, y) would overlap anything but ``moving``."""
        why = self._blocked(x, y, radius_m, () if moving is None else (moving,))
        if why is not None:
            raise ConfigError(f"{where}: {what} puts the robot footprint (radius {radius_m} m) "
                              f"{why}")


__all__ = ["RUNTIME_PARAMS", "TICK_PERIOD_S", "Disc", "RobotSeed", "WorldSim"]
