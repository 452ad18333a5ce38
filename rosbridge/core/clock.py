"""The one clock: what every deadline, throttle, timeout and stamp reads.

Everything that needs the time takes a ``Clock`` (constructed once by the application and
passed down), never ``time.time()`` or ``time.monotonic()`` directly, so that sim time and a
run faster than real time (``--speed``) change one object, not every module.

A clock holds two times. ``monotonic_s`` is always wall time: every interval on a client's
wire (rate and handling budgets, throttles, service timeouts, stall watchdogs, the idle
pause, when the next tick is due) is about people and networks, which run in real time.
``stamp_s`` is what the robot's messages are stamped with: wall time (``WallClock``), or sim
time (``SimClock``), which moves one tick period per tick of the schedule whatever the speed,
so a tick's stamp and the robot's state always agree. The robot's own timers (sensor rates,
the ``/cmd_vel`` timeout) count ticks, so they run on sim time by construction.
"""

from __future__ import annotations

import math
import time
from typing import Protocol

SPEED_MAX = math.inf
"""``--speed max``: ticks run back to back, as fast as the host (and the clients) allow."""

MIN_SPEED = 0.1
"""The slowest speed a sim clock runs at (times real time): slow motion, a tick every 0.5 s."""

MAX_SPEED = 100.0
"""The fastest finite speed (times real time): a tick every 0.5 ms of wall time, about what
one robot reaches on this project's machine; beyond it, ``max``."""


def speed_text(speed: float) -> float | str:
    """A speed as ``--speed`` says it: times real time, or ``"max"``."""
    return "max" if speed == SPEED_MAX else speed


class Clock(Protocol):
    """A source of time.

    ``monotonic_s`` is for intervals (deadlines, throttles, timeouts, ages): it never goes
    back. ``stamp_s`` is for message stamps: seconds since the epoch in wall time (as a real
    robot stamps its messages), or the simulation's time under sim time.
    """

    def monotonic_s(self) -> float:
        """Seconds on a clock that never goes back (its zero means nothing)."""

    def stamp_s(self) -> float:
        """Seconds for message stamps (``builtin_interfaces/Time``)."""


class WallClock:
    """Real time: the monotonic clock for intervals, the epoch for stamps."""

    def monotonic_s(self) -> float:
        """``time.monotonic()``."""
        return time.monotonic()

    def stamp_s(self) -> float:
        """``time.time()``."""
        return time.time()


class ManualClock:
    """A clock that moves only when told (``advance``): for tests and deterministic runs.

    Args:
        monotonic_s: its monotonic time to start at (s).
        epoch_s: the stamp at its monotonic zero (s since the epoch).
    """

    def __init__(self, monotonic_s: float = 0.0, epoch_s: float = 1_700_000_000.0) -> None:
        self._monotonic_s = monotonic_s
        self._epoch_s = epoch_s

    def monotonic_s(self) -> float:
        """Where it was moved to."""
        return self._monotonic_s

    def stamp_s(self) -> float:
        """The epoch plus its monotonic time."""
        return self._epoch_s + self._monotonic_s

    def advance(self, seconds: float) -> None:
        """Move forward by ``seconds`` (>= 0)."""
        if seconds < 0:
            raise ValueError(f"a clock does not go back ({seconds} s)")
        self._monotonic_s += seconds


class SimClock:
    """Sim time: stamps move one tick period per tick, at ``speed`` times real time.

    The schedule that ticks with it (``rosbridge.transport.schedule.Schedule``) calls
    ``tick`` once per tick, before any robot steps, so every message of the tick carries the
    same stamp, ``epoch_s + ticks * period_s``, and ``/clock`` says that time. Intervals stay
    on wall time (``monotonic_s``: see the module's docstring).

    Args:
        period_s: sim time per tick (s).
        speed: times real time the schedule runs it at: ``MIN_SPEED`` to ``MAX_SPEED``, or
            ``SPEED_MAX`` (as fast as the host allows).
        epoch_s: the stamp at tick 0 (s since the epoch); default: the wall time now, so at
            speed 1 stamps stay within a tick of the wall clock, as a real robot's do.
        wall: where ``monotonic_s`` is read (default: the wall clock).

    Raises:
        ValueError: a period or speed outside its range.
    """

    def __init__(self, period_s: float, speed: float = 1.0, epoch_s: float | None = None,
                 wall: Clock | None = None) -> None:
        if not (math.isfinite(period_s) and period_s > 0):
            raise ValueError(f"a tick period must be a positive number of seconds, got "
                             f"{period_s!r}")
        if speed != SPEED_MAX and not MIN_SPEED <= speed <= MAX_SPEED:
            raise ValueError(f"speed must be {MIN_SPEED:g} to {MAX_SPEED:g} times real time, "
                             f"or max; got {speed!r}")
        self._wall: Clock = WallClock() if wall is None else wall
        self.period_s = period_s
        self.speed = speed
        self._period_us = round(period_s * 1e6)
        start_s = self._wall.stamp_s() if epoch_s is None else epoch_s
        self._epoch_us = round(start_s * 1e6)
        self.ticks = 0
        """Ticks since the clock started."""

    def monotonic_s(self) -> float:
        """Wall time, for intervals (the wall clock's ``monotonic_s``)."""
        return self._wall.monotonic_s()

    def stamp_s(self) -> float:
        """Sim time: the epoch plus one period per tick (s; whole microseconds)."""
        return (self._epoch_us + self.ticks * self._period_us) / 1e6

    def tick(self) -> None:
        """A tick begins: sim time moves on one period."""
        self.ticks += 1


WALL_CLOCK = WallClock()
"""Real time, for what is given no clock (it holds no state: one serves everyone)."""
