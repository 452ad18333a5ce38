"""The one clock: what every deadline, throttle, timeout and stamp reads.

Everything that needs the time takes a ``Clock`` (constructed once by the application and
passed down), never ``time.time()`` or ``time.monotonic()`` directly, so that sim time and a
run faster than real time (``--speed``) change one object, not every module.

A clock holds two times. ``monotonic_s`` is always wall time: every interval on a client's
wire (rate and handling budgets, throttles, service timeouts, stall watchdogs, the idle
pause, when the next tick is due) is about people and networks, which run in real time.
``stamp_s`` is what messages are stamped with: wall time (``WallClock``), or whatever clock
the application hands in that satisfies ``Clock`` (websim's sim time, ``ros_nodes.sim_clock``:
this library knows no simulation).
"""

from __future__ import annotations

import time
from typing import Protocol


class Clock(Protocol):
    """A source of time.

    ``monotonic_s`` is for intervals (deadlines, throttles, timeouts, ages): it never goes
    back. ``stamp_s`` is for message stamps: seconds since the epoch in wall time (as a real
    robot stamps its messages), or a simulation's time.
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


WALL_CLOCK = WallClock()
"""Real time, for what is given no clock (it holds no state: one serves everyone)."""
