"""rosbridge's ``fragment`` op: long messages split into several frames, and put back together.

Out: a message whose JSON text is longer than the client's ``fragment_size`` is sent as
``{"op": "fragment", "id", "data", "num", "total"}`` messages, each its own WebSocket frame:
``data`` the ``num``-th slice (from 0) of the text, ``total`` how many there are, ``id`` the
message's own id if it has one, as rosbridge's ``Fragmentation`` does. Binary (CBOR) frames are
never fragmented: a fragment's ``data`` is text (rosbridge cannot fragment them either).

In: ``Reassembly`` holds one client's partly received messages, bounded in bytes, fragments,
messages and time (``ClientLimits``); a complete message comes back as its text, for the
bridge to handle as it handles any frame.
"""

from __future__ import annotations

import math
import uuid
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

from rosbridge.core.clock import WALL_CLOCK
from rosbridge.core.encoding import to_json
from rosbridge.core.errors import BridgeError
from rosbridge.core.limits import ClientLimits

MAX_OUTGOING_FRAGMENTS = 1000
"""Most fragments one outgoing message is cut into: a smaller ``fragment_size`` (1 is valid)
is raised for that message, so a client cannot make the server build and queue a frame of
some 60 bytes of framing for every character of a /scan."""


MIN_TOPIC_FRAGMENT_SIZE = 256
"""The smallest ``fragment_size`` a topic message is cut by: a client's smaller one is
raised to it. A fragment op's own fields take some 70 bytes, so smaller fragments would be
mostly framing (a /scan in 300 frames of 30 characters); rosbridge sets no minimum, and its
clients that fragment ask for kilobytes."""


def topic_fragment_size(fragment_size: int | None) -> int | None:
    """The ``fragment_size`` a topic message is cut by for a client that asked for this one.

    Rounded down to a power of two, at least ``MIN_TOPIC_FRAGMENT_SIZE``: every fragment is
    still at most what the client asked for (above the minimum), and a message has at most
    a dozen fragmented forms (256 B to 1 MiB), however many clients ask for however many
    sizes; they are made once each for all of them (``capabilities.topics.Encoded``).
    Replies are cut at the client's own size: they are made for that client alone.
    """
    if fragment_size is None:
        return None
    return max(MIN_TOPIC_FRAGMENT_SIZE, 1 << (fragment_size.bit_length() - 1))


def fragment(text: str, fragment_size: int, message_id: Any = None) -> tuple[str, ...]:
    """``text`` as the JSON texts of its ``fragment`` messages (rosbridge's fields).

    Args:
        text: the message's JSON text, longer than ``fragment_size``.
        fragment_size: the most characters of ``text`` in one fragment's ``data``.
        message_id: the message's id; None: a new unique one (rosbridge numbers them).
    """
    size = max(fragment_size, math.ceil(len(text) / MAX_OUTGOING_FRAGMENTS))
    total = math.ceil(len(text) / size)
    fragment_id = uuid.uuid4().hex if message_id is None else message_id
    return tuple(to_json({"op": "fragment", "id": fragment_id,
                          "data": text[num * size:(num + 1) * size], "num": num,
                          "total": total})
                 for num in range(total))


class FragmentError(BridgeError):
    """A fragment that cannot be used; the message says which and why."""


@dataclass
class _Partial:
    """One message being put back together."""

    total: int
    last_s: float
    data: dict[int, str] = field(default_factory=dict)
    size_bytes: int = 0


class Reassembly:
    """One client's partly received fragmented messages.

    Args:
        limits: the client's bounds: ``max_frame_bytes`` for all partial messages together
            (a fragmented message can be no larger than one frame), ``max_fragments``,
            ``max_partial_messages`` and ``fragment_timeout_s``.
        clock: monotonic time (s): a ``Clock``'s ``monotonic_s`` (default: wall time).
    """

    def __init__(self, limits: ClientLimits,
                 clock: Callable[[], float] = WALL_CLOCK.monotonic_s) -> None:
        self._limits = limits
        self._clock = clock
        self._partial: dict[Any, _Partial] = {}
        self.held_bytes = 0
        """UTF-8 bytes of the fragments held."""

    def __len__(self) -> int:
        return len(self._partial)

    def expire(self) -> list[str]:
        """Drop the messages that got no fragment for ``fragment_timeout_s``; why, for each."""
        now = self._clock()
        timeout_s = self._limits.fragment_timeout_s
        reasons = []
        for message_id, partial in list(self._partial.items()):
            if now - partial.last_s > timeout_s:
                self._drop(message_id)
                reasons.append(f"fragmented message {message_id!r}: incomplete after "
                               f"{timeout_s:g} s ({len(partial.data)} of {partial.total} "
                               "fragments arrived); dropped")
        return reasons

    def add(self, message: Mapping[str, Any]) -> str | None:
        """Take one ``fragment`` op (fields checked by the schema): the whole text once complete.

        Raises:
            FragmentError: ``num`` not below ``total``, ``total`` over ``max_fragments``, a
                ``total`` other than the message's first fragment said, a fragment received
                twice, too many messages in progress, or too many bytes held (the message is
                then dropped).
        """
        message_id, data = message["id"], message["data"]
        num, total = message["num"], message["total"]
        name = f"fragment {num} of message {message_id!r}"
        limits = self._limits
        if total > limits.max_fragments:
            raise FragmentError(f"{name}: total {total} is more than the {limits.max_fragments} "
                                "fragments a message may have")
        if num >= total:
            raise FragmentError(f"{name}: num must be below total ({total}); fragments are "
                                "numbered from 0")
        partial = self._partial.get(message_id)
        if partial is None:
            if len(self._partial) >= limits.max_partial_messages:
                raise FragmentError(f"{name}: {limits.max_partial_messages} fragmented "
                                    "messages are already incomplete; finish one first")
            partial = self._partial[message_id] = _Partial(total, self._clock())
        elif partial.total != total:
            raise FragmentError(f"{name}: total {total}, but its first fragment said "
                                f"{partial.total}")
        if num in partial.data:
            raise FragmentError(f"{name}: received twice")
        size_bytes = len(data.encode())
        if self.held_bytes + size_bytes > limits.max_frame_bytes:
            self._drop(message_id)
            raise FragmentError(f"{name}: the incomplete messages would hold more than "
                                f"{limits.max_frame_bytes} bytes (the largest message); "
                                "message dropped")
        partial.data[num] = data
        partial.size_bytes += size_bytes
        partial.last_s = self._clock()
        self.held_bytes += size_bytes
        if len(partial.data) < total:
            return None
        self._drop(message_id)
        return "".join(partial.data[index] for index in range(total))

    def _drop(self, message_id: Any) -> None:
        partial = self._partial.pop(message_id, None)
        if partial is not None:
            self.held_bytes -= partial.size_bytes
