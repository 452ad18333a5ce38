"""Per-connection limits of the embedded server: message rate and WebSocket origin.

No I/O here: the server asks ``RateLimit.allow`` for every frame and ``OriginPolicy.allows``
at every handshake, and closes or refuses the connection itself.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from urllib.parse import urlsplit

DEFAULT_MAX_RATE = 200.0
"""Messages per second a client may send, sustained; a browser sends a few dozen at most
(subscriptions at connect, /cmd_vel at 10-20 Hz), so 200 only stops a runaway loop."""

BYTES_PER_MESSAGE = 16 << 10
"""A frame counts as one message per started 16 KiB: a 1 MiB frame costs 64, so a client
cannot keep the server parsing megabytes of JSON at the full message rate."""


class RateLimit:
    """A token bucket: ``rate`` messages per second sustained, bursts of up to ``rate``.

    Args:
        rate: messages per second (> 0).
        clock: monotonic clock (s).
    """

    def __init__(self, rate: float = DEFAULT_MAX_RATE,
                 clock: Callable[[], float] = time.monotonic) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be a positive number of messages/s, got {rate}")
        self.rate = rate
        self._clock = clock
        self._tokens = rate
        self._last_s = clock()

    @staticmethod
    def cost(frame_bytes: int) -> int:
        """What a frame of ``frame_bytes`` counts as: one message per started 16 KiB."""
        return max(1, -(-frame_bytes // BYTES_PER_MESSAGE))

    def allow(self, frame_bytes: int = 0) -> bool:
        """Take a frame's cost from the bucket; False if the client exceeded the rate."""
        now = self._clock()
        self._tokens = min(self.rate, self._tokens + (now - self._last_s) * self.rate)
        self._last_s = now
        cost = min(self.cost(frame_bytes), self.rate)
        if self._tokens < cost:
            return False
        self._tokens -= cost
        return True

    def reason(self) -> str:
        """The close reason sent to a client that exceeded the rate."""
        return f"rate limit: more than {self.rate:g} messages/s"


ANY_ORIGIN = "*"
"""``--allow-origin '*'``: accept every page."""

ALL_INTERFACES = ("0.0.0.0", "::", "")

LOOPBACK_NAMES = frozenset({"localhost", "127.0.0.1", "::1"})
"""Pages from this machine, on any port (a student's own page under ``python -m http.server``),
are accepted: the policy is against other sites, not other local programs."""


@dataclass(frozen=True)
class OriginPolicy:
    """Which web pages may open the WebSocket (the browser's ``Origin`` header).

    Clients that send no Origin (roslibpy, roslibjs under Node, rclpy tools) are always
    accepted: only browsers send one, and the policy exists to stop another site's page from
    driving the robot through a student's browser.

    Attributes:
        allowed: accepted origins, ``scheme://host:port``, lower case.
        allow_any: accept every origin (``--allow-origin '*'``).
        page_port: the web interface's port; when bound to every interface, a page on this
            port is accepted from whatever address the request was sent to (the Host header),
            since the machine's classroom address is not known in advance. None: off.
    """

    allowed: frozenset[str]
    allow_any: bool = False
    page_port: int | None = None

    @classmethod
    def default(cls, host: str, http_port: int, extra: Iterable[str] = ()) -> OriginPolicy:
        """The pages this server serves itself, plus ``extra`` (``*`` for any).

        Pages from this machine (``LOOPBACK_NAMES``) on any port ``allows`` accepts anyway.
        """
        extra = list(extra)
        names = {"localhost", "127.0.0.1", "[::1]"}
        if host not in ALL_INTERFACES:
            names.add(f"[{host}]" if ":" in host else host)
        suffix = "" if http_port == 80 else f":{http_port}"  # browsers omit the default port
        allowed = {f"http://{name}{suffix}" for name in names}
        allowed.update(_normalize(origin) for origin in extra if origin != ANY_ORIGIN)
        return cls(frozenset(allowed), allow_any=ANY_ORIGIN in extra,
                   page_port=http_port if host in ALL_INTERFACES else None)

    def allows(self, origin: str | None, host_header: str | None = None) -> bool:
        """Whether a handshake with this Origin (None: none sent) to this Host is accepted."""
        if origin is None or self.allow_any:
            return True
        normalized = _normalize(origin)
        if normalized in self.allowed:
            return True
        parts = urlsplit(normalized)
        if parts.scheme in ("http", "https") and parts.hostname in LOOPBACK_NAMES:
            return True
        if self.page_port is None or not host_header:
            return False
        request_host = urlsplit(f"//{host_header}").hostname
        port = parts.port or (443 if parts.scheme == "https" else 80)
        return (parts.scheme in ("http", "https") and request_host is not None
                and parts.hostname == request_host and port == self.page_port)


def _normalize(origin: str) -> str:
    """``HTTP://Host:80/`` -> ``http://host:80``: case and trailing slash do not matter."""
    return origin.strip().rstrip("/").lower()
