"""The rosbridge v2 operations this server understands: each op's fields, types and ranges.

One table, used by the dispatcher to validate every incoming message before any handler sees
it, and by the tests and the fuzzer. Every number has a documented range and every string a
length bound, so nothing unvalidated reaches a queue, a timer or the physics. Fields not
listed are accepted and ignored, as rosbridge does (clients send extras).

Each op that names a topic, service or action names it in one field (``NAME_FIELDS``): that field,
and only that one, is resolved as ROS resolves names and checked by the allow-list, whatever
other fields the message has.
"""

from __future__ import annotations

import functools
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from enum import IntEnum
from typing import Any

MAX_ID_CHARS = 256
"""Longest string id; ids are echoed back in replies."""

MAX_ID_INTEGER = 2**53
"""Largest integer id magnitude: what JavaScript numbers hold exactly."""

MAX_THROTTLE_MS = 3_600_000
"""Largest ``throttle_rate`` (one hour, in ms)."""

MAX_QUEUE_LENGTH = 100
"""Largest ``queue_length``: the newest 100 of a topic may wait for a slow client (5 s of
/odom), within its byte budget (``limits.ClientLimits.max_queued_bytes``)."""

MAX_TYPE_CHARS = 256
"""Longest type name (``pkg/msg/Type``)."""

MAX_NAME_CHARS = 256
"""Longest topic or service name."""

MAX_FRAGMENT_SIZE = 2**31 - 1
MAX_FRAGMENT_NUMBER = 2**31 - 1
"""Largest ``num`` and ``total`` of a ``fragment`` (a client's ``max_fragments`` is less)."""
MAX_TIMEOUT_S = 3600.0

STATUS_LEVELS = ("info", "warning", "error", "none")
"""``set_level`` levels, least severe first; a client hears statuses at or above its level."""

COMPRESSIONS = ("none", "cbor", "png", "cbor-raw")
"""Compressions clients may ask for, as rosbridge serves them (``encoding``): ``cbor`` a
binary frame with typed arrays, ``png`` the JSON text as a PNG image in ``{"op": "png"}``,
``cbor-raw`` the message's CDR bytes in a binary frame. ``call_service`` and
``send_action_goal`` accept the field and, as rosbridge, answer in JSON whatever it says."""


class GoalStatus(IntEnum):
    """``action_msgs/msg/GoalStatus``: the ``status`` of an ``action_result``."""

    UNKNOWN = 0
    ACCEPTED = 1
    EXECUTING = 2
    CANCELING = 3
    SUCCEEDED = 4
    CANCELED = 5
    ABORTED = 6


@dataclass(frozen=True)
class Field:
    """One field of an operation.

    Attributes:
        types: accepted Python types after JSON decoding (``bool`` only where listed).
        required: whether the operation is invalid without it.
        minimum: smallest accepted number (numbers only).
        maximum: largest accepted number, or for strings the most characters.
        choices: the accepted strings; empty: any (up to ``maximum`` characters).
    """

    types: tuple[type, ...]
    required: bool = False
    minimum: float | None = None
    maximum: float | None = None
    choices: tuple[str, ...] = ()


ID = Field((str, int), maximum=MAX_ID_CHARS)
"""roslibjs sends string ids ("subscribe:/odom:1"); other clients send numbers."""

TOPIC = Field((str,), True, maximum=MAX_NAME_CHARS)
SERVICE = Field((str,), True, maximum=MAX_NAME_CHARS)
TYPE = Field((str,), maximum=MAX_TYPE_CHARS)
FRAGMENT_SIZE = Field((int, type(None)), minimum=1, maximum=MAX_FRAGMENT_SIZE)
"""The longest JSON frame the client is sent (``null``: no limit); see ``CLIENT_SETTINGS``."""
COMPRESSION = Field((str,), choices=COMPRESSIONS)
ACTION = Field((str,), True, maximum=MAX_NAME_CHARS)
GOAL_ID = Field((str, int), True, maximum=MAX_ID_CHARS)
"""The id of a pending goal: the server's own (``action_feedback``, ``action_result``) or
the sender's (``cancel_action_goal``)."""

