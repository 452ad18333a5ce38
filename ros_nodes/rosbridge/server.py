"""The embedded server: a robot in real time behind a rosbridge v2 WebSocket.

asyncio and websockets, in the websockets idiom: one ``ClientConnection`` object per client
(register on connect, unregister in ``finally``), no state shared between them but the
robot's bridge. Each client has a reader (frames into ``Bridge.handle``) and its ``Outbox``,
flushed onto the socket in one write after each tick (frames serialized once for all
clients, ``wire.py``); a client that falls behind gets a writer task that waits for its
socket, and a watchdog, so a slow client only ever delays itself.

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
import asyncio
import hmac
import http
import json
import logging
import socket
import time
from typing import Any, Protocol
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response
from websockets.protocol import State

from physics import TICK_PERIOD_S
from ros_nodes.rosbridge.bridge import Bridge
from ros_nodes.rosbridge.limits import ClientLimits, OriginPolicy, RateLimit, TokenBucket
from ros_nodes.rosbridge.outbox import Frame, Outbox
from ros_nodes.rosbridge.robot_host import RobotHost, Schedule, TickStats
from ros_nodes.rosbridge.session import Session
from ros_nodes.rosbridge.wire import WireFrames
from ros_nodes.virtual_robot_core import VirtualRobot

log = logging.getLogger("websim.server")

POLICY_VIOLATION = 1008
"""WebSocket close code for a client that broke a rule (rate, unread queue, stalled)."""

MAX_CLOSE_REASON_BYTES = 123
"""The WebSocket protocol's limit on a close reason (RFC 6455, 5.5)."""

PING_INTERVAL_S = 10.0
"""websockets keepalive: a browser that vanished without closing is dropped within ~20 s."""

WATCH_PERIOD_S = 0.5
"""How often a client's watchdog checks that its socket still accepts data."""

PROGRESS_BYTES = 4096
"""What a socket must accept to count as read from: a stalled peer's TCP window still lets a
few bytes through now and then (zero-window probes)."""

MAX_INCOMING_FRAMES = 2
"""Frames websockets buffers per client before it stops reading the socket (so a client
whose handling budget is spent holds at most this many frames of server memory)."""

LARGE_FRAME_BYTES = 64 << 10
"""Frames this large wait for room before the next tick (``Schedule.room``)."""

HANDLING_S_PER_BYTE = 10e-9
"""A generous estimate of what handling an accepted frame costs: 10 ms per MiB (parsing,
checking and canonical form measured at 3-5 ms per MiB on this project's machines)."""

FLOOD_CLOSE_TIMEOUT_S = 0.5
"""How long a client closed for flooding gets for the close handshake: its frames are no
longer read, so its close frame would only arrive behind them; its buffers go at once."""

ROBOTS_PREFIX = "/robots/"
"""Where a class's robots are: ``ws://HOST:9090/robots/NAME``."""

WRITE_BUFFER_BYTES = 64 << 10
"""What may wait in a client's transport buffer (beyond the kernel's) before its frames are
written one at a time, each after the socket drained (websockets' ``send``)."""

SEND_BUFFER_BYTES = 128 << 10
"""Kernel send buffer per client (Linux doubles it). Autotuned, it grows to about 4 MB, which a
client that stops reading fills at the stream's ~100 kB/s for most of a minute before its
outbox (bounded, newest first) takes over: 100 such clients would pin 400 MB of kernel memory.
128 KiB is still over a second of every topic, and a LAN's bandwidth-delay product."""


class Hub(Protocol):
    """What a connection's frames go to: a robot's ``Bridge``, or an instructor's view."""

    def connect(self, session: Session) -> None:
        """Register the client."""

    def disconnect(self, session: Session) -> None:
        """Forget the client and all it holds."""

    def handle(self, session: Session, frame: Frame) -> None:
        """Act on one frame of the client; never raises."""


class WebSocketFront(abc.ABC):
    """What every server does at a WebSocket handshake: health, origins, rights, routing.

    Subclasses say which robot a path names (``route``) and who is admin there.

    Args:
        admin_token: the secret that grants admin rights everywhere (``?token=``).
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).
    """

    def __init__(self, admin_token: str, limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None) -> None:
        self.limits = limits or ClientLimits()
        self._admin_token = admin_token
        self._origins = origins
        self.started_monotonic_s = time.monotonic()
        self.wire = WireFrames()
        """Outgoing frames serialized once for all the clients they go to."""

    @abc.abstractmethod
    def route(self, path: str) -> tuple[RobotHost, str | None] | str:
        """The robot a WebSocket path names, with its name, or why there is none.

        Returns:
            (host, name), name None for a server's single robot; or the reason to refuse.
        """

    def root_view(self, path: str, token: str | None) -> Hub | None:
        """A hub other than a robot for this path and token (an instructor's view), or None."""
        return None

    def schedule_of_view(self) -> Schedule:
        """The tick schedule a root view's large frames make room in."""
        return Schedule()

    def robot_admin(self, name: str | None, token: str | None) -> bool:
        """Whether ``token`` grants admin rights on robot ``name`` besides the admin token."""
        return False

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
            await ClientConnection(view, self.schedule_of_view(), connection, peer, True,
                                   self.limits, self.wire).run()
            return
        routed = self.route(target.path)
        if isinstance(routed, str):  # pragma: no cover - refused at the handshake
            return
        host, name = routed
        is_admin = self.is_admin_token(token) or self.robot_admin(name, token)
        if token and not is_admin:
            log.warning("client %s presented a wrong admin token", peer)
        await ClientConnection(host.bridge, host.schedule, connection, peer, is_admin,
                               self.limits, self.wire).run()

    def _uptime_s(self) -> float:
        return round(time.monotonic() - self.started_monotonic_s, 3)


