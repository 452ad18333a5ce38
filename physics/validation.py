"""Validation of values read from YAML files and set at runtime.

Every error names where the bad value came from (file and entry) and the value itself, so a
student can fix a world or parameter file without reading a traceback.
"""

from __future__ import annotations

import difflib
import math
from collections.abc import Iterable, Mapping
from typing import Any


class ConfigError(ValueError):
    """A world or parameter file, or a runtime setting, holds an invalid value."""


def fail(where: str, message: str) -> ConfigError:
    """Build a ConfigError whose message starts with the place of the error.

    Args:
        where: the file and entry, e.g. ``"worlds/maze.yaml: walls[3]"``.
        message: what is wrong with it.
    """
    return ConfigError(f"{where}: {message}")


def check_keys(where: str, mapping: Mapping[str, Any], allowed: Iterable[str]) -> None:
    """Reject keys that are not in ``allowed``, with a "did you mean" hint."""
    allowed_list = list(allowed)
    for key in mapping:
        if key not in allowed_list:
            close = difflib.get_close_matches(str(key), allowed_list, n=1)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            known = ", ".join(allowed_list)
            raise fail(where, f"unknown key '{key}'{hint} (known keys: {known})")


def as_mapping(where: str, value: Any) -> Mapping[str, Any]:
    """Return ``value`` if it is a mapping with string keys, else raise."""
    if not isinstance(value, Mapping):
        raise fail(where, f"expected a mapping, got {type(value).__name__} {value!r}")
    return value


def as_finite_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is a finite real number (bools are refused)."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise fail(where, f"expected a number, got {type(value).__name__} {value!r}")
    try:
        number = float(value)
    except OverflowError:  # an integer beyond float range, e.g. 10**400 from JSON
        raise fail(where, f"expected a finite number, got an integer of "
                          f"{len(str(abs(value)))} digits") from None
    if not math.isfinite(number):
        raise fail(where, f"expected a finite number, got {value!r}")
    return number


def as_float_in_range(where: str, value: Any, minimum: float, maximum: float) -> float:
    """Return ``value`` as a float if it is finite and within [minimum, maximum]."""
    number = as_finite_float(where, value)
    if not minimum <= number <= maximum:
        raise fail(where, f"must be between {minimum:g} and {maximum:g}, got {value!r}")
    return number


def as_positive_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and > 0."""
    number = as_finite_float(where, value)
    if number <= 0.0:
        raise fail(where, f"must be > 0, got {value!r}")
    return number


def as_non_negative_float(where: str, value: Any) -> float:
    """Return ``value`` as a float if it is finite and >= 0."""
    number = as_finite_float(where, value)
    if number < 0.0:
        raise fail(where, f"must be >= 0, got {value!r}")
    return number


def as_number_list(where: str, value: Any, length: int) -> list[float]:
    """Return ``value`` as ``length`` finite floats, e.g. a ``[x1, y1, x2, y2]`` wall."""
    if not isinstance(value, (list, tuple)) or len(value) != length:
        raise fail(where, f"expected a list of {length} numbers, got {value!r}")
    return [as_finite_float(f"{where}[{i}]", item) for i, item in enumerate(value)]
