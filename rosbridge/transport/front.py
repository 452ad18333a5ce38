"""The front door of a rosbridge WebSocket server: health, origins, rights, routing.

asyncio and websockets, in the websockets idiom: ``WebSocketFront`` answers the handshake
(``/healthz``, origins, which bridge a path leads to) and hands each client to one
``BridgeConnection`` (``connection.py``: register on connect, unregister in ``finally``), no
state shared between clients but the bridge they talk to. What a path leads to (a robot, a
class's robots) is the subclass's business: this package knows no robot.

Limits (``ClientLimits``, the README's limits table): pages from other origins are refused at
the handshake (403, ``OriginPolicy``); a message over ``max_frame_bytes`` closes the
connection (1009), and so does a client sending faster than ``max_rate`` (1008); the time
spent handling one client's input is budgeted (``handling_share`` of a core: past it, its
frames wait, and its socket backs up); a client that lets more than ``max_queued_bytes``
pile up, or whose socket accepts nothing for ``stall_timeout_s`` while frames wait, is closed
(1008), its transport aborted if even the close cannot be written. Each client's kernel send
buffer is capped.
"""

from __future__ import annotations

import abc
import dataclasses
import hmac
import http
import json
import logging
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from rosbridge.core.bridge import Bridge
from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.core.limits import (
    AddressBudgets,
    ClientLimits,
    OriginPolicy,
    RobotBudgets,
    TrustedProxies,
)
from rosbridge.transport.connection import (
    MAX_CLOSE_REASON_BYTES,
    POLICY_VIOLATION,
    BridgeConnection,
    Hub,
)
from rosbridge.transport.log_limits import LogThrottle
from rosbridge.transport.wire import WireFrames
from rosbridge.transport.writers import Pace

log = logging.getLogger("websim.server")

PING_INTERVAL_S = 10.0
"""websockets keepalive: a browser that vanished without closing is dropped within ~20 s."""

MAX_INCOMING_FRAMES = 2
"""Frames websockets buffers per client before it stops reading the socket (so a client
whose handling budget is spent holds at most this many frames of server memory)."""



@dataclass(frozen=True)
class Destination:
    """Where a WebSocket path leads (a robot, in websim).

    Attributes:
        bridge: the bridge the connection's frames go to.
        pace: what paces the messages there (``writers.Pace``): its connections are written
            through it and, above real time, waited for by it.
    """

    bridge: Bridge
    pace: Pace


