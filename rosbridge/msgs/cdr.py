"""Messages (canonical dicts) in CDR, the bytes ROS 2 nodes exchange: what ``cbor-raw`` sends.

rosbridge's ``cbor-raw`` hands a client the bytes rclpy received; websim has no rclpy, so a
message is serialized here with the rosbags typestore's CDR serializer (the definitions
``definitions`` checks messages against, little-endian, with the 4-byte encapsulation
header first, as rclpy delivers them). Only types that typestore knows can be serialized.
"""

from __future__ import annotations

import base64
import functools
import math
from typing import Any

import numpy as np
from rosbags.interfaces import Nodetype
from rosbags.typesys import get_typestore

from rosbridge.msgs import checks, definitions
from rosbridge.msgs.definitions import EMPTY_PLACEHOLDER

NUMPY_TYPES = {
    "bool": np.bool_, "byte": np.uint8, "char": np.uint8, "octet": np.uint8,
    "int8": np.int8, "uint8": np.uint8, "int16": np.int16, "uint16": np.uint16,
    "int32": np.int32, "uint32": np.uint32, "int64": np.int64, "uint64": np.uint64,
    "float32": np.float32, "float64": np.float64,
}
"""The numpy type of each base type: rosbags takes arrays of them as numpy arrays."""


class CdrError(ValueError):
    """A message cannot be serialized; the reason says why."""


@functools.cache
def typestore() -> Any:
    """The typestore of ``definitions``, with the shipped definitions (built once).

    What messages are serialized with, and where a recording takes each type's definition
    and hash from (``rosbags.typesys.store.Typestore``; do not register types in it).
    """
    store = get_typestore(definitions.TYPESTORE)
    store.register(definitions.shipped_definitions())
    return store


def serializable(type_name: str) -> bool:
    """Whether messages of ``type_name`` can be serialized here."""
    return type_name in typestore().fielddefs


def to_cdr(type_name: str, msg: Any) -> bytes:
    """``msg``, a canonical ``type_name`` message (``definitions.canonical``), in CDR.

    Raises:
        CdrError: the type is unknown here, or a field does not fit it.
    """
    if not serializable(type_name):
        raise CdrError(f"{type_name} is not a type websim can serialize (cbor-raw needs one "
                       "of its standard message types)")
    store = typestore()
    try:
        return bytes(store.serialize_cdr(_build(store, type_name, msg), type_name))
    except (KeyError, TypeError, ValueError, OverflowError, AttributeError) as error:
        raise CdrError(f"{type_name}: cannot be serialized: {type(error).__name__}: "
                       f"{error}") from None


def _build(store: Any, type_name: str, msg: Any) -> Any:
    """The typestore's message object of ``type_name`` holding ``msg``'s values."""
    values = {name: _value(store, kind, detail, msg[name]) if name != EMPTY_PLACEHOLDER else 0
              for name, (kind, detail) in store.fielddefs[type_name][1]}
    return store.types[type_name](**values)


def _value(store: Any, kind: Nodetype, detail: Any, value: Any) -> Any:
    if kind == Nodetype.BASE:
        return _base(detail[0], value)
    if kind == Nodetype.NAME:
        return _build(store, detail, value)
    (element_kind, element_detail), _ = detail
    if element_kind != Nodetype.BASE:
        return [_value(store, element_kind, element_detail, item) for item in value]
    base_type = element_detail[0]
    if base_type == "string":
        return [str(item) for item in value]
    if isinstance(value, str):  # a uint8[] as base64 text
        return np.frombuffer(base64.b64decode(value), dtype=np.uint8)
    if base_type in checks.FLOAT_TYPES:
        value = [math.nan if item is None else item for item in value]
    return np.asarray(value, dtype=NUMPY_TYPES[base_type])


def _base(base_type: str, value: Any) -> Any:
    if base_type == "string":
        return str(value)
    if base_type in checks.FLOAT_TYPES:
        return math.nan if value is None else float(value)
    if base_type == "bool":
        return bool(value)
    return int(value)
