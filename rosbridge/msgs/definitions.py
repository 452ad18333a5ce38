"""ROS 2 message definitions, and messages (dicts) checked and put in their canonical form.

A message a client publishes is relayed to every subscriber, so it is relayed as what it
means, not as what was sent: ``canonical`` keeps exactly the fields of the type (missing ones
get their defaults, as rosbridge fills them), refuses fields the type lacks, values of the
wrong type and integers out of their type's range, and accepts ROS 1's ``{secs, nsecs}``
stamp spelling (what roslibpy's ``Header`` writes, with its ``seq``, which is dropped). A
megabyte of extra fields on a Twist is an error, not a megabyte sent to every subscriber.
Numeric arrays come out as ``values.typed_sequence`` s and byte arrays (``uint8[]``,
``byte[]``) as ``values.Base64Bytes``, so the encoders write them as rosbridge does (base64
text in JSON; typed arrays and byte strings in CBOR), whichever spelling the client sent.

The definitions are those of ROS 2 Humble's standard message packages, from the rosbags
typestore (a maintained, ROS-free copy of them): std_msgs, geometry_msgs, sensor_msgs,
nav_msgs, tf2_msgs, visualization_msgs, builtin_interfaces, rcl_interfaces and more, plus
the packages it lacks that courses use, shipped as their ROS 2 ``.msg`` (or ``.idl``) text
in ``rosbridge/msgs/interfaces/<package>/msg/`` (example_interfaces). A type defined nowhere is
refused (``check_type``) with rosbridge's reason; with ``websim serve --ros`` the types of
every installed ROS 2 package count too (``graph=True``: converted through their rclpy
classes, ``rosbridge.msgs.rclpy_conversion``).
"""

from __future__ import annotations

import base64
import functools
import re
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from rosbags.interfaces import Nodetype
from rosbags.typesys import Stores, get_types_from_idl, get_types_from_msg, get_typestore

from rosbridge.msgs.checks import (
    BYTE_SEQUENCE_TYPES,
    FLOAT_TYPES,
    MessageError,
    check_length,
    check_value,
    decode_base64,
    from_ros1,
    numbers,
)
from rosbridge.msgs.values import NUMERIC_ELEMENTS, Base64Bytes, normalize_type, typed_sequence

INTERFACES_DIR = Path(__file__).with_name("interfaces")
"""Definitions the typestore lacks: ``<package>/msg/<Type>.msg`` (``.idl`` where the rosbags
``.msg`` reader falls short: ``wstring``), the ROS 2 interface text."""

TYPESTORE = Stores.ROS2_HUMBLE

SRV_SEPARATOR = re.compile(r"^---[ \t]*$", re.MULTILINE)
"""The line between a ``.srv`` file's request and response."""

EMPTY_PLACEHOLDER = "structure_needs_at_least_one_member"
"""The field ROS 2's IDL gives a message with none (``std_msgs/Empty``); rclpy shows no field
and rosbridge sends ``{}``, so websim's canonical form leaves it out too."""

FAST_SEQUENCE_MIN = 32
"""Numeric sequences longer than this are checked as a whole (``numbers``), not per item."""

MAX_DEPTH = 32
"""Deepest nesting of message types followed (standard messages nest fewer than ten)."""


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
    common types are checked as rosbridge fills them. A ``<package>/action/<Type>.action``
    gives ``_Goal``, ``_Result`` and ``_Feedback``: goals are checked as requests are.
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
            types.update(_part_types(text, name, part))
    for path in sorted(folder.glob("*/action/*.action")):
        name = f"{path.parent.parent.name}/action/{path.stem}"
        parts = SRV_SEPARATOR.split(path.read_text(encoding="utf-8"), maxsplit=2)
        for part, text in zip(("Goal", "Result", "Feedback"), parts, strict=True):
            types.update(_part_types(text, name, part))
    return types


