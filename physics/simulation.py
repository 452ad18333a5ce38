"""The simulation: one robot in one world, stepped at a fixed tick.

Example::

    from physics import Simulation, RobotParams, load_world
    sim = Simulation(load_world("worlds/empty.yaml"), RobotParams(), mode="kinematic", seed=0)
    sim.command(linear_mps=0.3, angular_rps=0.5)
    sim.step(20)                   # one second
    sim.odometry(), sim.ground_truth(), sim.scan()
"""

from __future__ import annotations

import dataclasses
import difflib
from collections.abc import Sequence
from typing import Any

import numpy as np

from physics.command_pipeline import AT_REST, drive
from physics.frames import map_to_odom
from physics.kinematics import clamp_command
from physics.lidar import Lidar, ScanRequest, scan_many
from physics.odometry import OdometryIntegrator
from physics.params import LidarParams, NoiseParams, RobotParams
from physics.robot import MobileRobotPhysics
from physics.snapshots import Command, LaserScan, Odometry, Pose2D, RobotState, WheelState
from physics.space import WALLS_ONLY, WorldSpace, build_world_space
from physics.validation import ConfigError, as_finite_float
from physics.wheels import WheelEncoders
from physics.world import World

TICK_PERIOD_S = 0.05
"""One tick of the course's virtual_robot node: 20 Hz."""

RUNTIME_PARAMS = tuple(item.name for item in dataclasses.fields(RobotParams))
"""Robot parameters that ``update_params`` may change between ticks."""


