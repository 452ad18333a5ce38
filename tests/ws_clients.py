"""Real WebSocket clients for the hostile-client tests: a healthy listener and a non-reader.

``OdomListener`` subscribes to /odom with the websockets library and records each message's
header stamp, so the robot's rate is measured from what it published, not from when this
(possibly loaded) test process got around to reading. ``NonReader`` speaks just enough of the
WebSocket protocol over a raw socket with a tiny receive buffer, subscribes, and then never
reads again: what a frozen phone on a stalled Wi-Fi looks like to the server.
"""

from __future__ import annotations

import asyncio
import base64
import itertools
import json
import os
import socket
import struct
from dataclasses import dataclass, field
from typing import Any

import websockets


@dataclass
class OdomListener:
    """Subscribes to /odom and keeps the stamps (s) of what it received."""

    url: str
    stamps_s: list[float] = field(default_factory=list)
    _task: asyncio.Task[None] | None = None

    async def __aenter__(self) -> OdomListener:
        connection = await websockets.connect(self.url, max_size=None)
        await connection.send(json.dumps({"op": "subscribe", "topic": "/odom",
                                          "queue_length": 100}))
        self._connection = connection
        self._task = asyncio.create_task(self._listen())
        return self

    async def _listen(self) -> None:
        async for frame in self._connection:
            message = json.loads(frame)
            if message.get("topic") == "/odom":
                stamp = message["msg"]["header"]["stamp"]
                self.stamps_s.append(stamp["sec"] + stamp["nanosec"] * 1e-9)

    async def __aexit__(self, *exc: object) -> None:
        assert self._task is not None
        self._task.cancel()
        await self._connection.close()

    def mark(self) -> int:
        """An index into the stamps, to measure from."""
        return len(self.stamps_s)

    def rate_since(self, start: int) -> tuple[float, float]:
        """(rate in Hz, largest gap in s) of the stamps received since ``mark()``."""
        stamps = self.stamps_s[start:]
        assert len(stamps) >= 2, f"only {len(stamps)} /odom messages since the mark"
        gaps = [b - a for a, b in itertools.pairwise(stamps)]
        return (len(stamps) - 1) / (stamps[-1] - stamps[0]), max(gaps)


class NonReader:
    """A WebSocket client on a raw socket that stops reading after its handshake.

    Args:
        port: the server's WebSocket port on 127.0.0.1.
        receive_buffer: the socket's SO_RCVBUF (bytes), set before connecting.
        path: the WebSocket path (a class robot's: ``/robots/NAME``).
    """

    def __init__(self, port: int, receive_buffer: int = 4096, path: str = "/") -> None:
        self.sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
        self.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, receive_buffer)
        self.sock.settimeout(5)
        self.sock.connect(("127.0.0.1", port))
        key = base64.b64encode(os.urandom(16)).decode()
        self.sock.sendall((f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n"
                           "Upgrade: websocket\r\n"
                           f"Connection: Upgrade\r\nSec-WebSocket-Key: {key}\r\n"
                           "Sec-WebSocket-Version: 13\r\n\r\n").encode())
        response = b""
        while b"\r\n\r\n" not in response:
            chunk = self.sock.recv(1)
            if not chunk:
                raise ConnectionError("closed during the handshake")
            response += chunk
        if not response.startswith(b"HTTP/1.1 101"):
            raise ConnectionError(response.decode(errors="replace"))

    def send(self, message: Any) -> None:
        """Send one masked text frame."""
        payload = json.dumps(message).encode()
        mask = os.urandom(4)
        header = bytes([0x81])
        if len(payload) < 126:
            header += bytes([0x80 | len(payload)])
        elif len(payload) < 65536:
            header += bytes([0x80 | 126]) + struct.pack(">H", len(payload))
        else:
            header += bytes([0x80 | 127]) + struct.pack(">Q", len(payload))
        masked = bytes(b ^ mask[i % 4] for i, b in enumerate(payload))
        self.sock.sendall(header + mask + masked)

    def read_available(self, limit_bytes: int = 1 << 24) -> int:
        """Read whatever the socket holds now, without waiting; the bytes read."""
        self.sock.setblocking(False)
        read = 0
        try:
            while read < limit_bytes:
                chunk = self.sock.recv(1 << 16)
                if not chunk:
                    break
                read += len(chunk)
        except BlockingIOError:
            pass
        finally:
            self.sock.setblocking(True)
            self.sock.settimeout(5)
        return read

    def is_closed_by_server(self) -> bool:
        """Whether the server closed or aborted the connection (reads what is left)."""
        self.sock.settimeout(0.5)
        try:
            while True:
                chunk = self.sock.recv(1 << 20)
                if not chunk:
                    return True
        except (ConnectionResetError, BrokenPipeError):
            return True
        except TimeoutError:
            return False

    def close(self) -> None:
        """Drop the socket."""
        self.sock.close()
