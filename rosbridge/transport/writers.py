"""Where the core's flushes are written: the connections of one event loop, by outbox.

The core returns who must be written (``Flush``); ``Writers`` finds each client's connection
by its outbox (the instructor's view of a class holds one session per robot, all on its one
connection's outbox) and has it write what waits there: at once for the clients closing a
loop, after the current callback for the others (so that everything one callback queued for
a client goes out in one write).

Whoever paces the messages above real time waits, before each tick, for the clients that have
not yet taken what they were written (``waiting``, ``progress``), so a faster run drops
nothing; a client it gave up on (``release``) is not waited for again until it has caught up.
Each connection belongs to one ``Pace`` (what its path leads to says which: a robot's, in
websim), and a pace waits only for its own connections.
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Protocol

from rosbridge.core.outbox import Outbox
from rosbridge.core.session import Flush


class Pace(Protocol):
    """What paces a connection's messages: where its flushes are written, room for big work.

    The application's (websim: a robot's tick driver). This library knows no tick: a pace
    is whatever decides when the next burst of messages comes.
    """

    @property
    def writers(self) -> Writers:
        """The connections of the event loop, where flushes are written."""

    async def room(self, cost_s: float) -> None:
        """Wait until ``cost_s`` of work can run before the next burst of messages."""


class Writers:
    """The connections of one event loop, each by the outbox it writes from."""

    def __init__(self) -> None:
        self._writers: dict[Outbox, Callable[[], None]] = {}
        self._groups: dict[Outbox, object] = {}
        self._members: dict[object, dict[Outbox, None]] = {}
        self._later: dict[Outbox, None] = {}
        self._scheduled = False
        self._released: set[Outbox] = set()
        self._progress = asyncio.Event()

    def __len__(self) -> int:
        return len(self._writers)

    def add(self, outbox: Outbox, write: Callable[[], None], group: object = None) -> None:
        """Have ``write`` called whenever frames in ``outbox`` are to be written.

        ``group``: whose pace waits for it (``waiting``); None: nobody's.
        """
        self._writers[outbox] = write
        self._groups[outbox] = group
        if group is not None:
            self._members.setdefault(group, {})[outbox] = None

    def remove(self, outbox: Outbox) -> None:
        """Forget ``outbox``'s writer (its connection is gone)."""
        self._writers.pop(outbox, None)
        group = self._groups.pop(outbox, None)
        members = self._members.get(group)
        if members is not None:
            members.pop(outbox, None)
            if not members:
                del self._members[group]
        self._later.pop(outbox, None)
        self._released.discard(outbox)
        self._progress.set()  # a client gone is waited for no more

    def write(self, flush: Flush) -> None:
        """Write ``flush``: ``now`` at once, in order; ``later`` after the current callback.

        Clients of no connection here (a test's sessions) are skipped.
        """
        if not flush:
            return
        writers = self._writers
        for session in flush.now:
            write = writers.get(session.outbox)
            if write is not None:
                write()
        for session in flush.later:
            if session.outbox in writers:
                self._later[session.outbox] = None
        if self._later and not self._scheduled:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._write_later)
        if flush.now:
            self._progress.set()

    def sweep(self) -> None:
        """Write every connection that has frames waiting, whoever queued them.

        For what reached the core other than through an entry point whose ``Flush`` was
        written (a ROS graph's answers and messages, arriving on the loop between ticks).
        """
        for outbox, write in list(self._writers.items()):
            if outbox.queued_bytes > 0 or outbox.overflowed is not None:
                write()

    def _write_later(self) -> None:
        self._scheduled = False
        later = list(self._later)
        self._later.clear()
        for outbox in later:
            write = self._writers.get(outbox)
            if write is not None:
                write()
        self._progress.set()

    def waiting(self, group: object) -> list[Outbox]:
        """The clients of ``group`` whose sockets have not taken all their frames, but released.

        A client has caught up when nothing waits in its outbox and it is not ``behind`` (its
        connection's writer is not sending a backlog); a released client that has caught up
        is waited for again from then on.
        """
        waiting = []
        for outbox in self._members.get(group, ()):
            if outbox.behind or outbox.queued_bytes > 0:
                if outbox not in self._released:
                    waiting.append(outbox)
            else:
                self._released.discard(outbox)
        return waiting

    def release(self, outboxes: list[Outbox]) -> None:
        """Stop waiting for ``outboxes`` until each has caught up (``waiting``).

        Only connections still here: one already gone is waited for no more anyway.
        """
        self._released.update(outbox for outbox in outboxes if outbox in self._writers)

    def caught_up(self) -> None:
        """A client's writer sent its whole backlog: whoever waits for the clients looks again."""
        self._progress.set()

    async def progress(self, timeout_s: float) -> None:
        """Wait until a client may have caught up (or one left), at most ``timeout_s``."""
        self._progress.clear()
        with contextlib.suppress(asyncio.TimeoutError):  # TimeoutError only from Python 3.11
            await asyncio.wait_for(self._progress.wait(), max(0.0, timeout_s))
