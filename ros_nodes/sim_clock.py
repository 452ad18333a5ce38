"""Sim time: a ``Clock`` whose stamps are a world's ticks, and the speeds it may run at.

A ``SimClock`` holds no tick count of its own: it reads the one tick counter of what it times
(``follow``): the world its robot lives in (``physics.world_sim.WorldSim.tick``, which
``VirtualRobot`` binds it to), or, for robots of several worlds on one clock (a class on the
ROS graph, which has one ``/clock``), the count of the ticks they run together
(``heartbeat.driver``). Every message of a tick carries the same stamp, ``epoch_s + ticks *
period_s``, and ``/clock`` says that time; intervals stay on wall time (``monotonic_s``:
``rosbridge.core.clock``).
"""

from __future__ import annotations

import math
from collections.abc import Callable

from rosbridge.core.clock import Clock, WallClock

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


def _no_ticks() -> int:
    return 0


class SimClock:
    """Sim time: stamps move one tick period per tick, at ``speed`` times real time.

    Args:
        period_s: sim time per tick (s).
        speed: times real time the tick driver runs it at: ``MIN_SPEED`` to ``MAX_SPEED``,
            or ``SPEED_MAX`` (as fast as the host allows).
        epoch_s: the stamp at tick 0 (s since the epoch); default: the wall time now, so at
            speed 1 stamps stay within a tick of the wall clock, as a real robot's do.
        wall: where ``monotonic_s`` is read (default: the wall clock).
        ticks: the tick counter it reads (default: none yet: ``follow`` gives it one; until
            then it stands at tick 0).

    Raises:
        ValueError: a period or speed outside its range.
    """

    def __init__(self, period_s: float, speed: float = 1.0, epoch_s: float | None = None,
                 wall: Clock | None = None, ticks: Callable[[], int] | None = None) -> None:
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
        self._ticks: Callable[[], int] = _no_ticks if ticks is None else ticks

    @property
    def following(self) -> bool:
        """Whether it reads a tick counter yet (``follow``)."""
        return self._ticks is not _no_ticks

    def follow(self, ticks: Callable[[], int]) -> None:
        """Read the ticks from ``ticks`` from now on (a world's ``tick``, a pace's count)."""
        self._ticks = ticks

    @property
    def ticks(self) -> int:
        """Ticks of what it follows: the one tick counter, read, never kept here."""
        return self._ticks()

    @property
    def epoch_s(self) -> float:
        """The stamp at tick 0 (s since the epoch)."""
        return self._epoch_us / 1e6

    def monotonic_s(self) -> float:
        """Wall time, for intervals (the wall clock's ``monotonic_s``)."""
        return self._wall.monotonic_s()

    def stamp_s(self) -> float:
        """Sim time: the epoch plus one period per tick (s; whole microseconds)."""
        return (self._epoch_us + self._ticks() * self._period_us) / 1e6
