"""Limits of the embedded server: what a connection, an address and a server may hold and cost.

``ClientLimits`` is the one definition of every bound (the README's limits table): per
connection, per client address (all the connections of one machine, or of one classroom
behind one NAT address: ``AddressBudgets``), per robot and per server. The token buckets
enforce the rates; ``OriginPolicy`` decides which web pages may connect; ``TrustedProxies``
which peers may say whom they forward (``X-Real-IP``, ``X-Forwarded-For``). No I/O here: the
server and the bridge ask, and close, refuse or wait themselves.
"""

from __future__ import annotations

import dataclasses
import ipaddress
import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from urllib.parse import urlsplit

from rosbridge.core.clock import WALL_CLOCK

DEFAULT_MAX_RATE = 200.0
"""Messages per second a client may send, sustained; a browser sends a few dozen at most
(subscriptions at connect, /cmd_vel at 10-20 Hz), so 200 only stops a runaway loop."""

BYTES_PER_MESSAGE = 16 << 10
"""A frame counts as one message per started 16 KiB: a 1 MiB frame costs 64, so a client
cannot keep the server parsing megabytes of JSON at the full message rate."""


@dataclass(frozen=True)
class ClientLimits:
    """Everything one client can make the server hold or do, bounded; one definition each.

    The README's limits table lists these. Counts are checked where a message is validated;
    byte and time budgets where frames are queued and handled.

    Attributes:
        max_rate: messages/s a client may send (token bucket, one second of burst); beyond
            it the connection closes (1008).
        max_frame_bytes: largest incoming WebSocket message; larger ones close it (1009).
        max_queued_bytes: all frames waiting to be sent to one client (topic frames and
            replies); a topic frame beyond it makes room by dropping the oldest topic frames
            (``outbox.Outbox``); replies beyond it close the client (1008).
        max_ids_per_topic: subscribe ids one client may hold on one topic.
        max_subscriptions: topics one client may subscribe to at once.
        max_advertised: topics one client may advertise at once.
        max_services: services one client may offer at once.
        max_actions: actions one client may offer (``advertise_action``) at once.
        max_goals: action goals one client may have pending at once (sent and not yet
            answered); beyond it a goal is answered at once with a failed ``action_result``.
        max_goals_per_action: goals pending at once on one client-provided action, from all
            senders: what its server is asked to hold; beyond it a goal fails at once.
        max_latched_bytes: largest message a client may publish with ``latch: true``.
        max_fragments: most ``fragment`` ops one incoming message may be split into (a
            message of ``max_frame_bytes`` in fragments of 1 KiB); a larger ``total`` is
            refused. What the incomplete messages hold together is within
            ``max_frame_bytes``.
        max_partial_messages: fragmented messages one client may have incomplete at once.
        fragment_timeout_s: an incomplete fragmented message that gets no fragment for this
            long is dropped, with an error to the client (s).
        relay_bytes_per_s: bytes/s of messages one client may have relayed to others (one
            second of burst); messages beyond it are dropped with an error to the sender.
        handling_share: fraction of one core the server spends on one client's input,
            sustained; a client over it is read more slowly (its socket backs up).
        handling_burst_s: handling time a client may use at once before it is slowed (s).
        stall_timeout_s: a client whose socket accepts nothing for this long while frames
            wait (watched once it is behind: ``server.WRITE_BUFFER_BYTES`` beyond its kernel
            buffer) is closed (1008) (s).
        close_timeout_s: how long a close handshake may take before the connection is
            aborted (s).
        max_replies: replies (service responses, statuses) that may wait at once.
        max_clients: connections one robot serves at once; beyond it the handshake is
            refused (HTTP 503), so sockets are bounded whatever the file limit.
        max_connections: WebSocket connections the whole server holds at once; beyond it
            the handshake is refused (HTTP 503).
        address_max_connections: WebSocket connections one client address may hold at once
            on the server (sized for a class of 40 behind one NAT address: a page, their code
            and a second tab each, about 4, plus the instructor's); beyond it the handshake
            is refused (HTTP 429). The instructor's root view does not count.
        address_max_robot_connections: connections one address may hold to one robot
            (a class of 40 behind one NAT address all watching the instructor's demo robot,
            some with their code too); beyond it HTTP 429, so no address can fill a
            robot's ``max_clients``.
        address_max_rate: messages/s all the connections of one address may send together
            (a frame counts as in ``max_rate``; one second of burst); beyond it their frames
            wait (their sockets back up), nobody is closed.
        address_handling_share: fraction of one core the server spends on one address's
            input, all its connections together; beyond it their frames wait.
        address_bytes_per_s: incoming bytes/s of one address, all its connections together
            (one second of burst, at least ``max_frame_bytes``); beyond it their frames wait.
        address_enrolments: new robots one address may enrol in an open class at once
            (burst); beyond it the handshake is refused (HTTP 429) until the budget refills.
        address_enrolments_per_s: how fast that budget refills (enrolments/s).
        robot_handling_share: fraction of one core the server spends on the input of all the
            clients of one robot together, from every address (a crowd of students on the
            instructor's demo robot); beyond it their frames wait, so no robot's clients
            can take the core from the other robots.
        robot_latched_bytes: what clients' latched messages on one robot may hold together
            (bytes as they arrived, each at most ``max_latched_bytes``; their encodings hold
            at most about six times as much); beyond it a latched publish is refused.
        server_latched_bytes: the same for all the robots of one server together.
    """

    max_rate: float = DEFAULT_MAX_RATE
    max_frame_bytes: int = 1 << 20
    max_queued_bytes: int = 4 << 20
    max_ids_per_topic: int = 16
    max_subscriptions: int = 64
    max_advertised: int = 32
    max_services: int = 16
    max_actions: int = 16
    max_goals: int = 32
    max_goals_per_action: int = 64
    max_latched_bytes: int = 64 << 10
    max_fragments: int = 1024
    max_partial_messages: int = 16
    fragment_timeout_s: float = 30.0
    relay_bytes_per_s: int = 256 << 10
    handling_share: float = 0.05
    handling_burst_s: float = 0.2
    stall_timeout_s: float = 10.0
    close_timeout_s: float = 3.0
    max_replies: int = 1000
    max_clients: int = 500
    max_connections: int = 4000
    address_max_connections: int = 200
    address_max_robot_connections: int = 64
    address_max_rate: float = 2000.0
    address_handling_share: float = 0.25
    address_bytes_per_s: int = 8 << 20
    address_enrolments: int = 60
    address_enrolments_per_s: float = 1.0
    robot_handling_share: float = 0.5
    robot_latched_bytes: int = 1 << 20
    server_latched_bytes: int = 16 << 20

    def __post_init__(self) -> None:
        for item in dataclasses.fields(self):
            value = getattr(self, item.name)
            if isinstance(value, bool) or not (isinstance(value, (int, float))
                                               and math.isfinite(value) and value > 0):
                raise ValueError(f"{item.name} must be a positive number, got {value!r}")


