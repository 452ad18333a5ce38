"""What the simulation services need of a world, and today's world of one robot.

``SimulatorControl`` is the seam between ROS 2's ``simulation_interfaces`` services
(``ros_nodes.simulation_services``: their requests, result codes and rights) and the world
they act on: its entities, their poses, pause, play and step, reset, spawn and delete, over
a world's host (``ros_nodes.world_host.WorldHost``): a world of one robot (``OneRobotWorld``:
the single robot of ``websim serve``, or one student's in a class), or the arena every robot
of a class shares (``SharedWorld``: ``--arena``).

Units and frames: poses are in the world's ``map`` frame (m, rad), velocities ``v`` (m/s,
along the heading) and ``omega`` (rad/s, counter-clockwise), as ``physics`` gives them.
"""

from __future__ import annotations

import dataclasses
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any, Protocol

from physics import ConfigError, WorldSim
from physics.snapshots import Odometry, Pose2D
from ros_nodes.urdf import CHASSIS_HEIGHT_M, LASER_HEIGHT_M
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.session import Flush, Session

CATEGORY_OBJECT = 0
CATEGORY_ROBOT = 1
CATEGORY_STATIC_OBJECT = 5
"""``simulation_interfaces/msg/EntityCategory`` values websim's entities have."""

ROBOT_TAGS = ("robot", "differential_drive", "lidar")
"""The tags of a websim robot (``EntityInfo.tags``, what ``TagsFilter`` matches)."""

ROBOT_DESCRIPTION = "differential-drive robot with a 2D LiDAR (the course's Pi 4B robot)"


class UnsupportedError(Exception):
    """What this world cannot do (yet): the call is answered FEATURE_UNSUPPORTED."""


@dataclass(frozen=True)
class Entity:
    """One thing of a world that the services name.

    Attributes:
        name: its unique name in the world (a robot's is its student's name in a class).
        category: an ``EntityCategory`` value (``CATEGORY_ROBOT``...).
        description: a sentence for people.
        tags: what ``TagsFilter`` matches.
        radius_m: its footprint's radius about its origin (m).
        height_m: how high it reaches above the ground (m).
        owner: the student who spawned it (None: the world's own, or the instructor's).
        spawned: whether it was spawned while the world runs (``SCOPE_SPAWNED`` removes it).
    """

    name: str
    category: int
    description: str
    tags: tuple[str, ...]
    radius_m: float
    height_m: float
    owner: str | None = None
    spawned: bool = False


@dataclass(frozen=True)
class Caller:
    """Who calls, as the rights see it (``SimulatorControl.caller``).

    Attributes:
        admin: may do anything in this world: the instructor, and a student in a world of
            their own robot only (what ``/websim/pause`` allows them).
        drives: the robots it may move and reset (None: every one; empty: none, it watches).
        name: the student whose spawned entities it may delete (None: nobody's).
        spawn_quota: how many spawned entities it may have at once, unless admin.
    """

    admin: bool
    drives: frozenset[str] | None
    name: str | None = None
    spawn_quota: int = 0


Progress = Callable[[int, str | None], None]
"""Called once per step a stepping request ran, with the steps done, and once more when it
ends early, with the reason (the simulation was played, the world went away)."""

Cancel = Callable[[], None]
"""Stops a stepping request: no more steps, no more progress."""


