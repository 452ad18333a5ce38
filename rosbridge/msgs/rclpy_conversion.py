"""ROS 2 messages <-> the plain dicts of ``ros_nodes.robot_messages``, for the rclpy adapters.

``rosidl_runtime_py`` is not published on PyPI, so this is its ``set_message_fields`` and
``message_to_ordereddict`` in small: both walk a message class's
``get_fields_and_field_types()``, so one function serves every type, including types this
project never heard of (a student's topic relayed to the browser). The dicts follow
rosbridge's JSON conventions: ``uint8[]`` and ``byte[]`` are base64 text
(``values.Base64Bytes``), other numeric arrays come out as ``values.typed_sequence`` s (so
CBOR packs them as typed arrays) and JSON ``null`` in a float field is NaN (the encoders write
non-finite floats as ``null``).

Every value is checked here, by ``checks``' rules, before rclpy sees it: rclpy's own
field checks are off by default since Jazzy (``ROS_PYTHON_CHECK_FIELDS``), and an int8 of
32767 would otherwise go out as -1. ROS 1's ``{secs, nsecs}`` stamps are accepted
(``checks.from_ros1``), as rosbridge accepts them.

No rclpy import: message packages are imported by name, lazily, when a type is first used.
"""

from __future__ import annotations

import array
import base64
import importlib
import re
from collections.abc import Mapping
from typing import Any

from rosbridge.msgs import checks
from rosbridge.msgs.values import (
    NUMERIC_ELEMENTS,
    Base64Bytes,
    Message,
    normalize_type,
    typed_sequence,
)

_SEQUENCE = re.compile(r"^sequence<(?P<element>[^,>]+(?:<\d+>)?)(?:,\s*(?P<bound>\d+))?>$")
_ARRAY = re.compile(r"^(?P<element>[^\[]+)\[(?P<size>\d+)\]$")
_BOUNDED_STRING = re.compile(r"^(?P<base>w?string)<(?P<bound>\d+)>$")
_IDENTIFIER = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
"""A package or type name: what a client's type may name, never a dotted module path."""
_BYTE_TYPES = ("uint8", "octet")
"""Element types whose arrays are base64 text (rosbridge: ``uint8[]``; ``byte[]`` too)."""

IDL_TO_MSG = {"boolean": "bool", "float": "float32", "double": "float64", "octet": "byte"}
"""rclpy's (IDL) names of the base types whose ``.msg`` names differ; the checks use these."""

_LISTS = (list, tuple, array.array)


class MessageConversionError(ValueError):
    """A dict does not fit a message type; the text names the field path and the reason."""


