"""A client's bounded send queue: the newest messages per subscription, replies in order.

There is no backpressure in a broadcast: a client that reads slowly must not stall the tick or
the other clients, nor grow without bound. Each subscribed topic keeps at most its
``queue_length`` newest frames (older ones are dropped, as rosbridge's ``queue_length``
promises). ``queue_length`` 0 (both libraries' default) means what it means in rosbridge
with no throttle: every message is sent, a burst of ten published at once included; only
while the client is ``behind`` (its socket does not take what is written) does such a topic
keep just its newest frame. Replies (service responses, statuses) are never dropped.
Everything waiting is counted in bytes, and bounded by ``max_bytes``: a topic frame that
would pass it makes room by dropping the oldest topic frames waiting (of any topic; never one
half sent), so a client is never closed for what others published, however much of it comes
at once (32 publishers bursting 1 MB each closed a subscriber that read at full speed). Only
its replies past ``max_bytes``, or past ``max_replies`` replies, mark the outbox
``overflowed`` with the reason, and the server closes the client; a client that stops
reading altogether is closed by its connection's watchdog (``stall_timeout_s``).

A topic frame may be ``Deferred``: an expensive format (``png``, ``cbor-raw``, fragments) is
made when the frame is taken to be written, not when it is queued, so its cost falls on the
client that asked for it (its connection charges ``encode_s`` to its handling budget), never
on the tick or on the publisher; one that a newer frame replaces is never made at all.

An outbox only holds frames: it calls nobody but the ``Deferred`` it was given. Whoever
queues into it reports the client as ready (``Session.ready``), and the core's entry points
return who must be written (``Flush``); the transport writes it (``take``, ``pop``).
"""

from __future__ import annotations

import itertools
import time
from collections import deque
from collections.abc import Callable

Frame = str | bytes
"""A WebSocket message: text (JSON) or binary (CBOR)."""

Frames = Frame | tuple[Frame, ...]
"""One message's frames: one, or a fragmented message's (``fragments``), which are queued,
dropped and counted together and sent one after the other."""


class Deferred:
    """A topic message's frames, made only when they are taken to be written.

    Args:
        make: makes the frames (never raises: a message that cannot be written in the
            format comes back as an error ``status`` frame).
        size: what it is counted as while it waits (its JSON text's length: about what a
            PNG or CDR of it takes, a little less than its fragments).
    """

    __slots__ = ("make", "size")

    def __init__(self, make: Callable[[], Frames], size: int) -> None:
        self.make = make
        self.size = size


Entry = Frames | Deferred
"""What a topic queue holds: frames, or frames still to be made."""


def _sequence_of(entry: tuple[int, Entry]) -> int:
    return entry[0]


def _size(frames: Entry) -> int:
    if isinstance(frames, Deferred):
        return frames.size
    return sum(map(len, frames)) if isinstance(frames, tuple) else len(frames)


def _flat(entries: list[Frames]) -> list[Frame]:
    return [frame for entry in entries
            for frame in (entry if isinstance(entry, tuple) else (entry,))]