class WebSocketFront(abc.ABC):
    """What every server does at a WebSocket handshake: health, origins, rights, routing.

    Subclasses say which robot a path names (``route``) and who is admin there.

    Args:
        admin_token: the secret that grants admin rights everywhere (``?token=``).
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).
        clock: the clock of uptime, client budgets and watchdogs (default: wall time).
        proxies: the reverse proxies whose ``X-Real-IP``/``X-Forwarded-For`` name the client
            (``--trusted-proxy``); default none: the peer is the client.
    """

    def __init__(self, admin_token: str, limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None, clock: Clock = WALL_CLOCK,
                 proxies: TrustedProxies | None = None) -> None:
        self.limits = limits or ClientLimits()
        self._admin_token = admin_token
        self._origins = origins
        self.proxies = proxies or TrustedProxies()
        self.addresses = AddressBudgets(self.limits, clock.monotonic_s)
        """What each client address holds and spends, all its connections together."""
        self.robot_budgets = RobotBudgets(self.limits, clock.monotonic_s)
        """What the clients of each robot spend together, from every address."""
        self.clock = clock
        self.started_monotonic_s = clock.monotonic_s()
        self.refusals = LogThrottle(log, clock)
        """Refusals logged once per kind and address per interval, with a count."""
        self.wire = WireFrames()
        """Outgoing frames serialized once for all the clients they go to."""

    @abc.abstractmethod
    def route(self, path: str) -> tuple[Destination, str | None] | str:
        """The robot a WebSocket path names, with its name, or why there is none.

        Returns:
            (host, name), name None for a server's single robot; or the reason to refuse.
        """

    def root_view(self, path: str, token: str | None) -> tuple[Hub, Pace] | None:
        """Another hub than a bridge for this path and token (an instructor's view), or None.

        Returns:
            (hub, the pace its messages follow), or None.
        """
        return None

    def robot_admin(self, name: str | None, token: str | None) -> bool:
        """Whether ``token`` grants admin rights on robot ``name`` besides the admin token."""
        return False

    def may_drive(self, name: str | None, is_admin: bool) -> bool:
        """Whether a client of robot ``name`` may change it, not only watch (default: all)."""
        return True

    @abc.abstractmethod
    def health(self, full: bool = True) -> dict[str, Any]:
        """The /healthz document.

        ``full`` False (public): status and counts only, no robot's name, no address.
        """

    @abc.abstractmethod
    async def run_ticks(self) -> None:
        """Tick the robots forever."""

    def health_for(self, token: str | None) -> dict[str, Any]:
        """``/healthz`` for the token presented (``?token=``), on both ports.

        The full document with the admin token, else counts only; and ``token_accepted``,
        whether the token is the admin token. A page can tell a wrong token from a server out
        of reach only so: a browser shows a handshake refused with 403 as a close (1006)
        without the status or the reason, as it shows a server that does not answer.
        """
        admin = self.is_admin_token(token)
        return {**self.health(full=admin), "token_accepted": admin}

    def is_admin_token(self, token: str | None) -> bool:
        """Constant-time comparison of a presented token with the admin token."""
        if not token:
            return False
        return hmac.compare_digest(token.encode(), self._admin_token.encode())

    def admit(self, name: str | None, address: str) -> tuple[int, str] | None:
        """A subclass's last word on a handshake that would make a robot.

        Called after every other check, so the place to spend a budget (an enrolment):
        nothing refuses after it. Returns (HTTP status, reason) refusing it, or None.
        """
        return None

    def client_address(self, connection: ServerConnection, request: Request) -> str:
        """The client's address: the peer's, or what a trusted proxy says it forwards."""
        return self.proxies.client(_host(connection), request.headers.get("X-Real-IP"),
                                   request.headers.get("X-Forwarded-For"))

    def process_request(self, connection: ServerConnection,
                        request: Request) -> Response | None:
        """Answer ``GET /healthz``; refuse what must be refused before anything changes.

        Another site's page gets 403, an unknown robot 404, an address over its connection
        or enrolment budget 429, a robot at ``max_clients`` or a full server 503.
        """
        target = urlsplit(request.path)
        path = target.path
        token = _token(target.query)
        if path == "/healthz":
            return json_response(self.health_for(token))
        address = self.client_address(connection, request)
        refused = self._check_origin(connection, request, address)
        if refused is not None:
            return refused
        if self.root_view(path, token) is not None:
            return None
        wrong = self.wrong_root_token(path, token)
        if wrong is not None:
            return self._refuse(connection, address, http.HTTPStatus.FORBIDDEN, wrong, "token")
        routed = self.find(path)
        if isinstance(routed, str):
            return self._refuse(connection, address, http.HTTPStatus.NOT_FOUND, routed,
                                "not found", self.log_hint(path))
        host, name = routed
        if host is not None and len(host.bridge.sessions) >= self.limits.max_clients:
            return self._refuse(connection, address, http.HTTPStatus.SERVICE_UNAVAILABLE,
                                f"this robot serves at most {self.limits.max_clients} "
                                "clients at once; try again later", "max_clients")
        over = self.addresses.refusal(address, name)
        if over is None and host is None:
            over = self.admit(name, address)
        if over is not None:
            status, reason = over
            return self._refuse(connection, address, http.HTTPStatus(status), reason,
                                reason.partition(" (")[0])
        return None

    def wrong_root_token(self, path: str, token: str | None) -> str | None:
        """Why a token presented for a root view is refused (not a missing robot), or None."""
        return None

    def find(self, path: str) -> tuple[Destination | None, str | None] | str:
        """The robot a path names, making none.

        Returns:
            (host, name), host None for a robot ``route`` would make; or why there is none.
        """
        return self.route(path)

    def log_hint(self, path: str) -> str:
        """What the log adds to a refusal of ``path`` that the client is not told."""
        return ""

    def _refuse(self, connection: ServerConnection, address: str, status: http.HTTPStatus,
                reason: str, kind: str, hint: str = "") -> Response:
        """The refusal ``reason`` with ``status``, logged once per kind and address a while.

        The reason is the body and the status line's reason phrase too (what clients that
        print no body show: roslibpy says "upgrade failed [404]: <phrase>"); ``hint`` goes to
        the log only.
        """
        self.refusals.note(address, kind,
                           f"refused a WebSocket ({status.value}): {reason}{hint}")
        response = connection.respond(status, f"{reason}\n")
        return dataclasses.replace(response, reason_phrase=reason_phrase(reason))

    def _check_origin(self, connection: ServerConnection, request: Request,
                      address: str) -> Response | None:
        origin = request.headers.get("Origin")
        if self._origins is not None and not self._origins.allows(
                origin, request.headers.get("Host")):
            return self._refuse(connection, address, http.HTTPStatus.FORBIDDEN,
                                f"origin {origin} is not allowed (websim serve "
                                f"--allow-origin {origin} admits it)", "origin")
        return None

    async def handle_connection(self, connection: ServerConnection) -> None:
        """Serve one client until it goes."""
        request = connection.request
        if request is None:  # pragma: no cover - websockets always has one here
            return
        address = self.client_address(connection, request)
        peer = _peer(connection, address)
        target = urlsplit(request.path)
        token = _token(target.query)
        view = self.root_view(target.path, token)
        if view is not None:
            log.info("instructor %s connected to the class's root view", peer)
            hub, pace = view
            await BridgeConnection(hub, pace, connection, peer, True,
                                   self.root_limits(), self.wire, self.clock).run()
            return
        routed = self.route(target.path)
        if isinstance(routed, str):  # refused at the handshake, or gone since
            await connection.close(POLICY_VIOLATION, routed[:MAX_CLOSE_REASON_BYTES])
            return
        host, name = routed
        is_admin = self.is_admin_token(token) or self.robot_admin(name, token)
        if token and not is_admin:
            self.refusals.note(address, "token", "presented a wrong admin token")
        budget = self.addresses.opened(address, name)
        robot_budget = self.robot_budgets.opened(name or "")
        try:
            client = BridgeConnection(host.bridge, host.pace, connection, peer, is_admin,
                                      self.limits, self.wire, self.clock, budget, robot_budget)
            client.session.may_drive = self.may_drive(name, is_admin)
            client.session.instructor = self.is_admin_token(token)
            client.session.url_path = target.path
            await client.run()
        finally:
            self.addresses.closed(address, name)
            self.robot_budgets.closed(name or "")

    def root_limits(self) -> ClientLimits:
        """The limits of the instructor's root view (default: a client's)."""
        return self.limits

    def _uptime_s(self) -> float:
        return round(self.clock.monotonic_s() - self.started_monotonic_s, 3)


