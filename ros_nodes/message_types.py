"""ROS 2 message definitions, and messages (dicts) checked and put in their canonical form.

A message a client publishes is relayed to every subscriber, so it is relayed as what it
means, not as what was sent: ``canonical`` keeps exactly the fields of the type (missing ones
get their defaults, as rosbridge fills them), refuses fields the type lacks, values of the
wrong type and integers out of their type's range, and accepts ROS 1's ``{secs, nsecs}``
stamp spelling (what roslibpy's ``Header`` writes, with its ``seq``, which is dropped). A
megabyte of extra fields on a Twist is an error, not a megabyte sent to every subscriber.
Numeric arrays come out as ``messages.typed_sequence`` s and byte arrays (``uint8[]``,
``byte[]``) as ``messages.Base64Bytes``, so the encoders write them as rosbridge does (base64
text in JSON; typed arrays and byte strings in CBOR), whichever spelling the client sent.

The definitions are those of ROS 2 Humble's standard message packages, from the rosbags
typestore (a maintained, ROS-free copy of them): std_msgs, geometry_msgs, sensor_msgs,
nav_msgs, tf2_msgs, visualization_msgs, builtin_interfaces, rcl_interfaces and more, plus
the packages it lacks that courses use, shipped as their ROS 2 ``.msg`` (or ``.idl``) text
in ``ros_nodes/interfaces/<package>/msg/`` (example_interfaces). A type defined nowhere is
refused (``check_type``) with rosbridge's reason; with ``websim serve --ros`` the types of
every installed ROS 2 package count too (``graph=True``: converted through their rclpy
classes, ``ros_nodes.ros_interop``).
"""

from __future__ import annotations

import base64
import binascii
import functools
import math
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from physics.validation import ConfigError
from ros_nodes.messages import NUMERIC_ELEMENTS, Base64Bytes, normalize_type, typed_sequence

INTERFACES_DIR = Path(__file__).with_name("interfaces")
"""Definitions the typestore lacks: ``<package>/msg/<Type>.msg`` (``.idl`` where the rosbags
``.msg`` reader falls short: ``wstring``), the ROS 2 interface text."""

TYPESTORE = Stores.ROS2_HUMBLE

SRV_SEPARATOR = re.compile(r"^---[ \t]*$", re.MULTILINE)
"""The line between a ``.srv`` file's request and response."""

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

EMPTY_PLACEHOLDER = "structure_needs_at_least_one_member"
"""The field ROS 2's IDL gives a message with none (``std_msgs/Empty``); rclpy shows no field
and rosbridge sends ``{}``, so websim's canonical form leaves it out too."""

FAST_SEQUENCE_MIN = 32
"""Numeric sequences longer than this are checked as a whole (``numbers``), not per item."""

MAX_DEPTH = 32
"""Deepest nesting of message types followed (standard messages nest fewer than ten)."""


class MessageError(ConfigError):
    """A message does not fit its type; the message names the field and the reason."""


@functools.cache
def _fielddefs() -> Mapping[str, Any]:
    """The typestore's definitions and the shipped ones (read once, never changed)."""
    store = get_typestore(TYPESTORE)  # a new store of this process's own
    store.register(shipped_definitions())
    return store.fielddefs


def shipped_definitions(folder: Path = INTERFACES_DIR) -> dict[str, Any]:
    """The definitions of ``folder``'s ``<package>/msg/<Type>.msg`` and ``.idl`` files.

    A ``<package>/srv/<Type>.srv`` gives two messages, ``<package>/srv/<Type>_Request`` and
    ``_Response`` (ROS 2's names for a service's parts), so client-provided services of the
    common types are checked as rosbridge fills them.
    """
    types: dict[str, Any] = {}
    for path in sorted(folder.glob("*/msg/*.msg")):
        name = f"{path.parent.parent.name}/msg/{path.stem}"
        types.update(get_types_from_msg(path.read_text(encoding="utf-8"), name))
    for path in sorted(folder.glob("*/msg/*.idl")):
        types.update(get_types_from_idl(path.read_text(encoding="utf-8")))
    for path in sorted(folder.glob("*/srv/*.srv")):
        name = f"{path.parent.parent.name}/srv/{path.stem}"
        request, response = SRV_SEPARATOR.split(path.read_text(encoding="utf-8"), maxsplit=1)
        for part, text in (("Request", request), ("Response", response)):
            parsed = get_types_from_msg(text.strip(), f"{name}_{part}")
            # rosbags names it pkg/srv/msg/Type_Part; ROS 2 (and rclpy) pkg/srv/Type_Part
            types.update({key.replace("/srv/msg/", "/srv/"): value
                          for key, value in parsed.items()})
    return types


def load() -> None:
    """Read the definitions now (about 0.1 s, once per process) rather than at first use."""
    _fielddefs()


def known(type_name: str) -> bool:
    """Whether ``type_name`` (``pkg/msg/Type``) is a message type defined here."""
    return type_name in _fielddefs()


@functools.cache
def packages() -> tuple[str, ...]:
    """The packages whose message types are defined here, sorted."""
    return tuple(sorted({name.split("/")[0] for name in _fielddefs()}))


COURSE_PACKAGES = ("std_msgs", "geometry_msgs", "sensor_msgs", "nav_msgs", "example_interfaces")
"""The packages the refusal of an unknown type names first."""