OP_FIELDS: Mapping[str, Mapping[str, Field]] = {
    "advertise": {"topic": TOPIC, "type": Field((str,), True, maximum=MAX_TYPE_CHARS),
                  "id": ID, "latch": Field((bool,)),
                  "queue_size": Field((int,), minimum=0, maximum=10_000)},
    "unadvertise": {"topic": TOPIC, "id": ID},
    "publish": {"topic": TOPIC, "msg": Field((dict,), True), "id": ID,
                "latch": Field((bool,))},
    "subscribe": {"topic": TOPIC, "type": TYPE, "id": ID,
                  "throttle_rate": Field((int, float), minimum=0, maximum=MAX_THROTTLE_MS),
                  "queue_length": Field((int,), minimum=0, maximum=MAX_QUEUE_LENGTH),
                  "fragment_size": FRAGMENT_SIZE, "compression": COMPRESSION},
    "unsubscribe": {"topic": TOPIC, "id": ID},
    "call_service": {"service": SERVICE, "args": Field((dict, list)), "id": ID, "type": TYPE,
                     "fragment_size": FRAGMENT_SIZE, "compression": COMPRESSION,
                     "timeout": Field((int, float), minimum=0, maximum=MAX_TIMEOUT_S)},
    "service_response": {"service": SERVICE, "id": ID, "values": Field((dict, list, str)),
                         "result": Field((bool,), True)},
    "advertise_service": {"service": SERVICE,
                          "type": Field((str,), True, maximum=MAX_TYPE_CHARS)},
    "unadvertise_service": {"service": SERVICE},
    "advertise_action": {"action": ACTION, "type": Field((str,), True, maximum=MAX_TYPE_CHARS),
                         "id": ID},
    "unadvertise_action": {"action": ACTION, "id": ID},
    "send_action_goal": {"action": ACTION,
                         "action_type": Field((str,), True, maximum=MAX_TYPE_CHARS),
                         "id": ID, "args": Field((dict, list)), "feedback": Field((bool,)),
                         "fragment_size": FRAGMENT_SIZE, "compression": COMPRESSION},
    "cancel_action_goal": {"action": ACTION, "id": GOAL_ID},
    "action_feedback": {"action": ACTION, "id": GOAL_ID, "values": Field((dict,))},
    "action_result": {"action": ACTION, "id": GOAL_ID, "values": Field((dict,)),
                      "status": Field((int,), True, minimum=min(GoalStatus),
                                      maximum=max(GoalStatus)),
                      "result": Field((bool,), True)},
    "set_level": {"level": Field((str,), True, choices=STATUS_LEVELS), "id": ID},
    "fragment": {"id": Field((str, int), True, maximum=MAX_ID_CHARS),
                 "data": Field((str,), True),
                 "num": Field((int,), True, minimum=0, maximum=MAX_FRAGMENT_NUMBER),
                 "total": Field((int,), True, minimum=1, maximum=MAX_FRAGMENT_NUMBER)},
    "auth": {},
}
"""Every operation and its fields."""

CLIENT_SETTINGS: Mapping[str, Field] = {"fragment_size": FRAGMENT_SIZE}
"""Fields any op may carry that set the client's own settings, whatever the op (rosbridge's
``Protocol.incoming``): the client's ``fragment_size`` is the last one it sent."""

NAME_FIELDS: Mapping[str, str] = {
    op: name for op, fields in OP_FIELDS.items()
    for name in ("topic", "service", "action") if name in fields}
"""The one field of each op that names its topic, service or action."""


class ProtocolError(ValueError):
    """An incoming message is not a valid rosbridge operation; the reason says why.

    Attributes:
        message: the decoded JSON object whose fields were invalid (None: it was not one),
            so that a refused call or goal can still be answered under its id.
    """

    message: dict[str, Any] | None = None


