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
import hmac
import http
import json
import logging
from typing import Any, Protocol
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from rosbridge.core.bridge import Bridge
from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.core.limits import ClientLimits, OriginPolicy
from rosbridge.transport.connection import BridgeConnection, Hub
from rosbridge.transport.schedule import Schedule
from rosbridge.transport.wire import WireFrames

log = logging.getLogger("websim.server")

PING_INTERVAL_S = 10.0
"""websockets keepalive: a browser that vanished without closing is dropped within ~20 s."""

MAX_INCOMING_FRAMES = 2
"""Frames websockets buffers per client before it stops reading the socket (so a client
whose handling budget is spent holds at most this many frames of server memory)."""



class Destination(Protocol):
    """Where a WebSocket path leads: a bridge and the tick schedule it follows (a robot's host)."""

    @property
    def bridge(self) -> Bridge:
        """The bridge the connection's frames go to."""

    @property
    def schedule(self) -> Schedule:
        """The tick schedule large frames make room in."""


class WebSocketFront(abc.ABC):
    """What every server does at a WebSocket handshake: health, origins, rights, routing.

    Subclasses say which robot a path names (``route``) and who is admin there.

    Args:
        admin_token: the secret that grants admin rights everywhere (``?token=``).
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).
        clock: the clock of uptime, client budgets and watchdogs (default: wall time).
    """

    def __init__(self, admin_token: str, limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None, clock: Clock = WALL_CLOCK) -> None:
        self.limits = limits or ClientLimits()
        self._admin_token = admin_token
        self._origins = origins
        self.clock = clock
        self.started_monotonic_s = clock.monotonic_s()
        self.wire = WireFrames()
        """Outgoing frames serialized once for all the clients they go to."""

    @abc.abstractmethod
    def route(self, path: str) -> tuple[Destination, str | None] | str:
        """The robot a WebSocket path names, with its name, or why there is none.

        Returns:
            (host, name), name None for a server's single robot; or the reason to refuse.
        """

    def root_view(self, path: str, token: str | None) -> tuple[Hub, Schedule] | None:
        """Another hub than a bridge for this path and token (an instructor's view), or None.

        Returns:
            (hub, the schedule its large frames make room in), or None.
        """
        return None

    def robot_admin(self, name: str | None, token: str | None) -> bool:
        """Whether ``token`` grants admin rights on robot ``name`` besides the admin token."""
        return False

    def may_drive(self, name: str | None, is_admin: bool) -> bool:
        """Whether a client of robot ``name`` may change it, not only watch (default: all)."""
        return True

    @abc.abstractmethod
    def health(self) -> dict[str, Any]:
        """The /healthz document."""

    @abc.abstractmethod
    async def run_ticks(self) -> None:
        """Tick the robots forever."""

    def is_admin_token(self, token: str | None) -> bool:
        """Constant-time comparison of a presented token with the admin token."""
        if not token:
            return False
        return hmac.compare_digest(token.encode(), self._admin_token.encode())

    def process_request(self, connection: ServerConnection,
                        request: Request) -> Response | None:
        """Answer ``GET /healthz``; refuse unknown robots, full robots and other origins.

        Unknown robots get 404, a robot at ``max_clients`` 503, another site's page 403.
        """
        target = urlsplit(request.path)
        path = target.path
        if path == "/healthz":
            return json_response(self.health())
        if self.root_view(path, _token(target.query)) is not None:
            return self._check_origin(connection, request)
        routed = self.route(path)
        if isinstance(routed, str):
            log.warning("refused a WebSocket from %s for %s: %s", _peer(connection),
                        path[:80], routed)
            return connection.respond(http.HTTPStatus.NOT_FOUND, f"{routed}\n")
        host, _ = routed
        if len(host.bridge.sessions) >= self.limits.max_clients:
            log.warning("refused a WebSocket from %s: %d clients already (the limit)",
                        _peer(connection), self.limits.max_clients)
            return connection.respond(http.HTTPStatus.SERVICE_UNAVAILABLE,
                                      f"this robot serves at most {self.limits.max_clients} "
                                      "clients at once; try again later\n")
        return self._check_origin(connection, request)

    def _check_origin(self, connection: ServerConnection,
                      request: Request) -> Response | None:
        origin = request.headers.get("Origin")
        if self._origins is not None and not self._origins.allows(
                origin, request.headers.get("Host")):
            log.warning("refused a WebSocket from %s: origin %s is not allowed "
                        "(websim serve --allow-origin %s admits it)",
                        _peer(connection), origin, origin)
            return connection.respond(http.HTTPStatus.FORBIDDEN,
                                      f"origin {origin} is not allowed\n")
        return None

    async def handle_connection(self, connection: ServerConnection) -> None:
        """Serve one client until it goes."""
        peer = _peer(connection)
        target = urlsplit(connection.request.path if connection.request else "")
        token = _token(target.query)
        view = self.root_view(target.path, token)
        if view is not None:
            log.info("instructor %s connected to the class's root view", peer)
            hub, schedule = view
            await BridgeConnection(hub, schedule, connection, peer, True,
                                   self.limits, self.wire, self.clock).run()
            return
        routed = self.route(target.path)
        if isinstance(routed, str):  # pragma: no cover - refused at the handshake
            return
        host, name = routed
        is_admin = self.is_admin_token(token) or self.robot_admin(name, token)
        if token and not is_admin:
            log.warning("client %s presented a wrong admin token", peer)
        client = BridgeConnection(host.bridge, host.schedule, connection, peer, is_admin,
                                  self.limits, self.wire, self.clock)
        client.session.may_drive = self.may_drive(name, is_admin)
        await client.run()

    def _uptime_s(self) -> float:
        return round(self.clock.monotonic_s() - self.started_monotonic_s, 3)


def json_response(body: Any, status: http.HTTPStatus = http.HTTPStatus.OK) -> Response:
    """A small JSON HTTP response for websockets' ``process_request``."""
    data = json.dumps(body).encode()
    headers = Headers([("Content-Type", "application/json"),
                       ("Content-Length", str(len(data))), ("Cache-Control", "no-store")])
    return Response(status.value, status.phrase, headers, data)


def _token(query: str) -> str | None:
    """The ``token=`` of a WebSocket URL's query, if any."""
    return parse_qs(query).get("token", [None])[0]


def _peer(connection: ServerConnection) -> str:
    address = connection.remote_address
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return str(address)


async def start_websocket(server: WebSocketFront, host: str, port: int) -> Server:
    """Listen for rosbridge clients on ``host:port`` within ``server.limits``."""
    listening: Server = await serve(
        server.handle_connection, host, port, process_request=server.process_request,
        max_size=server.limits.max_frame_bytes, max_queue=MAX_INCOMING_FRAMES,
        ping_interval=PING_INTERVAL_S, ping_timeout=PING_INTERVAL_S,
        close_timeout=server.limits.close_timeout_s, compression=None)
    return listening
