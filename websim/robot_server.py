"""The WebSocket front of ``websim serve`` with one robot: every path but ``/robots/...``."""

from __future__ import annotations

from typing import Any

from heartbeat.driver import TickDriver
from ros_nodes.robot_host import TickStats
from ros_nodes.robot_interface import ROBOTS_PREFIX
from ros_nodes.virtual_robot_core import VirtualRobot
from ros_nodes.world_host import WorldHost
from rosbridge.core.bridge import Bridge
from rosbridge.core.limits import ClientLimits, LatchedBytes, OriginPolicy
from rosbridge.transport.front import Destination, WebSocketFront


class SimServer(WebSocketFront):
    """The WebSocket front of one robot, at every path but ``/robots/...``.

    Args:
        robot: the virtual robot to run (its clock is the front's: uptime, client budgets;
            and its driver's: a ``SimClock`` sets the speed).
        admin_token: the secret that grants admin rights (``?token=`` in the URL).
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).

    Attributes:
        world: the robot's world, served.
        host: the robot's host (its bridge, endpoint, statistics).
        driver: the tick driver of the server (its one world).
    """

    def __init__(self, robot: VirtualRobot, admin_token: str,
                 limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None) -> None:
        super().__init__(admin_token, limits, origins, robot.clock)
        self.world, self.host = WorldHost.of(
            robot, latched=LatchedBytes.for_server(self.limits).for_robot())
        self.driver = TickDriver.for_clock(robot.clock)
        self._destination = Destination(self.host.bridge, self.driver.add(self.world))

    @property
    def robot(self) -> VirtualRobot:
        """The robot served."""
        return self.host.robot

    @property
    def bridge(self) -> Bridge:
        """The robot's bridge."""
        return self.host.bridge

    @property
    def stats(self) -> TickStats:
        """The robot's tick statistics."""
        return self.host.stats

    def route(self, path: str) -> tuple[Destination, str | None] | str:
        """The one robot, whatever the path (a proxy may pass its own), but ``/robots/...``."""
        if path.startswith(ROBOTS_PREFIX):
            return "this server runs one robot, not a class: connect to ws://HOST:PORT/"
        return self._destination, None

    async def run_ticks(self) -> None:
        """Run the tick driver forever."""
        await self.driver.run()

    def health(self, full: bool = True) -> dict[str, Any]:
        """A small status report: uptime, the robot's ticks, jitter, clients and faults.

        ``full`` False (public): without the last driver's address.
        """
        report = {**self.host.health(self.driver.report(self.world)),
                  "uptime_s": self._uptime_s()}
        if not full:
            report.pop("last_driver", None)
        return report

