"""Checks of single ROS values against their IDL types: integers, floats, strings, bytes.

Shared by the definitions (``definitions.canonical``) and the rclpy conversion
(``rclpy_conversion.to_message``), so a value is refused for the same reason either way.
"""

from __future__ import annotations

import base64
import binascii
import math
from collections.abc import Mapping
from typing import Any

import numpy as np

INTEGER_RANGES = {
    "bool": None, "byte": (0, 255), "char": (0, 255), "octet": (0, 255),
    "int8": (-(2**7), 2**7 - 1), "uint8": (0, 2**8 - 1),
    "int16": (-(2**15), 2**15 - 1), "uint16": (0, 2**16 - 1),
    "int32": (-(2**31), 2**31 - 1), "uint32": (0, 2**32 - 1),
    "int64": (-(2**63), 2**63 - 1), "uint64": (0, 2**64 - 1),
}
"""Accepted values of each integer type of the ROS IDL."""

FLOAT_TYPES = frozenset({"float32", "float64"})
FLOAT32_MAX = float(np.finfo(np.float32).max)
"""Largest finite float32: a larger finite value is refused, not sent as infinity."""

BYTE_SEQUENCE_TYPES = frozenset({"uint8", "byte", "char", "octet"})
"""Element types whose arrays and sequences rosbridge writes as base64 text."""

TIME_TYPES = frozenset({"builtin_interfaces/msg/Time", "builtin_interfaces/msg/Duration"})
ROS1_TIME_FIELDS = {"secs": "sec", "nsecs": "nanosec"}
"""ROS 1 spellings of ``builtin_interfaces`` fields that rosbridge accepts."""
HEADER_TYPE = "std_msgs/msg/Header"
ROS1_HEADER_FIELDS = frozenset({"seq"})
"""Fields of ROS 1's ``Header`` that ROS 2's lacks; dropped (roslibpy's ``Header`` writes
``seq``, null or a counter)."""

class MessageError(ValueError):
    """A message does not fit its type; the message names the field and the reason."""


def from_ros1(type_name: str, msg: Mapping[Any, Any]) -> Mapping[Any, Any]:
    """``msg`` with the ROS 1 spellings rosbridge accepts put in ROS 2's (see the module text).

    ``{secs, nsecs}`` of a ``builtin_interfaces`` Time or Duration become ``{sec, nanosec}``;
    the ``seq`` of a ``std_msgs/Header`` is dropped. Other messages are returned as they are.
    """
    if type_name in TIME_TYPES and not msg.keys().isdisjoint(ROS1_TIME_FIELDS):
        return {ROS1_TIME_FIELDS.get(key, key): value for key, value in msg.items()}
    if type_name == HEADER_TYPE and not msg.keys().isdisjoint(ROS1_HEADER_FIELDS):
        return {key: value for key, value in msg.items() if key not in ROS1_HEADER_FIELDS}
    return msg


def decode_base64(text: str, where: str) -> bytes:
    """The bytes of a ``uint8[]`` field's base64 text.

    Raises:
        MessageError: not base64 text.
    """
    try:
        return base64.b64decode(text, validate=True)
    except (binascii.Error, ValueError):
        raise MessageError(f"{where}: expected base64 text or a list of bytes") from None


def check_length(fixed: bool, length: int, count: int, where: str,
                 what: str = "elements") -> None:
    """Refuse ``count`` items where they do not fit.

    Args:
        fixed: an array of exactly ``length`` items; else a sequence of at most ``length``.
        length: the array's length, or the sequence's bound (0: unbounded).
        count: how many items came.
        where: the field path, for the reason.
        what: what the items are called in the reason.

    Raises:
        MessageError: ``count`` does not fit.
    """
    if fixed and count != length:
        raise MessageError(f"{where}: expected exactly {length} {what}, got {count}")
    if not fixed and length and count > length:
        raise MessageError(f"{where}: at most {length} {what}, got {count}")


def numbers(base_type: str, value: list[Any]) -> list[Any] | None:
    """A numeric sequence checked as a whole, at C speed; None: check each item instead.

    None also when an item is refused (not a plain number, out of range): the item-by-item
    check then names it.
    """
    kinds = set(map(type, value))
    if base_type in FLOAT_TYPES and kinds <= {int, float} and value:
        try:
            floats = list(value) if kinds == {float} else [float(item) for item in value]
        except OverflowError:
            return None
        if base_type == "float32":
            array = np.asarray(floats, dtype=np.float64)
            beyond = np.abs(array) > FLOAT32_MAX  # infinities too, which are fine
            if beyond.any() and np.isfinite(array[beyond]).any():
                return None  # a finite value beyond float32: named one by one
        return floats
    bounds = INTEGER_RANGES.get(base_type)
    if bounds is not None and kinds == {int} and bounds[0] <= min(value) \
            and max(value) <= bounds[1]:
        return list(value)
    return None


def check_value(base_type: str, value: Any, where: str, max_length: int = 0) -> Any:
    """One value of a ROS base type (``int8``, ``float32``, ``string``...), checked.

    Args:
        base_type: the ROS ``.msg`` name of the type.
        value: as the client sent it (JSON ``null`` in a float field is NaN).
        where: the field path, for the reason.
        max_length: the bound of a bounded string (``string<=5``), 0 for none.

    Returns:
        The value (floats as ``float``).

    Raises:
        MessageError: the value is not of the type or out of its range, naming ``where``.
    """
    if base_type in FLOAT_TYPES:
        if value is None:  # rosbridge writes NaN and infinities as null
            return math.nan
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise MessageError(f"{where}: expected a number ({base_type}), got "
                               f"{type(value).__name__}")
        try:
            number = float(value)
        except OverflowError:
            raise MessageError(f"{where}: {len(str(abs(value)))}-digit integer is out of "
                               f"{base_type} range") from None
        if base_type == "float32" and math.isfinite(number) and abs(number) > FLOAT32_MAX:
            raise MessageError(f"{where}: {number:g} is out of float32 range "
                               f"(±{FLOAT32_MAX:.7g})")
        return number
    if base_type == "string" or base_type == "wstring":
        if not isinstance(value, str):
            raise MessageError(f"{where}: expected a string, got {type(value).__name__}")
        if max_length and len(value) > max_length:
            raise MessageError(f"{where}: at most {max_length} characters, got {len(value)}")
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
