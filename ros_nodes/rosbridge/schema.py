"""The rosbridge v2 operations this server understands, and the fields of each.

One table, used by the dispatcher to validate every incoming message and by the tests. Fields
not listed are accepted and ignored, as rosbridge does (clients send extras such as
``fragment_size``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

Id = (str, int)
"""roslibjs sends string ids ("subscribe:/odom:1"); other clients send numbers."""


@dataclass(frozen=True)
class Field:
    """One field of an operation.

    Attributes:
        types: accepted Python types after JSON decoding.
        required: whether the operation is invalid without it.
    """

    types: tuple[type, ...]
    required: bool = False


OP_FIELDS: Mapping[str, Mapping[str, Field]] = {
    "advertise": {"topic": Field((str,), True), "type": Field((str,), True),
                  "id": Field(Id), "latch": Field((bool,)), "queue_size": Field((int,))},
    "unadvertise": {"topic": Field((str,), True), "id": Field(Id)},
    "publish": {"topic": Field((str,), True), "msg": Field((dict,), True), "id": Field(Id),
                "latch": Field((bool,))},
    "subscribe": {"topic": Field((str,), True), "type": Field((str,)), "id": Field(Id),
                  "throttle_rate": Field((int, float)), "queue_length": Field((int,)),
                  "fragment_size": Field((int,)), "compression": Field((str,))},
    "unsubscribe": {"topic": Field((str,), True), "id": Field(Id)},
    "call_service": {"service": Field((str,), True), "args": Field((dict, list)),
                     "id": Field(Id), "type": Field((str,)), "fragment_size": Field((int,)),
                     "compression": Field((str,)), "timeout": Field((int, float))},
    "service_response": {"service": Field((str,), True), "id": Field(Id),
                         "values": Field((dict, list, str)), "result": Field((bool,), True)},
    "advertise_service": {"service": Field((str,), True), "type": Field((str,), True)},
    "unadvertise_service": {"service": Field((str,), True)},
    "set_level": {"level": Field((str,), True), "id": Field(Id)},
    "auth": {},
}
"""Every operation and its fields."""

STATUS_LEVELS = ("info", "warning", "error", "none")
"""``set_level`` levels, least severe first; a client hears statuses at or above its level."""

COMPRESSIONS = ("none", "cbor", "png", "cbor-raw")
"""Compressions clients may ask for; ``png`` and ``cbor-raw`` are served as ``none``."""


class ProtocolError(ValueError):
    """An incoming message is not a valid rosbridge operation; the reason says why."""


def check_fields(message: Mapping[str, Any]) -> str:
    """Validate ``message`` against its operation's fields and return the op name.

    Raises:
        ProtocolError: no or unknown ``op``, a required field missing, or a field of the wrong
            type.
    """
    op = message.get("op")
    if not isinstance(op, str):
        raise ProtocolError("message has no 'op' field")
    fields = OP_FIELDS.get(op)
    if fields is None:
        raise ProtocolError(f"unknown op '{op}'")
    for name, spec in fields.items():
        if name not in message:
            if spec.required:
                raise ProtocolError(f"{op}: missing field '{name}'")
            continue
        value = message[name]
        if isinstance(value, bool) and bool not in spec.types:
            raise ProtocolError(f"{op}: field '{name}' has the wrong type (bool)")
        if not isinstance(value, spec.types):
            expected = " or ".join(t.__name__ for t in spec.types)
            raise ProtocolError(f"{op}: field '{name}' must be {expected}, "
                                f"got {type(value).__name__}")
    return op
