"""A client's bounded send queue: the newest messages per subscription, replies in order.

There is no backpressure in a broadcast: a client that reads slowly must not stall the tick or
the other clients, nor grow without bound. Each subscribed topic keeps at most its
``queue_length`` newest frames (older ones are dropped, as rosbridge's ``queue_length``
promises); replies (service responses, statuses) are never dropped, but a client that lets
more than ``reply_limit`` of them pile up is marked ``overflowed``, and the server closes it.
"""

from __future__ import annotations

import itertools
from collections import deque
from collections.abc import Callable

Frame = str | bytes
"""A WebSocket message: text (JSON) or binary (CBOR)."""


class Outbox:
    """Frames waiting to be sent to one client.

    Args:
        reply_limit: most replies that may wait at once.
        wake: called whenever a frame is added (the writer task's event).
    """

    def __init__(self, reply_limit: int = 1000, wake: Callable[[], None] | None = None) -> None:
        self._replies: deque[Frame] = deque()
        self._topics: dict[str, deque[tuple[int, Frame]]] = {}
        self._sequence = itertools.count()
        self._reply_limit = reply_limit
        self._wake = wake
        self.dropped = 0
        """Topic frames dropped because a newer one replaced them."""
        self.overflowed = False
        """True once a reply found ``reply_limit`` replies waiting: the client is not reading."""

    def __len__(self) -> int:
        return len(self._replies) + sum(len(queue) for queue in self._topics.values())

    def put_reply(self, frame: Frame) -> None:
        """Queue a reply; past ``reply_limit`` waiting replies, mark the outbox overflowed."""
        if len(self._replies) >= self._reply_limit:
            self.overflowed = True
        else:
            self._replies.append(frame)
        self._notify()

    def put_topic(self, topic: str, frame: Frame, queue_length: int) -> None:
        """Queue a topic frame, keeping the newest ``max(1, queue_length)`` for ``topic``."""
        queue = self._topics.get(topic)
        limit = max(1, queue_length)
        if queue is None or queue.maxlen != limit:
            queue = deque(queue or (), maxlen=limit)
            self._topics[topic] = queue
        if len(queue) == limit:
            self.dropped += 1
        queue.append((next(self._sequence), frame))
        self._notify()

    def discard_topic(self, topic: str) -> None:
        """Forget frames of a topic the client unsubscribed from."""
        self._topics.pop(topic, None)

    def pop(self) -> Frame | None:
        """The next frame to send: replies first, then topic frames oldest first."""
        if self._replies:
            return self._replies.popleft()
        oldest: deque[tuple[int, Frame]] | None = None
        for queue in self._topics.values():
            if queue and (oldest is None or queue[0][0] < oldest[0][0]):
                oldest = queue
        return None if oldest is None else oldest.popleft()[1]

    def _notify(self) -> None:
        if self._wake is not None:
            self._wake()