class SimServer(WebSocketFront):
    """The WebSocket front of one robot, at every path but ``/robots/...``.

    Args:
        robot: the virtual robot to run.
        admin_token: the secret that grants admin rights (``?token=`` in the URL).
        period_s: tick period (s).
        limits: the bounds every client lives within.
        origins: which web pages may connect; None: any (tests and benchmarks).
    """

    def __init__(self, robot: VirtualRobot, admin_token: str,
                 period_s: float = TICK_PERIOD_S, limits: ClientLimits | None = None,
                 origins: OriginPolicy | None = None) -> None:
        super().__init__(admin_token, limits, origins)
        self.host = RobotHost(robot, Schedule(period_s))

    @property
    def robot(self) -> VirtualRobot:
        """The robot served."""
        return self.host.robot

    @property
    def bridge(self) -> Bridge:
        """The robot's bridge."""
        return self.host.bridge

    @property
    def stats(self) -> TickStats:
        """The robot's tick statistics."""
        return self.host.stats

    def route(self, path: str) -> tuple[RobotHost, str | None] | str:
        """The one robot, whatever the path (a proxy may pass its own), but ``/robots/...``."""
        if path.startswith(ROBOTS_PREFIX):
            return "this server runs one robot, not a class: connect to ws://HOST:PORT/"
        return self.host, None

    async def run_ticks(self) -> None:
        """Run the robot's tick loop forever."""
        await self.host.run_ticks()

    def health(self) -> dict[str, Any]:
        """A small status report: uptime, the robot's ticks, jitter, clients and faults."""
        return {**self.host.health(), "uptime_s": self._uptime_s()}


