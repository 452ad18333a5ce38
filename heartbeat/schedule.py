"""One pace of ticks: deadlines without drift, room for large work, waits for its own clients.

A ``Schedule`` calls its tick every ``period_s / speed`` of wall time. At up to real time a
tick is due at its deadline and waits for nobody: a tick that starts late is late (a robot
sheds its /scan first) and a slow client gets the newest of each topic. Above real time
(``speed`` over 1, or ``SPEED_MAX``), ``period_s / speed`` is a pace not to exceed, not a
deadline: before each tick the clients read and write, and the schedule waits until each of
ITS clients (the connections that registered in its group of the loop's ``Writers``: a
robot's, never a classmate's) has taken the frames it was written, so a faster run drops
nothing and no tick is ever late (nothing is shed); a client that cannot keep the pace slows
its own robot's run, never loses its messages and never holds another robot. A client that
has not taken its frames within ``CLIENT_WAIT_S`` is released: the ticks go on without
waiting for it (it gets the newest of each topic, as a slow client does at real time) until
it has caught up, and the connection's stall watchdog closes it if its socket keeps taking
nothing. Whatever else must keep up with the ticks (a recording's writer) is waited for the
same way (``pacers``). A ``gate`` holds the next tick for as long as it says, whatever the
speed (a graded run in lock step with its controller: ``websim.grade_server``); the time it
held is not counted late.

The schedule is a ``rosbridge.transport.writers.Pace``: the connections of its robots make
room in it for their large frames and are written through its ``writers``.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Awaitable, Callable

from ros_nodes.sim_clock import SPEED_MAX
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

CATCH_UP_S = 0.05
"""Above real time, a schedule behind its pace runs ticks back to back to make up at most this
much wall time (a late wake-up); more is forgiven: the speed is a pace not to exceed."""

CLIENT_WAIT_S = 2.0
"""Above real time, how long a tick waits for a client to take the frames it was written
before it releases that client (wall time, s): two seconds for a tick's few kilobytes is a
client that stopped reading, not a slow one."""

CLIENT_POLL_S = 0.01
"""While waiting for clients, how often the schedule looks again besides when told (s)."""

Gate = Callable[[], Awaitable[None]]
"""Holds the next tick as long as it must (and bounds its own wait)."""


class Schedule:
    """One pace of ticks on an event loop.

    Deadlines advance by exactly one period on the clock's monotonic time (no drift); a loop
    that falls ``RESYNC_AFTER_S`` behind restarts its schedule instead of replaying the ticks.
    Before each tick, whatever waits for a connection is written (``Writers.sweep``: frames
    queued between ticks by something other than a client's frame, a ROS graph's answers).

    Args:
        period_s: tick period (s of sim time; of wall time at real time).
        clock: what the deadlines are read on (its ``monotonic_s``; default: wall time).
        speed: times real time the ticks run (1: real time; ``SPEED_MAX``: back to back).
        writers: the event loop's connections (default: a set of its own), where flushes are
            written; it waits for those of its own group (itself).
        gates: awaited in turn before every tick, at any speed (default: its own list).
        pacers: above real time, waited for as clients are: each says whether it has taken
            what the ticks gave it (a recording's writer); one that has not within
            ``CLIENT_WAIT_S`` is not waited for at that tick (default: its own list).
        tick_listeners: called after every tick (default: its own list).

    Attributes:
        speed: times real time the ticks run.
        ahead: whether that is above real time (the ticks wait for the clients, never shed).
        wall_period_s: wall time per tick at that speed (0 at ``max``).
        started_s: when the schedule started (the clock's monotonic s), None before.
        ticks: ticks it has run.
        resyncs: times the schedule was restarted after falling far behind.
        clients_released: times a client was released (not waited for) above real time.
    """

    def __init__(self, period_s: float, clock: Clock = WALL_CLOCK, speed: float = 1.0,
                 writers: Writers | None = None, gates: list[Gate] | None = None,
                 pacers: list[Callable[[], bool]] | None = None,
                 tick_listeners: list[Callable[[], None]] | None = None) -> None:
        self.period_s = period_s
        self.clock = clock
        self.speed = speed
        self.ahead = speed > 1.0
        self.wall_period_s = 0.0 if speed == SPEED_MAX else period_s / speed
        self.writers = Writers() if writers is None else writers
        self.gates: list[Gate] = [] if gates is None else gates
        self.pacers: list[Callable[[], bool]] = [] if pacers is None else pacers
        self.tick_listeners: list[Callable[[], None]] = \
            [] if tick_listeners is None else tick_listeners
        self.started_s: float | None = None
        self.ticks = 0
        self.resyncs = 0
        self.clients_released = 0
        self._next_deadline_s: float | None = None

    async def run(self, tick: Callable[[float], None]) -> None:
        """Call ``tick(lateness_s)`` every period, forever (above real time: lateness 0)."""
        clock = self.clock
        deadline = clock.monotonic_s()
        self.started_s = deadline
        while True:
            deadline += self.wall_period_s
            self._next_deadline_s = deadline
            delay = deadline - clock.monotonic_s()
            if delay > 0:
                await asyncio.sleep(delay)
            elif self.ahead:
                await asyncio.sleep(0)  # the clients read and write between ticks
            if self.ahead:
                await self._wait_for_clients()
            if self.gates:
                gated_s = clock.monotonic_s()
                for gate in self.gates:
                    await gate()
                deadline += max(0.0, clock.monotonic_s() - max(gated_s, deadline))
            now = clock.monotonic_s()
            if self.ahead:
                deadline = max(deadline, now - CATCH_UP_S)
            elif now - deadline > RESYNC_AFTER_S:
                log.warning("tick loop %.1f s behind; restarting its schedule", now - deadline)
                self.resyncs += 1
                self.started_s = now - self.ticks * self.wall_period_s
                deadline = now
            self.ticks += 1
            self.writers.sweep()
            tick(0.0 if self.ahead else max(0.0, now - deadline))
            for listener in self.tick_listeners:
                try:
                    listener()
                except Exception:  # a listener's fault must not stop the ticks
                    log.exception("a tick listener failed")

    async def _wait_for_clients(self) -> None:
        """Wait until each of its clients and every pacer has taken its frames.

        A client that does not within ``CLIENT_WAIT_S`` is released.
        """
        writers, clock = self.writers, self.clock
        waiting = writers.waiting(self)
        if not waiting and self._paced():
            return
        started_s = clock.monotonic_s()
        while waiting or not self._paced():
            left_s = CLIENT_WAIT_S - (clock.monotonic_s() - started_s)
            if left_s <= 0:
                if waiting:
                    writers.release(waiting)
                    self.clients_released += len(waiting)
                    log.warning("%d client(s) did not take one tick's frames within %g s: "
                                "the ticks go on without waiting for them (they get the "
                                "newest of each topic until they catch up)", len(waiting),
                                CLIENT_WAIT_S)
                return
            await writers.progress(min(left_s, CLIENT_POLL_S))
            waiting = writers.waiting(self)

    def _paced(self) -> bool:
        """Whether every pacer has taken what it was given."""
        return all(pacer() for pacer in self.pacers)

    def ticks_due(self) -> int:
        """Ticks the schedule should have run by now (above real time: those it ran)."""
        if self.started_s is None:
            return 0
        if self.ahead:
            return self.ticks
        return int((self.clock.monotonic_s() - self.started_s) / self.wall_period_s)

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
