"""A robot and its bridge driven in-process, for the tests of the protocol layer.

The Bridge does no I/O, so these tests feed it frames and read what it queued per client.
A hand-advanced monotonic clock stands in for time where throttling and timeouts are checked.
"""

from __future__ import annotations

import json
from typing import Any

import cbor2

from physics import LidarParams, Simulation, load_world
from ros_nodes.robot_endpoint import RobotEndpoint
from ros_nodes.virtual_robot_core import VirtualRobot
from rosbridge.core.bridge import Bridge, Session
from rosbridge.core.clock import ManualClock
from rosbridge.core.outbox import Outbox


class Clock:
    def __init__(self) -> None:
        self.now_s = 100.0

    def __call__(self) -> float:
        return self.now_s

    def monotonic_s(self) -> float:
        return self.now_s

    def stamp_s(self) -> float:
        return 1_700_000_000.0 + self.now_s


class Rig:
    """A robot, its bridge, and helpers to act as clients."""

    def __init__(self, lidar: LidarParams | None = None) -> None:
        self.clock = Clock()
        self.robot = VirtualRobot(Simulation(load_world("empty"), lidar=lidar, seed=0),
                                  clock=ManualClock(epoch_s=1_700_000_000.25))
        self.bridge = Bridge(clock=self.clock)
        self.endpoint = RobotEndpoint(self.bridge, self.robot)

    def client(self, admin: bool = False) -> Session:
        session = Session("test-peer", admin, Outbox())
        self.bridge.connect(session)
        return session

    def send(self, session: Session, message: Any) -> None:
        self.bridge.handle(session, message if isinstance(message, (str, bytes))
                           else json.dumps(message))

    def tick(self, n: int = 1) -> None:
        for _ in range(n):
            for spec, msg in self.robot.step():
                self.bridge.publish(spec.name, msg)

    @staticmethod
    def drain(session: Session) -> list[Any]:
        frames = []
        while (frame := session.outbox.pop()) is not None:
            frames.append(cbor2.loads(frame) if isinstance(frame, bytes) else json.loads(frame))
        return frames

    def call(self, session: Session, service: str, args: Any = None, call_id: str = "c1") -> Any:
        self.send(session, {"op": "call_service", "service": service, "id": call_id,
                            "args": {} if args is None else args})
        replies = [f for f in self.drain(session) if f.get("op") == "service_response"]
        assert len(replies) == 1, replies
        assert replies[0]["id"] == call_id
        return replies[0]


def topics_of(frames: list[Any]) -> list[str]:
    return [f["topic"] for f in frames if f.get("op") == "publish"]
