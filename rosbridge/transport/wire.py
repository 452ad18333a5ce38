"""Outgoing WebSocket frames, serialized once per message for every client it goes to.

A server's frames to its clients are not masked (RFC 6455, 5.1), so a message's frame is the
same bytes on every connection: one /odom that 500 clients subscribe to is framed once here
(websockets' own ``Frame.serialize``) and then only written to each socket. Text frames are
``str`` (JSON), binary frames ``bytes`` (CBOR), as in the outbox.

``WireFrames`` keeps the frames of recent messages, bounded in bytes: a frame is looked up
by the identity of the message object (a topic's subscribers share it; no hashing of its
text), and the whole memo is dropped when it would exceed its budget, so a client that is
behind at worst makes its frame be serialized once more.
"""

from __future__ import annotations

from websockets.frames import Frame as WebSocketFrame
from websockets.frames import Opcode

from rosbridge.core.outbox import Frame

WIRE_MEMO_BYTES = 8 << 20
"""Most bytes of serialized frames kept for reuse (a tick of 100 robots is about 1.2 MB); the
messages they frame are held with them, as large again."""


def serialize(frame: Frame) -> bytes:
    """The bytes of ``frame`` as one unmasked, unfragmented, uncompressed WebSocket frame."""
    if isinstance(frame, str):
        return WebSocketFrame(Opcode.TEXT, frame.encode()).serialize(mask=False)
    return WebSocketFrame(Opcode.BINARY, frame).serialize(mask=False)


class WireFrames:
    """A bounded memo of serialized frames.

    Args:
        max_bytes: most bytes of serialized frames kept at once.
    """

    def __init__(self, max_bytes: int = WIRE_MEMO_BYTES) -> None:
        self._max_bytes = max_bytes
        self._frames: dict[int, tuple[Frame, bytes]] = {}
        self._bytes = 0

    def of(self, frame: Frame) -> bytes:
        """``frame`` serialized (from the memo when the same message was framed before)."""
        entry = self._frames.get(id(frame))
        if entry is not None and entry[0] is frame:
            return entry[1]
        wire = serialize(frame)
        if self._bytes + len(wire) > self._max_bytes:
            self._frames.clear()
            self._bytes = 0
        self._frames[id(frame)] = (frame, wire)  # the frame held: its id is not reused
        self._bytes += len(wire)
        return wire

    def __len__(self) -> int:
        return len(self._frames)

    @property
    def held_bytes(self) -> int:
        """Bytes of serialized frames held now."""
        return self._bytes
