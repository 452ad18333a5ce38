"""ROS 2 messages <-> the plain dicts of ``ros_nodes.messages``, for the rclpy adapters.

``rosidl_runtime_py`` is not published on PyPI, so this is its ``set_message_fields`` and
``message_to_ordereddict`` in small: both walk a message class's
``get_fields_and_field_types()``, so one function serves every type, including types this
project never heard of (a student's topic relayed to the browser). The dicts follow
rosbridge's JSON conventions: ``uint8[]`` and ``byte[]`` are base64 strings, ``float32[]``
comes out as a ``Float32Sequence`` (so CBOR packs it as a typed array) and JSON ``null`` in a
float field is NaN (the encoders write non-finite floats as ``null``).

No rclpy import: message packages are imported by name, lazily, when a type is first used.
"""

from __future__ import annotations

import array
import base64
import importlib
import math
import re
from collections.abc import Mapping
from typing import Any

from ros_nodes.messages import Float32Sequence, Message, normalize_type

_SEQUENCE = re.compile(r"^sequence<(?P<element>[^,>]+)(?:,\s*\d+)?>$")
_ARRAY = re.compile(r"^(?P<element>[^\[]+)\[(?P<size>\d+)\]$")
_BYTE_TYPES = ("uint8", "octet")
_FLOAT_TYPES = ("float", "double", "long double")
_INTEGER_TYPES = ("char", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
                  "uint64")


class MessageConversionError(ValueError):
    """A dict does not fit a message type; the text names the field path and the reason."""


def message_class(type_name: str) -> Any:
    """The Python class of ``pkg/msg/Type`` (or ``pkg/Type``, or ``pkg/srv/Type``).

    Raises:
        MessageConversionError: not a type name, or its package is not installed (the text
            says which wheel to install).
    """
    try:
        package, kind, name = normalize_type(type_name).split("/")
    except ValueError as error:
        raise MessageConversionError(str(error)) from None
    try:
        module = importlib.import_module(f"{package}.{kind}")
    except ImportError:
        wheel = "ros-" + package.replace("_", "-")
        raise MessageConversionError(
            f"{package}/{kind}/{name}: package {package} is not installed "
            f"(pip install {wheel}, or source a ROS 2 installation that has it)") from None
    cls = getattr(module, name, None)
    if cls is None or not hasattr(cls, "get_fields_and_field_types"):
        raise MessageConversionError(f"{package}/{kind}/{name}: no such type in {package}")
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
        except (AssertionError, TypeError, ValueError, OverflowError) as error:
            if isinstance(error, MessageConversionError):
                raise
            raise MessageConversionError(f"{where}: {value!r} does not fit {field_type}"
                                         f"{': ' + str(error) if str(error) else ''}") from None


def _element_type(field_type: str) -> tuple[str, bool]:
    """(element type, is a sequence or array) of a field type string."""
    for pattern in (_SEQUENCE, _ARRAY):
        match = pattern.match(field_type)
        if match:
            return match.group("element").strip(), True
    return field_type, False


def _field_value(field_type: str, value: Any, strict: bool, where: str) -> Any:
    element, many = _element_type(field_type)
    if not many:
        return _scalar(element, value, strict, where)
    if element in _BYTE_TYPES and isinstance(value, str):
        data = base64.b64decode(value, validate=True)
        return [bytes([b]) for b in data] if element == "octet" else data
    if not isinstance(value, (list, tuple, array.array)):
        raise MessageConversionError(f"{where}: expected a list for {field_type}, got "
                                     f"{type(value).__name__} {value!r}")
    return [_scalar(element, item, strict, f"{where}[{index}]")
            for index, item in enumerate(value)]


def _scalar(element: str, value: Any, strict: bool, where: str) -> Any:
    if "/" in element:
        nested = message_class(element)()
        _fill(nested, value, strict, f"{where}.")
        return nested
    if element in _FLOAT_TYPES:
        if value is None:
            return math.nan
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise MessageConversionError(f"{where}: expected a number, got {value!r}")
        return float(value)
    if element in _INTEGER_TYPES:
        if isinstance(value, bool) or not isinstance(value, int):
            raise MessageConversionError(f"{where}: expected an integer, got {value!r}")
        return value
    if element == "boolean":
        if not isinstance(value, bool):
            raise MessageConversionError(f"{where}: expected true or false, got {value!r}")
        return value
    if element == "octet":
        if isinstance(value, int) and not isinstance(value, bool):
            return bytes([value])
        return value
    if element.startswith(("string", "wstring")):
        if not isinstance(value, str):
            raise MessageConversionError(f"{where}: expected a string, got {value!r}")
        return value
    return value


def to_dict(msg: Any) -> Message:
    """The dict of a message, as rosbridge sends it (see the module text)."""
    out: Message = {}
    for name, field_type in msg.get_fields_and_field_types().items():
        out[name] = _dict_value(field_type, getattr(msg, name))
    return out


def _dict_value(field_type: str, value: Any) -> Any:
    element, many = _element_type(field_type)
    if not many:
        return _dict_scalar(element, value)
    if element in _BYTE_TYPES:
        data = b"".join(value) if element == "octet" else bytes(value)
        return base64.b64encode(data).decode("ascii")
    if element == "float":
        return Float32Sequence(float(item) for item in value)
    if "/" in element:
        return [to_dict(item) for item in value]
    if hasattr(value, "tolist"):  # numpy arrays (fixed-size numeric arrays) and array.array
        return list(value.tolist())
    return [_dict_scalar(element, item) for item in value]


def _dict_scalar(element: str, value: Any) -> Any:
    if "/" in element:
        return to_dict(value)
    if element == "octet" and isinstance(value, bytes):
        return value[0] if value else 0
    if element in _FLOAT_TYPES:
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
