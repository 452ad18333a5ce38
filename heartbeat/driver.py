"""The one tick driver of a server: every world's ticks, and each robot's messages out.

Nothing else ticks. A tick of a set of worlds is::

    commands (already applied as they came in)
      -> each world's one step for all its robots           (WorldHost.begin_tick)
      -> a crowded world's /odom and /tf out                 (WorldHost.end_tick, scans=False)
      -> one scan pass for every robot of those worlds due   (physics.simulation.cast_scans)
      -> each robot's endpoint builds and delivers the rest  (WorldHost.end_tick)
      -> the flushes written through the loop's connections  (Writers)

Paces (``heartbeat.schedule.Schedule``). At up to real time every world keeps one pace, the
server's deadlines: a class's worlds are ticked in up to ``SLOTS`` groups spread over
``SPREAD`` of the period, so a robot's frames go out right after its group's step, not after
the whole class's. Above real time (``--speed`` over 1) each world keeps its own pace: it
waits only for its own clients (a class's robot never waits for a classmate's watchers), and
a watcher that cannot keep up is released without holding anyone else. Worlds whose robots
share one sim clock (a class on the ROS graph, which has one ``/clock``) share one pace, and
that clock counts the pace's ticks.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
from collections.abc import Callable, Iterable
from typing import Any

from heartbeat.schedule import Gate, Schedule
from physics import TICK_PERIOD_S
from physics.simulation import cast_scans
from ros_nodes.sim_clock import SimClock, speed_text
from ros_nodes.world_host import WorldHost
from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.core.session import Flush
from rosbridge.transport.writers import Writers

log = logging.getLogger("websim.robot")

SPREAD = 0.8
"""Share of the tick period the worlds' ticks are spread over at real time (the last group
steps 40 ms after the first at 20 Hz, leaving the rest of the period for the frames to go
out)."""

SLOTS = 10
"""The spread's slots per period: worlds are ticked in up to this many groups, one group every
``SPREAD / SLOTS`` of the period (4 ms at 20 Hz). A robot's frames go out after its group,
not after the whole class; and the event loop wakes ten times a tick, not once per world."""


class TickDriver:
    """Every world of a server, ticked: one driver, one tick counter per pace.

    Args:
        period_s: the tick (s of sim time).
        clock: what deadlines are read on (its ``monotonic_s``: wall time).
        speed: times real time (1: real time; a ``SimClock``'s speed: ``--speed``).

    Attributes:
        writers: the event loop's connections; every flush is written through them.
        gates: awaited before every tick of every pace (a graded run's lock step).
        pacers: above real time, waited for before every tick as clients are (recordings).
        tick_listeners: called after every tick of every pace.
        ahead: whether it runs above real time (each world at its own pace).
    """

    def __init__(self, period_s: float = TICK_PERIOD_S, clock: Clock = WALL_CLOCK,
                 speed: float = 1.0) -> None:
        self.period_s = period_s
        self.clock = clock
        self.speed = speed
        self.ahead = speed > 1.0
        self.writers = Writers()
        self.gates: list[Gate] = []
        self.pacers: list[Callable[[], bool]] = []
        self.tick_listeners: list[Callable[[], None]] = []
        self.shared = self._schedule()
        """The pace of every world at up to real time (and of the instructor's view)."""
        self._paces: dict[WorldHost, Schedule] = {}
        self._by_clock: dict[int, Schedule] = {}
        self._members: dict[Schedule, list[WorldHost]] = {self.shared: []}
        self._tasks: dict[Schedule, asyncio.Task[None]] = {}
        self._running = False

    def _schedule(self) -> Schedule:
        return Schedule(self.period_s, self.clock, self.speed, self.writers, self.gates,
                        self.pacers, self.tick_listeners)

    @classmethod
    def for_clock(cls, clock: Clock, period_s: float = TICK_PERIOD_S) -> TickDriver:
        """The driver of robots on ``clock``: at its speed if a ``SimClock``, else real time.

        Its deadlines are read on ``clock``'s monotonic time (wall time).
        """
        speed = clock.speed if isinstance(clock, SimClock) else 1.0
        return cls(period_s, clock, speed)

    # ---- worlds ---------------------------------------------------------------------------

    def add(self, world: WorldHost) -> Schedule:
        """Tick ``world`` from now on; the pace its connections follow (a ``Pace``)."""
        pace = self.shared
        clock = world.clock
        if self.ahead:
            key = id(clock) if isinstance(clock, SimClock) else id(world)
            pace = self._by_clock.get(key) or self._schedule()
            self._by_clock[key] = pace
        members = self._members.setdefault(pace, [])
        members.append(world)
        self._paces[world] = pace
        if isinstance(clock, SimClock) and sum(other.clock is clock for other in members) == 2:
            # One clock for several worlds: it counts their pace's ticks from now on, on from
            # where it stood (no stamp goes back or jumps).
            offset = clock.ticks - pace.ticks
            clock.follow(lambda: pace.ticks + offset)
        if self._running and pace is not self.shared and pace not in self._tasks:
            self._start(pace)
        return pace

    def remove(self, world: WorldHost) -> None:
        """Tick ``world`` no more."""
        pace = self._paces.pop(world, None)
        if pace is None:
            return
        members = self._members[pace]
        members.remove(world)
        if not members and pace is not self.shared:
            del self._members[pace]
            self._by_clock = {key: value for key, value in self._by_clock.items()
                              if value is not pace}
            task = self._tasks.pop(pace, None)
            if task is not None:
                task.cancel()

    def pace(self, world: WorldHost) -> Schedule:
        """The pace ``world`` keeps (KeyError: not ticked here)."""
        return self._paces[world]

    @property
    def worlds(self) -> list[WorldHost]:
        """Every world ticked, in the order they were added."""
        return list(self._paces)

    def report(self, world: WorldHost) -> dict[str, Any]:
        """What ``/healthz`` says of ``world``'s pace, for each of its robots."""
        pace = self._paces.get(world, self.shared)
        return {"ticks_due": pace.ticks_due(), "tick_resyncs": pace.resyncs,
                "speed": speed_text(pace.speed), "clients_released": pace.clients_released}

    # ---- running --------------------------------------------------------------------------

    async def run(self) -> None:
        """Tick every world forever: one pace at up to real time, one per world above it."""
        self._running = True
        try:
            if not self.ahead:
                await self.shared.run(self._tick_spread)
                return
            for pace in list(self._members):
                if pace is not self.shared:
                    self._start(pace)
            await asyncio.Event().wait()  # the paces' tasks tick; this one waits for the end
        finally:
            self._running = False
            tasks = list(self._tasks.values())
            self._tasks.clear()
            for task in tasks:
                task.cancel()
            for task in tasks:
                with contextlib.suppress(asyncio.CancelledError):
                    await task

    def _start(self, pace: Schedule) -> None:
        def tick(lateness_s: float) -> None:
            self.tick(self._members.get(pace, ()), lateness_s)

        self._tasks[pace] = asyncio.get_running_loop().create_task(self._run_pace(pace, tick))

    @staticmethod
    async def _run_pace(pace: Schedule, tick: Callable[[float], None]) -> None:
        try:
            await pace.run(tick)
        except asyncio.CancelledError:
            raise
        except Exception:  # pragma: no cover - a pace's loop itself failing
            log.exception("a world's tick loop failed")

    def _tick_spread(self, lateness_s: float) -> None:
        """A real-time tick of every world, spread in up to ``SLOTS`` groups over the period.

        The first group now; each next one a slot later, one loop turn after its timer (a
        /cmd_vel that arrived with the timer is applied first: its reader was woken by the
        same poll, and runs before what ``call_soon`` adds).
        """
        worlds = self._members[self.shared]
        if not worlds:
            return
        if len(worlds) == 1:
            self.tick(worlds, lateness_s)
            return
        loop = asyncio.get_running_loop()
        now_s = self.clock.monotonic_s()
        slots = min(SLOTS, len(worlds))
        slot_s = SPREAD * self.period_s / slots
        groups = [worlds[index::slots] for index in range(slots)]
        self.tick(groups[0], lateness_s)
        for index, group in enumerate(groups[1:], start=1):
            loop.call_later(index * slot_s, loop.call_soon, self._tick_late, group,
                            now_s + index * slot_s, lateness_s)

    def _tick_late(self, worlds: list[WorldHost], due_s: float, lateness_s: float) -> None:
        self.tick(worlds, lateness_s + max(0.0, self.clock.monotonic_s() - due_s))

    def tick(self, worlds: Iterable[WorldHost], lateness_s: float = 0.0) -> None:
        """One tick of ``worlds``: each steps, one scan pass for all, each delivers.

        Never raises: a world's or a robot's fault stays its own (``WorldHost``); a fault of
        the shared scan pass is recorded on every robot in it, each then casting its own.
        """
        stepped = [world for world in worlds if world.begin_tick(lateness_s)]
        crowded = {world for world in stepped if world.crowded}
        write = self.write
        for world in stepped:  # a crowded world's /odom and /tf do not wait for the scans
            if world in crowded:
                world.end_tick(write, lateness_s, scans=False)
        due = [sim for world in stepped for sim in world.scans_due(lateness_s)]
        if len(due) > 1:
            try:
                cast_scans(due)
            except Exception as error:  # each robot then casts its own, in its boundary
                for world in stepped:
                    for _, host in world:
                        if host.robot.sim in due:
                            host.faults.record("casting the tick's scans together", error)
        for world in stepped:
            world.end_tick(write, lateness_s, scans=True if world in crowded else None)

    def write(self, flush: Flush) -> None:
        """Write ``flush`` through the loop's connections (the loop closers at once)."""
        self.writers.write(flush)
