"""Frames on the wire: JSON text (non-finite floats as null), CBOR binary, and rosbridge's PNG.

roslibjs parses JSON with ``JSON.parse``, which throws on ``NaN`` and ``Infinity``, so every
non-finite float goes out as ``null``, as rosbridge_server does (encoded by orjson, which
writes the list and str subclasses of ``ros_nodes.robot_messages`` as plain lists and strings).
CBOR keeps floats as they are and packs every numeric array (``TypedSequence``) as the
RFC 8746 typed array of its element, little-endian, as rosbridge's ``cbor_conversion`` does
and roslibjs's ``cborTypedArrayTags`` decodes (into a ``Float32Array``, ``Int32Array``...);
a ``uint8[]`` field (``Base64Bytes``) is a CBOR byte string, as rosbridge sends ``bytes``.

``compression: "png"`` (``png_frame``) is rosbridge's ``pngcompression.encode``: the JSON
text's bytes as the pixels of an RGB image about as wide as high, padded with newlines,
in base64. ``cbor-raw`` (``cbor_raw_frame``) sends the message's CDR bytes (``cdr``) in
``{"op": "publish", "topic", "msg": {"secs", "nsecs", "bytes"}}``.
"""

from __future__ import annotations

import base64
import io
import json
import math
import re
from collections.abc import Mapping
from typing import Any

import cbor2
import numpy as np
import orjson

from rosbridge.msgs.values import Base64Bytes, TypedSequence

CBOR_TYPED_ARRAYS: Mapping[str, tuple[int, str]] = {
    "uint8": (64, "u1"), "uint16": (69, "<u2"), "uint32": (70, "<u4"), "uint64": (71, "<u8"),
    "int8": (72, "i1"), "int16": (77, "<i2"), "int32": (78, "<i4"), "int64": (79, "<i8"),
    "float32": (85, "<f4"), "float64": (86, "<f8"),
}
"""ROS element type -> (RFC 8746 tag of its little-endian typed array, numpy dtype): the
tags of rosbridge's ``TAGGED_ARRAY_FORMATS``, with 64 (uint8) for a ``uint8[]`` that is not
base64; roslibjs decodes every one of them."""

PNG_PADDING = b"\n"
"""What fills the last pixels of a PNG-packed message (JSON whitespace), as in rosbridge."""

_NON_ASCII = re.compile(r"[^\x00-\x7f]")

