"""ROS 2 message definitions, and messages (dicts) checked and put in their canonical form.

A message a client publishes is relayed to every subscriber, so it is relayed as what it
means, not as what was sent: ``canonical`` keeps exactly the fields of the type (missing ones
get their defaults, as rosbridge fills them), refuses fields the type lacks, values of the
wrong type and integers out of their type's range, and accepts ROS 1's ``{secs, nsecs}``
stamp spelling (what roslibpy's ``Header`` writes). A megabyte of extra fields on a Twist is
an error, not a megabyte sent to every subscriber.

The definitions are those of ROS 2 Humble's standard message packages, from the rosbags
typestore (a maintained, ROS-free copy of them): std_msgs, geometry_msgs, sensor_msgs,
nav_msgs, tf2_msgs, visualization_msgs, builtin_interfaces, rcl_interfaces and more. Types it
does not know are the caller's concern (``known`` says which are known).
"""

from __future__ import annotations

import base64
import binascii
import functools
import math
from collections.abc import Mapping
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_typestore

from physics.validation import ConfigError

INTEGER_RANGES = {
    "bool": None, "byte": (0, 255), "char": (0, 255), "octet": (0, 255),
    "int8": (-(2**7), 2**7 - 1), "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1),
}
"""Accepted values of each integer type of the ROS IDL."""

FLOAT_TYPES = frozenset({"float32", "float64"})
BYTE_SEQUENCE_TYPES = frozenset({"uint8", "byte", "char", "octet"})
"""Element types whose sequences rosbridge writes as base64 text."""