class TokenBucket:
    """``rate`` units per second sustained, at most ``burst`` at once.

    Args:
        rate: units refilled per second (> 0).
        burst: the bucket's size (> 0).
        clock: monotonic time (s): a ``Clock``'s ``monotonic_s`` (default: wall time).
    """

    def __init__(self, rate: float, burst: float,
                 clock: Callable[[], float] = WALL_CLOCK.monotonic_s) -> None:
        if not (math.isfinite(rate) and rate > 0 and math.isfinite(burst) and burst > 0):
            raise ValueError(f"rate and burst must be positive, got {rate}, {burst}")
        self.rate = rate
        self.burst = burst
        self._clock = clock
        self._tokens = burst
        self._last_s = clock()

    def _refill(self) -> float:
        now = self._clock()
        self._tokens = min(self.burst, self._tokens + (now - self._last_s) * self.rate)
        self._last_s = now
        return self._tokens

    def take(self, amount: float) -> bool:
        """Take ``amount`` if the bucket holds it; False (and nothing taken) if not."""
        if self._refill() < amount:
            return False
        self._tokens -= amount
        return True

    def charge(self, amount: float) -> None:
        """Take ``amount`` whatever the bucket holds (it may go negative: a debt)."""
        self._refill()
        self._tokens -= amount

    def wait_s(self) -> float:
        """How long until the bucket is no longer in debt (0: now)."""
        tokens = self._refill()
        return 0.0 if tokens >= 0 else -tokens / self.rate

    def full(self) -> bool:
        """Whether the bucket holds its whole burst."""
        return self._refill() >= self.burst