class SimulatorControl(Protocol):
    """A world as the simulation services act on it."""

    def entities(self) -> list[Entity]:
        """Its entities, in a stable order."""

    def state(self, name: str) -> Odometry:
        """Entity ``name``'s ground truth in the map frame; KeyError if there is none."""

    def teleport(self, name: str, pose: Pose2D) -> None:
        """Put entity ``name`` at rest at ``pose`` (map frame), its odometry untouched.

        Raises:
            KeyError: no such entity.
            ConfigError: its footprint there overlaps a wall or another entity (nothing moves).
        """

    def reset_entity(self, name: str) -> None:
        """Entity ``name`` back to its spawn pose at rest, odometry zeroed."""

    def reset(self, *, spawned: bool) -> None:
        """Every entity back to its spawn pose; the spawned ones removed if ``spawned``."""

    @property
    def paused(self) -> bool:
        """Whether the world is held: it advances only when stepped."""

    @property
    def stopped(self) -> bool:
        """Whether it is held at its reset state, not advanced since (STATE_STOPPED)."""

    def set_paused(self, paused: bool, *, stopped: bool = False) -> None:
        """Hold (or run) the world; ``stopped``: held at its reset state (reset it first)."""

    def step(self, steps: int, progress: Progress) -> Cancel:
        """Advance a held world ``steps`` ticks, one per tick of the server.

        Raises:
            ConfigError: it is not held, or another stepping request is running.
        """

    def spawn(self, name: str, pose: Pose2D, owner: str | None) -> None:
        """Add a robot ``name`` at ``pose``.

        Raises:
            UnsupportedError: this world cannot.
            ConfigError: the pose is not free, or the world is full.
        """

    def delete(self, name: str) -> None:
        """Remove entity ``name`` (UnsupportedError: this world cannot)."""

    @property
    def can_spawn(self) -> bool:
        """Whether ``spawn`` and ``delete`` work here."""

    def start_pose(self) -> Pose2D:
        """Where the world's robot starts (the named pose ``start``)."""

    def caller(self, session: Session) -> Caller:
        """The rights of a client of this world's bridge."""

    def stamp_s(self) -> float:
        """The stamp of now, as the world's messages are stamped (s since the epoch)."""

    def answered(self) -> None:
        """Write what was queued for clients outside a client's frame (a step's answer)."""


class _Host(Protocol):
    """What a control uses of a robot's host (``ros_nodes.robot_host.RobotHost``)."""

    robot: VirtualRobot
    bridge: Bridge
    held: bool


class _World(Protocol):
    """What a control uses of a world's host (``ros_nodes.world_host.WorldHost``)."""

    world: WorldSim
    hosts: dict[str, Any]

    def __iter__(self) -> Iterator[tuple[str, Any]]:
        """Each robot's name and host."""

    def tick(self, write: Callable[[Flush], None], lateness_s: float = 0.0) -> None:
        """A whole tick of the world alone."""


class Ticker(Protocol):
    """What a world's control needs of the tick driver (``heartbeat.driver.TickDriver``)."""

    @property
    def tick_listeners(self) -> list[Callable[[], None]]:
        """Called after every tick of the server."""

    def write(self, flush: Flush) -> None:
        """Write ``flush`` through the server's connections."""


class Spawner(Protocol):
    """Who makes and removes robots of a shared world (a class: ``Classroom``)."""

    def spawn(self, name: str, pose: Pose2D, owner: str | None) -> None:
        """Add robot ``name`` at ``pose`` (ConfigError: a taken name, no room there)."""

    def delete(self, name: str) -> None:
        """Remove robot ``name`` (KeyError: no such robot)."""

    def owner(self, name: str) -> str | None:
        """Who spawned robot ``name`` (None: the world's own, or the instructor)."""

    def spawned(self, name: str) -> bool:
        """Whether robot ``name`` was spawned while the world runs."""


