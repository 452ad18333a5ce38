"""The simulation: one robot's view of its world, stepped at a fixed tick.

Example::

    from physics import Simulation, RobotParams, load_world
    sim = Simulation(load_world("worlds/empty.yaml"), RobotParams(), mode="kinematic", seed=0)
    sim.command(linear_mps=0.3, angular_rps=0.5)
    sim.step(20)                   # one second
    sim.odometry(), sim.ground_truth(), sim.scan()

``Simulation(world, ...)`` is a world of one robot (``physics.world_sim.WorldSim``), named
``SINGLE_ROBOT`` unless given a name. ``Simulation.of(world, name)`` is the same view of a
robot of a world of many: its readings and commands are its own, ``step`` steps its whole
world.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from physics.lidar import Lidar, ScanRequest, scan_many
from physics.params import LidarParams, NoiseParams, RobotParams
from physics.robot import MobileRobotPhysics
from physics.snapshots import Command, LaserScan, Odometry, Pose2D, RobotState, WheelState
from physics.world import World
from physics.world_sim import RUNTIME_PARAMS, TICK_PERIOD_S, WorldSim

SINGLE_ROBOT = "robot"
"""The name of the robot of a world of one (``Simulation(world, ...)``)."""

__all__ = ["RUNTIME_PARAMS", "SINGLE_ROBOT", "TICK_PERIOD_S", "Simulation", "cast_scans"]


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
        name: the robot's name in its world (a class robot's: its student's).

    Raises:
        ConfigError: the robot's footprint at the start pose overlaps a wall.
    """

    def __init__(self, world: World, params: RobotParams | None = None, *,
                 mode: str = "kinematic", seed: int | None = None,
                 lidar: LidarParams | None = None, noise: NoiseParams | None = None,
                 dt_s: float = TICK_PERIOD_S, name: str = SINGLE_ROBOT) -> None:
        params = RobotParams() if params is None else params
        if mode not in ("kinematic", "dynamic"):
            raise ValueError(f"mode must be one of kinematic, dynamic, got {mode!r}")
        self._world_sim = WorldSim(world, dt_s=dt_s, seed=seed, lidar=lidar, noise=noise)
        self._world_sim._check_clear(world.start.x, world.start.y, params.footprint_radius_m,
                                     None, f"{world.source}: start",
                                     f"start {list(world.start)}")
        self._world_sim.spawn(name, world.start, params, mode=mode, seed=seed)
        self._name = name

    @classmethod
    def of(cls, world_sim: WorldSim, name: str) -> Simulation:
        """Robot ``name``'s view of ``world_sim`` (KeyError: no such robot)."""
        world_sim._row(name)
        view = cls.__new__(cls)
        view._world_sim = world_sim
        view._name = name
        return view

    @property
    def world_sim(self) -> WorldSim:
        """The world this robot is in (with every other robot of it)."""
        return self._world_sim

    @property
    def name(self) -> str:
        """The robot's name in its world."""
        return self._name

    @property
    def model(self) -> MobileRobotPhysics:
        """The robot's physical model (its pymunk body, pose and speeds)."""
        return self._world_sim._row(self._name).model

    @property
    def seed(self) -> int | None:
        """The seed the robot's random generator started from (None: fresh entropy)."""
        seed = self._world_sim._row(self._name).seed
        return seed if isinstance(seed, int) or seed is None else self._world_sim.seed

    @property
    def world(self) -> World:
        """The world being simulated."""
        return self._world_sim.world

    @property
    def params(self) -> RobotParams:
        """The robot parameters in force (payload changes included)."""
        return self._world_sim._row(self._name).model.params

    @property
    def lidar(self) -> Lidar:
        """The LiDAR model."""
        return self._world_sim._row(self._name).lidar

    @property
    def noise(self) -> NoiseParams:
        """The noise sigmas in force."""
        return self._world_sim._row(self._name).noise

    @property
    def dt_s(self) -> float:
        """Tick length (s)."""
        return self._world_sim.dt_s

    @property
    def tick(self) -> int:
        """Ticks since spawn or the last reset."""
        return self._world_sim.robot_tick(self._name)

    @property
    def time_s(self) -> float:
        """Simulated time since spawn or the last reset (s)."""
        return self._world_sim.robot_tick(self._name) * self._world_sim.dt_s

    @property
    def mode(self) -> str:
        """``"kinematic"`` or ``"dynamic"``; may be switched between ticks, state carried over."""
        return self._world_sim._row(self._name).model.mode

    @mode.setter
    def mode(self, mode: str) -> None:
        self._world_sim.set_mode(self._name, mode)

    @property
    def last_command(self) -> Command:
        """The clamped command in force; the robot keeps it until the next one."""
        return self._world_sim._row(self._name).command

    def command(self, linear_mps: float, angular_rps: float) -> Command:
        """Set the velocity command, like a ``/cmd_vel`` Twist (linear.x, angular.z).

        Values beyond the limits are clamped; the robot keeps this command until the next.

        Raises:
            ConfigError: a value is not a finite number; the command in force is unchanged.
        """
        return self._world_sim.command(self._name, linear_mps, angular_rps)

    def step(self, n: int = 1) -> None:
        """Advance ``n`` ticks of ``dt_s`` each (the whole world: every robot in it)."""
        self._world_sim.step(n)

    def odometry(self) -> Odometry:
        """Wheel odometry in the ``odom`` frame: zero at spawn, integrated from the encoders."""
        return self._world_sim.odometry(self._name)

    def wheels(self) -> WheelState:
        """The drive wheels' angles and speeds, as the encoders odometry reads count them."""
        return self._world_sim.wheels(self._name)

    def ground_truth(self) -> Odometry:
        """True pose and body-frame velocity in the ``map`` frame."""
        return self._world_sim.ground_truth(self._name)

    def map_to_odom(self) -> Pose2D:
        """The ``odom`` frame in ``map`` (m, rad): what perfect localization publishes.

        The ground truth composed with the inverse of the odometry, so that map -> odom ->
        base_link is the true pose however far the odometry has drifted.
        """
        return self._world_sim.map_to_odom(self._name)

    @property
    def scan_is_current(self) -> bool:
        """Whether this tick's scan has been cast already."""
        return self._world_sim.scan_is_current(self._name)

    def scan(self) -> LaserScan:
        """The LiDAR scan at the current pose, other robots seen (computed once per tick)."""
        return self._world_sim.scan(self._name)

    def scan_request(self) -> ScanRequest:
        """This tick's scan to cast elsewhere (``physics.lidar.scan_many``).

        Its LiDAR, pose, noise, and the other robots of its world.
        """
        return self._world_sim.scan_request(self._name)

    def accept_scan(self, scan: LaserScan) -> None:
        """Keep ``scan``, cast from this tick's ``scan_request``, as this tick's ``scan()``."""
        self._world_sim.accept_scan(self._name, scan)

    def state(self) -> RobotState:
        """A snapshot of everything that changes per tick."""
        return self._world_sim.state(self._name)

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
        return self._world_sim.update_params(self._name, **changes)

    def place(self, pose: Pose2D, odometry: Pose2D) -> None:
        """Put the robot at rest at ``pose`` (map frame) with odometry reading ``odometry``.

        What a class restores after a restart (``classroom.state``); a pose whose footprint
        overlaps a wall is refused (ConfigError) and nothing is changed.
        """
        self._world_sim.place(self._name, pose, odometry)

    def teleport(self, pose: Pose2D) -> None:
        """Put the robot at rest at ``pose`` (map frame), its odometry as it is (``WorldSim``)."""
        self._world_sim.teleport(self._name, pose)

    def reset(self, *, seed: int | None = None) -> None:
        """Back to the spawn pose at rest with a zero command and odometry zeroed.

        Parameters and mode stay as they are. ``seed`` restarts the noise streams as if the
        simulation had been built with it; without it, noise goes on with fresh values. In a
        world of several robots, another robot standing on the spawn pose sends this one to
        the nearest free pose.
        """
        self._world_sim.reset_robot(self._name, seed=seed)


def cast_scans(simulations: Sequence[Simulation]) -> None:
    """Cast this tick's scan of every simulation not yet scanned, alike LiDARs together.

    ``physics.lidar.scan_many`` of their ``scan_request``: robots in worlds of the same shapes
    (a class's copies of one world, or one arena) share one ray intersection with the walls,
    each adding the other robots of its world and its own noise, so ``scan()`` then gives what
    it would have cast alone (to rounding, ~1e-15 m).
    """
    pending = [simulation for simulation in simulations if not simulation.scan_is_current]
    scans = scan_many([simulation.scan_request() for simulation in pending])
    for simulation, scan in zip(pending, scans, strict=True):
        simulation.accept_scan(scan)

