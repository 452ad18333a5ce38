"""The robot rig as the protocol tests use it: the test moves the clock, ticks do not.

The Bridge does no I/O, so these tests feed it frames and read what it queued per client
(``robot_rig``: the robot, its host and bridge, as ``websim serve`` builds them). Here the
clock stands still while the robot ticks: a test that checks throttling or timeouts sets
``rig.clock.now_s`` itself.
"""

from __future__ import annotations

from typing import Any

from robot_rig import RobotRig, robot_rig

from physics import LidarParams
from ros_nodes.robot_endpoint import RobotEndpoint
from rosbridge.core.limits import LatchedBytes

START_S = 100.0
"""The clock's monotonic time when a rig starts (s)."""

START_STAMP_S = 1_700_000_000.25
"""The robot's stamps at ``START_S`` (s since the epoch)."""


class Clock:
    """A clock whose monotonic time a test sets (``now_s``, forward or back); stamps follow."""

    def __init__(self) -> None:
        self.now_s = START_S

    def monotonic_s(self) -> float:
        """``now_s``."""
        return self.now_s

    def stamp_s(self) -> float:
        """``START_STAMP_S`` at ``START_S``, moving with ``now_s``."""
        return START_STAMP_S + (self.now_s - START_S)

    def __call__(self) -> float:
        return self.now_s


class Rig(RobotRig):
    """A hosted robot on a ``Clock`` that ticks without moving it."""

    def __init__(self, lidar: LidarParams | None = None,
                 latched: LatchedBytes | None = None) -> None:
        rig = robot_rig("empty", lidar=lidar, clock=Clock(),  # type: ignore[arg-type]
                        latched=latched)
        super().__init__(rig.host, rig.clock, rig.world)

    @property
    def endpoint(self) -> RobotEndpoint:
        """The robot's endpoint on its bridge."""
        return self.host.endpoint

    def tick(self, n: int = 1, lateness_s: float = 0.0) -> None:
        """``n`` ticks of its world at the clock's present time."""
        for _ in range(n):
            self.tick_now(lateness_s)


def topics_of(frames: list[Any]) -> list[str]:
    return [f["topic"] for f in frames if f.get("op") == "publish"]
