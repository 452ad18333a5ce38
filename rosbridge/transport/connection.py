"""One client's WebSocket connection: its session, reader, writer and watchdog.

The core is pull-style: what a call into a hub queues, the call returns as a ``Flush`` (who
must be written, the clients closing a loop first), and the I/O layer writes it through the
``Writers`` of its event loop (its ``Pace``'s ``writers``): a connection after each of its
frames, whoever runs a tick after it, the pace for what came in between (``sweep``).
"""

from __future__ import annotations

import asyncio
import logging
import socket
import time
from typing import Protocol

from websockets.asyncio.server import ServerConnection
from websockets.exceptions import ConnectionClosed
from websockets.protocol import State

from rosbridge.core.clock import WALL_CLOCK, Clock
from rosbridge.core.limits import (
    AddressBudget,
    ClientLimits,
    RateLimit,
    RobotBudget,
    TokenBucket,
)
from rosbridge.core.outbox import Frame, Outbox
from rosbridge.core.session import Flush, Session
from rosbridge.transport.wire import WireFrames
from rosbridge.transport.writers import Pace, Writers

log = logging.getLogger("websim.server")

POLICY_VIOLATION = 1008
"""WebSocket close code for a client that broke a rule (rate, unread queue, stalled)."""

MAX_CLOSE_REASON_BYTES = 123
"""The WebSocket protocol's limit on a close reason (RFC 6455, 5.5)."""

WATCH_PERIOD_S = 0.5
"""How often a client's watchdog checks that its socket still accepts data."""

PROGRESS_BYTES = 4096
"""What a socket must accept to count as read from: a stalled peer's TCP window still lets a
few bytes through now and then (zero-window probes)."""

LARGE_FRAME_BYTES = 64 << 10
"""Frames this large wait for room before the next tick (``Pace.room``)."""

HANDLING_S_PER_BYTE = 10e-9
"""A generous estimate of what handling an accepted frame costs: 10 ms per MiB (parsing,
checking and canonical form measured at 3-5 ms per MiB on this project's machines)."""

FLOOD_CLOSE_TIMEOUT_S = 0.5
"""How long a client closed for flooding gets for the close handshake: its frames are no
longer read, so its close frame would only arrive behind them; its buffers go at once."""

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
        """Register the client (its frames are noted in the hub's flushes from now on)."""

    def disconnect(self, session: Session) -> Flush:
        """Forget the client and all it holds; who must be written (the others told)."""

    def handle(self, session: Session, frame: Frame) -> Flush:
        """Act on one frame of the client; never raises. Who must be written."""


