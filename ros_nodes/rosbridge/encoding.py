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


def parse_json(text: str | bytes) -> Any:
    """Decode an incoming JSON frame.

    ``NaN`` and ``Infinity`` literals decode to float nan and inf and are refused where a
    finite number is needed (a Twist), instead of failing the whole frame.
    """
    return json.loads(text)