def _part_types(text: str, name: str, part: str) -> dict[str, Any]:
    """A service's or action's part (``pkg/srv/Type`` + ``Request``) as ``pkg/srv/Type_Part``.

    Parsed as the message ``pkg/msg/Type_Part``, so that a field of a type of its own package
    named without it (``Result result``) is ``pkg/msg/Result``, as rosidl reads it.
    """
    package, kind, type_name = name.split("/")
    parsed = get_types_from_msg(text.strip(), f"{package}/msg/{type_name}_{part}")
    (consts, fields), = parsed.values()
    return {f"{package}/{kind}/{type_name}_{part}": (consts, fields)}


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
        from rosbridge.msgs.rclpy_conversion import MessageConversionError, message_class

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
            rclpy package is converted through its class (``rclpy_conversion``).

    Raises:
        MessageError: ``type_name`` is not known (``check_type``), or ``msg`` does not fit
            it; the reason names the field (``linear.x: expected a number, got str``).
    """
    if known(type_name):
        shape = _float_tree(type_name)
        if shape is not None:
            plain = _plain_floats(shape, msg)
            if plain is not None:
                return plain
        return _message(type_name, msg, type_name, 0)
    check_type(type_name, graph=graph)
    from rosbridge.msgs.rclpy_conversion import (
        MessageConversionError,
        message_class,
        to_dict,
        to_message,
    )

    try:
        return to_dict(to_message(message_class(type_name), msg))
    except MessageConversionError as error:
        raise MessageError(str(error)) from None


def default(type_name: str) -> dict[str, Any]:
    """A ``type_name`` message with every field at its default."""
    return _message(type_name, {}, type_name, 0)


@functools.cache
def _layout(type_name: str) -> tuple[tuple[tuple[str, Any], ...], frozenset[str]]:
    """A type's fields (name, (kind, detail)) and their names, made once per type."""
    definition = tuple((name, kind) for name, kind in _fielddefs()[type_name][1]
                       if name != EMPTY_PLACEHOLDER)
    return definition, frozenset(name for name, _ in definition)


FloatTree = tuple[tuple[str, "FloatTree | None"], ...]
"""A type whose every field is a ``float64`` (None) or, nested, such a type."""


@functools.cache
def _float_tree(type_name: str, depth: int = 0) -> FloatTree | None:
    """``type_name``'s fields as a ``FloatTree`` (Twist, Vector3, Pose...); None if not one."""
    definition, _ = _layout(type_name)
    if not definition or depth > MAX_DEPTH:
        return None
    shape: list[tuple[str, FloatTree | None]] = []
    for name, (kind, detail) in definition:
        if kind == Nodetype.BASE and detail[0] == "float64":
            shape.append((name, None))
        elif kind == Nodetype.NAME and (nested := _float_tree(detail, depth + 1)) is not None:
            shape.append((name, nested))
        else:
            return None
    return tuple(shape)


def _plain_floats(shape: FloatTree, msg: Any) -> dict[str, Any] | None:
    """``msg`` in canonical form if it is already: every field, in order, each a float.

    The common message (a Twist from any client) is then checked without the general
    path's reasons and defaults; None: not so (``_message`` checks it and says why).
    """
    if type(msg) is not dict or len(msg) != len(shape):
        return None
    out: dict[str, Any] = {}
    for (name, nested), key in zip(shape, msg, strict=True):
        if name != key:
            return None
        value = msg[key]
        if nested is None:
            if type(value) is not float:
                return None
        elif (value := _plain_floats(nested, value)) is None:
            return None
        out[name] = value
    return out


def _message(type_name: str, msg: Any, where: str, depth: int) -> dict[str, Any]:
    if depth > MAX_DEPTH:
        raise MessageError(f"{where}: nested too deeply")
    if type(msg) is not dict and not isinstance(msg, Mapping):
        prefix = "" if where == type_name else f"{where}: "
        raise MessageError(f"{prefix}expected an object ({type_name}), got "
                           f"{type(msg).__name__}")
    definition, names = _layout(type_name)
    msg = from_ros1(type_name, msg)
    if not names.issuperset(msg):
        prefix = "" if where == type_name else f"{where}: "
        key = next(key for key in msg if key not in names)
        raise MessageError(f"{prefix}{type_name} has no field '{str(key)[:60]}' "
                           f"(fields: {', '.join(name for name, _ in definition)})")
    out: dict[str, Any] = {}
    top = where == type_name
    for name, (kind, detail) in definition:
        if name in msg:
            value = msg[name]
            if kind == Nodetype.BASE and type(value) is float and detail[0] == "float64":
                out[name] = value  # the common case, as check_value would return it
            else:
                out[name] = _value(kind, detail, value, name if top else f"{where}.{name}",
                                   depth)
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