class Outbox:
    """Frames waiting to be sent to one client.

    Args:
        max_bytes: most bytes (characters of text frames) that may wait at once.
        max_replies: most replies that may wait at once.
    """

    def __init__(self, max_bytes: int = 4 << 20, max_replies: int = 1000) -> None:
        self._replies: deque[Frames] = deque()
        self._topics: dict[str, deque[tuple[int, Entry]]] = {}
        self._sequence = itertools.count()
        self._max_bytes = max_bytes
        self._max_replies = max_replies
        self.queued_bytes = 0
        """Bytes of every frame waiting."""
        self._reply_bytes = 0
        self._sending: int | None = None
        """The sequence number of the topic message whose frames are half sent, if any."""
        self.dropped = 0
        """Topic frames dropped because a newer one replaced them."""
        self.sent = 0
        """Topic messages taken to be written (``pop``, ``take``): with ``dropped`` and what
        waits, every topic message queued is accounted for."""
        self.overflowed: str | None = None
        """Why the client must be closed (it let too much pile up), or None."""
        self.behind = False
        """Whether frames wait for the client's socket (the connection sets it): then a
        ``queue_length`` 0 topic keeps only its newest frame."""
        self.encode_s = 0.0
        """Time spent making ``Deferred`` frames since the connection last charged it (s)."""

    def __len__(self) -> int:
        return len(self._replies) + sum(len(queue) for queue in self._topics.values())

    def put_reply(self, frame: Frames) -> None:
        """Queue a reply, making room by dropping topic frames (``_make_room``).

        Past the reply budget, or with the replies alone past the byte budget, the outbox is
        marked overflowed.
        """
        if len(self._replies) >= self._max_replies:
            self._overflow(f"{self._max_replies} replies unread")
            return
        self._replies.append(frame)
        self._reply_bytes += _size(frame)
        self.queued_bytes += _size(frame)
        self._make_room(None)

    def put_topic(self, topic: str, frame: Entry, queue_length: int) -> None:
        """Queue a topic frame, keeping the newest ``queue_length`` for ``topic``.

        ``queue_length`` 0: every frame while the client keeps up, the newest one while it is
        ``behind``.
        """
        queue = self._topics.get(topic)
        limit = queue_length if queue_length > 0 else (1 if self.behind else None)
        if queue is None or queue.maxlen != limit:
            old = list(queue or ())
            kept = old if limit is None else old[-limit:]
            self.dropped += len(old) - len(kept)
            self.queued_bytes -= sum(_size(f) for _, f in old[:len(old) - len(kept)])
            queue = deque(kept, maxlen=limit)
            self._topics[topic] = queue
        if len(queue) == limit:
            self.dropped += 1
            self.queued_bytes -= _size(queue[0][1])
        sequence = next(self._sequence)
        queue.append((sequence, frame))
        self.queued_bytes += _size(frame)
        self._make_room(sequence)

    def _make_room(self, keep: int | None) -> None:
        """Drop the oldest topic frames (but ``keep``) until all fits ``max_bytes``.

        What is left beyond it (the replies alone, or one frame larger than the budget)
        stays; replies past the budget mark the outbox overflowed.
        """
        while self.queued_bytes > self._max_bytes and self._drop_oldest_topic_frame(keep):
            pass
        if self._reply_bytes > self._max_bytes:
            self._overflow(f"more than {self._max_bytes} bytes of replies waiting to be sent")

    def _drop_oldest_topic_frame(self, keep: int | None) -> bool:
        """Drop the oldest topic frame waiting but ``keep`` and a half-sent one; whether any.

        Takes the head of the queue whose head is oldest: what ``queue_length`` would drop
        first anyway.
        """
        oldest: deque[tuple[int, Entry]] | None = None
        for queue in self._topics.values():
            if not queue:
                continue
            head = queue[0][0] if queue[0][0] != self._sending else (
                queue[1][0] if len(queue) > 1 else None)
            if head is None or head == keep:
                continue
            if oldest is None or head < self._head_of(oldest):
                oldest = queue
        if oldest is None:
            return False
        index = 0 if oldest[0][0] != self._sending else 1
        _, dropped = oldest[index]
        del oldest[index]
        self.dropped += 1
        self.queued_bytes -= _size(dropped)
        return True

    def _head_of(self, queue: deque[tuple[int, Entry]]) -> int:
        """The sequence of the first frame of ``queue`` that may be dropped."""
        return queue[0][0] if queue[0][0] != self._sending else queue[1][0]

    def discard_topic(self, topic: str) -> None:
        """Forget frames of a topic the client unsubscribed from."""
        queue = self._topics.pop(topic, None)
        if queue:
            self.queued_bytes -= sum(_size(frame) for _, frame in queue)

    def has_deferred(self) -> bool:
        """Whether any frame waiting is still to be made (``Deferred``)."""
        return any(isinstance(entry, Deferred)
                   for queue in self._topics.values() for _, entry in queue)

    def _made(self, entry: Entry) -> Frames:
        """``entry``'s frames, made now if deferred (the time counted in ``encode_s``)."""
        if not isinstance(entry, Deferred):
            return entry
        started = time.perf_counter()
        frames = entry.make()
        self.encode_s += time.perf_counter() - started
        self.queued_bytes += _size(frames) - entry.size
        return frames

    def pop(self) -> Frame | None:
        """The next frame to send: replies first, then topic frames oldest first.

        A fragmented message's frames come one per call, its rest left at the head.
        """
        entry: Frames
        if self._replies:
            entry = self._replies.popleft()
            if isinstance(entry, tuple) and len(entry) > 1:
                self._replies.appendleft(entry[1:])
            self._reply_bytes -= len(entry[0] if isinstance(entry, tuple) else entry)
        else:
            oldest: deque[tuple[int, Entry]] | None = None
            for queue in self._topics.values():
                if queue and (oldest is None or queue[0][0] < oldest[0][0]):
                    oldest = queue
            if oldest is None:
                return None
            sequence, waiting = oldest.popleft()
            entry = self._made(waiting)
            self._sending = None
            if isinstance(entry, tuple) and len(entry) > 1:
                oldest.appendleft((sequence, entry[1:]))
                self._sending = sequence
            else:
                self.sent += 1
        frame = entry[0] if isinstance(entry, tuple) else entry
        self.queued_bytes -= len(frame)
        return frame

    def take(self, max_bytes: int) -> list[Frame]:
        """The next frames to send, in ``pop`` order, up to about ``max_bytes`` (at least one).

        Everything at once when it all fits (a client that keeps up: one tick's frames).
        """
        if self.queued_bytes > max_bytes:
            frames: list[Frame] = []
            while max_bytes > 0 and (frame := self.pop()) is not None:
                frames.append(frame)
                max_bytes -= len(frame)
            return frames
        frames = _flat(list(self._replies))
        self._replies.clear()
        self._reply_bytes = 0
        self._sending = None
        topic_frames = [entry for queue in self._topics.values() for entry in queue]
        self.sent += len(topic_frames)
        if topic_frames:
            topic_frames.sort(key=_sequence_of)
            frames.extend(_flat([self._made(frame) for _, frame in topic_frames]))
            for queue in self._topics.values():
                queue.clear()
        self.queued_bytes = 0
        return frames

    def _overflow(self, reason: str) -> None:
        if self.overflowed is None:
            self.overflowed = f"send queue overflow: {reason} (the client is not reading)"
