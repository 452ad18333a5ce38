"""How a metric's parameters are declared, so the scenario loader checks every one alike.

Each metric has one frozen dataclass of parameters; each field says, in its metadata, its
unit, how a value read from a file is checked, and where the value may come from besides the
metric's own entry in the scenario file: the scenario's ``parameters`` (what the controller
is told as ``WEBSIM_<NAME>``, so a fact is written once) or a fact of the scenario itself
(the robot's radius, the run's duration, the end point), which a file never sets per metric.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from typing import Any

from physics.validation import (
    as_finite_float,
    as_non_negative_float,
    as_positive_float,
    fail,
    shown,
)

Check = Callable[[str, Any], Any]
"""Checks a value read from a file: (where, value) -> the value to use, or ConfigError."""


def param(default: Any = dataclasses.MISSING, *, unit: str = "", check: Check | None = None,
          from_parameter: bool = False, from_scenario: str | None = None) -> Any:
    """A dataclass field of a metric's parameters.

    Args:
        default: its default; none makes it required.
        unit: its unit, for the docs and the report.
        check: how a value from a file is checked; None for a field no file sets.
        from_parameter: when the metric's entry does not give it, the scenario's parameter
            of the same name does (e.g. ``desired_distance_m``, which the controller is told).
        from_scenario: the name of a scenario fact that sets it (never a key of the entry).
    """
    metadata = {"unit": unit, "check": check, "from_parameter": from_parameter,
                "from_scenario": from_scenario}
    return dataclasses.field(default=default, metadata=metadata)


def number(where: str, value: Any) -> float:
    """Any finite number."""
    return as_finite_float(where, value)


def positive(where: str, value: Any) -> float:
    """A finite number > 0."""
    return as_positive_float(where, value)


def non_negative(where: str, value: Any) -> float:
    """A finite number >= 0."""
    return as_non_negative_float(where, value)


def optional(check: Check) -> Check:
    """``check``, or ``null`` in the file for "none" (e.g. no threshold)."""
    def checked(where: str, value: Any) -> Any:
        return None if value is None else check(where, value)
    return checked


def fraction(where: str, value: Any) -> float:
    """A number from 0 to 1."""
    number_value = as_finite_float(where, value)
    if not 0.0 <= number_value <= 1.0:
        raise fail(where, f"must be between 0 and 1, got {shown(value)}")
    return number_value


def one_of(*choices: str) -> Check:
    """One of the given words."""
    def checked(where: str, value: Any) -> str:
        if value not in choices:
            raise fail(where, f"must be one of {', '.join(choices)}, got {shown(value)}")
        return str(value)
    return checked


def whole(where: str, value: Any) -> int:
    """A whole number >= 0."""
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise fail(where, f"expected a whole number >= 0, got {shown(value)}")
    return value
