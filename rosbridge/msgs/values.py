"""Values of ROS messages as plain dicts: the shapes rosbridge puts on the wire.

Dicts are what rosbridge sends (JSON or CBOR) and what ``rosidl_runtime_py`` fills a real
rclpy message from. ``uint8[]`` fields are base64 strings (``Base64Bytes``) and other numeric
arrays ``TypedSequence`` s, as rosbridge sends them, so a message encodes alike whether it was
built by a robot, checked by ``rosbridge.msgs.definitions`` or read from rclpy. This module
knows no robot.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any, ClassVar

Message = dict[str, Any]
"""A ROS message as a dict (field name -> value)."""


class TypedSequence(list[Any]):
    """A numeric array field of one ROS element type: a list that encoders may pack.

    JSON writes it as a list; CBOR as an RFC 8746 typed array of ``element``
    (``rosbridge.core.encoding``), as rosbridge does. Subclasses fix ``element``.
    """

    element: ClassVar[str] = ""


class Float32Sequence(TypedSequence):
    """A ``float32[]`` field (e.g. ``LaserScan.ranges``)."""

    element = "float32"


NUMERIC_ELEMENTS = ("int8", "uint8", "int16", "uint16", "int32", "uint32", "int64", "uint64",
                    "float32", "float64")
"""ROS element types whose arrays are ``TypedSequence`` s (``uint8[]`` only when not base64)."""

_SEQUENCE_CLASSES: dict[str, type[TypedSequence]] = {"float32": Float32Sequence}
for _element in NUMERIC_ELEMENTS:
    if _element not in _SEQUENCE_CLASSES:
        _SEQUENCE_CLASSES[_element] = type(f"{_element.capitalize()}Sequence",
                                           (TypedSequence,), {"element": _element})


def typed_sequence(element: str, values: Iterable[Any]) -> list[Any]:
    """``values`` as the ``TypedSequence`` of ``element``; a plain list for other elements."""
    cls = _SEQUENCE_CLASSES.get(element)
    return cls(values) if cls is not None else list(values)


class Base64Bytes(str):
    """A ``uint8[]``/``byte[]`` field as base64 text (rosbridge's JSON form).

    JSON writes the text; CBOR writes the bytes it stands for (a byte string), as rosbridge's
    CBOR encoding does.
    """


def normalize_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/msg/Type`` (or ``srv``) -> the ROS 2 spelling ``pkg/msg/Type``."""
    parts = type_name.strip("/").split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/msg/{parts[1]}"
    if len(parts) == 3 and all(parts) and parts[1] in ("msg", "srv", "action"):
        return "/".join(parts)
    raise ValueError(f"not a ROS type name: {type_name!r} (expected pkg/msg/Type)")


def normalize_service_type(type_name: str) -> str:
    """``pkg/Type`` or ``pkg/srv/Type`` -> ``pkg/srv/Type``."""
    parts = type_name.strip("/").split("/")
    if len(parts) == 2 and all(parts):
        return f"{parts[0]}/srv/{parts[1]}"
    return normalize_type(type_name)


def stamp(time_s: float) -> Message:
    """``builtin_interfaces/Time`` for a time in seconds (e.g. ``time.time()``).

    Rounded to the microsecond: a float of seconds since the epoch holds no finer time (its
    resolution there is a quarter of a microsecond), and sim time's ticks, whole microseconds,
    then come out exact (50 ms apart to the nanosecond).
    """
    sec, microsec = divmod(round(time_s * 1e6), 1_000_000)
    return {"sec": int(sec), "nanosec": int(microsec) * 1000}