class WorldControl(ABC):
    """A world's robots as the simulation services act on them: a ``WorldHost``.

    Stepping a paused world runs one tick of it after each tick of the server
    (``Ticker.tick_listeners``), so a step publishes what a tick publishes, stamped as a tick
    is. Subclasses say what pausing holds and who may do what.

    Args:
        world: the world's host (its simulation and its robots' hosts).
        name: the entity whose bridge these services are on (its robot).
        ticker: the server's tick driver.
    """

    can_spawn = False

    def __init__(self, world: _World, name: str, ticker: Ticker) -> None:
        self._world = world
        self.name = name
        self._ticker = ticker
        self._stopped = False
        self._stepping: _Stepping | None = None

    @property
    def _host(self) -> _Host:
        host: _Host = self._world.hosts[self.name]
        return host

    def entities(self) -> list[Entity]:
        """Every robot of the world, in spawn order."""
        return [self._entity(name, host) for name, host in self._world]

    def _entity(self, name: str, host: _Host) -> Entity:
        params = host.robot.sim.params
        return Entity(name, CATEGORY_ROBOT, ROBOT_DESCRIPTION, ROBOT_TAGS,
                      params.footprint_radius_m,
                      params.wheel_radius_m + CHASSIS_HEIGHT_M + LASER_HEIGHT_M)

    def _robot(self, name: str) -> VirtualRobot:
        host: _Host | None = self._world.hosts.get(name)
        if host is None:
            raise KeyError(name)
        return host.robot

    def state(self, name: str) -> Odometry:
        """Robot ``name``'s ground truth (map frame)."""
        return self._robot(name).sim.ground_truth()

    def teleport(self, name: str, pose: Pose2D) -> None:
        """Robot ``name`` at rest at ``pose``, its odometry reading as it was (carried)."""
        self._robot(name).sim.teleport(pose)

    def reset_entity(self, name: str) -> None:
        """Robot ``name`` back at its spawn (``/reset_simulation``'s reset)."""
        self._robot(name).reset()

    def reset(self, *, spawned: bool) -> None:
        """Every robot back at its spawn."""
        for _, host in self._world:
            host.robot.reset()

    @property
    @abstractmethod
    def paused(self) -> bool:
        """Whether the world is held."""

    @abstractmethod
    def _hold(self, held: bool) -> None:
        """Hold the world (True) or let it run."""

    @property
    def stopped(self) -> bool:
        """Held at its reset state since ``SetSimulationState`` STOPPED."""
        return self.paused and self._stopped

    def set_paused(self, paused: bool, *, stopped: bool = False) -> None:
        """Hold or run the world."""
        self._hold(paused)
        self._stopped = paused and stopped

    def step(self, steps: int, progress: Progress) -> Cancel:
        """Run ``steps`` ticks of the held world, one after each tick of the server."""
        if not self.paused:
            raise ConfigError("the simulation is not paused (SetSimulationState "
                              "STATE_PAUSED first)")
        if self._stepping is not None:
            raise ConfigError(f"the simulation is being stepped already "
                              f"({self._stepping.left} steps left)")
        stepping = _Stepping(self, steps, progress)
        self._stepping = stepping
        self._stopped = False
        self._ticker.tick_listeners.append(stepping.tick)
        return stepping.cancel

    def _run_step(self) -> None:
        """One tick of the held world (the tick driver's tick of it alone)."""
        self._hold(False)
        try:
            self._world.tick(self._ticker.write)
        finally:
            self._hold(True)

    def _end_stepping(self, stepping: _Stepping) -> None:
        listeners = self._ticker.tick_listeners
        if stepping.tick in listeners:
            listeners.remove(stepping.tick)
        if self._stepping is stepping:
            self._stepping = None

    def spawn(self, name: str, pose: Pose2D, owner: str | None) -> None:
        """Not in a world of one robot."""
        raise UnsupportedError("spawning needs a world of several robots (websim serve --class "
                               "--arena); this world holds one robot")

    def delete(self, name: str) -> None:
        """Not in a world of one robot."""
        raise UnsupportedError("deleting needs a world of several robots (websim serve --class "
                               "--arena); this world holds one robot")

    def start_pose(self) -> Pose2D:
        """The world's start pose."""
        return self._world.world.world.start

    def caller(self, session: Session) -> Caller:
        """Admins own this world; the drive right moves the robot."""
        return Caller(admin=session.is_admin,
                      drives=None if session.may_drive else frozenset())

    def stamp_s(self) -> float:
        """The robots' clock's stamp."""
        return self._host.robot.clock.stamp_s()

    def answered(self) -> None:
        """Write the bridge's queued frames through the server's connections."""
        self._ticker.write(self._host.bridge.take_flush())


