"""The embedded server: the simulation in real time behind a rosbridge v2 WebSocket.

asyncio and websockets. One task ticks the simulation every 50 ms against the monotonic clock
(deadlines advance by exactly one period, so there is no drift) and hands the tick's messages
to the ``Bridge``, which encodes each once and queues it per client. Each client has a reader
(frames into ``Bridge.handle``) and a writer (its ``Outbox`` onto the socket), so a slow
client only ever delays itself. websockets' ping keepalive drops dead connections.

Limits: pages from other origins are refused at the handshake (403, ``OriginPolicy``); a
message over ``max_frame_bytes`` closes the connection (1009), and so does a client sending
faster than ``max_rate`` (1008, ``RateLimit``); each client's kernel send buffer is capped.
When the host cannot keep up (a tick starts half a period late), that tick's /scan is shed
first; /odom and /tf keep their rate.
"""

from __future__ import annotations

import asyncio
import hmac
import http
import json
import logging
import socket
import time
from collections import deque
from dataclasses import dataclass
from typing import Any
from urllib.parse import parse_qs, urlsplit

from websockets.asyncio.server import Server, ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed
from websockets.http11 import Request, Response

from physics import TICK_PERIOD_S
from ros_nodes.rosbridge.bridge import Bridge, Session
from ros_nodes.rosbridge.limits import DEFAULT_MAX_RATE, OriginPolicy, RateLimit
from ros_nodes.rosbridge.outbox import Outbox
from ros_nodes.rosbridge.services import add_robot_services
from ros_nodes.topics import SCAN
from ros_nodes.virtual_robot_core import VirtualRobot

log = logging.getLogger("websim.server")

MAX_FRAME_BYTES = 1 << 20
"""Largest incoming WebSocket message by default (1 MiB); larger ones close the connection
(1009, "... exceeds limit of 1048576 bytes"). A full /scan in JSON is about 5 KiB."""

POLICY_VIOLATION = 1008
"""WebSocket close code for a client that broke a rule (rate, unread queue)."""

PING_INTERVAL_S = 10.0
"""websockets keepalive: a browser that vanished without closing is dropped within ~20 s."""

SEND_BUFFER_BYTES = 128 << 10
"""Kernel send buffer per client (Linux doubles it). Autotuned, it grows to about 4 MB, which a
client that stops reading fills at the stream's ~100 kB/s for most of a minute before its
outbox (bounded, newest first) takes over: 100 such clients would pin 400 MB of kernel memory.
128 KiB is still over a second of every topic, and a LAN's bandwidth-delay product."""

SHED_SCANS_AFTER_S = 0.025
"""A tick that starts this late (half a period: the host cannot keep up with the clients)
publishes no /scan: the biggest message goes first, /odom and /tf keep their rate."""

RESYNC_AFTER_S = 1.0
"""If the tick loop falls this far behind (a suspended laptop), it restarts its schedule
instead of replaying every missed tick at once."""


@dataclass
class TickStats:
    """What the tick loop has done, for /healthz and benchmarks.

    Attributes:
        ticks: ticks run since start.
        started_s: when the schedule started (event-loop monotonic s), None before.
        lateness_s: how late each recent tick started after its deadline (s).
        resyncs: times the schedule was restarted after falling far behind.
        scans_shed: /scan messages not published because their tick was late.
    """

    ticks: int = 0
    started_s: float | None = None
    lateness_s: deque[float] | None = None
    resyncs: int = 0
    scans_shed: int = 0

    def __post_init__(self) -> None:
        self.lateness_s = deque(maxlen=1200)

    def jitter_p99_ms(self) -> float:
        """99th percentile of recent tick lateness (ms)."""
        samples = sorted(self.lateness_s or ())
        if not samples:
            return 0.0
        return 1000.0 * samples[min(len(samples) - 1, int(0.99 * len(samples)))]