class RateLimit:
    """A client's message rate: ``rate`` messages per second sustained, bursts of ``rate``.

    Args:
        rate: messages per second (> 0).
        clock: monotonic time (s): a ``Clock``'s ``monotonic_s`` (default: wall time).
    """

    def __init__(self, rate: float = DEFAULT_MAX_RATE,
                 clock: Callable[[], float] = WALL_CLOCK.monotonic_s) -> None:
        if not (math.isfinite(rate) and rate > 0):
            raise ValueError(f"rate must be a positive number of messages/s, got {rate}")
        self.rate = rate
        self._bucket = TokenBucket(rate, rate, clock)

    @staticmethod
    def cost(frame_bytes: int) -> int:
        """What a frame of ``frame_bytes`` counts as: one message per started 16 KiB."""
        return max(1, -(-frame_bytes // BYTES_PER_MESSAGE))

    def allow(self, frame_bytes: int = 0) -> bool:
        """Take a frame's cost from the bucket; False if the client exceeded the rate."""
        return self._bucket.take(min(self.cost(frame_bytes), self.rate))

    def reason(self) -> str:
        """The close reason sent to a client that exceeded the rate."""
        return f"rate limit: more than {self.rate:g} messages/s"


class AddressBudget:
    """What all the connections of one client address spend together (``ClientLimits``).

    Connections are counted (on the server and per robot); messages, handling time and bytes
    are charged to shared token buckets that may go into debt, and a connection of an
    address in debt waits (``wait_s``) before its next frame is handled; enrolments in an
    open class are taken from a bucket of their own.
    """

    def __init__(self, limits: ClientLimits, clock: Callable[[], float]) -> None:
        self.connections = 0
        self.robots: dict[str, int] = {}
        self._rate = TokenBucket(limits.address_max_rate, limits.address_max_rate, clock)
        self._handling = TokenBucket(limits.address_handling_share,
                                     max(limits.handling_burst_s,
                                         limits.address_handling_share * 2), clock)
        byte_burst = max(limits.address_bytes_per_s, limits.max_frame_bytes)
        self._bytes = TokenBucket(limits.address_bytes_per_s, byte_burst, clock)
        self._enrolments = TokenBucket(limits.address_enrolments_per_s,
                                       limits.address_enrolments, clock)

    def wait_s(self) -> float:
        """How long this address's next frame must wait (0: now)."""
        return max(self._rate.wait_s(), self._handling.wait_s(), self._bytes.wait_s())

    def charge(self, frame_bytes: int, handling_s: float) -> None:
        """Charge one handled frame: its message cost, its bytes and the time it took."""
        self._rate.charge(RateLimit.cost(frame_bytes))
        self._bytes.charge(frame_bytes)
        self._handling.charge(handling_s)

    def charge_time(self, handling_s: float) -> None:
        """Charge time spent for this address beyond handling frames (its costly formats)."""
        self._handling.charge(handling_s)

    def handling_wait_s(self) -> float:
        """How long until this address's handling time is no longer in debt (0: now)."""
        return self._handling.wait_s()

    def enrol(self) -> bool:
        """Take one enrolment; False if this address enrolled too many too fast."""
        return self._enrolments.take(1)

    def idle(self) -> bool:
        """No connection, and nothing spent that has not refilled: it can be forgotten."""
        return (self.connections == 0 and self.wait_s() == 0.0
                and self._enrolments.full())


class AddressBudgets:
    """Every client address's ``AddressBudget``, and the server's connection count.

    ``refusal`` says why a new connection is refused (None: admitted); ``opened`` and
    ``closed`` count it. Addresses with nothing outstanding are forgotten, so the table is
    bounded by the connections (and the recent enrolments) the server holds.

    Args:
        limits: the bounds (``address_*``, ``max_connections``).
        clock: monotonic time (s).
    """

    def __init__(self, limits: ClientLimits,
                 clock: Callable[[], float] = WALL_CLOCK.monotonic_s) -> None:
        self.limits = limits
        self.connections = 0
        self._clock = clock
        self._budgets: dict[str, AddressBudget] = {}

    def __len__(self) -> int:
        return len(self._budgets)

    def of(self, address: str) -> AddressBudget:
        """The budget of ``address`` (made now if it has none)."""
        address = budget_key(address)
        budget = self._budgets.get(address)
        if budget is None:
            if len(self._budgets) >= 1024:
                self._forget_idle()
            budget = self._budgets[address] = AddressBudget(self.limits, self._clock)
        return budget

    def _forget_idle(self) -> None:
        for address in [a for a, budget in self._budgets.items() if budget.idle()]:
            del self._budgets[address]

    def refusal(self, address: str, robot: str | None) -> tuple[int, str] | None:
        """(HTTP status, reason) refusing one more connection of ``address`` to ``robot``."""
        limits = self.limits
        if self.connections >= limits.max_connections:
            return 503, (f"this server holds at most {limits.max_connections} connections "
                         "at once; try again later")
        budget = self._budgets.get(budget_key(address))
        if budget is None:
            return None
        if budget.connections >= limits.address_max_connections:
            return 429, (f"at most {limits.address_max_connections} connections from one "
                         "address (websim serve --max-connections-per-address raises it)")
        if robot is not None and budget.robots.get(robot, 0) >= \
                limits.address_max_robot_connections:
            return 429, (f"at most {limits.address_max_robot_connections} connections from "
                         "one address to one robot")
        return None

    def opened(self, address: str, robot: str | None) -> AddressBudget:
        """Count a connection of ``address`` (to ``robot``); its budget."""
        budget = self.of(address)
        budget.connections += 1
        self.connections += 1
        if robot is not None:
            budget.robots[robot] = budget.robots.get(robot, 0) + 1
        return budget

    def closed(self, address: str, robot: str | None) -> None:
        """Count a connection of ``address`` (to ``robot``) gone."""
        budget = self._budgets.get(budget_key(address))
        self.connections -= 1
        if budget is None:
            return
        budget.connections -= 1
        if robot is not None:
            left = budget.robots.get(robot, 1) - 1
            if left > 0:
                budget.robots[robot] = left
            else:
                budget.robots.pop(robot, None)


class RobotBudget:
    """What all the clients of one robot spend together, from every address: handling time.

    Charged as ``AddressBudget`` is (a connection of a robot in debt waits before its next
    frame is handled, and before its costly formats are made), so a crowd on one robot slows
    that robot's clients, never the other robots'.
    """

    def __init__(self, limits: ClientLimits, clock: Callable[[], float]) -> None:
        self.connections = 0
        self._handling = TokenBucket(limits.robot_handling_share,
                                     limits.robot_handling_share * 2, clock)  # 2 s worth

    def wait_s(self) -> float:
        """How long the robot's clients' next frame must wait (0: now)."""
        return self._handling.wait_s()

    def charge_time(self, handling_s: float) -> None:
        """Charge time spent for one of the robot's clients."""
        self._handling.charge(handling_s)

    def idle(self) -> bool:
        """No connection and no debt: it can be forgotten."""
        return self.connections == 0 and self._handling.full()


class RobotBudgets:
    """Each robot's ``RobotBudget``, kept while it has connections (or debt).

    Args:
        limits: the bounds (``robot_handling_share``).
        clock: monotonic time (s).
    """

    def __init__(self, limits: ClientLimits,
                 clock: Callable[[], float] = WALL_CLOCK.monotonic_s) -> None:
        self._limits = limits
        self._clock = clock
        self._budgets: dict[str, RobotBudget] = {}

    def __len__(self) -> int:
        return len(self._budgets)

    def opened(self, robot: str) -> RobotBudget:
        """Count a connection to ``robot``; its budget."""
        budget = self._budgets.get(robot)
        if budget is None:
            for name in [n for n, b in self._budgets.items() if b.idle()]:
                del self._budgets[name]
            budget = self._budgets[robot] = RobotBudget(self._limits, self._clock)
        budget.connections += 1
        return budget

    def closed(self, robot: str) -> None:
        """Count a connection to ``robot`` gone."""
        budget = self._budgets.get(robot)
        if budget is not None:
            budget.connections -= 1


class LatchedBytes:
    """Bytes of clients' latched messages held, bounded here and in the pool above.

    A server holds one pool (``server_latched_bytes``), each of its robots one of its own
    within it (``for_robot``: ``robot_latched_bytes``): a latched message fits when it fits
    both.

    Args:
        limit_bytes: what this pool may hold.
        parent: the pool it is part of (None: the server's).
        robot_limit_bytes: the limit of each robot's pool made by ``for_robot``.
    """

    def __init__(self, limit_bytes: int, parent: LatchedBytes | None = None,
                 robot_limit_bytes: int = 0) -> None:
        self.limit_bytes = limit_bytes
        self.held_bytes = 0
        self.parent = parent
        self._robot_limit_bytes = robot_limit_bytes or limit_bytes

    @classmethod
    def for_server(cls, limits: ClientLimits) -> LatchedBytes:
        """A server's pool, by ``limits``."""
        return cls(limits.server_latched_bytes, robot_limit_bytes=limits.robot_latched_bytes)

    def for_robot(self) -> LatchedBytes:
        """A robot's pool within this server's."""
        return LatchedBytes(self._robot_limit_bytes, self)

    def refusal(self, added: int, released: int = 0) -> str | None:
        """Why ``added`` more bytes (``released`` freed at once) do not fit; None: they do."""
        pool: LatchedBytes | None = self
        while pool is not None:
            held = pool.held_bytes - released
            if held + added > pool.limit_bytes:
                whose = "this robot's" if pool.parent is not None else "this server's"
                return (f"{whose} latched messages hold {held} bytes; with this one they would "
                        f"exceed {pool.limit_bytes}")
            pool = pool.parent
        return None

    def change(self, delta: int) -> None:
        """Count ``delta`` bytes more (or fewer) held, here and in every pool above."""
        pool: LatchedBytes | None = self
        while pool is not None:
            pool.held_bytes += delta
            pool = pool.parent


def budget_key(address: str) -> str:
    """Whose budget an address spends: its own for IPv4, its /64 for IPv6.

    One machine or one home gets a whole /64: its addresses are one client's.
    """
    if ":" not in address:
        return address
    try:
        return str(ipaddress.IPv6Network(f"{address}/64", strict=False))
    except ValueError:
        return address


Network = ipaddress.IPv4Network | ipaddress.IPv6Network


@dataclass(frozen=True)
class TrustedProxies:
    """Which peers are our reverse proxies (``--trusted-proxy``), trusted to name the client.

    Behind nginx every connection comes from nginx; ``websim nginx-config`` sets
    ``X-Real-IP`` and ``X-Forwarded-For``. Those headers are believed only from these
    addresses: from anyone else they are a client's claim, and ignored.

    Attributes:
        networks: the proxies' addresses or networks (``10.0.0.5``, ``10.0.0.0/24``).
    """

    networks: tuple[Network, ...] = ()

    @classmethod
    def parse(cls, texts: Iterable[str]) -> TrustedProxies:
        """From ``--trusted-proxy`` values; ValueError for one that is no address/network."""
        return cls(tuple(ipaddress.ip_network(text.strip(), strict=False) for text in texts))

    def trusts(self, address: str) -> bool:
        """Whether ``address`` is one of the proxies."""
        try:
            ip = ipaddress.ip_address(address)
        except ValueError:
            return False
        return any(ip in network for network in self.networks)

    def client(self, peer: str, real_ip: str | None, forwarded_for: str | None) -> str:
        """The client's address: the peer's, or the one a trusted proxy names.

        ``X-Real-IP`` first; else the last address of ``X-Forwarded-For`` that is not a
        proxy's (the ones before it are the client's own claims).
        """
        if not self.networks or not self.trusts(peer):
            return peer
        if real_ip and _is_ip(real_ip.strip()):
            return real_ip.strip()
        if forwarded_for:
            for hop in reversed([hop.strip() for hop in forwarded_for.split(",")]):
                if not _is_ip(hop):
                    break
                if not self.trusts(hop):
                    return hop
        return peer


def _is_ip(text: str) -> bool:
    try:
        ipaddress.ip_address(text)
    except ValueError:
        return False
    return True


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
        page_port: the web interface's port; when bound to every interface, or behind a
            reverse proxy, a page on this port is accepted from whatever address the request
            was sent to (the Host header), since the address students type is not known in
            advance. None: off.
    """

    allowed: frozenset[str]
    allow_any: bool = False
    page_port: int | None = None

    @classmethod
    def default(cls, host: str, http_port: int, extra: Iterable[str] = (), *,
                proxied: bool = False) -> OriginPolicy:
        """The pages this server serves itself, plus ``extra`` (``*`` for any).

        Pages from this machine (``LOOPBACK_NAMES``) on any port ``allows`` accepts anyway.
        ``proxied``: behind a reverse proxy that passes the client's Host header on (nginx's
        ``proxy_set_header Host $http_host``), ``http_port`` being the proxy's page port:
        students reach the pages and the WebSocket at the proxy's address, whatever this
        process is bound to.
        """
        extra = list(extra)
        names = {"localhost", "127.0.0.1", "[::1]"}
        if host not in ALL_INTERFACES:
            names.add(f"[{host}]" if ":" in host else host)
        suffix = "" if http_port == 80 else f":{http_port}"  # browsers omit the default port
        allowed = {f"http://{name}{suffix}" for name in names}
        allowed.update(_normalize(origin) for origin in extra if origin != ANY_ORIGIN)
        return cls(frozenset(allowed), allow_any=ANY_ORIGIN in extra,
                   page_port=http_port if proxied or host in ALL_INTERFACES else None)

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