def message_class(type_name: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (or ``pkg/Type``, or ``pkg/srv/Type``).

    Raises:
        MessageConversionError: not a type name, or its package or type is not installed:
            rosbridge's reason, and which wheel to install.
    """
    try:
        package, kind, name = normalize_type(type_name).split("/")
    except ValueError as error:
        raise MessageConversionError(str(error)) from None
    if not (_IDENTIFIER.match(package) and _IDENTIFIER.match(name)):
        raise MessageConversionError(f"not a ROS type name: {type_name[:80]!r} (a package and "
                                     "a type are letters, digits and underscores)")
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError as error:
        wheel = "ros-" + package.replace("_", "-")
        raise MessageConversionError(
            f"Unable to import {package}.{kind} from package {package}. Caused by: {error} "
            f"(pip install {wheel}, or source a ROS 2 installation that has it)") from None
    cls = getattr(module, name, None)
    if cls is None or not any(hasattr(cls, mark) for mark in (  # a msg, srv or action
            "get_fields_and_field_types", "Request", "Goal")):
        raise MessageConversionError(
            f"Unable to import {kind} class {name} from package {package}. Caused by module "
            f"'{package}.{kind}' has no attribute '{name}'")
    return cls


def type_name_of(cls: Any) -> str:
    """``pkg/msg/Type`` of a message class."""
    package, kind = cls.__module__.split(".")[:2]
    return f"{package}/{kind}/{cls.__name__}"


def to_message(cls: Any, values: Mapping[str, Any], *, strict: bool = True) -> Any:
    """A new ``cls`` message with the fields of ``values``; fields left out keep defaults.

    Args:
        cls: a generated message class.
        values: the dict (nested dicts for nested messages, rosbridge conventions).
        strict: refuse keys the type does not have; with False they are skipped (websim's own
            messages carry fields older distributions lack, e.g. Humble's Marker has no
            ``texture``).

    Raises:
        MessageConversionError: a key or value does not fit, naming the field.
    """
    msg = cls()
    _fill(msg, values, strict, "")
    return msg


def _fill(msg: Any, values: Any, strict: bool, path: str) -> None:
    if not isinstance(values, Mapping):
        raise MessageConversionError(f"{path or 'message'}: expected an object, got "
                                     f"{type(values).__name__} {values!r}")
    fields = msg.get_fields_and_field_types()
    values = checks.from_ros1(type_name_of(type(msg)), values)
    for name, value in values.items():
        field_type = fields.get(name)
        where = f"{path}{name}"
        if field_type is None:
            if strict:
                raise MessageConversionError(
                    f"{where}: {type_name_of(type(msg))} has no such field "
                    f"(fields: {', '.join(fields)})")
            continue
        try:
            setattr(msg, name, _field_value(field_type, value, strict, where))
        except checks.MessageError as error:
            raise MessageConversionError(str(error)) from None
        except (AssertionError, TypeError, ValueError, OverflowError) as error:
            if isinstance(error, MessageConversionError):
                raise
            raise MessageConversionError(f"{where}: {value!r} does not fit {field_type}"
                                         f"{': ' + str(error) if str(error) else ''}") from None


def field_shape(field_type: str) -> tuple[str, str, int]:
    """(element type, ``scalar``/``array``/``sequence``, length or bound) of an rclpy field type.

    ``int32[3]`` is an array of exactly 3, ``sequence<int32, 3>`` a sequence of at most 3,
    ``sequence<int32>`` unbounded (0).
    """
    match = _SEQUENCE.match(field_type)
    if match:
        return match.group("element").strip(), "sequence", int(match.group("bound") or 0)
    match = _ARRAY.match(field_type)
    if match:
        return match.group("element").strip(), "array", int(match.group("size"))
    return field_type, "scalar", 0


def _field_value(field_type: str, value: Any, strict: bool, where: str) -> Any:
    element, shape, length = field_shape(field_type)
    if shape == "scalar":
        return _scalar(element, value, strict, where)
    fixed = shape == "array"
    if element in _BYTE_TYPES and isinstance(value, (str, bytes, bytearray)):
        data = checks.decode_base64(value, where) if isinstance(value, str) \
            else bytes(value)
        checks.check_length(fixed, length, len(data), where, "bytes")
        if element == "octet":
            return [bytes([b]) for b in data]
        return list(data) if fixed else data
    if not isinstance(value, _LISTS):
        raise MessageConversionError(f"{where}: expected a list for {field_type}, got "
                                     f"{type(value).__name__} {value!r}")
    checks.check_length(fixed, length, len(value), where)
    base = IDL_TO_MSG.get(element, element)
    if base in checks.INTEGER_RANGES or base in checks.FLOAT_TYPES:
        items = list(value)
        checked = checks.numbers(base, items) if element != "octet" else None
        if checked is None:
            checked = [checks.check_value(base, item, f"{where}[{index}]")
                       for index, item in enumerate(items)]
        return [bytes([b]) for b in checked] if element == "octet" else checked
    return [_scalar(element, item, strict, f"{where}[{index}]")
            for index, item in enumerate(value)]


def _scalar(element: str, value: Any, strict: bool, where: str) -> Any:
    if "/" in element:
        nested = message_class(element)()
        _fill(nested, value, strict, f"{where}.")
        return nested
    if element == "octet" and isinstance(value, bytes) and len(value) == 1:
        return value
    if element in ("char", "wchar"):  # an IDL character (rclpy: a one-character str)
        if not isinstance(value, str) or len(value) != 1:
            raise MessageConversionError(f"{where}: expected one character, got {value!r}")
        return value
    bounded = _BOUNDED_STRING.match(element)
    if bounded:
        return checks.check_value(bounded.group("base"), value, where,
                                         int(bounded.group("bound")))
    base = IDL_TO_MSG.get(element, element)
    checked = checks.check_value(base, value, where)
    return bytes([checked]) if element == "octet" else checked


def to_dict(msg: Any) -> Message:
    """The dict of a message, as rosbridge sends it (see the module text)."""
    out: Message = {}
    for name, field_type in msg.get_fields_and_field_types().items():
        out[name] = _dict_value(field_type, getattr(msg, name))
    return out


def _dict_value(field_type: str, value: Any) -> Any:
    element, shape, _ = field_shape(field_type)
    if shape == "scalar":
        return _dict_scalar(element, value)
    if element in _BYTE_TYPES:
        data = b"".join(value) if element == "octet" else bytes(value)
        return Base64Bytes(base64.b64encode(data).decode("ascii"))
    if "/" in element:
        return [to_dict(item) for item in value]
    base = IDL_TO_MSG.get(element, element)
    items = value.tolist() if hasattr(value, "tolist") else list(value)  # numpy, array.array
    if base in NUMERIC_ELEMENTS:
        return typed_sequence(base, items)
    return [_dict_scalar(element, item) for item in items]


def _dict_scalar(element: str, value: Any) -> Any:
    if "/" in element:
        return to_dict(value)
    if element == "octet" and isinstance(value, bytes):
        return value[0] if value else 0
    if element in ("float", "double"):
        return float(value)
    return value


class PublisherFilter:
    """Tells whether a message on one topic came from one node's publishers (by GID).

    An in-process relay subscribes to topics it also publishes: this keeps its own messages
    from coming back to it.

    Args:
        node: an rclpy node, to ask the graph with.
        topic: the topic the messages arrive on.
        publisher_node: the name of the node whose messages are to be recognised.
    """

    def __init__(self, node: Any, topic: str, publisher_node: str) -> None:
        self._node = node
        self._topic = topic
        self._publisher_node = publisher_node
        self._known: dict[bytes, bool] = {}

    def is_from(self, info: Mapping[str, Any]) -> bool:
        """True if the message with this ``MessageInfo`` came from ``publisher_node``."""
        gid = info.get("publisher_gid")
        if not gid:
            return False
        key = bytes(gid["data"])
        known = self._known.get(key)
        if known is None:
            self._known = {bytes(endpoint.endpoint_gid): endpoint.node_name == self._publisher_node
                           for endpoint in self._node.get_publishers_info_by_topic(self._topic)}
            known = self._known.get(key, False)
        return known