class OneRobotWorld(WorldControl):
    """A world of one robot (the single robot of ``websim serve``, a class robot's own).

    Pausing is the host's hold (``/websim/pause`` holds the same). Spawning and deleting need
    a world of many robots: ``UnsupportedError`` here.

    Rights: the robot's admins (its token or the instructor's in a class; the admin token of
    a single robot) may do anything in it: the world holds nothing of anybody else. A client
    with the drive right (``Session.may_drive``) may move and reset the robot.
    """

    @property
    def paused(self) -> bool:
        """Held by an admin (``/websim/pause``, ``SetSimulationState``)."""
        return self._host.held

    def _hold(self, held: bool) -> None:
        self._host.held = held

    def reset(self, *, spawned: bool) -> None:
        """The robot back at spawn (nothing here was spawned)."""
        self._host.robot.reset()


class SharedWorld(WorldControl):
    """The world every robot of an arena shares (``--class --arena``), from one robot's bridge.

    Pausing holds the whole world (``WorldSim.paused``); spawning adds a robot (the course's)
    to the class, reachable at ``/robots/NAME`` as a student's is, and deleting removes one
    that was spawned (``Spawner``: the class).

    Rights: the instructor (the server's admin token) may do anything; a student, with their
    robot's token, may move and reset their own robot only, and spawn up to ``spawn_quota``
    robots (``--student-spawn``) and delete those; a connection without a token watches.

    Args:
        world: the arena's host.
        name: the robot whose bridge offers these services.
        ticker: the server's tick driver.
        spawner: who makes and removes the arena's robots (the class).
        spawn_quota: how many robots one student may have spawned at once.
    """

    can_spawn = True

    def __init__(self, world: _World, name: str, ticker: Ticker, spawner: Spawner,
                 spawn_quota: int = 0) -> None:
        super().__init__(world, name, ticker)
        self._spawner = spawner
        self._quota = spawn_quota

    def _entity(self, name: str, host: _Host) -> Entity:
        entity = super()._entity(name, host)
        return dataclasses.replace(entity, owner=self._spawner.owner(name),
                                   spawned=self._spawner.spawned(name))

    @property
    def paused(self) -> bool:
        """Whether the arena is held (every robot)."""
        return self._world.world.paused

    def _hold(self, held: bool) -> None:
        self._world.world.paused = held

    def reset(self, *, spawned: bool) -> None:
        """Every robot back at its spawn; the spawned ones removed if ``spawned``."""
        if spawned:
            for name, _ in self._world:
                if self._spawner.spawned(name):
                    self._spawner.delete(name)
        super().reset(spawned=spawned)

    def spawn(self, name: str, pose: Pose2D, owner: str | None) -> None:
        """A robot ``name`` at ``pose``, a robot of the class from now on."""
        self._spawner.spawn(name, pose, owner)

    def delete(self, name: str) -> None:
        """Robot ``name`` out of the arena and the class."""
        self._spawner.delete(name)

    def caller(self, session: Session) -> Caller:
        """The instructor may do anything; a student, their own robot and their spawns."""
        if session.is_admin and session.instructor:
            return Caller(admin=True, drives=None)
        if session.is_admin or session.may_drive:  # the robot's token (or an open class)
            return Caller(admin=False, drives=frozenset({self.name}), name=self.name,
                          spawn_quota=self._quota)
        return Caller(admin=False, drives=frozenset())


class _Stepping:
    """One stepping request of a world: runs after each tick of the server."""

    def __init__(self, world: WorldControl, steps: int, progress: Progress) -> None:
        self._world = world
        self.left = steps
        self._done = 0
        self._progress = progress

    def tick(self) -> None:
        """After a tick of the server: one step, or the end of the request."""
        world = self._world
        if not world.paused:
            world._end_stepping(self)
            self._progress(self._done, "the simulation was played while it was being "
                                       f"stepped ({self._done} of {self._done + self.left} "
                                       "steps done)")
            return
        world._run_step()
        self.left -= 1
        self._done += 1
        if self.left <= 0:
            world._end_stepping(self)
        self._progress(self._done, None)

    def cancel(self) -> None:
        """No more steps."""
        self._world._end_stepping(self)
