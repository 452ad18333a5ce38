"""Frames on the wire: JSON text (non-finite floats as null) and CBOR binary.

roslibjs parses JSON with ``JSON.parse``, which throws on ``NaN`` and ``Infinity``, so every
non-finite float goes out as ``null``, as rosbridge_server does (encoded by orjson). CBOR
keeps floats as they are and packs ``float32[]`` fields (``Float32Sequence``) as RFC 8746
typed arrays (tag 85, little-endian), which roslibjs decodes into a ``Float32Array``.
"""

from __future__ import annotations

import json
import math
from typing import Any

import cbor2
import numpy as np
import orjson

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
    """Encode ``message`` as compact JSON with every NaN or infinity written as ``null``.

    orjson writes non-finite floats as ``null`` itself and is about ten times faster than
    the standard library (a /scan: 21 µs instead of 212 µs): every message is encoded on
    the tick. What orjson cannot write (an integer beyond 64 bits, from a client's message of
    a type websim does not know) goes through the standard library instead.
    """
    try:
        return orjson.dumps(message).decode()
    except TypeError:  # orjson.JSONEncodeError
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
fewer than ten levels (a MarkerArray: five); deeper input only exists to exhaust the stack."""

MAX_ELEMENTS = 30_000
"""Most elements an incoming message may have: values (commas outside strings, plus one)
and objects and arrays. Parsing costs 0.1-0.3 µs of a core per element, so this bounds one
message's parse to about 10 ms, well inside a 50 ms tick, whatever the frame size allows; a
LaserScan has about 400 elements, a 1000-pose nav_msgs/Path about 20,000."""

QUICK_REFUSAL_FACTOR = 4
"""A frame with this many times ``MAX_ELEMENTS`` commas and brackets (strings included) is
refused from the counts alone (about 1 ms per MiB), without the exact count: only a message
whose strings hold over 90,000 commas or brackets could be refused wrongly."""

_QUOTE, _COMMA = ord('"'), ord(",")
_OPENERS, _CLOSERS = (ord("["), ord("{")), (ord("]"), ord("}"))


def structure(data: bytes) -> tuple[int, int]:
    """(deepest nesting, elements: values, objects and arrays) of a JSON text, in numpy.

    Escaped backslashes and quotes are removed first, so the quotes left delimit strings.
    Linear in the text and about 5 ms per MiB; valid or not, the text is never parsed.
    """
    unescaped = data.replace(b"\\\\", b"").replace(b'\\"', b"")
    chars = np.frombuffer(unescaped, dtype=np.uint8)
    quotes = chars == _QUOTE
    outside = (np.cumsum(quotes, dtype=np.int32) & 1) == 0  # a closing quote counts as out
    opens = ((chars == _OPENERS[0]) | (chars == _OPENERS[1])) & outside
    closes = ((chars == _CLOSERS[0]) | (chars == _CLOSERS[1])) & outside
    steps = opens.view(np.int8) - closes.view(np.int8)
    depth = int(np.cumsum(steps, dtype=np.int32).max()) if steps.size else 0
    values = int(np.count_nonzero((chars == _COMMA) & outside)) + 1
    return depth, values + int(np.count_nonzero(opens))


def parse_json(text: str | bytes) -> Any:
    """Decode an incoming JSON frame, refusing costly shapes before parsing them.

    ``NaN`` and ``Infinity`` literals decode to float nan and inf and are refused where a
    finite number is needed (a Twist), instead of failing the whole frame. Integers keep
    every digit (the schema refuses those out of range).

    Raises:
        ValueError: invalid JSON, nested more than ``MAX_NESTING`` levels deep, or more
            than ``MAX_ELEMENTS`` elements.
    """
    if isinstance(text, str):
        brackets, commas = text.count("[") + text.count("{"), text.count(",")
    else:
        brackets, commas = text.count(b"[") + text.count(b"{"), text.count(b",")
    if brackets + commas > QUICK_REFUSAL_FACTOR * MAX_ELEMENTS:  # not even worth counting
        raise ValueError(f"too many elements (about {brackets + commas}; at most "
                         f"{MAX_ELEMENTS} values, objects and arrays)")
    if brackets > MAX_NESTING or brackets + commas >= MAX_ELEMENTS:  # upper bounds
        depth, elements = structure(text.encode() if isinstance(text, str) else text)
        if depth > MAX_NESTING:
            raise ValueError(f"too deeply nested (more than {MAX_NESTING} levels)")
        if elements > MAX_ELEMENTS:
            raise ValueError(f"too many elements ({elements}; at most {MAX_ELEMENTS} "
                             "values, objects and arrays)")
    return json.loads(text)