def _describe(value: Any) -> str:
    """A short description of a bad value for an error (it may be huge)."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) >= 10**20:
        return f"a {len(str(abs(value)))}-digit integer"
    text = repr(value)
    return text if len(text) <= 40 else f"{text[:40]}... ({len(text)} characters)"


def check_fields(message: Mapping[str, Any]) -> str:
    """Validate ``message`` against its operation's fields and return the op name.

    Raises:
        ProtocolError: no or unknown ``op``, a required field missing, a field of the wrong
            type, a number out of its range, a string too long or not one of its choices.
    """
    op = message.get("op")
    if not isinstance(op, str):
        raise ProtocolError("message has no 'op' field")
    fields = OP_FIELDS.get(op)
    if fields is None:
        raise ProtocolError(f"unknown op '{op[:40]}'")
    for name, spec in fields.items():
        if name not in message:
            if spec.required:
                raise ProtocolError(f"{op}: missing field '{name}'")
            continue
        _check_value(op, name, spec, message[name])
    for name, spec in CLIENT_SETTINGS.items():
        if name in message and name not in fields:
            _check_value(op, name, spec, message[name])
    return op


def _check_value(op: str, name: str, spec: Field, value: Any) -> None:
    if isinstance(value, bool) and bool not in spec.types:
        raise ProtocolError(f"{op}: field '{name}' has the wrong type (bool)")
    if not isinstance(value, spec.types):
        expected = " or ".join(t.__name__ for t in spec.types)
        raise ProtocolError(f"{op}: field '{name}' must be {expected}, "
                            f"got {type(value).__name__}")
    if isinstance(value, str):
        if spec.choices and value not in spec.choices:
            raise ProtocolError(f"{op}: field '{name}' must be one of "
                                f"{', '.join(spec.choices)}, got {_describe(value)}")
        if spec.maximum is not None and len(value) > spec.maximum:
            raise ProtocolError(f"{op}: field '{name}' is longer than {spec.maximum:g} "
                                f"characters ({len(value)})")
    elif isinstance(value, (int, float)) and not isinstance(value, bool):
        if name == "id":  # ID or GOAL_ID: a number id is bounded by value, not length
            if abs(value) > MAX_ID_INTEGER:
                raise ProtocolError(f"{op}: field 'id' must be within ±2^53, got "
                                    f"{_describe(value)}")
            return
        low = -float("inf") if spec.minimum is None else spec.minimum
        high = float("inf") if spec.maximum is None else spec.maximum
        if not low <= value <= high:  # NaN fails too; huge ints compare exactly
            raise ProtocolError(f"{op}: field '{name}' must be between {low:g} and {high:g}, "
                                f"got {_describe(value)}")


def echoable_id(message: Any) -> Any:
    """The message's id if it is one the schema accepts (it is echoed back), else None."""
    value = message.get("id") if isinstance(message, dict) else None
    if isinstance(value, str) and len(value) <= MAX_ID_CHARS:
        return value
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) <= MAX_ID_INTEGER:
        return value
    return None


def read_operation(frame: str | bytes, parse: Callable[[str], Any]) -> tuple[str, dict[str, Any]]:
    """One incoming frame as a validated operation: (op, message).

    A binary frame is read as JSON text in UTF-8, as rosbridge_server reads it (CBOR is only
    ever sent, never read, by rosbridge 2.x).

    Args:
        frame: the WebSocket message.
        parse: the JSON decoder (``encoding.parse_json``).

    Raises:
        ProtocolError: a binary frame that is not UTF-8, invalid JSON, not an object, or
            invalid fields.
    """
    if isinstance(frame, bytes):
        try:
            frame = frame.decode("utf-8")
        except UnicodeDecodeError as error:
            raise ProtocolError(f"a binary frame must hold JSON text in UTF-8, as rosbridge "
                                f"reads it (CBOR is not read): byte {error.start} is not "
                                "UTF-8") from None
    try:
        message = parse(frame)
    except ValueError as error:
        raise ProtocolError(f"invalid JSON: {error}") from None
    if not isinstance(message, dict):
        raise ProtocolError(f"expected a JSON object, got {type(message).__name__}")
    try:
        return check_fields(message), message
    except ProtocolError as error:
        error.message = message
        raise


NAME_TOKEN = re.compile(r"[A-Za-z_][A-Za-z0-9_]*")


RESOLVED_NAMES = 1024
"""Names resolved kept for reuse (a client sends the same few with every message): at most
about 0.5 MB of names (``MAX_NAME_CHARS``); a refused name is never kept."""


@functools.lru_cache(maxsize=RESOLVED_NAMES)
def resolve_name(name: str, namespace: str = "/") -> str:
    """A topic or service name resolved as ROS 2 resolves it for a node in ``namespace``.

    ``odom`` and ``/odom`` are the same topic for a node at the root (rosbridge's node), so
    both become ``/odom``; a trailing ``/`` or an empty token is an error, as are private
    names (``~/x``: the bridge node's own) and substitutions (``{node}``).

    Raises:
        ProtocolError: not a valid ROS 2 name, with the reason.
    """
    if not name:
        raise ProtocolError("empty name")
    if len(name) > MAX_NAME_CHARS:
        raise ProtocolError(f"name longer than {MAX_NAME_CHARS} characters")
    if name.startswith("~"):
        raise ProtocolError(f"'{name[:80]}': private names (~) are not offered to clients")
    absolute = name if name.startswith("/") else f"{namespace.rstrip('/')}/{name}"
    tokens = absolute[1:].split("/")
    if not all(NAME_TOKEN.fullmatch(token) for token in tokens):
        raise ProtocolError(f"'{name[:80]}' is not a ROS name (letters, digits and _ in "
                            f"/-separated tokens, none starting with a digit)")
    return absolute