TIME_TYPES = frozenset({"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})
ROS1_TIME_FIELDS = {"secs": "sec", "nsecs": "nanosec"}
"""ROS 1 spellings of ``builtin_interfaces`` fields that rosbridge accepts."""

FAST_SEQUENCE_MIN = 32
"""Numeric sequences longer than this are checked as a whole (``_numbers``), not per item."""

MAX_DEPTH = 32
"""Deepest nesting of message types followed (standard messages nest fewer than ten)."""


class MessageError(ConfigError):
    """A message does not fit its type; the message names the field and the reason."""


@functools.cache
def _fielddefs() -> Mapping[str, Any]:
    """The typestore's definitions (read once, never changed)."""
    return get_typestore(Stores.ROS2_HUMBLE).fielddefs


def load() -> None:
    """Read the definitions now (about 0.1 s, once per process) rather than at first use."""
    _fielddefs()


def known(type_name: str) -> bool:
    """Whether ``type_name`` (``pkg/msg/Type``) is a message type defined here."""
    return type_name in _fielddefs()


def fields(type_name: str) -> list[str]:
    """The field names of a known message type, in order; KeyError if unknown."""
    return [name for name, _ in _fielddefs()[type_name][1]]


def canonical(type_name: str, msg: Any) -> dict[str, Any]:
    """``msg`` as a ``type_name`` message: the type's fields only, defaults filled in.

    Raises:
        MessageError: ``type_name`` is not known, or ``msg`` does not fit it; the reason names
            the field (``linear.x: expected a number, got str``).
        KeyError: never; unknown types raise MessageError.
    """
    if not known(type_name):
        raise MessageError(f"unknown message type {type_name}")
    return _message(type_name, msg, type_name, 0)


def default(type_name: str) -> dict[str, Any]:
    """A ``type_name`` message with every field at its default."""
    return _message(type_name, {}, type_name, 0)


def _message(type_name: str, msg: Any, where: str, depth: int) -> dict[str, Any]:
    if depth > MAX_DEPTH:
        raise MessageError(f"{where}: nested too deeply")
    if not isinstance(msg, Mapping):
        raise MessageError(f"{where}: expected an object ({type_name}), got "
                           f"{type(msg).__name__}")
    definition = _fielddefs()[type_name][1]
    names = {name for name, _ in definition}
    if type_name in TIME_TYPES:
        msg = {ROS1_TIME_FIELDS.get(key, key): value for key, value in msg.items()}
    for key in msg:
        if key not in names:
            raise MessageError(f"{where}: {type_name} has no field '{str(key)[:60]}' "
                               f"(fields: {', '.join(name for name, _ in definition)})")
    out: dict[str, Any] = {}
    for name, (kind, detail) in definition:
        path = name if where == type_name else f"{where}.{name}"
        if name in msg:
            out[name] = _value(kind, detail, msg[name], path, depth)
        else:
            out[name] = _default(kind, detail, depth)
    return out


def _value(kind: Nodetype, detail: Any, value: Any, where: str, depth: int) -> Any:
    if kind == Nodetype.BASE:
        return _base(detail[0], value, where)
    if kind == Nodetype.NAME:
        return _message(detail, value, where, depth + 1)
    element, length = detail
    if kind == Nodetype.SEQUENCE and element[0] == Nodetype.BASE \
            and element[1][0] in BYTE_SEQUENCE_TYPES and isinstance(value, str):
        try:
            data = base64.b64decode(value, validate=True)
        except (binascii.Error, ValueError):
            raise MessageError(f"{where}: expected base64 text or a list of bytes") from None
        if length and len(data) > length:
            raise MessageError(f"{where}: at most {length} bytes, got {len(data)}")
        return value
    if not isinstance(value, list):
        raise MessageError(f"{where}: expected a list, got {type(value).__name__}")
    if kind == Nodetype.ARRAY and len(value) != length:
        raise MessageError(f"{where}: expected exactly {length} elements, got {len(value)}")
    if kind == Nodetype.SEQUENCE and length and len(value) > length:
        raise MessageError(f"{where}: at most {length} elements, got {len(value)}")
    sub_kind, sub_detail = element
    if sub_kind == Nodetype.BASE and len(value) > FAST_SEQUENCE_MIN:
        fast = _numbers(sub_detail[0], value)
        if fast is not None:
            return fast
    return [_value(sub_kind, sub_detail, item, f"{where}[{index}]", depth)
            for index, item in enumerate(value)]


def _numbers(base_type: str, value: list[Any]) -> list[Any] | None:
    """A long numeric sequence checked at C speed; None: not plain numbers (check each)."""
    kinds = set(map(type, value))
    if base_type in FLOAT_TYPES and kinds <= {int, float}:
        if kinds == {float}:
            return list(value)
        try:
            return [float(item) for item in value]
        except OverflowError:
            return None
    bounds = INTEGER_RANGES.get(base_type)
    if bounds is not None and kinds == {int} and bounds[0] <= min(value) \
            and max(value) <= bounds[1]:
        return list(value)
    return None


def _base(base_type: str, value: Any, where: str) -> Any:
    if base_type in FLOAT_TYPES:
        if value is None:  # rosbridge writes NaN and infinities as null
            return math.nan
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise MessageError(f"{where}: expected a number ({base_type}), got "
                               f"{type(value).__name__}")
        try:
            return float(value)
        except OverflowError:
            raise MessageError(f"{where}: {len(str(abs(value)))}-digit integer is out of "
                               f"{base_type} range") from None
    if base_type == "string" or base_type == "wstring":
        if not isinstance(value, str):
            raise MessageError(f"{where}: expected a string, got {type(value).__name__}")
        return value
    if base_type == "bool":
        if not isinstance(value, bool):
            raise MessageError(f"{where}: expected true or false, got {type(value).__name__}")
        return value
    bounds = INTEGER_RANGES.get(base_type)
    if bounds is None:
        raise MessageError(f"{where}: unsupported field type {base_type}")
    if isinstance(value, bool) or not isinstance(value, int):
        raise MessageError(f"{where}: expected an integer ({base_type}), got "
                           f"{type(value).__name__}")
    low, high = bounds
    if not low <= value <= high:
        shown = value if abs(value) < 10**20 else f"a {len(str(abs(value)))}-digit integer"
        raise MessageError(f"{where}: {shown} is out of {base_type} range ({low} to {high})")
    return value


def _default(kind: Nodetype, detail: Any, depth: int) -> Any:
    if kind == Nodetype.BASE:
        base_type = detail[0]
        if base_type in FLOAT_TYPES:
            return 0.0
        if base_type in ("string", "wstring"):
            return ""
        return False if base_type == "bool" else 0
    if kind == Nodetype.NAME:
        if depth > MAX_DEPTH:
            raise MessageError(f"{detail}: nested too deeply")
        return _message(detail, {}, detail, depth + 1)
    element, length = detail
    if kind == Nodetype.ARRAY:
        return [_default(element[0], element[1], depth) for _ in range(length)]
    return []
