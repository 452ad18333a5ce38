"""What a metric hands back: its figure, the limit it was held to, pass, score and why."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class MetricResult:
    """One metric of one run.

    Attributes:
        name: the metric's name in its scenario (its kind unless the scenario names it).
        kind: which metric (``heading_step``, ``wall_following``...).
        value: its main figure in ``unit`` (settling time, loss, time to goal...); None when
            what it measures never happened (never settled, never reached the goal).
        unit: the unit of ``value`` and ``threshold``.
        threshold: the limit ``value`` is held to for a pass, None for no limit.
        passed: whether the run meets every condition of the metric.
        score: in [0, 1], by the metric's formula (docs/grading.md).
        reason: why it failed, or what it found when it passed, in one line.
        figures: the other figures it computed (overshoot, path length, contacts...).
        inputs: what it was computed from: its parameters and the data it read.
    """

    name: str
    kind: str
    value: float | None
    unit: str
    threshold: float | None
    passed: bool
    score: float
    reason: str
    figures: Mapping[str, Any]
    inputs: Mapping[str, Any]

    def __post_init__(self) -> None:
        if not 0.0 <= self.score <= 1.0 or math.isnan(self.score):
            raise ValueError(f"{self.kind}: score {self.score!r} is outside [0, 1]")

    def to_json(self) -> dict[str, Any]:
        """The result as JSON-ready values (report.json): no NaN or infinity, None instead."""
        return {field.name: _plain(getattr(self, field.name))
                for field in dataclasses.fields(self)}


def _plain(value: Any) -> Any:
    """``value`` with mappings and sequences made JSON-ready and non-finite numbers None."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, Mapping):
        return {str(key): _plain(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(item) for item in value]
    return value


def within_ratio(value: float, limit: float) -> float:
    """1 when ``value`` is within ``limit``, ``limit / value`` beyond it (0 for a limit of 0).

    The house rule for a "lower is better" figure with no formula of its own: full marks up
    to the limit, then half at twice the limit, a third at three times.
    """
    if value <= limit:
        return 1.0
    return limit / value if limit > 0.0 else 0.0


def figure(value: Any, unit: str = "") -> str:
    """A metric's figure as a person reads it: 4 significant digits and its unit.

    ``0.04499999999999993`` is ``0.045``; None (what it measures never happened) is
    ``none``; a whole number stays whole.
    """
    if value is None:
        return "none"
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return f"{value} {unit}".strip()
    if isinstance(value, float) and not math.isfinite(value):
        return "none"
    text = f"{value:.4g}" if isinstance(value, float) else str(value)
    return f"{text} {unit}".strip()
