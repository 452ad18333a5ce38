"""What the simulation services need of a world, and today's world of one robot.

``SimulatorControl`` is the seam between ROS 2's ``simulation_interfaces`` services
(``ros_nodes.simulation_services``: their requests, result codes and rights) and the world
they act on: its entities, their poses, pause, play and step, reset, spawn and delete. Today a
world holds one robot (``OneRobotWorld``: a ``RobotHost``, the single robot of ``websim
serve`` or one student's in a class); a world of many robots is one more adapter of the same
protocol.

Units and frames: poses are in the world's ``map`` frame (m, rad), velocities ``v`` (m/s,
along the heading) and ``omega`` (rad/s, counter-clockwise), as ``physics`` gives them.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Protocol

from physics import ConfigError
from physics.snapshots import Odometry, Pose2D
from ros_nodes.urdf import CHASSIS_HEIGHT_M, LASER_HEIGHT_M
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge
from rosbridge.core.session import Session
from rosbridge.transport.schedule import Schedule

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
        """Advance a held world ``steps`` ticks, one per tick of its schedule.

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
    """What ``OneRobotWorld`` uses of a ``RobotHost`` (structurally: no import of it)."""

    robot: VirtualRobot
    bridge: Bridge
    schedule: Schedule
    held: bool

    def tick(self, lateness_s: float = 0.0) -> None:
        """One tick of the robot (stepped unless held or idle)."""


class OneRobotWorld:
    """A world of one robot: a ``RobotHost`` (its simulation, bridge and ticks).

    Pausing is the host's hold (``/websim/pause`` holds the same); stepping runs the held
    robot's tick once after each tick of its schedule (``Schedule.tick_listeners``), so a
    step publishes what a tick publishes, stamped as a tick is. Spawning and deleting need a
    world of many robots: ``UnsupportedError`` here.

    Rights: the robot's admins (its token or the instructor's in a class; the admin token of
    a single robot) may do anything in it: the world holds nothing of anybody else. A client
    with the drive right (``Session.may_drive``) may move and reset the robot.

    Args:
        host: the robot's host.
        name: the robot's entity name (a class robot's name; ``robot`` for a single robot).
    """

    can_spawn = False

    def __init__(self, host: _Host, name: str) -> None:
        self._host = host
        self.name = name
        self._stopped = False
        self._stepping: _Stepping | None = None

    def entities(self) -> list[Entity]:
        """The robot."""
        params = self._host.robot.sim.params
        return [Entity(self.name, CATEGORY_ROBOT, ROBOT_DESCRIPTION, ROBOT_TAGS,
                       params.footprint_radius_m,
                       params.wheel_radius_m + CHASSIS_HEIGHT_M + LASER_HEIGHT_M)]

    def _sim_of(self, name: str) -> VirtualRobot:
        if name != self.name:
            raise KeyError(name)
        return self._host.robot

    def state(self, name: str) -> Odometry:
        """The robot's ground truth (map frame)."""
        return self._sim_of(name).sim.ground_truth()

    def teleport(self, name: str, pose: Pose2D) -> None:
        """The robot at rest at ``pose``, its odometry reading as it was (it was carried)."""
        robot = self._sim_of(name)
        odometry = robot.sim.odometry()
        robot.sim.place(pose, Pose2D(odometry.x, odometry.y, odometry.theta))

    def reset_entity(self, name: str) -> None:
        """The robot back at spawn (``/reset_simulation``'s reset)."""
        self._sim_of(name).reset()

    def reset(self, *, spawned: bool) -> None:
        """The robot back at spawn (nothing here was spawned)."""
        self._host.robot.reset()

    @property
    def paused(self) -> bool:
        """Held by an admin (``/websim/pause``, ``SetSimulationState``)."""
        return self._host.held

    @property
    def stopped(self) -> bool:
        """Held at its reset state since ``SetSimulationState`` STOPPED."""
        return self._host.held and self._stopped

    def set_paused(self, paused: bool, *, stopped: bool = False) -> None:
        """Hold or run the robot (what ``/websim/pause`` does)."""
        self._host.held = paused
        self._stopped = paused and stopped

    def step(self, steps: int, progress: Progress) -> Cancel:
        """Run ``steps`` ticks of the held robot, one after each tick of its schedule."""
        if not self._host.held:
            raise ConfigError("the simulation is not paused (SetSimulationState "
                              "STATE_PAUSED first)")
        if self._stepping is not None:
            raise ConfigError(f"the simulation is being stepped already "
                              f"({self._stepping.left} steps left)")
        stepping = _Stepping(self, steps, progress)
        self._stepping = stepping
        self._stopped = False
        self._host.schedule.tick_listeners.append(stepping.tick)
        return stepping.cancel

    def _run_step(self) -> None:
        """One tick of the held robot."""
        host = self._host
        host.held = False
        try:
            host.tick()
        finally:
            host.held = True

    def _end_stepping(self, stepping: _Stepping) -> None:
        listeners = self._host.schedule.tick_listeners
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
        """The world's start pose (the robot's spawn)."""
        return self._host.robot.sim.world.start

    def caller(self, session: Session) -> Caller:
        """Admins own this world; the drive right moves the robot."""
        return Caller(admin=session.is_admin,
                      drives=None if session.may_drive else frozenset())

    def stamp_s(self) -> float:
        """The robot's clock's stamp."""
        return self._host.robot.clock.stamp_s()

    def answered(self) -> None:
        """Write the bridge's queued frames through the schedule's writers."""
        self._host.schedule.writers.write(self._host.bridge.take_flush())


class _Stepping:
    """One stepping request of a ``OneRobotWorld``: runs after each tick of its schedule."""

    def __init__(self, world: OneRobotWorld, steps: int, progress: Progress) -> None:
        self._world = world
        self.left = steps
        self._done = 0
        self._progress = progress

    def tick(self) -> None:
        """After a tick of the schedule: one step, or the end of the request."""
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