_SURROGATE_ESCAPE = re.compile(r"\\u[dD][89a-fA-F]")
"""A JSON escape of a UTF-16 surrogate: only these make text that UTF-8 cannot hold (a
lone one); a pair decodes to one character."""


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
    if isinstance(value, TypedSequence):
        tag, dtype = CBOR_TYPED_ARRAYS[value.element]
        try:
            packed = np.asarray(value, dtype=dtype).tobytes()
        except (OverflowError, TypeError) as error:
            raise ValueError(f"a {value.element}[] holds a value that is not one: "
                             f"{error}") from None
        return cbor2.CBORTag(tag, packed)
    if isinstance(value, Base64Bytes):
        return base64.b64decode(value)
    if isinstance(value, dict):
        return {key: _pack_typed_arrays(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_pack_typed_arrays(item) for item in value]
    return value


def to_cbor(message: Any) -> bytes:
    """Encode ``message`` as CBOR: numeric arrays as typed arrays, ``uint8[]`` as bytes.

    Raises:
        ValueError: a ``TypedSequence`` holds a value its element type cannot (300 in a
            ``uint8[]``).
    """
    return cbor2.dumps(_pack_typed_arrays(message))


def _ascii_escape(match: re.Match[str]) -> str:
    code = ord(match.group())
    if code < 0x10000:
        return f"\\u{code:04x}"
    code -= 0x10000
    return f"\\u{0xD800 + (code >> 10):04x}\\u{0xDC00 + (code & 0x3FF):04x}"


def png_frame(text: str) -> str:
    """The ``{"op": "png", "data"}`` frame of the JSON text ``text`` (rosbridge's PNG).

    The text is written with JSON escapes (backslash-u) for non-ASCII characters first (what
    rosbridge's encoder writes): a browser's roslibjs reads one character per byte.
    """
    from PIL import Image  # only for clients that ask for PNG

    data = _NON_ASCII.sub(_ascii_escape, text).encode("ascii")
    width = max(1, math.floor(math.sqrt(len(data) / 3)))
    height = max(1, math.ceil(len(data) / 3 / width))
    pixels = data + PNG_PADDING * (width * height * 3 - len(data))
    buffer = io.BytesIO()
    Image.frombytes("RGB", (width, height), pixels).save(buffer, "png")
    return to_json({"op": "png", "data": base64.b64encode(buffer.getvalue()).decode()})


def cbor_raw_frame(topic: str, cdr: bytes, time_s: float) -> bytes:
    """The ``cbor-raw`` frame of a message serialized as ``cdr`` (rosbridge's fields).

    Args:
        topic: the topic it was published on.
        cdr: the message in CDR, its 4-byte encapsulation header first (what rclpy hands a
            raw subscription).
        time_s: when the bridge received it (s since the epoch): ``secs`` and ``nsecs``.
    """
    secs = math.floor(time_s)
    nsecs = min(round((time_s - secs) * 1e9), 999_999_999)
    return cbor2.dumps({"op": "publish", "topic": topic,
                        "msg": {"secs": secs, "nsecs": nsecs, "bytes": bytes(cdr)}})


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

    A string escaping a lone UTF-16 surrogate (backslash-u D800 to DFFF, unpaired) is
    refused: no encoder (UTF-8, CBOR, CDR) could write it to another client.

    ``NaN`` and ``Infinity`` literals decode to float nan and inf and are refused where a
    finite number is needed (a Twist), instead of failing the whole frame. Integers keep
    every digit (the schema refuses those out of range).

    Raises:
        ValueError: invalid JSON, nested more than ``MAX_NESTING`` levels deep, more
            than ``MAX_ELEMENTS`` elements, or a lone surrogate in a string.
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
    message = _loads(text)
    probe = text if isinstance(text, str) else text.decode("utf-8", "replace")
    if _SURROGATE_ESCAPE.search(probe):
        _refuse_lone_surrogates(message)
    return message


_DIGITS_AS_ZERO = bytes(48 if byte in b"0123456789" else 32 for byte in range(256))
"""A ``bytes.translate`` table: every digit a ``0``, every other byte a blank."""

_LONG_NUMBER = b"0" * 19
"""19 digits in a row: perhaps an integer beyond 64 bits, which orjson reads as a float."""


def _loads(text: str | bytes) -> Any:
    """``json.loads(text)``, by orjson where it gives the same (about 4 times faster).

    orjson reads a JSON text as the standard library does, except that it refuses ``NaN``,
    ``Infinity``, numbers beyond float range and lone surrogates (the standard library then
    reads the text, or gives its reason) and reads integers beyond 64 bits as floats (a text
    with 19 digits in a row goes to the standard library).
    """
    data = text.encode("utf-8", "surrogatepass") if isinstance(text, str) else text
    if _LONG_NUMBER not in data.translate(_DIGITS_AS_ZERO):
        try:
            return orjson.loads(data)
        except orjson.JSONDecodeError:
            pass  # the standard library's reading, or its reason
    return json.loads(text)


def _refuse_lone_surrogates(value: Any) -> None:
    """Raise ValueError if a string (or key) of ``value`` holds a lone surrogate."""
    stack = [value]
    while stack:
        item = stack.pop()
        if isinstance(item, str):
            try:
                item.encode("utf-8")
            except UnicodeEncodeError as error:
                raise ValueError(f"a string holds a lone UTF-16 surrogate "
                                 f"(\\u{ord(item[error.start]):04x}): text that UTF-8, CBOR "
                                 "and ROS cannot carry") from None
        elif isinstance(item, dict):
            stack.extend(item.keys())
            stack.extend(item.values())
        elif isinstance(item, list):
            stack.extend(item)