class ClientConnection:
    """One client's connection: its session, reader, writer and watchdog.

    Args:
        hub: what its frames go to: the bridge of the robot it talks to (or the instructor's
            view of a class).
        schedule: the tick schedule large frames make room in.
        connection: its WebSocket.
        peer: its address, for logs.
        is_admin: whether it presented the admin token.
        limits: the bounds it lives within.
        wire: where its frames are serialized (shared with the clients of the same server,
            so a message is framed once).
    """

    def __init__(self, hub: Hub, schedule: Schedule, connection: ServerConnection, peer: str,
                 is_admin: bool, limits: ClientLimits, wire: WireFrames | None = None) -> None:
        self._schedule = schedule
        self._bridge = hub
        self._connection = connection
        self._peer = peer
        self._limits = limits
        self._wire = wire if wire is not None else WireFrames()
        self._loop = asyncio.get_running_loop()
        self._flush_due = False
        self._backed_up = asyncio.Event()
        outbox = Outbox(limits.max_queued_bytes, limits.max_replies, wake=self._wake,
                        send=self._flush)
        self.session = Session(peer, is_admin, outbox, limits=limits)
        self._rate = RateLimit(limits.max_rate)
        self._handling = TokenBucket(limits.handling_share, limits.handling_burst_s)
        self._handed_bytes = 0
        self._closing: asyncio.Task[None] | None = None

    async def run(self) -> None:
        """Register, read frames until the connection ends, and unregister in ``finally``."""
        raw_socket = self._connection.transport.get_extra_info("socket")
        if raw_socket is not None:
            raw_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        self._bridge.connect(self.session)
        log.info("client %s connected%s", self._peer,
                 " (admin)" if self.session.is_admin else "")
        writer = asyncio.create_task(self._write())
        try:
            await self._read()
        finally:
            writer.cancel()
            self._bridge.disconnect(self.session)
            self.session.outbox.detach()
            log.info("client %s disconnected", self._peer)
            if self._closing is not None:
                await asyncio.wait([self._closing])

    async def _read(self) -> None:
        try:
            async for frame in self._connection:
                if not self._rate.allow(len(frame)):
                    self._close(POLICY_VIOLATION, self._rate.reason(), FLOOD_CLOSE_TIMEOUT_S)
                    return  # its further frames are not even read: the close ends it
                wait_s = self._handling.wait_s()
                if wait_s > 0:  # its budget is spent: its frames wait, its socket backs up
                    await asyncio.sleep(wait_s)
                if len(frame) >= LARGE_FRAME_BYTES:  # handled between ticks, not across one
                    await self._schedule.room(len(frame) * HANDLING_S_PER_BYTE)
                started = time.perf_counter()
                self._bridge.handle(self.session, frame)
                self._handling.charge(time.perf_counter() - started)
        except ConnectionClosed:
            pass

    def _wake(self) -> None:
        """The outbox got a frame: flush it once the current callback (a tick) is done."""
        if not self._flush_due:
            self._flush_due = True
            self._loop.call_soon(self._scheduled_flush)

    def _scheduled_flush(self) -> None:
        self._flush_due = False
        self._flush()

    def _flush(self) -> None:
        """Write what waits in the outbox onto the socket, in one write, without waiting.

        Scheduled after the callback that queued a frame (``_wake``: a tick's frames go out
        together), or called at once (``Outbox.send_now``: a client closing a loop).

        Every frame goes out as its serialized bytes (``WireFrames``: framed once for all
        subscribers); nothing else of websockets runs per frame. Past ``WRITE_BUFFER_BYTES``
        in the transport's buffer the client is behind: the writer task takes over, through
        websockets' ``send``, which waits for the socket to drain.
        """
        outbox = self.session.outbox
        if outbox.overflowed is not None or self._closing is not None:
            self._backed_up.set()  # the writer closes it
            return
        if self._backed_up.is_set() or self._connection.protocol.state is not State.OPEN:
            return
        transport = self._connection.transport
        room = WRITE_BUFFER_BYTES - transport.get_write_buffer_size()
        if room > 0:
            wire = self._wire.of
            chunks = [wire(frame) for frame in outbox.take(room)]
            if chunks:
                data = b"".join(chunks) if len(chunks) > 1 else chunks[0]
                self._handed_bytes += len(data)
                transport.write(data)
        if len(outbox) > 0 or outbox.overflowed is not None:
            outbox.behind = True
            self._backed_up.set()

    async def _write(self) -> None:
        """Serve a client that is behind: one frame at a time, waiting for its socket.

        Only while it is behind does a watchdog look at its socket (``_watch``): a client
        that keeps up has nothing waiting beyond ``WRITE_BUFFER_BYTES``.
        """
        outbox = self.session.outbox
        try:
            while True:
                await self._backed_up.wait()
                watchdog = asyncio.create_task(self._watch())
                try:
                    while outbox.overflowed is None and (frame := outbox.pop()) is not None:
                        self._handed_bytes += len(frame)
                        await self._connection.send(frame)  # waits while the socket is full
                finally:
                    watchdog.cancel()
                if outbox.overflowed is not None:
                    self._close(POLICY_VIOLATION, outbox.overflowed)
                    return
                outbox.behind = False
                self._backed_up.clear()  # caught up: back to flushing after each tick
        except ConnectionClosed:
            pass

    async def _watch(self) -> None:
        """Close the client if it lets too much pile up, or its socket stops accepting.

        An overflowed outbox is checked here too, since the writer may be blocked in
        ``send``; a socket that accepts (next to) nothing for ``stall_timeout_s`` while
        frames wait is a client that does not read.
        """
        loop = asyncio.get_running_loop()
        transport = self._connection.transport
        baseline = 0
        progress_s = loop.time()
        while True:
            await asyncio.sleep(WATCH_PERIOD_S)
            if self.session.outbox.overflowed is not None:  # the writer may be stuck in send
                self._close(POLICY_VIOLATION, self.session.outbox.overflowed)
                return
            buffered = transport.get_write_buffer_size()
            accepted = self._handed_bytes - buffered  # what the kernel took so far
            waiting = buffered > 0 or len(self.session.outbox) > 0
            if not waiting or accepted - baseline >= PROGRESS_BYTES:
                baseline, progress_s = accepted, loop.time()
                continue
            stalled_s = loop.time() - progress_s
            if stalled_s >= self._limits.stall_timeout_s:
                self._close(POLICY_VIOLATION, f"not reading: the socket accepted nothing for "
                                              f"{stalled_s:.0f} s")
                return

    def _close(self, code: int, reason: str, timeout_s: float | None = None) -> None:
        """Start closing with ``code`` and ``reason``; abort the transport if that stalls.

        ``timeout_s``: how long the close handshake may take (default
        ``limits.close_timeout_s``).
        """
        if self._closing is not None:
            return
        log.warning("client %s: %s; disconnecting it", self._peer, reason)
        self._closing = asyncio.create_task(self._close_or_abort(
            code, reason, self._limits.close_timeout_s if timeout_s is None else timeout_s))

    async def _close_or_abort(self, code: int, reason: str, timeout_s: float) -> None:
        shortened = reason.encode()[:MAX_CLOSE_REASON_BYTES].decode(errors="ignore")
        try:
            await asyncio.wait_for(self._connection.close(code, shortened), timeout_s)
        except TimeoutError:
            log.warning("client %s: the close handshake could not be written; aborting",
                        self._peer)
            self._connection.transport.abort()


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