class Simulation:
    """A robot in a world, advanced in fixed ticks of ``dt_s``.

    Args:
        world: the world to drive in; the robot spawns at ``world.start``.
        params: the robot; defaults to the Pi 4B robot of ``config/pi4b_params.yaml``.
        mode: ``"kinematic"`` (course Eq. 1-3, the default) or ``"dynamic"`` (pymunk).
        seed: seed of the simulation's own random generator (noise); same seed, same run.
        lidar: the LiDAR; defaults to the shipped parameters.
        noise: noise sigmas; defaults to the shipped parameters (noiseless).
        dt_s: tick length (s).

    Raises:
        ConfigError: the robot's footprint at the start pose overlaps a wall.
    """

    def __init__(self, world: World, params: RobotParams | None = None, *,
                 mode: str = "kinematic", seed: int | None = None,
                 lidar: LidarParams | None = None, noise: NoiseParams | None = None,
                 dt_s: float = TICK_PERIOD_S) -> None:
        params = RobotParams() if params is None else params
        self._world = world
        self._dt_s = as_finite_float("dt_s", dt_s)
        self._noise = NoiseParams() if noise is None else noise
        self._world_space = build_world_space(world)
        _check_clearance(self._world_space, world, world.start.x, world.start.y,
                         params.footprint_radius_m, f"{world.source}: start",
                         f"start {list(world.start)}")
        self._robot = MobileRobotPhysics(params, self._world_space, world.start, mode)
        self._lidar = Lidar(LidarParams() if lidar is None else lidar, self._world_space)
        self._odometry = OdometryIntegrator()
        self._wheels = WheelEncoders()
        self._seed = seed
        self._seed_noise(seed)
        self._command = Command(0.0, 0.0)
        self._drive = AT_REST
        self._tick = 0
        self._scan_cache: tuple[int, LaserScan] | None = None

    @property
    def seed(self) -> int | None:
        """The seed the simulation's random generator started from (None: fresh entropy)."""
        return self._seed

    @property
    def world(self) -> World:
        """The world being simulated."""
        return self._world

    @property
    def params(self) -> RobotParams:
        """The robot parameters in force (payload changes included)."""
        return self._robot.params

    @property
    def lidar(self) -> Lidar:
        """The LiDAR model."""
        return self._lidar

    @property
    def noise(self) -> NoiseParams:
        """The noise sigmas in force."""
        return self._noise

    @property
    def dt_s(self) -> float:
        """Tick length (s)."""
        return self._dt_s

    @property
    def tick(self) -> int:
        """Ticks since spawn or the last reset."""
        return self._tick

    @property
    def time_s(self) -> float:
        """Simulated time since spawn or the last reset (s)."""
        return self._tick * self._dt_s

    @property
    def mode(self) -> str:
        """``"kinematic"`` or ``"dynamic"``; may be switched between ticks, state carried over."""
        return self._robot.mode

    @mode.setter
    def mode(self, mode: str) -> None:
        self._robot.mode = mode

    @property
    def last_command(self) -> Command:
        """The clamped command in force; the robot keeps it until the next one."""
        return self._command

    def command(self, linear_mps: float, angular_rps: float) -> Command:
        """Set the velocity command, like a ``/cmd_vel`` Twist (linear.x, angular.z).

        Values beyond the limits are clamped; the robot keeps this command until the next.

        Raises:
            ConfigError: a value is not a finite number; the command in force is unchanged.
        """
        linear = as_finite_float("linear_mps", linear_mps)
        angular = as_finite_float("angular_rps", angular_rps)
        params = self._robot.params
        self._command = clamp_command(linear, angular, params.max_linear_mps,
                                      params.max_angular_rps)
        return self._command

    def step(self, n: int = 1) -> None:
        """Advance ``n`` ticks of ``dt_s`` each.

        The command in force reaches the wheels through the robot's driver
        (``physics.command_pipeline.drive``: its lag, scales and ramps; the shipped robot's
        passes it through unchanged).
        """
        for _ in range(n):
            self._drive, wheels = drive(self._drive, self._command, self._robot.params,
                                        self._dt_s)
            samples = self._robot.step(wheels, self._dt_s)
            v_noise = self._draw_noise(self._noise.odom_linear_sigma_mps)
            omega_noise = self._draw_noise(self._noise.odom_angular_sigma_rps)
            self._odometry.integrate(samples, v_noise, omega_noise)
            params = self._robot.params
            self._wheels.integrate(samples, params.half_wheelbase_m, params.wheel_radius_m,
                                   v_noise, omega_noise)
            self._tick += 1

    def _seed_noise(self, seed: int | None) -> None:
        """Give each noise source its own stream, so reading one never shifts another."""
        odom_seed, self._scan_seed = np.random.SeedSequence(seed).spawn(2)
        self._odom_rng = np.random.default_rng(odom_seed)
        self._episode = 0

    def _draw_noise(self, sigma: float) -> float:
        return float(self._odom_rng.normal(0.0, sigma)) if sigma > 0.0 else 0.0

    def _scan_rng(self) -> np.random.Generator | None:
        """This tick's scan noise stream, or None when the scan is noiseless.

        A function of seed, episode and tick only, so a client that reads every scan and one
        that reads every tenth see the same values.
        """
        if self._noise.scan_sigma_m <= 0.0:
            return None
        key = (*self._scan_seed.spawn_key, self._episode, self._tick)
        return np.random.default_rng(
            np.random.SeedSequence(self._scan_seed.entropy, spawn_key=key))

    def odometry(self) -> Odometry:
        """Wheel odometry in the ``odom`` frame: zero at spawn, integrated from the encoders."""
        return self._odometry.odometry()

    def wheels(self) -> WheelState:
        """The drive wheels' angles and speeds, as the encoders odometry reads count them."""
        return self._wheels.state()

    def ground_truth(self) -> Odometry:
        """True pose and body-frame velocity in the ``map`` frame."""
        pose = self._robot.pose
        return Odometry(pose.x, pose.y, pose.theta, self._robot.v, self._robot.omega)

    def map_to_odom(self) -> Pose2D:
        """The ``odom`` frame in ``map`` (m, rad): what perfect localization publishes.

        The ground truth composed with the inverse of the odometry, so that map -> odom ->
        base_link is the true pose however far the odometry has drifted.
        """
        odom = self._odometry.odometry()
        return map_to_odom(self._robot.pose, Pose2D(odom.x, odom.y, odom.theta))

    @property
    def scan_is_current(self) -> bool:
        """Whether this tick's scan has been cast already."""
        return self._scan_cache is not None and self._scan_cache[0] == self._tick

    def scan(self) -> LaserScan:
        """The LiDAR scan at the current pose (computed once per tick)."""
        if self._scan_cache is None or self._scan_cache[0] != self._tick:
            scan = self._lidar.scan(self._robot.pose, self._scan_rng(), self._noise.scan_sigma_m)
            self._scan_cache = (self._tick, scan)
        return self._scan_cache[1]

    def scan_request(self) -> ScanRequest:
        """This tick's scan to cast elsewhere (``physics.lidar.scan_many``): LiDAR, pose, noise."""
        return ScanRequest(self._lidar, self._robot.pose, self._scan_rng(),
                           self._noise.scan_sigma_m)

    def accept_scan(self, scan: LaserScan) -> None:
        """Keep ``scan``, cast from this tick's ``scan_request``, as this tick's ``scan()``."""
        self._scan_cache = (self._tick, scan)

    def state(self) -> RobotState:
        """A snapshot of everything that changes per tick."""
        return RobotState(time_s=self.time_s, tick=self._tick, mode=self.mode,
                          command=self._command, ground_truth=self.ground_truth(),
                          odometry=self.odometry(), collided=self._robot.collided)

    def set_payload(self, mass_kg: float | None = None,
                    inertia_kg_m2: float | None = None) -> RobotParams:
        """Change mass and/or inertia now, without a reset (the admin page's perturbation).

        In kinematic mode they do not affect motion; in dynamic mode they act from the next tick.

        Raises:
            ConfigError: a value is not a finite number > 0; nothing is changed.
        """
        changes = {name: value for name, value in
                   (("mass_kg", mass_kg), ("inertia_kg_m2", inertia_kg_m2)) if value is not None}
        return self.update_params(**changes)

    def update_params(self, **changes: Any) -> RobotParams:
        """Change any robot parameters now (see ``RUNTIME_PARAMS``); returns those in force.

        Raises:
            ConfigError: an unknown name or an invalid value; nothing is changed.
        """
        for name in changes:
            if name not in RUNTIME_PARAMS:
                close = difflib.get_close_matches(name, RUNTIME_PARAMS, n=1)
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise ConfigError(f"{name}: unknown robot parameter{hint}")
        params = dataclasses.replace(self._robot.params, **changes)
        if params.footprint_radius_m != self._robot.params.footprint_radius_m:
            _check_clearance(self._world_space, self._world, self._robot.pose.x,
                             self._robot.pose.y, params.footprint_radius_m, "footprint_radius_m",
                             f"{params.footprint_radius_m!r} at the robot's current position")
        self._robot.set_params(params)
        self._command = clamp_command(*self._command, params.max_linear_mps,
                                      params.max_angular_rps)
        return params

    def place(self, pose: Pose2D, odometry: Pose2D) -> None:
        """Put the robot at rest at ``pose`` (map frame) with odometry reading ``odometry``.

        What a class restores after a restart (``classroom.state``); a pose whose footprint
        overlaps a wall is refused (ConfigError) and nothing is changed.
        """
        _check_clearance(self._world_space, self._world, pose.x, pose.y,
                         self._robot.params.footprint_radius_m, "restored pose",
                         f"{list(pose)}")
        self._robot.teleport(pose)
        self._odometry.place(odometry)
        self._wheels.reset()
        self._command = Command(0.0, 0.0)
        self._drive = AT_REST
        self._scan_cache = None

    def reset(self, *, seed: int | None = None) -> None:
        """Back to the spawn pose at rest with a zero command and odometry zeroed.

        Parameters and mode stay as they are. ``seed`` restarts the noise streams as if the
        simulation had been built with it; without it, noise goes on with fresh values.
        """
        if seed is not None:
            self._seed_noise(seed)
        else:
            self._episode += 1
        self._robot.teleport(self._world.start)
        self._odometry.reset()
        self._wheels.reset()
        self._command = Command(0.0, 0.0)
        self._drive = AT_REST
        self._tick = 0
        self._scan_cache = None


