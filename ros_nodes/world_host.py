"""A world served: its simulation and the hosts of its robots, one tick at a time.

``WorldHost`` is what the tick driver (``heartbeat.driver``) ticks. A tick of a world has
three parts, so the driver can do the middle one for many worlds at once:

1. ``begin_tick``: each robot's part before the step (held or idle robots sit it out; the
   command watchdog), the world's one ``step`` for all its robots, each robot's part after
   (collision count; a state gone non-finite is reset);
2. the tick's scan pass: ``scans_due`` lists the robots whose LiDAR scan a message will read;
   the driver casts them with every other world's (``physics.simulation.cast_scans``);
3. ``end_tick``: each robot's host builds its messages (the scans are ready) and delivers them,
   with the world's own, ``/world_robots``, built once for all of them.

A world of one robot (``websim serve``, each student's in a class) whose robot is paused is
not stepped at all: its time stands still. In a world of several (an arena) a paused robot is
held where it stands (``WorldSim.hold``) while the others go on, and the world stops only
when every robot is paused or the world itself is (``WorldSim.paused``).
"""

from __future__ import annotations

from collections.abc import Iterator

from physics import Simulation, WorldSim
from physics.simulation import cast_scans
from ros_nodes.robot_host import RobotHost, Write
from ros_nodes.robot_interface import WORLD_ROBOTS
from ros_nodes.robot_messages import world_robots_msg
from ros_nodes.virtual_robot_core import Publication, VirtualRobot
from rosbridge.core.clock import Clock
from rosbridge.core.limits import LatchedBytes


class WorldHost:
    """A world and the hosts of its robots, ticked as one.

    Args:
        world: the world's simulation (its robots' ``Simulation`` views are of it).
        idle_pause_s: a robot nobody has been connected to for this long pauses (None: never).

    Attributes:
        world: the world's simulation.
        hosts: each robot's host, by its name in the world.
    """

    def __init__(self, world: WorldSim, idle_pause_s: float | None = None) -> None:
        self.world = world
        self.hosts: dict[str, RobotHost] = {}
        self._idle_pause_s = idle_pause_s
        self._stepped: list[RobotHost] = []
        self._clock: Clock | None = None

    @classmethod
    def of(cls, robot: VirtualRobot, idle_pause_s: float | None = None,
           latched: LatchedBytes | None = None) -> tuple[WorldHost, RobotHost]:
        """The host of ``robot``'s world with ``robot`` in it, and the robot's host."""
        world_host = cls(robot.sim.world_sim, idle_pause_s)
        return world_host, world_host.add(robot, latched)

    @property
    def clock(self) -> Clock | None:
        """Its robots' clock (one per world: every robot of a world stamps with its time)."""
        return self._clock

    def add(self, robot: VirtualRobot, latched: LatchedBytes | None = None) -> RobotHost:
        """Serve ``robot``, a robot of this world (``robot.sim`` is its view of it).

        Raises:
            ValueError: the robot lives in another world, or runs on another clock than this
                world's other robots.
        """
        sim = robot.sim
        if sim.world_sim is not self.world:
            raise ValueError(f"robot '{sim.name}' lives in another world than "
                             f"'{self.world.world.name}'")
        if self._clock is not None and robot.clock is not self._clock:
            raise ValueError("every robot of a world runs on its one clock")
        self._clock = robot.clock
        host = RobotHost(robot, self._idle_pause_s, latched)
        self.hosts[sim.name] = host
        return host

    def remove(self, name: str) -> RobotHost:
        """Stop serving robot ``name`` and take it out of the world; its host (KeyError)."""
        host = self.hosts.pop(name)
        if name in self.world:
            self.world.delete(name)
        return host

    def __iter__(self) -> Iterator[tuple[str, RobotHost]]:
        return iter(list(self.hosts.items()))

    def __len__(self) -> int:
        return len(self.hosts)

    def begin_tick(self, lateness_s: float = 0.0) -> bool:
        """Step the world once for all its robots, unless all are paused; whether it stepped.

        Never raises: a fault of a robot is its own (recorded, the robot reset to its spawn);
        one of the world's step is every stepping robot's.
        """
        hosts = list(self.hosts.values())
        world = self.world
        paused = {host: host.pausing() or world.paused for host in hosts}
        stepping = [host for host in hosts if not paused[host]]
        self._stepped = []
        if not stepping:
            return False
        if len(hosts) > 1:  # a shared world runs on: a paused robot is held where it stands
            for host in hosts:
                name = host.robot.sim.name
                if world.is_held(name) != paused[host]:
                    world.hold(name, paused[host])
        stepping = [host for host in stepping if host.before_step(lateness_s)]
        try:
            world.step()
        except Exception as error:  # every robot that stepped shares the world's fault
            for host in stepping:
                host.faults.record("stepping the robot", error)
                host.recover("its step failed")
            return False
        self._stepped = [host for host in stepping if host.after_step()]
        return bool(self._stepped)

    def scans_due(self, lateness_s: float = 0.0) -> list[Simulation]:
        """The robots stepped this tick whose messages will read their LiDAR's scan."""
        return [host.robot.sim for host in self._stepped if host.reads_scan(lateness_s)]

    @property
    def crowded(self) -> bool:
        """Whether its tick delivers in two parts (more than one robot stepped).

        Every robot's /odom and /tf, then the scan pass, then the scans: in one part each
        robot's /odom would wait for every robot's scan and the messages of those before it.
        """
        return len(self._stepped) > 1

    def end_tick(self, write: Write, lateness_s: float = 0.0,
                 scans: bool | None = None) -> None:
        """Each stepped robot builds and delivers its messages (``RobotHost.end_tick``).

        ``scans``: only the messages that read the LiDAR's scan (True: after the scan pass),
        only the others (False: before it), or all (None). The world's own message,
        ``/world_robots`` (every robot at this tick), is built once for all its robots, if a
        client of one of them wants it, and goes out with the others.
        """
        shared = self._shared_publications() if not scans else []
        for host in self._stepped:
            host.end_tick(write, lateness_s, shared, scans)

    def _shared_publications(self) -> list[Publication]:
        if not any(host.wants(WORLD_ROBOTS.name) for host in self._stepped):
            return []
        world = self.world
        try:
            footprints = world.footprints()
            msg = world_robots_msg(world.names, world.poses().tolist(),
                                   footprints[:, 2].tolist(),
                                   self._stepped[0].robot.clock.stamp_s())
        except Exception as error:  # the world's message: every robot's fault
            for host in self._stepped:
                host.faults.record(f"building {WORLD_ROBOTS.name}", error)
            return []
        return [(WORLD_ROBOTS, msg)]

    def tick(self, write: Write, lateness_s: float = 0.0) -> None:
        """A whole tick of this world alone: step, its own scan pass, deliver."""
        if self.begin_tick(lateness_s):
            crowded = self.crowded
            if crowded:
                self.end_tick(write, lateness_s, scans=False)
            due = self.scans_due(lateness_s)
            if len(due) > 1:
                cast_scans(due)
            self.end_tick(write, lateness_s, scans=True if crowded else None)
