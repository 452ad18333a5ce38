"""Refusals and client errors logged once per kind, per client address, per interval.

A client sending invalid messages as fast as it may, or opening refused handshakes in a
loop, must not write the server's log at its rate: 40 such clients wrote about 1 MB/s. The
first of a kind from an address is logged at once; the next ones within ``INTERVAL_S`` are
counted, and the first after it says how many were left out.

``LogThrottle`` is both what the front calls for its refusals (``note``) and a
``logging.Filter`` on the bridge's and the server's loggers, whose per-client warnings
(``"client %s: %s"``, the peer first) it throttles the same way.
"""

from __future__ import annotations

import logging
from collections import OrderedDict

from rosbridge.core.clock import WALL_CLOCK, Clock

INTERVAL_S = 10.0
"""A kind of refusal from one address is logged at most once per this many seconds."""

MAX_KEYS = 4096
"""(address, kind) pairs remembered; the oldest are forgotten beyond it."""

THROTTLED_LOGGERS = ("websim.bridge", "websim.server")
"""The loggers whose per-client warnings are throttled (``install``)."""


class LogThrottle(logging.Filter):
    """Let the first record of each (address, kind) through per ``interval_s``, count the rest.

    Args:
        logger: where ``note`` writes.
        clock: the clock of the intervals.
        interval_s: the interval (s).
    """

    def __init__(self, logger: logging.Logger, clock: Clock = WALL_CLOCK,
                 interval_s: float = INTERVAL_S) -> None:
        super().__init__()
        self._log = logger
        self._clock = clock
        self._interval_s = interval_s
        self._seen: OrderedDict[tuple[str, str], list[float]] = OrderedDict()

    def admit(self, address: str, kind: str) -> int | None:
        """None: drop this one (counted); else log it, with how many were dropped before."""
        key = (address, kind[:60])
        now = self._clock.monotonic_s()
        entry = self._seen.get(key)
        if entry is not None and now - entry[0] < self._interval_s:
            entry[1] += 1
            return None
        dropped = int(entry[1]) if entry is not None else 0
        self._seen[key] = [now, 0]
        self._seen.move_to_end(key)
        while len(self._seen) > MAX_KEYS:
            self._seen.popitem(last=False)
        return dropped

    def note(self, address: str, kind: str, message: str) -> None:
        """Log ``message`` about ``address`` (a warning) unless one of ``kind`` was just logged."""
        dropped = self.admit(address, kind)
        if dropped is not None:
            self._log.warning("client %s: %s%s", address, message, _more(dropped, self._interval_s))

    def filter(self, record: logging.LogRecord) -> bool:
        """A ``"client %s: ..."`` warning passes once per address and kind per interval."""
        if record.levelno < logging.WARNING or not isinstance(record.msg, str) \
                or not record.msg.startswith("client %s") or not isinstance(record.args, tuple) \
                or not record.args:
            return True
        peer = str(record.args[0])
        address = peer.rpartition(":")[0] if peer.count(":") == 1 else peer
        rest = record.args[1] if len(record.args) > 1 else record.msg
        kind = str(rest).partition(":")[0].partition("'")[0]
        dropped = self.admit(address, f"{record.msg}|{kind}")
        if dropped is None:
            return False
        if dropped:
            record.msg = f"{record.msg}{_more(dropped, self._interval_s)}"
        return True

    def install(self) -> None:
        """Throttle the per-client warnings of ``THROTTLED_LOGGERS``."""
        for name in THROTTLED_LOGGERS:
            logging.getLogger(name).addFilter(self)

    def uninstall(self) -> None:
        """Stop throttling them."""
        for name in THROTTLED_LOGGERS:
            logging.getLogger(name).removeFilter(self)


def _more(dropped: int, interval_s: float) -> str:
    return f" (and {dropped} more like it in the last {interval_s:g} s)" if dropped else ""