def cast_scans(simulations: Sequence[Simulation]) -> None:
    """Cast this tick's scan of every simulation not yet scanned, alike LiDARs together.

    ``physics.lidar.scan_many`` of their ``scan_request``: robots of a class in one world
    share one ray intersection, each with its own noise, so ``scan()`` then gives what it
    would have cast alone (to rounding, ~1e-15 m).
    """
    pending = [simulation for simulation in simulations if not simulation.scan_is_current]
    scans = scan_many([simulation.scan_request() for simulation in pending])
    for simulation, scan in zip(pending, scans, strict=True):
        simulation.accept_scan(scan)


def _check_clearance(world_space: WorldSpace, world: World, x: float, y: float,
                     radius_m: float, where: str, what: str) -> None:
    """Raise if a footprint of ``radius_m`` at (x, y) would overlap a wall or obstacle."""
    nearest = world_space.space.point_query_nearest((x, y), radius_m, WALLS_ONLY)
    if nearest is None or nearest.distance >= radius_m:
        return
    shapes = (*world_space.wall_shapes, *world_space.circle_shapes)
    origins = [wall.origin for wall in world.walls] + [disc.origin for disc in world.circles]
    origin = origins[shapes.index(nearest.shape)]
    gap = max(nearest.distance, 0.0)
    raise ConfigError(f"{where}: {what} puts the robot footprint (radius {radius_m} m) "
                      f"{gap:.3f} m from {origin}; it needs {radius_m} m of clearance")