class BridgeConnection:
    """One client's connection: its session, reader, writer and watchdog.

    Args:
        hub: what its frames go to: the bridge of the robot it talks to (or the instructor's
            view of a class).
        pace: what paces its messages: large frames make room before its next tick; its
            ``writers`` write what the hub returns (the connection registers there, by its
            outbox, in the pace's group: above real time that pace waits for it).
        connection: its WebSocket.
        peer: its address, for logs.
        is_admin: whether it presented the admin token.
        limits: the bounds it lives within.
        wire: where its frames are serialized (shared with the clients of the same server,
            so a message is framed once).
        clock: the clock of its budgets and its watchdog (default: wall time).
        address: what all the connections of its client address spend together (messages,
            handling time, bytes); None: only its own budgets (the instructor's root view).
        robot: what all the clients of its robot spend together (handling time), from every
            address; None: no such budget (the instructor's root view).
    """

    def __init__(self, hub: Hub, pace: Pace, connection: ServerConnection, peer: str,
                 is_admin: bool, limits: ClientLimits, wire: WireFrames | None = None,
                 clock: Clock = WALL_CLOCK, address: AddressBudget | None = None,
                 robot: RobotBudget | None = None) -> None:
        self._pace = pace
        self._writers: Writers = pace.writers
        self._bridge = hub
        self._connection = connection
        self._peer = peer
        self._limits = limits
        self._wire = wire if wire is not None else WireFrames()
        self._clock = clock
        self._backed_up = asyncio.Event()
        outbox = Outbox(limits.max_queued_bytes, limits.max_replies)
        self.session = Session(peer, is_admin, outbox, limits=limits, clock=clock)
        self._rate = RateLimit(limits.max_rate, clock.monotonic_s)
        self._handling = TokenBucket(limits.handling_share, limits.handling_burst_s,
                                     clock.monotonic_s)
        self._address = address
        self._robot = robot
        self._held_until_s = 0.0
        """Until when frames read may be a backlog its address's budget held back (then
        reading them faster than ``max_rate`` is no flood of the client's)."""
        self._handed_bytes = 0
        self._closing: asyncio.Task[None] | None = None
        self._pacing = False
        """Whether its writer waits for its handling budget (its costly formats): its own
        lateness, which the watchdog does not take for a socket that stopped reading."""

    async def run(self) -> None:
        """Register, read frames until the connection ends, and unregister in ``finally``."""
        raw_socket = self._connection.transport.get_extra_info("socket")
        if raw_socket is not None:
            raw_socket.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, SEND_BUFFER_BYTES)
        outbox = self.session.outbox
        self._writers.add(outbox, self._flush, self._pace)
        self._bridge.connect(self.session)
        log.info("client %s connected%s", self._peer,
                 " (admin)" if self.session.is_admin else "")
        writer = asyncio.create_task(self._write())
        try:
            await self._read()
        finally:
            writer.cancel()
            self._writers.remove(outbox)
            self._writers.write(self._bridge.disconnect(self.session))
            log.info("client %s disconnected", self._peer)
            if self._closing is not None:
                await asyncio.wait([self._closing])

    async def _read(self) -> None:
        try:
            async for frame in self._connection:
                if not self._rate.allow(len(frame)):
                    if self._clock.monotonic_s() < self._held_until_s:  # we held it back:
                        await asyncio.sleep(1.0 / self._limits.max_rate)  # its backlog, read
                    else:
                        self._close(POLICY_VIOLATION, self._rate.reason(),
                                    FLOOD_CLOSE_TIMEOUT_S)
                        return  # its further frames are not even read: the close ends it
                wait_s = self._handling.wait_s()
                held_s = max(self._address.wait_s() if self._address is not None else 0.0,
                             self._robot.wait_s() if self._robot is not None else 0.0)
                if held_s > 0:  # its address's or its robot's budget: shared with others
                    wait_s = max(wait_s, held_s)
                    self._held_until_s = self._clock.monotonic_s() + held_s + 1.0
                if wait_s > 0:  # its budget is spent: its frames wait, its socket backs up
                    await asyncio.sleep(wait_s)
                if len(frame) >= LARGE_FRAME_BYTES:  # handled between ticks, not across one
                    await self._pace.room(len(frame) * HANDLING_S_PER_BYTE)
                started = time.perf_counter()
                self._writers.write(self._bridge.handle(self.session, frame))
                handling_s = time.perf_counter() - started
                self._handling.charge(handling_s)
                if self._address is not None:
                    self._address.charge(len(frame), handling_s)
                if self._robot is not None:
                    self._robot.charge_time(handling_s)
        except ConnectionClosed:
            pass

    def _flush(self) -> None:
        """Write what waits in the outbox onto the socket, in one write, without waiting.

        Called by ``Writers``: at once for a client closing a loop (``Flush.now``), else
        after the callback that queued its frames (a tick's frames go out together).

        Every frame goes out as its serialized bytes (``WireFrames``: framed once for all
        subscribers); nothing else of websockets runs per frame. Past ``WRITE_BUFFER_BYTES``
        in the transport's buffer the client is behind: the writer task takes over, through
        websockets' ``send``, which waits for the socket to drain.
        """
        outbox = self.session.outbox
        if outbox.overflowed is not None or self._closing is not None:
            self._writers.release([outbox])  # closing: the ticks wait for it no more
            self._backed_up.set()  # the writer closes it
            return
        if self._connection.protocol.state is not State.OPEN:
            self._writers.release([outbox])
            return
        if self._backed_up.is_set():
            return
        if outbox.has_deferred() and self._encoding_wait_s() > 0:  # the cheaper test first
            outbox.behind = True  # its costly formats wait for its budget, in its writer
            self._backed_up.set()
            self._writers.release([outbox])  # its own lateness: the ticks do not wait for it
            return
        transport = self._connection.transport
        room = WRITE_BUFFER_BYTES - transport.get_write_buffer_size()
        if room > 0:
            wire = self._wire.of
            chunks = [wire(frame) for frame in outbox.take(room)]
            self._charge_encoding()
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
                    while outbox.overflowed is None:
                        wait_s = self._encoding_wait_s()
                        if wait_s > 0 and outbox.has_deferred():
                            self._writers.release([outbox])  # its lateness, not the ticks'
                            self._pacing = True
                            try:
                                await asyncio.sleep(wait_s)  # only this client waits
                            finally:
                                self._pacing = False
                        frame = outbox.pop()
                        self._charge_encoding()
                        if frame is None:
                            break
                        self._handed_bytes += len(frame)
                        await self._connection.send(frame)  # waits while the socket is full
                finally:
                    watchdog.cancel()
                if outbox.overflowed is not None:
                    self._close(POLICY_VIOLATION, outbox.overflowed)
                    return
                outbox.behind = False
                self._backed_up.clear()  # caught up: back to flushing after each tick
                self._writers.caught_up()
        except ConnectionClosed:
            pass

    def _charge_encoding(self) -> None:
        """Charge the client's handling budgets with the costly formats made for it.

        Its ``png``, ``cbor-raw`` and fragmented frames are made when they are written
        (``outbox.Deferred``): the client that asked pays, in time it is then read and
        written more slowly, and so do its address and its robot (many connections, each
        asking a little, pay together), never the tick nor the publisher.
        """
        outbox = self.session.outbox
        if outbox.encode_s:
            self._handling.charge(outbox.encode_s)
            if self._address is not None:
                self._address.charge_time(outbox.encode_s)
            if self._robot is not None:
                self._robot.charge_time(outbox.encode_s)
            outbox.encode_s = 0.0

    def _encoding_wait_s(self) -> float:
        """How long its costly formats must wait: the debt of its, its address's or robot's."""
        return max(self._handling.wait_s(),
                   self._address.handling_wait_s() if self._address is not None else 0.0,
                   self._robot.wait_s() if self._robot is not None else 0.0)

    async def _watch(self) -> None:
        """Close the client if it lets too much pile up, or its socket stops accepting.

        An overflowed outbox is checked here too, since the writer may be blocked in
        ``send``; a socket that accepts (next to) nothing for ``stall_timeout_s`` while
        frames wait is a client that does not read.
        """
        clock = self._clock
        transport = self._connection.transport
        baseline = 0
        progress_s = clock.monotonic_s()
        while True:
            await asyncio.sleep(WATCH_PERIOD_S)
            if self.session.outbox.overflowed is not None:  # the writer may be stuck in send
                self._close(POLICY_VIOLATION, self.session.outbox.overflowed)
                return
            buffered = transport.get_write_buffer_size()
            accepted = self._handed_bytes - buffered  # what the kernel took so far
            waiting = buffered > 0 or len(self.session.outbox) > 0
            if not waiting or self._pacing or accepted - baseline >= PROGRESS_BYTES:
                baseline, progress_s = accepted, clock.monotonic_s()
                continue
            stalled_s = clock.monotonic_s() - progress_s
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