class SimServer:
    """The robot, its bridge and the WebSocket endpoint.

    Args:
        robot: the virtual robot to run.
        admin_token: the secret that grants admin rights (``?token=`` in the URL).
        period_s: tick period (s).
        max_rate: messages per second one client may send before it is disconnected.
        origins: which web pages may connect; None: any (tests and benchmarks).
    """

    def __init__(self, robot: VirtualRobot, admin_token: str,
                 period_s: float = TICK_PERIOD_S, max_rate: float = DEFAULT_MAX_RATE,
                 origins: OriginPolicy | None = None) -> None:
        self.robot = robot
        self.bridge = Bridge(robot.on_cmd_vel)
        add_robot_services(self.bridge, robot)
        self._admin_token = admin_token
        self._period_s = period_s
        self._max_rate = max_rate
        self._origins = origins
        RateLimit(max_rate)  # fail at start, not at the first client, on a bad rate
        self.stats = TickStats()
        self.started_monotonic_s = time.monotonic()
        for spec, msg in robot.latched():
            self.bridge.publish(spec.name, msg, latch=True)

    def health(self) -> dict[str, Any]:
        """A small status report: uptime, ticks, jitter, clients, queued frames, sim time."""
        started = self.stats.started_s
        due = 0 if started is None else int((time.monotonic() - started) / self._period_s)
        return {
            "status": "ok",
            "uptime_s": round(time.monotonic() - self.started_monotonic_s, 3),
            "ticks": self.stats.ticks,
            "ticks_due": due,
            "tick_jitter_p99_ms": round(self.stats.jitter_p99_ms(), 3),
            "tick_resyncs": self.stats.resyncs,
            "scans_shed": self.stats.scans_shed,
            "clients": len(self.bridge.sessions),
            "queued_frames": sum(len(session.outbox) for session in self.bridge.sessions),
            "sim_time_s": round(self.robot.sim.time_s, 3),
            "mode": self.robot.sim.mode,
            "world": self.robot.sim.world.name,
        }

    def is_admin_token(self, token: str | None) -> bool:
        """Constant-time comparison of a presented token with the admin token."""
        if not token:
            return False
        return hmac.compare_digest(token.encode(), self._admin_token.encode())

    async def run_ticks(self) -> None:
        """Tick forever at ``period_s``, deadlines fixed to the monotonic clock."""
        loop = asyncio.get_running_loop()
        deadline = loop.time()
        self.stats.started_s = deadline
        while True:
            deadline += self._period_s
            delay = deadline - loop.time()
            if delay > 0:
                await asyncio.sleep(delay)
            now = loop.time()
            if now - deadline > RESYNC_AFTER_S:
                log.warning("tick loop %.1f s behind; restarting its schedule", now - deadline)
                self.stats.resyncs += 1
                self.stats.started_s = now - self.stats.ticks * self._period_s
                deadline = now
            assert self.stats.lateness_s is not None
            lateness_s = max(0.0, now - deadline)
            self.stats.lateness_s.append(lateness_s)
            for spec, msg in self.robot.step():
                if spec is SCAN and lateness_s > SHED_SCANS_AFTER_S:
                    self.stats.scans_shed += 1
                    continue
                self.bridge.publish(spec.name, msg)
            self.bridge.expire_calls()
            self.stats.ticks += 1

    def process_request(self, connection: ServerConnection,
                        request: Request) -> Response | None:
        """Answer ``GET /healthz`` over plain HTTP; refuse pages from other origins (403)."""
        if urlsplit(request.path).path == "/healthz":
            return json_response(self.health())
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
        """Serve one client: register, read frames, and unregister in ``finally``."""
        peer = _peer(connection)
        query = parse_qs(urlsplit(connection.request.path if connection.request else "").query)
        token = query.get("token", [None])[0]
        is_admin = self.is_admin_token(token)
        if token and not is_admin:
            log.warning("client %s presented a wrong admin token", peer)
        raw_socket = connection.transport.get_extra_info("socket")
        if raw_socket is not None:
            raw_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        wake = asyncio.Event()
        session = Session(peer, is_admin, Outbox(wake=wake.set))
        self.bridge.connect(session)
        log.info("client %s connected%s", peer, " (admin)" if is_admin else "")
        writer = asyncio.create_task(self._write(connection, session, wake))
        limit = RateLimit(self._max_rate)
        closing: asyncio.Task[None] | None = None
        try:
            async for frame in connection:
                if closing is not None:
                    continue  # keep reading until the client's close frame arrives
                if not limit.allow(len(frame)):
                    log.warning("client %s: %s; disconnecting it", peer, limit.reason())
                    closing = asyncio.create_task(
                        connection.close(POLICY_VIOLATION, limit.reason()))
                    continue
                self.bridge.handle(session, frame)
        except ConnectionClosed:
            pass
        finally:
            writer.cancel()
            self.bridge.disconnect(session)
            log.info("client %s disconnected", peer)
            if closing is not None:
                await asyncio.wait([closing])

    async def _write(self, connection: ServerConnection, session: Session,
                     wake: asyncio.Event) -> None:
        """Move frames from the client's outbox onto its socket, oldest first."""
        outbox = session.outbox
        try:
            while True:
                await wake.wait()
                wake.clear()
                if outbox.overflowed:
                    await connection.close(POLICY_VIOLATION,
                                           "send queue overflow: client is not reading")
                    return
                while (frame := outbox.pop()) is not None:
                    await connection.send(frame)
        except ConnectionClosed:
            pass


def json_response(body: Any, status: http.HTTPStatus = http.HTTPStatus.OK) -> Response:
    """A small JSON HTTP response for websockets' ``process_request``."""
    data = json.dumps(body).encode()
    headers = Headers([("Content-Type", "application/json"),
                       ("Content-Length", str(len(data))), ("Cache-Control", "no-store")])
    return Response(status.value, status.phrase, headers, data)


def _peer(connection: ServerConnection) -> str:
    address = connection.remote_address
    if isinstance(address, tuple) and len(address) >= 2:
        return f"{address[0]}:{address[1]}"
    return str(address)


async def start_websocket(server: SimServer, host: str, port: int,
                          max_frame_bytes: int = MAX_FRAME_BYTES) -> Server:
    """Listen for rosbridge clients on ``host:port``; larger messages close with 1009."""
    listening: Server = await serve(server.handle_connection, host, port,
                       process_request=server.process_request,
                       max_size=max_frame_bytes, ping_interval=PING_INTERVAL_S,
                       ping_timeout=PING_INTERVAL_S, compression=None)
    return listening

