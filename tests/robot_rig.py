"""One rig for driving a robot's ticks in unit tests: a robot, its host and bridge, one clock.

``robot_rig()`` builds what ``websim serve`` builds for one robot (``VirtualRobot`` on a
``Simulation``, its world's ``WorldHost`` and the robot's ``RobotHost`` with its bridge and
endpoint) on a ``ManualClock``, without sockets or an event loop: the test connects sessions,
feeds them frames and ticks the world by hand (``WorldHost.tick``, what the tick driver does
for each world).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import cbor2

from physics import LidarParams, NoiseParams, Simulation, load_world
from ros_nodes.robot_host import RobotHost
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.bridge import Bridge
from rosbridge.core.clock import ManualClock
from rosbridge.core.limits import LatchedBytes
from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Flush, Session


@dataclass
class RobotRig:
    """A hosted robot and the clock it runs on.

    Attributes:
        host: the robot's host (its bridge, endpoint, statistics).
        clock: the robot's one clock; it moves only when the test (or ``tick``) says.
        world: the host of the robot's world (what the tick driver ticks).
    """

    host: RobotHost
    clock: ManualClock
    world: WorldHost
    tick_listeners: list[Callable[[], None]] = field(default_factory=list)
    """Called after every tick, as the tick driver calls its own (``TickDriver``)."""

    def write(self, flush: Flush) -> None:
        """The tick driver's write: nothing to write here (frames stay in the outboxes)."""

    @property
    def robot(self) -> VirtualRobot:
        """The robot."""
        return self.host.robot

    @property
    def bridge(self) -> Bridge:
        """The robot's bridge."""
        return self.host.bridge

    def client(self, peer: str = "test-peer", admin: bool = False,
               outbox: Outbox | None = None) -> Session:
        """A connected client session (its frames queue in ``outbox``)."""
        session = Session(peer, admin, Outbox() if outbox is None else outbox)
        self.bridge.connect(session)
        return session

    def send(self, session: Session, message: Any) -> None:
        """``session`` sends ``message`` (a dict as JSON; text or bytes as they are)."""
        self.bridge.handle(session, message if isinstance(message, (str, bytes))
                           else json.dumps(message))

    def tick_now(self, lateness_s: float = 0.0) -> None:
        """One tick of its world at the clock's present time (the clock is not moved), then
        the tick listeners, as the tick driver runs them."""
        self.world.tick(_ignore, lateness_s)
        for listener in list(self.tick_listeners):
            listener()

    def tick(self, n: int = 1, lateness_s: float = 0.0) -> None:
        """``n`` ticks of its world, the clock moving one tick period (``dt_s``) after each.

        Frames go to the sessions' outboxes (no connection writes them here).
        """
        for _ in range(n):
            self.tick_now(lateness_s)
            self.clock.advance(self.robot.sim.dt_s)

    @staticmethod
    def drain(session: Session) -> list[Any]:
        """Every frame queued for ``session``, decoded (JSON or CBOR), oldest first."""
        frames = []
        while (frame := session.outbox.pop()) is not None:
            frames.append(cbor2.loads(frame) if isinstance(frame, bytes) else json.loads(frame))
        return frames

    def call(self, session: Session, service: str, args: Any = None,
             call_id: str = "c1") -> Any:
        """``session`` calls ``service``: its one ``service_response`` (other frames dropped)."""
        self.send(session, {"op": "call_service", "service": service, "id": call_id,
                            "args": {} if args is None else args})
        replies = [frame for frame in self.drain(session) if frame.get("op") == "service_response"]
        assert len(replies) == 1, replies
        assert replies[0]["id"] == call_id
        return replies[0]


def robot_rig(world: str = "empty", *, seed: int = 0, mode: str = "kinematic",
              lidar: LidarParams | None = None, noise: NoiseParams | None = None,
              clock: ManualClock | None = None,
              idle_pause_s: float | None = None,
              latched: LatchedBytes | None = None) -> RobotRig:
    """A robot in ``world`` (a shipped name or a file), hosted, on a manual clock.

    Args:
        world: the world.
        seed: the simulation's seed.
        mode: ``"kinematic"`` or ``"dynamic"``.
        lidar: the LiDAR (default: the shipped one).
        noise: the noise sigmas (default: none).
        clock: the clock (default: a ``ManualClock`` at 0 s).
        idle_pause_s: the host pauses the robot after this long without clients (s); None:
            never.
        latched: the robot's pool of clients' latched messages (default: its own).
    """
    clock = ManualClock() if clock is None else clock
    sim = Simulation(load_world(world), seed=seed, mode=mode, lidar=lidar, noise=noise)
    world_host, host = WorldHost.of(VirtualRobot(sim, clock), idle_pause_s, latched)
    return RobotRig(host, clock, world_host)


def _ignore(flush: Flush) -> None:
    """No connection to write: the frames stay in the sessions' outboxes for the test."""