MAX_REASON_PHRASE_CHARS = 160
"""The longest reason phrase of a refusal's status line (the reason, cut)."""


def reason_phrase(reason: str) -> str:
    """``reason`` as an HTTP status line may carry it: printable ASCII, one line, cut."""
    printable = "".join(char if " " <= char <= "~" else "?" for char in reason.split("\n")[0])
    return printable[:MAX_REASON_PHRASE_CHARS]


def json_response(body: Any, status: http.HTTPStatus = http.HTTPStatus.OK) -> Response:
    """A small JSON HTTP response for websockets' ``process_request``."""
    data = json.dumps(body).encode()
    headers = Headers([("Content-Type", "application/json"),
                       ("Content-Length", str(len(data))), ("Cache-Control", "no-store")])
    return Response(status.value, status.phrase, headers, data)


def _token(query: str) -> str | None:
    """The ``token=`` of a WebSocket URL's query, if any."""
    return parse_qs(query).get("token", [None])[0]


def _host(connection: ServerConnection) -> str:
    """The peer's IP address."""
    address = connection.remote_address
    if isinstance(address, tuple) and len(address) >= 2:
        return str(address[0])
    return str(address)


def _peer(connection: ServerConnection, client: str | None = None) -> str:
    """``ADDRESS:PORT`` for logs: the client's address (a proxy's client's), the peer's port."""
    address = connection.remote_address
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{client or address[0]}:{address[1]}"
    return str(address)


async def start_websocket(server: WebSocketFront, host: str, port: int) -> Server:
    """Listen for rosbridge clients on ``host:port`` within ``server.limits``."""
    listening: Server = await serve(
        server.handle_connection, host, port, process_request=server.process_request,
        max_size=server.limits.max_frame_bytes, max_queue=MAX_INCOMING_FRAMES,
        ping_interval=PING_INTERVAL_S, ping_timeout=PING_INTERVAL_S,
        close_timeout=server.limits.close_timeout_s, compression=None)
    return listening
