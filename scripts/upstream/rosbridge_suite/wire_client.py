"""A traced rosbridge WebSocket client for the upstream runners: every frame in and out, timed.

Each test owns one ``Trace``; every client it opens writes each frame it sends and receives
there (text as sent, binary frames decoded from CBOR, or from JSON when a server puts JSON in
a binary frame), so a failure prints the exact exchange. Messages are read by a background
task into a queue, as upstream's Twisted client hands each one to a handler.
"""

from __future__ import annotations

import asyncio
import contextlib
import json
import time
from dataclasses import dataclass, field
from typing import Any

import cbor2
import websockets

MAX_TRACE_CHARS = 400
"""Longest frame text kept in a trace line (longer ones are cut, with their length)."""


@dataclass
class Trace:
    """Every frame of one test, in order, with its time since the test started."""

    start_s: float = field(default_factory=time.monotonic)
    lines: list[str] = field(default_factory=list)

    def add(self, who: str, arrow: str, text: str) -> None:
        """Record one frame (or a note: ``arrow`` '--')."""
        if len(text) > MAX_TRACE_CHARS:
            text = f"{text[:MAX_TRACE_CHARS]}... ({len(text)} chars)"
        self.lines.append(f"{time.monotonic() - self.start_s:7.3f} {who:>8} {arrow} {text}")


def decode_frame(frame: str | bytes) -> tuple[Any, str]:
    """A received frame as (message, how it was framed): 'text', 'cbor' or 'json-in-binary'."""
    if isinstance(frame, str):
        return json.loads(frame), "text"
    try:
        return cbor2.loads(frame), "cbor"
    except Exception:
        return json.loads(frame.decode("utf-8")), "json-in-binary"


@dataclass
class Received:
    """One message a client received and how it was framed."""

    message: Any
    framing: str


class TracedClient:
    """One WebSocket connection to the bridge; ``await next()`` the messages it receives."""

    def __init__(self, name: str, connection: Any, trace: Trace) -> None:
        self.name = name
        self.connection = connection
        self.trace = trace
        self.inbox: asyncio.Queue[Received] = asyncio.Queue()
        self.closed_reason: str | None = None
        self.asked_for_errors = False
        """Whether this client sent ``set_level`` (``library_cases.ask_for_errors``)."""
        self._reader = asyncio.get_running_loop().create_task(self._read())

    @classmethod
    async def connect(cls, url: str, name: str, trace: Trace) -> TracedClient:
        """Open a connection (no compression, no size limit: what the server sends is seen)."""
        connection = await websockets.connect(url, max_size=None, compression=None,
                                              open_timeout=10)
        trace.add(name, "--", f"connected to {url}")
        return cls(name, connection, trace)

    async def _read(self) -> None:
        try:
            async for frame in self.connection:
                message, framing = decode_frame(frame)
                shown = frame if isinstance(frame, str) else \
                    f"<{framing} {len(frame)} B> {message!r}"
                self.trace.add(self.name, "<-", shown)
                await self.inbox.put(Received(message, framing))
        except websockets.ConnectionClosed as closed:
            self.closed_reason = f"closed {closed.rcvd}"
        self.closed_reason = self.closed_reason or "closed"
        self.trace.add(self.name, "--", self.closed_reason)

    async def send(self, message: dict[str, Any], times: int = 1) -> None:
        """Send ``message`` as one JSON text frame, ``times`` times."""
        text = json.dumps(message)
        for _ in range(times):
            self.trace.add(self.name, "->", text)
            await self.connection.send(text)

    async def next(self, timeout_s: float = 5.0, what: str = "a message") -> Any:
        """The next message received, or AssertionError after ``timeout_s``."""
        return (await self.next_framed(timeout_s, what)).message

    async def next_framed(self, timeout_s: float = 5.0, what: str = "a message") -> Received:
        """The next message with its framing, or AssertionError after ``timeout_s``."""
        try:
            return await asyncio.wait_for(self.inbox.get(), timeout_s)
        except asyncio.TimeoutError:
            raise AssertionError(f"{self.name}: no {what} within {timeout_s:g} s"
                                 f"{' (' + self.closed_reason + ')' if self.closed_reason else ''}"
                                 ) from None

    async def collect(self, count: int, timeout_s: float, what: str) -> list[Any]:
        """Exactly the next ``count`` messages (upstream's ``expect_messages``)."""
        got: list[Any] = []
        deadline = time.monotonic() + timeout_s
        while len(got) < count:
            left_s = deadline - time.monotonic()
            if left_s <= 0:
                raise AssertionError(f"{self.name}: {len(got)} of {count} {what} within "
                                     f"{timeout_s:g} s")
            try:
                got.append((await asyncio.wait_for(self.inbox.get(), left_s)).message)
            except asyncio.TimeoutError:
                continue
        return got

    async def drain(self, seconds: float) -> list[Any]:
        """Everything received within the next ``seconds``."""
        got: list[Any] = []
        deadline = time.monotonic() + seconds
        while (left_s := deadline - time.monotonic()) > 0:
            try:
                got.append((await asyncio.wait_for(self.inbox.get(), left_s)).message)
            except asyncio.TimeoutError:
                break
        return got

    async def close(self) -> None:
        """Close the connection (a clean close handshake) and stop reading."""
        self.trace.add(self.name, "--", "close")
        await self.connection.close()
        with contextlib.suppress(asyncio.CancelledError):
            await asyncio.wait_for(self._reader, 5)
