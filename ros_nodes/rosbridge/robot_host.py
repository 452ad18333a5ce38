"""One robot in real time: its simulation, its bridge, its tick loop, its health.

A ``RobotHost`` owns everything of one robot and nothing of another, so a server may run
several. Its tick loop runs against the monotonic clock (deadlines advance by exactly one
period, so there is no drift) and is the robot's fault boundary: an exception while stepping
the robot, or while encoding or delivering one of its messages, is recorded
(``Faults``: logged once with the cause, counted, ``/healthz`` says ``degraded``) and the loop
goes on; a robot whose state went non-finite is reset to its spawn pose. When the host cannot
keep up (a tick starts half a period late), that tick's /scan is shed first; /odom and /tf
keep their rate.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Any

from physics import TICK_PERIOD_S
from ros_nodes.rosbridge.bridge import Bridge
from ros_nodes.rosbridge.faults import Faults
from ros_nodes.rosbridge.robot_endpoint import RobotEndpoint
from ros_nodes.topics import SCAN
from ros_nodes.virtual_robot_core import Publication, VirtualRobot

log = logging.getLogger("websim.robot")

SHED_SCANS_AFTER_S = 0.025
"""A tick that starts this late (half a period: the host cannot keep up with the clients)
publishes no /scan: the biggest message goes first, /odom and /tf keep their rate."""

AFTER_TICK_S = 0.002
"""Work waiting for a tick to pass resumes this long after the tick's deadline."""

MAX_TICKS_WAITED = 3
"""Work waits for room before at most this many ticks, then runs regardless (it may be
larger than a period)."""

RESYNC_AFTER_S = 1.0
"""If the tick loop falls this far behind (a suspended laptop), it restarts its schedule
instead of replaying every missed tick at once."""


@dataclass
class TickStats:
    """What the tick loop has done, for /healthz and benchmarks.

    Attributes:
        ticks: ticks run since start.
        started_s: when the schedule started (event-loop monotonic s), None before.
        lateness_s: how late each recent tick started after its deadline (s).
        resyncs: times the schedule was restarted after falling far behind.
        scans_shed: /scan messages not published because their tick was late.
        resets: times the robot was reset because a fault left it in a non-finite state.
    """

    ticks: int = 0
    started_s: float | None = None
    lateness_s: deque[float] = field(default_factory=lambda: deque(maxlen=1200))
    resyncs: int = 0
    scans_shed: int = 0
    resets: int = 0

    def jitter_p99_ms(self) -> float:
        """99th percentile of recent tick lateness (ms)."""
        samples = sorted(self.lateness_s)
        if not samples:
            return 0.0
        return 1000.0 * samples[min(len(samples) - 1, int(0.99 * len(samples)))]


class RobotHost:
    """A robot, its bridge and its tick loop.

    Args:
        robot: the virtual robot to run.
        period_s: tick period (s).
    """

    def __init__(self, robot: VirtualRobot, period_s: float = TICK_PERIOD_S) -> None:
        self.robot = robot
        self.faults = Faults()
        self.bridge = Bridge(faults=self.faults)
        self.endpoint = RobotEndpoint(self.bridge, robot)
        self.stats = TickStats()
        self._period_s = period_s
        self._next_deadline_s: float | None = None

    async def run_ticks(self) -> None:
        """Tick forever at ``period_s``, deadlines fixed to the monotonic clock."""
        loop = asyncio.get_running_loop()
        deadline = loop.time()
        self.stats.started_s = deadline
        while True:
            deadline += self._period_s
            self._next_deadline_s = deadline
            delay = deadline - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            now = loop.time()
            if now - deadline > RESYNC_AFTER_S:
                log.warning("tick loop %.1f s behind; restarting its schedule", now - deadline)
                self.stats.resyncs += 1
                self.stats.started_s = now - self.stats.ticks * self._period_s
                deadline = now
            lateness_s = max(0.0, now - deadline)
            self.stats.lateness_s.append(lateness_s)
            self.tick(lateness_s)

    async def before_tick_room(self, cost_s: float) -> None:
        """Wait until ``cost_s`` of work can run before the next tick is due.

        Large client frames are handled between ticks, not across one: work that would make
        the next tick late waits until that tick has run.
        """
        loop = asyncio.get_running_loop()
        for _ in range(MAX_TICKS_WAITED):
            deadline = self._next_deadline_s
            if deadline is None or deadline - loop.time() >= cost_s:
                return
            await asyncio.sleep(max(0.0, deadline - loop.time()) + AFTER_TICK_S)

    def tick(self, lateness_s: float = 0.0) -> None:
        """One tick: step the robot, deliver its messages, expire service calls; never raises."""
        self.stats.ticks += 1
        publications = self._step()
        for spec, msg in publications:
            if spec is SCAN and lateness_s > SHED_SCANS_AFTER_S:
                self.stats.scans_shed += 1
                continue
            try:
                self.bridge.publish(spec.name, msg)
            except Exception as error:  # the robot's boundary: record, go on
                self.faults.record(f"delivering {spec.name}", error)
        try:
            self.bridge.services.expire()
        except Exception as error:
            self.faults.record("expiring service calls", error)

    def _step(self) -> list[Publication]:
        try:
            publications = self.robot.step()
        except Exception as error:  # the robot's boundary: record, recover, go on
            self.faults.record("stepping the robot", error)
            self._recover("its step failed")
            return []
        truth = self.robot.sim.ground_truth()
        if not all(math.isfinite(value) for value in truth):
            self.faults.record("stepping the robot", FloatingPointError(
                f"non-finite state {tuple(truth)}"))
            self._recover("its state went non-finite")
            return []
        return publications

    def _recover(self, why: str) -> None:
        """Put the robot back at spawn (a finite state) after a fault."""
        self.stats.resets += 1
        log.error("robot reset to its spawn pose: %s", why)
        try:
            self.robot.reset()
        except Exception as error:
            self.faults.record("resetting the robot", error)

    def health(self) -> dict[str, Any]:
        """This robot's part of /healthz."""
        started = self.stats.started_s
        due = 0 if started is None else int((time.monotonic() - started) / self._period_s)
        sessions = self.bridge.sessions
        report: dict[str, Any] = {
            "status": "degraded" if self.faults.degraded else "ok",
            "ticks": self.stats.ticks,
            "ticks_due": due,
            "tick_jitter_p99_ms": round(self.stats.jitter_p99_ms(), 3),
            "tick_resyncs": self.stats.resyncs,
            "scans_shed": self.stats.scans_shed,
            "robot_resets": self.stats.resets,
            "clients": len(sessions),
            "queued_frames": sum(len(session.outbox) for session in sessions),
            "queued_bytes": sum(session.outbox.queued_bytes for session in sessions),
            "sim_time_s": round(self.robot.sim.time_s, 3),
            "mode": self.robot.sim.mode,
            "world": self.robot.sim.world.name,
            "last_driver": self.endpoint.last_driver,
        }
        report.update(self.faults.report())
        return report
