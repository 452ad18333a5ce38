"""Frames on the wire: JSON text (non-finite floats as null) and CBOR binary.

roslibjs parses JSON with ``JSON.parse``, which throws on ``NaN`` and ``Infinity``, so every
non-finite float goes out as ``null``, as rosbridge_server does. CBOR keeps floats as they are
and packs ``float32[]`` fields (``Float32Sequence``) as RFC 8746 typed arrays (tag 85,
little-endian), which roslibjs decodes into a ``Float32Array``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import cbor2
import numpy as np

from ros_nodes.messages import Float32Sequence

CBOR_TAG_FLOAT32_LE = 85
"""RFC 8746 tag of a little-endian float32 typed array."""


def _null_non_finite(value: Any) -> Any:
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {key: _null_non_finite(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_null_non_finite(item) for item in value]
    return value


def to_json(message: Any) -> str:
    """Encode ``message`` as compact JSON with every NaN or infinity written as ``null``."""
    try:
        return json.dumps(message, allow_nan=False, separators=(",", ":"))
    except ValueError:
        return json.dumps(_null_non_finite(message), allow_nan=False, separators=(",", ":"))


def _pack_typed_arrays(value: Any) -> Any:
    if isinstance(value, Float32Sequence):
        packed = np.asarray(value, dtype="<f4").tobytes()
        return cbor2.CBORTag(CBOR_TAG_FLOAT32_LE, packed)
    if isinstance(value, dict):
        return {key: _pack_typed_arrays(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_pack_typed_arrays(item) for item in value]
    return value


def to_cbor(message: Any) -> bytes:
    """Encode ``message`` as CBOR with ``float32[]`` fields as typed arrays."""
    return cbor2.dumps(_pack_typed_arrays(message))


MAX_NESTING = 64
"""Deepest nesting of objects and arrays an incoming message may have. ROS messages nest
fewer than ten levels (a MarkerArray: five); deeper input only exists to exhaust the stack, and
json.loads itself gives up near 1000 levels with a RecursionError."""


def parse_json(text: str | bytes) -> Any:
    """Decode an incoming JSON frame.

    ``NaN`` and ``Infinity`` literals decode to float nan and inf and are refused where a
    finite number is needed (a Twist), instead of failing the whole frame.

    Raises:
        ValueError: invalid JSON, or nested more than ``MAX_NESTING`` levels deep.
    """
    try:
        value = json.loads(text)
    except RecursionError:
        raise ValueError(f"too deeply nested (more than {MAX_NESTING} levels)") from None
    brackets = text.count("[") + text.count("{") if isinstance(text, str) else \
        text.count(b"[") + text.count(b"{")
    if brackets > MAX_NESTING and nesting_exceeds(value, MAX_NESTING):  # count: a fast bound
        raise ValueError(f"too deeply nested (more than {MAX_NESTING} levels)")
    return value


def nesting_exceeds(value: Any, limit: int) -> bool:
    """Whether ``value`` has objects or arrays nested more than ``limit`` deep (no recursion)."""
    if not isinstance(value, (dict, list)):
        return False
    stack: list[tuple[Any, int]] = [(value, 1)]
    while stack:
        item, depth = stack.pop()
        if depth > limit:
            return True
        children = item.values() if isinstance(item, dict) else item
        stack.extend((child, depth + 1) for child in children
                     if isinstance(child, (dict, list)))
    return False