def check_type(type_name: str, *, graph: bool = False) -> str:
    """``type_name`` as ``pkg/msg/Type`` if it is a message type websim can check.

    Args:
        type_name: ``pkg/msg/Type`` or ``pkg/Type``.
        graph: a ROS 2 graph is attached (``--ros``): an importable rclpy message class counts.

    Raises:
        MessageError: not a type name, or a type defined nowhere; the reason is rosbridge's
            (``Unable to import wangle_msgs.msg from package wangle_msgs. Caused by: ...``).
    """
    try:
        normalized = normalize_type(type_name)
    except ValueError as error:
        raise MessageError(str(error)) from None
    if known(normalized):
        return normalized
    if graph:
        from ros_nodes.ros_interop import MessageConversionError, message_class

        try:
            message_class(normalized)
        except MessageConversionError as error:
            raise MessageError(str(error)) from None
        return normalized
    raise MessageError(unknown_type_reason(normalized))


def unknown_type_reason(type_name: str) -> str:
    """Why ``pkg/kind/Type`` is refused: rosbridge's reason (its import error), then a hint."""
    package, kind, name = type_name.split("/")
    if package in packages():
        reason = (f"Unable to import {kind} class {name} from package {package}. Caused by "
                  f"module '{package}.{kind}' has no attribute '{name}'")
    else:
        reason = (f"Unable to import {package}.{kind} from package {package}. Caused by: "
                  f"No module named '{package}'")
    others = len(packages()) - len(COURSE_PACKAGES)
    return (f"{reason} (websim knows {', '.join(COURSE_PACKAGES)} and {others} more "
            "packages; with --ros, every installed one)")


def fields(type_name: str) -> list[str]:
    """The field names of a known message type, in order; KeyError if unknown."""
    return [name for name, _ in _fielddefs()[type_name][1]]


def canonical(type_name: str, msg: Any, *, graph: bool = False) -> dict[str, Any]:
    """``msg`` as a ``type_name`` message: the type's fields only, defaults filled in.

    Args:
        type_name: ``pkg/msg/Type``.
        msg: the message as a client sent it.
        graph: a ROS 2 graph is attached (``--ros``): a type defined only by an installed
            rclpy package is converted through its class (``ros_interop``).

    Raises:
        MessageError: ``type_name`` is not known (``check_type``), or ``msg`` does not fit
            it; the reason names the field (``linear.x: expected a number, got str``).
    """
    if known(type_name):
        return _message(type_name, msg, type_name, 0)
    check_type(type_name, graph=graph)
    from ros_nodes.ros_interop import MessageConversionError, message_class, to_dict, to_message

    try:
        return to_dict(to_message(message_class(type_name), msg))
    except MessageConversionError as error:
        raise MessageError(str(error)) from None


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


def default(type_name: str) -> dict[str, Any]:
    """A ``type_name`` message with every field at its default."""
    return _message(type_name, {}, type_name, 0)


def _message(type_name: str, msg: Any, where: str, depth: int) -> dict[str, Any]:
    prefix = "" if where == type_name else f"{where}: "
    if depth > MAX_DEPTH:
        raise MessageError(f"{where}: nested too deeply")
    if not isinstance(msg, Mapping):
        raise MessageError(f"{prefix}expected an object ({type_name}), got "
                           f"{type(msg).__name__}")
    definition = [(name, kind) for name, kind in _fielddefs()[type_name][1]
                  if name != EMPTY_PLACEHOLDER]
    names = {name for name, _ in definition}
    msg = from_ros1(type_name, msg)
    for key in msg:
        if key not in names:
            raise MessageError(f"{prefix}{type_name} has no field '{str(key)[:60]}' "
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
        return check_value(detail[0], value, where, detail[1])
    if kind == Nodetype.NAME:
        return _message(detail, value, where, depth + 1)
    element, length = detail
    sub_kind, sub_detail = element
    is_bytes = sub_kind == Nodetype.BASE and sub_detail[0] in BYTE_SEQUENCE_TYPES
    if is_bytes and isinstance(value, str):
        data = decode_base64(value, where)
        check_length(kind == Nodetype.ARRAY, length, len(data), where, "bytes")
        return value if isinstance(value, Base64Bytes) else Base64Bytes(value)
    if not isinstance(value, list):
        raise MessageError(f"{where}: expected a list, got {type(value).__name__}")
    check_length(kind == Nodetype.ARRAY, length, len(value), where)
    if sub_kind == Nodetype.BASE:
        base_type = sub_detail[0]
        checked = numbers(base_type, value) if len(value) > FAST_SEQUENCE_MIN else None
        if checked is None:
            checked = [check_value(base_type, item, f"{where}[{index}]", sub_detail[1])
                       for index, item in enumerate(value)]
        if is_bytes:
            return Base64Bytes(base64.b64encode(bytes(checked)).decode("ascii"))
        return typed_sequence(base_type, checked)
    return [_value(sub_kind, sub_detail, item, f"{where}[{index}]", depth)
            for index, item in enumerate(value)]


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
    count = length if kind == Nodetype.ARRAY else 0
    if element[0] == Nodetype.BASE and element[1][0] in BYTE_SEQUENCE_TYPES:
        return Base64Bytes(base64.b64encode(bytes(count)).decode("ascii"))
    items = [_default(element[0], element[1], depth) for _ in range(count)]
    if element[0] == Nodetype.BASE and element[1][0] in NUMERIC_ELEMENTS:
        return typed_sequence(element[1][0], items)
    return items
