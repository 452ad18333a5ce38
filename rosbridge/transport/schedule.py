"""The tick schedule of one event loop: deadlines without drift, room for large work.

It also holds the loop's ``Writers``: the connections register there, and whoever runs a
tick writes what it returns through them.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable

from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.transport.writers import Writers

log = logging.getLogger("websim.robot")

AFTER_TICK_S = 0.002
"""Work waiting for a tick to pass resumes this long after the tick's deadline."""

MAX_TICKS_WAITED = 3
"""Work waits for room before at most this many ticks, then runs regardless (it may be
larger than a period)."""

RESYNC_AFTER_S = 1.0
"""If the tick loop falls this far behind (a suspended laptop), it restarts its schedule
instead of replaying every missed tick at once."""


class Schedule:
    """The tick schedule of one event loop, shared by every robot on it.

    Deadlines advance by exactly one period on the clock's monotonic time (no drift); a loop
    that falls ``RESYNC_AFTER_S`` behind restarts its schedule instead of replaying the ticks.
    Before each tick, whatever waits for a connection is written (``Writers.sweep``: frames
    queued between ticks by something other than a client's frame, a ROS graph's answer).

    Args:
        period_s: tick period (s).
        clock: what the deadlines are read on (its ``monotonic_s``; default: wall time).

    Attributes:
        started_s: when the schedule started (the clock's monotonic s), None before.
        resyncs: times the schedule was restarted after falling far behind.
        writers: the connections of the loop, where flushes are written.
    """

    def __init__(self, period_s: float, clock: Clock = WALL_CLOCK) -> None:
        self.period_s = period_s
        self.clock = clock
        self.writers = Writers()
        self.started_s: float | None = None
        self.resyncs = 0
        self._ticks = 0
        self._next_deadline_s: float | None = None

    async def run(self, tick: Callable[[float], None]) -> None:
        """Call ``tick(lateness_s)`` every period, forever."""
        clock = self.clock
        deadline = clock.monotonic_s()
        self.started_s = deadline
        while True:
            deadline += self.period_s
            self._next_deadline_s = deadline
            delay = deadline - clock.monotonic_s()
            if delay > 0:
                await asyncio.sleep(delay)
            now = clock.monotonic_s()
            if now - deadline > RESYNC_AFTER_S:
                log.warning("tick loop %.1f s behind; restarting its schedule", now - deadline)
                self.resyncs += 1
                self.started_s = now - self._ticks * self.period_s
                deadline = now
            self._ticks += 1
            self.writers.sweep()
            tick(max(0.0, now - deadline))

    def ticks_due(self) -> int:
        """Ticks the schedule should have run by now."""
        if self.started_s is None:
            return 0
        return int((self.clock.monotonic_s() - self.started_s) / self.period_s)

    async def room(self, cost_s: float) -> None:
        """Wait until ``cost_s`` of work can run before the next tick is due.

        Large client frames are handled between ticks, not across one: work that would make
        the next tick late waits until that tick has run.
        """
        clock = self.clock
        for _ in range(MAX_TICKS_WAITED):
            deadline = self._next_deadline_s
            if deadline is None or deadline - clock.monotonic_s() >= cost_s:
                return
            await asyncio.sleep(max(0.0, deadline - clock.monotonic_s()) + AFTER_TICK_S)
